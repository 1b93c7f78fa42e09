"""Bench cases of keystone: a 24 mm camera tilted up 20 degrees and swung 12 degrees left
over a procedural texture with fine detail, scored against the exact keystoned image;
OpenCV's warpPerspective with the same homography as the peers and bilinear warpPerspective
as the naive method.

Ground truth
------------
The texture (:func:`clfx.bench.cases.shared.texture`, distortion's) is a function of
continuous source coordinates.  The source is its area average over each pixel (8x8 points);
the truth is the area average of the *exact* keystoned image over each output pixel: 8x8
points per output pixel sent through the float64 inverse map
(:func:`clfx.plugins.keystone.source_points`), the texture evaluated there (0 outside the
source frame: the ``black`` border).  Where the tilt compresses the plate (the top rows read
up to ~1.5x their width here) fine detail averages out instead of aliasing.

Cases: ``tilt`` (the main case: tilt 20, swing -12, no fit, black border: the plate's
outline shows) and the ``steep`` variant (tilt 40 on a 16 mm lens: the top rows compress
~3x).
"""
from __future__ import annotations

import math

import numpy as np

from clfx.bench.cases import Case, Naive
from clfx.bench.cases.shared import (SUPERSAMPLE, box_average, cv2_border, edge_mask,
                                     grey_rgba, texture)
from clfx.core.camera import Camera
from clfx.core.rect import Rect
from clfx.plugins.keystone import Keystone, geometry, source_points

TRUTH_DEPENDS = ("clfx.plugins.keystone",)
"""The truth sends points through the plugin's inverse map: a change there rebuilds it."""

TILT = dict(tilt=20.0, swing=-12.0, fit="none", border="black")
TILT_CAMERA = Camera(focal_length=24.0, sensor_width=36.0)
STEEP = dict(tilt=40.0, fit="none", border="black")
STEEP_CAMERA = Camera(focal_length=16.0, sensor_width=36.0)


def truth_image(params: dict, camera: Camera, width: int, height: int,
                ss: int = SUPERSAMPLE) -> np.ndarray:
    """The exact keystoned texture area-averaged over each output pixel (float64 RGBA)."""
    frame = Rect(0, 0, width, height)
    g = geometry(Keystone.params(**params), camera, frame, frame, 1.0)

    def keystoned(ox, oy):
        sx, sy = source_points(g, ox, oy)
        inside = (sx >= 0) & (sx <= width) & (sy >= 0) & (sy <= height)   # NaN: outside
        return np.where(inside, texture(np.nan_to_num(sx), np.nan_to_num(sy), width, height),
                        0.0)

    return grey_rgba(box_average(keystoned, width, height, ss))


def _make(params: dict, camera: Camera, width: int, height: int) -> dict:
    source = grey_rgba(box_average(lambda x, y: texture(x, y, width, height), width, height))
    truth = truth_image(params, camera, width, height)
    return dict(source=source.astype(np.float32), depth=None, velocity=None,
                params=dict(params), camera=camera, truth=truth, edge_mask=edge_mask(truth))


def make(width, height, rng):
    """Tilt 20 degrees up, swing 12 left, 24 mm on full frame."""
    return _make(TILT, TILT_CAMERA, width, height)


def make_steep(width, height, rng):
    """Tilt 40 degrees up on a 16 mm lens: the top rows compress ~3x."""
    return _make(STEEP, STEEP_CAMERA, width, height)


def homography(params, ctx) -> np.ndarray:
    """warpPerspective's inverse map (output -> source, OpenCV pixel centres at integers,
    source-window coordinates): ``K_s R K_o^-1`` with the centring shift and the fit scale,
    written out from the model (clfx.plugins.keystone's docstring)."""
    win = ctx.source.window
    g = geometry(params, ctx.camera, ctx.display_window, win, ctx.pixel_aspect)
    fx, fy, cx, cy, s = g["fx"], g["fy"], g["cx"], g["cy"], g["fit_scale"]
    t = math.radians(params.tilt), math.radians(params.swing)
    rx = np.array([[1, 0, 0], [0, math.cos(t[0]), -math.sin(t[0])],
                   [0, math.sin(t[0]), math.cos(t[0])]])
    ry = np.array([[math.cos(t[1]), 0, math.sin(t[1])], [0, 1, 0],
                   [-math.sin(t[1]), 0, math.cos(t[1])]])
    r = ry @ rx
    shift = r[0, 2] / r[2, 2], r[1, 2] / r[2, 2]
    k_out = np.array([[s / fx, 0, -cx * s / fx], [0, s / fy, -cy * s / fy], [0, 0, 1]])
    k_src = np.array([[fx, 0, cx - shift[0] * fx], [0, fy, cy - shift[1] * fy], [0, 0, 1]])
    # frame coordinates (centres at +0.5) of the source window -> OpenCV's (at integers)
    to_cv = np.array([[1, 0, -0.5 - win.x0], [0, 1, -0.5 - win.y0], [0, 0, 1]])
    from_cv = np.array([[1, 0, 0.5 + win.x0], [0, 1, 0.5 + win.y0], [0, 0, 1]])
    return to_cv @ k_src @ r @ k_out @ from_cv


def _warp(case, params, ctx, flag):
    import cv2  # lazy: OpenCV is optional (test extra); the bench's peers go without it

    src = np.ascontiguousarray(case["source"], np.float32)
    h = homography(params, ctx)
    size = (src.shape[1], src.shape[0])
    border = cv2_border(params.border)
    cv2.setNumThreads(2)
    return lambda: cv2.warpPerspective(src, h, size, flags=flag | cv2.WARP_INVERSE_MAP,
                                       borderMode=border)


def peers(case, params, ctx):
    """cv2.warpPerspective with the same homography: bilinear, bicubic and Lanczos-4."""
    try:
        import cv2  # lazy: OpenCV is optional (test extra); the bench's peers go without it
    except ImportError:
        return {}
    return {f"cv2.warpPerspective {name}": (_warp(case, params, ctx, flag), level)
            for name, flag, level in (("bilinear", cv2.INTER_LINEAR, "draft"),
                                      ("cubic", cv2.INTER_CUBIC, "preview"),
                                      ("lanczos4", cv2.INTER_LANCZOS4, "final"))}


def naive(case, params, ctx):
    """Bilinear ``cv2.warpPerspective``: one point per pixel."""
    import cv2  # lazy: OpenCV is optional (test extra); the bench's peers go without it

    return _warp(case, params, ctx, cv2.INTER_LINEAR)


CASE = Case(make=make, peers=peers,
            naive=Naive("bilinear homography (cv2.warpPerspective INTER_LINEAR)", naive),
            variants={"steep": make_steep})
