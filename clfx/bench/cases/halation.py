"""Bench case of halation: street lights and a bright window edge on a dim night frame through
CineStill 800T on a Super 35 camera; peers OpenCV's filter2D and SciPy's float32 FFT doing
the same halation (same highlights, PSF and additive mix)."""
from __future__ import annotations

import math

import numpy as np

from clfx.bench.cases import Case
from clfx.bench.cases.shared import soft_knee_highlight
from clfx.core.camera import Camera
from clfx.plugins.halation import Halation


def make(width, height, rng):
    """Dim textured night frame (0.01-0.05), a bright window (20) with a hard edge, a row of
    small lights (50-2000); the stock's PSF (8 x 0.13 mm on a 24.89 mm wide sensor)."""
    src = np.empty((height, width, 4), np.float32)
    src[..., :3] = rng.uniform(0.01, 0.05, (height, width, 3))
    src[..., 3] = 1.0
    src[int(0.55 * height):int(0.8 * height), int(0.1 * width):int(0.35 * width), :3] = \
        (20.0, 16.0, 10.0)
    diag = math.hypot(width, height)
    yy, xx = np.mgrid[0:height, 0:width]
    for i, v in enumerate((50.0, 300.0, 2000.0, 120.0, 800.0)):
        lamp = (xx - (0.45 + 0.1 * i) * width) ** 2 + (yy - 0.3 * height) ** 2 \
            <= (0.003 * diag) ** 2
        src[lamp, :3] = (v, 0.8 * v, 0.5 * v)
    return dict(source=src, depth=None, velocity=None, params={"stock": "cinestill-800t"},
                camera=Camera(focal_length=40.0, sensor_width=24.89))


def peers(case, params, ctx):
    """The same halation with OpenCV's filter2D (DFT inside for large kernels) and SciPy's
    float32 FFT convolution."""
    plugin = Halation()
    s = plugin.settings(params, ctx)
    kernel = plugin.psf(params, ctx).astype(np.float32)
    src = np.nan_to_num(np.asarray(case["source"], np.float32), nan=0.0, posinf=0.0,
                        neginf=0.0)
    hl = soft_knee_highlight(np.maximum(src[..., :3], 0.0), params.threshold, params.knee)
    st = np.float32(s.strength) * np.asarray(s.tint, np.float32)

    def mix(spread):
        out = src.copy()
        out[..., :3] = src[..., :3] + st * np.maximum(spread, 0.0)
        return out

    found = {}
    try:
        import cv2  # lazy: OpenCV is optional (test extra); the bench's peers go without it

        cv2.setNumThreads(2)
        found["cv2.filter2D"] = lambda: mix(cv2.filter2D(
            hl, -1, kernel, borderType=cv2.BORDER_CONSTANT))  # PSF symmetric
    except ImportError:
        pass
    try:
        from scipy.signal import fftconvolve  # lazy: optional (test extra)

        found["scipy.signal.fftconvolve float32"] = lambda: mix(np.stack(
            [fftconvolve(hl[..., c], kernel, mode="same") for c in range(3)], axis=-1))
    except ImportError:
        pass
    return found


CASE = Case(make=make, peers=peers)
