"""Bench case of grain: 500T-like colour grain over an HDR gradient; OpenCV's randn and
GaussianBlur as the peer (its own random samples: compare times, not pixels)."""
from __future__ import annotations

import math

import numpy as np

from clfx.bench.cases import Case
from clfx.core.camera import Camera
from clfx.plugins.grain import MID_GREY, STOCKS, grain_amounts, grain_sigmas_px


def make(width, height, rng):
    """A representative hard case: an HDR gradient with highlights, 500T-like colour grain."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    base = 0.02 + 1.5 * (x / max(width - 1, 1)) * (y / max(height - 1, 1))
    src = np.empty((height, width, 4), np.float32)
    src[..., 0], src[..., 1], src[..., 2] = base * 1.1, base, base * 0.8
    src[..., 3] = 1.0
    hot = rng.integers(0, height * width, size=max(1, height * width // 50000))
    src.reshape(-1, 4)[hot, :3] = 1e4
    stock = STOCKS["fast-500t"]
    return dict(source=src, depth=None, velocity=None,
                params={"stock": "fast-500t", "amount": stock.nominal_amount,
                        "size": stock.nominal_size, "seed": 7},
                camera=Camera())


def peers(case, params, ctx=None):
    """OpenCV doing the same operation (its own random samples: compare times, not pixels)."""
    try:
        import cv2
    except ImportError:
        return {}
    src = np.asarray(case["source"], np.float32)
    sigmas = grain_sigmas_px(params, src.shape[1])
    amounts = grain_amounts(params)

    def opencv_grain():
        rgb = src[..., :3]
        noise = np.empty(rgb.shape, np.float32)
        cv2.randn(noise, 0.0, 1.0)
        lum = np.clip(rgb @ np.array([0.2126, 0.7152, 0.0722], np.float32), 1e-30, 1e30)
        scale = (lum / MID_GREY) ** params.response
        out = src.copy()
        for c in range(3):
            # continuous-limit normalisation of Gaussian-filtered white noise: 2 sqrt(pi) sigma
            field = cv2.GaussianBlur(np.ascontiguousarray(noise[..., c]), (0, 0), sigmas[c])
            norm = 2 * math.sqrt(math.pi) * sigmas[c]
            out[..., c] = rgb[..., c] + amounts[c] * scale * field * norm
        return out

    return {"opencv randn + GaussianBlur + mix": opencv_grain}


CASE = Case(make=make, peers=peers)
