"""Bench cases of breathing: a rack focus on a 35 mm unit-focusing lens scales a procedural
texture with fine detail, scored against the texture rendered at the scaled field of view;
OpenCV's warpAffine as the peers and bilinear warpAffine about the centre as the naive method.

Ground truth
------------
The texture is distortion's (:func:`clfx.bench.cases.shared.texture`: a zone plate up to
0.45 cycles/px, a fine checker, 7-segment glyphs of 0.45 px strokes, HDR spots), a function of
continuous frame coordinates.  The source is its area average over each pixel of the data
window (8x8 points); the truth is the area average over each output pixel of the texture seen
through the breathing lens, ``texture(c + (u - c) / m)`` at 8x8 points per pixel: the scene
rendered at the scaled field of view, nothing resampled from pixels.  Where the view widens
(m < 1) fine detail averages out instead of aliasing.

Cases: ``widen`` (the main case) focuses from 0.35 m (the reference) to 10 m with
``amount`` 1: m = 0.903, the view widens 10.7%, and the input has overscan (a data window
beyond the display window, enough for the widening), so every kept pixel has a source; only
the display window is scored (the truth is NaN in the overscan ring, which the metrics skip).
The ``narrow`` variant racks the other way (10 m to 0.35 m, m = 1.107): the frame crops, no
overscan needed.
"""
from __future__ import annotations

import math

import numpy as np

from clfx.bench.cases import Case, Naive
from clfx.bench.cases.shared import SUPERSAMPLE, box_average, edge_mask, grey_rgba, texture
from clfx.core.camera import Camera
from clfx.core.rect import Rect
from clfx.plugins.breathing import Breathing

TRUTH_DEPENDS = ("clfx.plugins.breathing",)
"""The scale comes from the plugin's thin-lens model (the texture from the shared helpers)."""

NEAR, FAR = 0.35, 10.0
"""The rack focus, metres: a 35 mm lens at 10 focal lengths and at 10 m."""


def _make(focus: float, reference: float, width: int, height: int) -> dict:
    camera = Camera(focal_length=35.0, sensor_width=36.0, focus_distance=focus, breathing=1.0)
    params = {"reference_focus": reference}
    p = Breathing.params(**params)
    m, _ = Breathing().scale(p, _Ctx(camera))
    display = Rect(0, 0, width, height)
    # overscan: what the widening reads past the frame, plus the filters' reach
    margin = max(0, math.ceil(0.5 * max(width, height) * (1.0 / m - 1.0))) + 8 if m < 1 else 0
    data = display.grown(margin)
    cx, cy = display.center

    def frame_texture(x, y):
        return texture(x + data.x0, y + data.y0, width, height)

    def seen(x, y):   # output points (data-window coordinates) through the lens
        fx, fy = x + data.x0, y + data.y0
        return texture(cx + (fx - cx) / m, cy + (fy - cy) / m, width, height)

    source = grey_rgba(box_average(frame_texture, data.width, data.height)).astype(np.float32)
    truth = grey_rgba(box_average(seen, data.width, data.height, SUPERSAMPLE))
    if margin:
        inside = np.zeros(truth.shape[:2], bool)
        inside[margin:margin + height, margin:margin + width] = True
        truth[~inside] = np.nan        # the overscan ring is not kept: not scored
    return dict(source=source, depth=None, velocity=None, params=params, camera=camera,
                data_window=data, display_window=display, truth=truth, edge_mask=edge_mask(truth),
                scale=m)


class _Ctx:
    """What :meth:`Breathing.scale` reads of a render context."""

    def __init__(self, camera):
        self.camera = camera
        self.reference_camera = camera
        self.plans = {}          # Plugin.planned keeps the step's plan here
        self.tiling = None       # a whole frame, not a band of one
        self.tile_pixels = None


def make(width, height, rng):
    """Focus 0.35 m -> 10 m (m = 0.903: the view widens 10.7%), with overscan."""
    return _make(FAR, NEAR, width, height)


def make_narrow(width, height, rng):
    """Focus 10 m -> 0.35 m (m = 1.107: the frame crops), no overscan."""
    return _make(NEAR, FAR, width, height)


def _warp_matrix(case):
    """warpAffine's inverse map (OpenCV pixel centres at integers, data-window coordinates):
    ``s = u / m + (c - 1/2) (1 - 1 / m)`` with c the optical centre (centres at +0.5)."""
    m, data, display = case["scale"], case["data_window"], case["display_window"]
    cx, cy = display.center
    cx, cy = cx - data.x0, cy - data.y0
    inv = 1.0 / m
    return np.array([[inv, 0.0, (cx - 0.5) * (1.0 - inv)], [0.0, inv, (cy - 0.5) * (1.0 - inv)]])


def _warp(case, flag):
    import cv2  # lazy: OpenCV is optional (test extra); the bench's peers go without it

    src = np.ascontiguousarray(case["source"], np.float32)
    mat = _warp_matrix(case)
    size = (src.shape[1], src.shape[0])
    cv2.setNumThreads(2)
    return lambda: cv2.warpAffine(src, mat, size, flags=flag | cv2.WARP_INVERSE_MAP,
                                  borderMode=cv2.BORDER_REPLICATE)


def peers(case, params, ctx):
    """cv2.warpAffine about the centre: bilinear, bicubic and Lanczos-4 (edge border)."""
    try:
        import cv2  # lazy: OpenCV is optional (test extra); the bench's peers go without it
    except ImportError:
        return {}
    return {f"cv2.warpAffine {name}": (_warp(case, flag), level)
            for name, flag, level in (("bilinear", cv2.INTER_LINEAR, "draft"),
                                      ("cubic", cv2.INTER_CUBIC, "preview"),
                                      ("lanczos4", cv2.INTER_LANCZOS4, "final"))}


def naive(case, params, ctx):
    """Bilinear ``cv2.warpAffine``, scaled about the centre: one point per pixel."""
    import cv2  # lazy: OpenCV is optional (test extra); the bench's peers go without it

    return _warp(case, cv2.INTER_LINEAR)


CASE = Case(make=make, peers=peers,
            naive=Naive("bilinear scale about the centre (cv2.warpAffine INTER_LINEAR)", naive),
            variants={"narrow": make_narrow})
