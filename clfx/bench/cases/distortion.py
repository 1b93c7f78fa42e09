"""Bench cases of distortion: strong barrel and moustache distortion of a procedural texture
with fine detail, scored against the exact distorted image; OpenCV's remap as the peers and
bilinear remap on the exact map as the naive method.

Ground truth
------------
The texture (:func:`clfx.bench.cases.shared.texture`) is a function of continuous source coordinates, band-limited
so that box quadrature converges fast: a zone plate whose local frequency rises to 0.45
cycles/px at the frame corner, a soft checker (period 3.4 px, turned by 17 degrees),
7-segment "glyphs" of Gaussian strokes (sigma 0.45 px, 9x12 px cells) and small HDR lights
(Gaussian spots, peak 40).  The source frame is its area average over each source pixel
(8x8 samples); the truth is the area average of the *exact* distorted image over each
output pixel: 8x8 points per output pixel are sent through the float64 inverse map
(:func:`clfx.plugins.distortion.map_points`) and the texture is evaluated there (0 outside
the source frame: the ``black`` border).  Nothing is resampled from pixels, so the truth
holds what a perfect lens would image: where the map compresses the source (up to ~2x
here), fine detail averages out instead of aliasing.

Cases: ``strong`` (the main case: k1 = -0.35, k2 = 0.12, k3 = -0.01, 24 mm on full frame,
no fit, black border: the source outline shows) and the ``moustache`` variant (k1 = -0.9,
k2 = 0.8 at 21.6 mm: barrel in the middle, pincushion at the corners).
"""
from __future__ import annotations

import numpy as np

from clfx.bench.cases import Case, Naive
from clfx.bench.cases.shared import (SUPERSAMPLE, box_average, cv2_border, cv2_map, edge_mask,
                                     grey_rgba, texture)
from clfx.core.camera import Camera
from clfx.core.rect import Rect
from clfx.plugins.distortion import Distortion, build_map, map_points

TRUTH_DEPENDS = ("clfx.plugins.distortion",)
"""The truth sends points through the plugin's inverse map: a change there rebuilds it."""

STRONG = dict(k1=-0.35, k2=0.12, k3=-0.01, fit="none", border="black")
STRONG_CAMERA = Camera(focal_length=24.0, sensor_width=36.0)
MOUSTACHE = dict(k1=-0.9, k2=0.8, fit="none", border="black")
MOUSTACHE_CAMERA = Camera(focal_length=21.6, sensor_width=36.0)

def source_image(width: int, height: int) -> np.ndarray:
    """The texture area-averaged over each source pixel: RGBA float32 (grey, alpha 1)."""
    grey = box_average(lambda x, y: texture(x, y, width, height), width, height)
    return grey_rgba(grey).astype(np.float32)


def truth_image(params: dict, camera: Camera, width: int, height: int,
                ss: int = SUPERSAMPLE) -> np.ndarray:
    """The exact distorted texture area-averaged over each output pixel (float64 RGBA)."""
    p = Distortion.params(**params)
    frame = Rect(0, 0, width, height)

    def distorted(ox, oy):
        sx, sy = map_points(p, camera, frame, frame, 1.0, ox, oy)
        inside = (sx >= 0) & (sx <= width) & (sy >= 0) & (sy <= height)   # NaN: outside
        return np.where(inside, texture(np.nan_to_num(sx), np.nan_to_num(sy), width, height), 0.0)

    return grey_rgba(box_average(distorted, width, height, ss))


def _make(params: dict, camera: Camera, width: int, height: int) -> dict:
    truth = truth_image(params, camera, width, height)
    return dict(source=source_image(width, height), depth=None, velocity=None,
                params=dict(params), camera=camera, truth=truth, edge_mask=edge_mask(truth))


def make(width, height, rng):
    """Strong barrel (k1 = -0.35, k2 = 0.12, k3 = -0.01) of the procedural texture."""
    return _make(STRONG, STRONG_CAMERA, width, height)


def make_moustache(width, height, rng):
    """Moustache distortion (k1 = -0.9, k2 = 0.8): barrel inside, pincushion outside."""
    return _make(MOUSTACHE, MOUSTACHE_CAMERA, width, height)


def _exact_cv2_maps(params, ctx):
    win = ctx.source.window
    sx, sy, _ = build_map(params, ctx.camera, ctx.display_window, win, ctx.pixel_aspect)
    return cv2_map(sx - win.x0, sy - win.y0)


def peers(case, params, ctx):
    """cv2.remap with the same (float64-inverted) map: bilinear, bicubic and Lanczos-4."""
    try:
        import cv2  # lazy: OpenCV is optional (test extra); the bench's peers go without it
    except ImportError:
        return {}
    src = np.ascontiguousarray(case["source"], np.float32)
    map_x, map_y = _exact_cv2_maps(params, ctx)
    border = cv2_border(params.border)
    cv2.setNumThreads(2)
    return {f"cv2.remap {name}": ((lambda flag=flag: cv2.remap(src, map_x, map_y, flag,
                                                               borderMode=border)), level)
            for name, flag, level in (("bilinear", cv2.INTER_LINEAR, "draft"),
                                      ("cubic", cv2.INTER_CUBIC, "preview"),
                                      ("lanczos4", cv2.INTER_LANCZOS4, "final"))}


def naive(case, params, ctx):
    """Bilinear ``cv2.remap`` on the exact (float64-inverted) map: one point per pixel."""
    import cv2  # lazy: OpenCV is optional (test extra); the bench's peers go without it

    src = np.ascontiguousarray(case["source"], np.float32)
    map_x, map_y = _exact_cv2_maps(params, ctx)
    border = cv2_border(params.border)
    return lambda: cv2.remap(src, map_x, map_y, cv2.INTER_LINEAR, borderMode=border)


CASE = Case(make=make, peers=peers,
            naive=Naive("bilinear remap on the exact map (cv2.remap INTER_LINEAR)", naive),
            variants={"moustache": make_moustache})
