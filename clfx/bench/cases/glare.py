"""Bench case of glare: a 1e5 sun, moderate lights and 1e-2 shadows; peers SciPy's float32 FFT
convolution and OpenCV's filter2D doing the same glare (same highlights, PSF and mix)."""
from __future__ import annotations

import math

import numpy as np

from clfx.bench.cases import Case
from clfx.bench.cases.shared import soft_knee_highlight
from clfx.core.camera import Camera
from clfx.plugins.glare import Glare


def make(width, height, rng):
    """A 1e5 sun, a few moderate lights and 1e-2 shadows; PSF 1025 px wide at 1080p."""
    src = np.empty((height, width, 4), np.float32)
    src[..., :3] = rng.uniform(0.005, 0.02, (height, width, 3))
    src[..., 3] = 1.0
    diag = math.hypot(width, height)
    yy, xx = np.mgrid[0:height, 0:width]
    sun = (xx - 0.62 * width) ** 2 + (yy - 0.38 * height) ** 2 <= (0.004 * diag) ** 2
    src[sun, :3] = 1e5
    for fx, fy, v in ((0.2, 0.7, 20.0), (0.8, 0.8, 5.0), (0.35, 0.25, 50.0)):
        lamp = (xx - fx * width) ** 2 + (yy - fy * height) ** 2 <= (0.006 * diag) ** 2
        src[lamp, :3] = v
    return dict(source=src, depth=None, velocity=None,
                params={"strength": 0.05, "threshold": 1.0, "size": 512.0 / math.hypot(1920, 1080)},
                camera=Camera())


def peers(case, params, ctx):
    """The same glare (same highlights, PSF and mix) with SciPy's float32 FFT convolution and
    with OpenCV's filter2D (DFT-based for large kernels, float64 inside)."""
    kernel = Glare().psf(params, ctx).astype(np.float32)
    src = np.nan_to_num(np.asarray(case["source"], np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    rgb = np.maximum(src[..., :3], 0.0)
    hl = soft_knee_highlight(rgb, params.threshold, params.knee)
    tint = np.asarray(params.tint, np.float32)

    def mix(spread):
        out = src.copy()
        out[..., :3] = src[..., :3] - params.strength * hl + params.strength * tint * spread
        return out

    found = {}
    try:
        from scipy.signal import fftconvolve  # lazy: optional (test extra)

        found["scipy.signal.fftconvolve float32"] = lambda: mix(np.stack(
            [fftconvolve(hl[..., c], kernel, mode="same") for c in range(3)], axis=-1))
    except ImportError:
        pass
    try:
        import cv2  # lazy: OpenCV is optional (test extra); the bench's peers go without it

        cv2.setNumThreads(2)
        found["cv2.filter2D"] = lambda: mix(cv2.filter2D(
            hl, -1, kernel, borderType=cv2.BORDER_CONSTANT))  # PSF symmetric: correlation = convolution
    except ImportError:
        pass
    return found


CASE = Case(make=make, peers=peers)
