"""Bench case of chromatic aberration: strong spectral CA over an HDR grid; OpenCV's remap of
red and blue as the peer of the three-channel (draft) level."""
from __future__ import annotations

import numpy as np

from clfx.bench.cases import Case
from clfx.bench.cases.shared import cv2_border, cv2_map
from clfx.core.camera import Camera
from clfx.plugins.chromatic_aberration import channel_points


def make(width, height, rng):
    """Strong spectral CA over a high-contrast HDR grid (white lines at 50 on grey)."""
    src = np.full((height, width, 4), 0.18, np.float32)
    src[::max(height // 12, 1), :, :3] = 50.0
    src[:, ::max(width // 20, 1), :3] = 50.0
    src[..., :3] += rng.uniform(0.0, 0.05, (height, width, 3)).astype(np.float32)
    src[..., 3] = 1.0
    return dict(source=src, depth=None, velocity=None,
                params=dict(amount=0.004, cubic=0.3, spectral=True), camera=Camera())


def peers(case, params, ctx):
    """cv2.remap of red and blue with the float64 source points of the three-channel mode
    (the ``draft`` level's operation: green and alpha stay in place), bilinear."""
    try:
        import cv2  # lazy: OpenCV is optional (test extra); the bench's peers go without it
    except ImportError:
        return {}
    src = np.ascontiguousarray(case["source"], np.float32)
    maps = [cv2_map(sx, sy) for sx, sy in
            channel_points(params, ctx.display_window, ctx.source.window, ctx.pixel_aspect)]
    border = cv2_border(params.border)
    cv2.setNumThreads(2)

    def remap_red_blue():
        out = src.copy()
        for c, (mx, my) in zip((0, 2), maps):
            out[..., c] = cv2.remap(np.ascontiguousarray(src[..., c]), mx, my, cv2.INTER_LINEAR,
                                    borderMode=border)
        return out

    return {"cv2.remap bilinear (R, B)": (remap_red_blue, "draft")}


CASE = Case(make=make, peers=peers)
