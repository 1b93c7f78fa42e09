"""Bench cases of distortion: strong barrel and moustache distortion of a procedural texture
with fine detail, scored against the exact distorted image; OpenCV's remap as the peers and
bilinear remap on the exact map as the naive method.

Ground truth
------------
The texture (:func:`texture`) is a function of continuous source coordinates, band-limited
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

import math

import numpy as np

from clfx.bench.cases import Case, Naive
from clfx.core.camera import Camera
from clfx.core.rect import Rect
from clfx.plugins.distortion import Distortion, build_map, map_points

TRUTH_DEPENDS = ("clfx.plugins.distortion",)
"""The truth sends points through the plugin's inverse map: a change there rebuilds it."""

SUPERSAMPLE = 8
"""Points per axis and pixel of the source's and the truth's area averages."""

STRONG = dict(k1=-0.35, k2=0.12, k3=-0.01, fit="none", border="black")
STRONG_CAMERA = Camera(focal_length=24.0, sensor_width=36.0)
MOUSTACHE = dict(k1=-0.9, k2=0.8, fit="none", border="black")
MOUSTACHE_CAMERA = Camera(focal_length=21.6, sensor_width=36.0)

# 7-segment glyph strokes in a 9 x 12 px cell (plus one diagonal), px from the cell's corner
_SEGMENTS = (((2, 2), (7, 2)), ((2, 6), (7, 6)), ((2, 10), (7, 10)), ((2, 2), (2, 6)),
             ((7, 2), (7, 6)), ((2, 6), (2, 10)), ((7, 6), (7, 10)), ((2, 10), (7, 2)))


def texture(x, y, width: int, height: int):
    """The procedural texture at continuous source-frame points (float64, one channel)."""
    x = np.asarray(x, np.float64)
    y = np.asarray(y, np.float64)
    cx, cy = width / 2.0, height / 2.0
    half_diag = max(math.hypot(cx, cy), 1e-9)
    # zone plate: phase pi f r^2 / R, local frequency f r / R cycles/px (0.45 at the corner)
    zone = 0.5 + 0.5 * np.cos(math.pi * 0.45 * ((x - cx) ** 2 + (y - cy) ** 2) / half_diag)
    a = math.radians(17.0)
    u, v = x * math.cos(a) + y * math.sin(a), -x * math.sin(a) + y * math.cos(a)
    checker = 0.5 + 0.5 * np.cos(2 * math.pi * u / 3.4) * np.cos(2 * math.pi * v / 3.4)
    blend = np.clip((x / max(width, 1) - 0.3) / 0.4, 0.0, 1.0)
    out = 0.1 + 0.6 * ((1 - blend) * zone + blend * checker)
    # glyphs: each 9x12 cell lights a pseudo-random subset of the strokes
    ci, cj = np.floor(x / 9.0), np.floor(y / 12.0)
    lx, ly = x - 9.0 * ci, y - 12.0 * cj
    code = np.mod(ci * 73856093.0 + cj * 19349663.0, 251.0)
    strokes = np.zeros_like(x)
    for k, ((x0, y0), (x1, y1)) in enumerate(_SEGMENTS):
        dx, dy = x1 - x0, y1 - y0
        t = np.clip(((lx - x0) * dx + (ly - y0) * dy) / (dx * dx + dy * dy), 0.0, 1.0)
        d2 = (lx - x0 - t * dx) ** 2 + (ly - y0 - t * dy) ** 2
        on = np.mod(np.floor(code / 2 ** k), 2.0) == 1.0
        strokes = np.maximum(strokes, np.where(on, np.exp(-d2 / (2 * 0.45 ** 2)), 0.0))
    out += 2.0 * strokes
    # HDR lights: Gaussian spots (sigma 1.2 px, peak 40) on a sparse lattice
    gx, gy = np.round(x / 61.0) * 61.0 + 17.3, np.round(y / 47.0) * 47.0 + 11.7
    out += 40.0 * np.exp(-((x - gx) ** 2 + (y - gy) ** 2) / (2 * 1.2 ** 2))
    return out


def _box_average(fn, width: int, height: int, ss: int = SUPERSAMPLE) -> np.ndarray:
    """The mean of ``fn(x, y)`` over ss x ss points of every pixel (row by row of points)."""
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float64)
    acc = np.zeros((height, width))
    for oy in (np.arange(ss) + 0.5) / ss:
        for ox in (np.arange(ss) + 0.5) / ss:
            acc += fn(xs + ox, ys + oy)
    return acc / (ss * ss)


def source_image(width: int, height: int) -> np.ndarray:
    """The texture area-averaged over each source pixel: RGBA float32 (grey, alpha 1)."""
    grey = _box_average(lambda x, y: texture(x, y, width, height), width, height)
    return _rgba(grey).astype(np.float32)


def truth_image(params: dict, camera: Camera, width: int, height: int,
                ss: int = SUPERSAMPLE) -> np.ndarray:
    """The exact distorted texture area-averaged over each output pixel (float64 RGBA)."""
    p = Distortion.params(**params)
    frame = Rect(0, 0, width, height)

    def distorted(ox, oy):
        sx, sy = map_points(p, camera, frame, frame, 1.0, ox, oy)
        inside = (sx >= 0) & (sx <= width) & (sy >= 0) & (sy <= height)   # NaN: outside
        return np.where(inside, texture(np.nan_to_num(sx), np.nan_to_num(sy), width, height), 0.0)

    return _rgba(_box_average(distorted, width, height, ss))


def _rgba(grey: np.ndarray) -> np.ndarray:
    out = np.empty(grey.shape + (4,))
    out[..., 0] = grey
    out[..., 1] = 0.9 * grey
    out[..., 2] = 0.8 * grey
    out[..., 3] = 1.0
    return out


def edge_mask(truth: np.ndarray) -> np.ndarray:
    """The fine detail: pixels where the truth's log tone map changes by more than 0.25 to a
    neighbour (glyph strokes, lights, the source outline), grown by one pixel."""
    t = np.log1p(np.maximum(truth[..., 0], 0.0))
    g = np.zeros(t.shape, bool)
    g[:, 1:] |= np.abs(np.diff(t, axis=1)) > 0.25
    g[:, :-1] |= np.abs(np.diff(t, axis=1)) > 0.25
    g[1:] |= np.abs(np.diff(t, axis=0)) > 0.25
    g[:-1] |= np.abs(np.diff(t, axis=0)) > 0.25
    grown = g.copy()
    grown[1:] |= g[:-1]
    grown[:-1] |= g[1:]
    grown[:, 1:] |= g[:, :-1]
    grown[:, :-1] |= g[:, 1:]
    return grown


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


def cv2_border(border: str):
    """OpenCV's border mode for a warp's ``border`` parameter."""
    import cv2

    return {"edge": cv2.BORDER_REPLICATE, "mirror": cv2.BORDER_REFLECT_101}.get(
        border, cv2.BORDER_CONSTANT)


def cv2_map(sx, sy):
    """cv2.remap's float32 maps from source points in clfx's source-window coordinates:
    OpenCV puts pixel centres at integers; points without a source read the border."""
    return (np.where(np.isfinite(sx), sx - 0.5, -1e6).astype(np.float32),
            np.where(np.isfinite(sy), sy - 0.5, -1e6).astype(np.float32))


def _exact_cv2_maps(params, ctx):
    win = ctx.source.window
    sx, sy, _ = build_map(params, ctx.camera, ctx.display_window, win, ctx.pixel_aspect)
    return cv2_map(sx - win.x0, sy - win.y0)


def peers(case, params, ctx):
    """cv2.remap with the same (float64-inverted) map: bilinear, bicubic and Lanczos-4."""
    try:
        import cv2
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
    import cv2

    src = np.ascontiguousarray(case["source"], np.float32)
    map_x, map_y = _exact_cv2_maps(params, ctx)
    border = cv2_border(params.border)
    return lambda: cv2.remap(src, map_x, map_y, cv2.INTER_LINEAR, borderMode=border)


CASE = Case(make=make, peers=peers,
            naive=Naive("bilinear remap on the exact map (cv2.remap INTER_LINEAR)", naive),
            variants={"moustache": make_moustache})
