"""Bench case of defocus: noisy texture with HDR highlights, beside OpenCV's Gaussian blur."""
from __future__ import annotations

import math

import numpy as np

from clfx.bench.cases import Case
from clfx.core.camera import Camera
from clfx.plugins.defocus import defocus_sigmas


def make(width: int, height: int, rng) -> dict:
    """A representative hard case: noisy texture with HDR highlights, sigma ~50 px at 1080p."""
    src = rng.uniform(0.0, 1.0, (height, width, 4)).astype(np.float32)
    src[..., 3] = 1.0
    n = max(1, width * height // 20000)
    ys, xs = rng.integers(0, height, n), rng.integers(0, width, n)
    src[ys, xs, :3] = 1e4  # highlights: blur must stay positive, energy conserved
    return dict(source=src, depth=None, velocity=None,
                params={"size": 50.0 / math.hypot(1920, 1080), "aspect": 1.0, "edges": "clamp"},
                camera=Camera())


def peers(case, params, ctx) -> dict:
    """OpenCV's Gaussian blur of the same sigma and edge mode (what a user reaches for)."""
    try:
        import cv2  # lazy: OpenCV is optional (test extra); the bench's peers go without it
    except ImportError:
        return {}
    src = np.ascontiguousarray(case["source"], np.float32)
    sx, sy = defocus_sigmas(params, ctx)
    border = {"clamp": cv2.BORDER_REPLICATE, "mirror": cv2.BORDER_REFLECT_101,
              "black": cv2.BORDER_CONSTANT}[params.edges]
    cv2.setNumThreads(2)
    return {"cv2.GaussianBlur": lambda: cv2.GaussianBlur(src, (0, 0), sx, sigmaY=sy,
                                                         borderType=border)}


CASE = Case(make=make, peers=peers)
