"""Helpers the bench's case modules share (they import from here, never from one another
nor from the runner): a case's render context, distortion's procedural texture and its area
averages (the warps' truths), OpenCV remap maps, the glare family's soft-knee highlight and
the per-pixel line blur (the naive method of both motion blurs).

This module's source is part of every cached truth's key (`clfx.bench.cache`).
"""
from __future__ import annotations

import math

import numpy as np

from clfx.core.camera import Camera
from clfx.core.rect import Rect
from clfx.host import RenderContext
from clfx.io.lenses import read_lens
from clfx.pipeline.look import read_image_rgba


# -- a case's render context ---------------------------------------------------------------
def case_context(rt, case: dict, quality: str) -> RenderContext:
    """A `clfx.host.RenderContext` of a case dict (`clfx.bench.cases` protocol) at ``quality``:
    its source and passes uploaded over its data window, its camera, windows and frame."""
    src = np.asarray(case["source"], np.float32)
    window = case.get("data_window") or Rect.from_size(src.shape[1], src.shape[0])
    up = rt.upload(src, window)
    depth = rt.upload(np.asarray(case["depth"], np.float32), window) if case.get("depth") is not None else None
    vel = rt.upload(np.asarray(case["velocity"], np.float32), window) if case.get("velocity") is not None else None
    back = case.get("velocity_back")
    back = rt.upload(np.asarray(back, np.float32), window) if back is not None else None
    return RenderContext(rt, up, depth=depth, velocity=vel, velocity_back=back,
                         display_window=case.get("display_window") or window,
                         pixel_aspect=case.get("pixel_aspect", 1.0), frame=case.get("frame", 1),
                         seed=case.get("seed", 0), camera=case.get("camera") or Camera(),
                         quality=quality, display_referred=case.get("display_referred", False),
                         read_image=read_image_rgba, read_lens=read_lens)


# -- distortion's procedural texture (the warps' cases) ----------------------------------
SUPERSAMPLE = 8
"""Points per axis and pixel of the source's and the truth's area averages."""

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


def box_average(fn, width: int, height: int, ss: int = SUPERSAMPLE) -> np.ndarray:
    """The mean of ``fn(x, y)`` over ss x ss points of every pixel (row by row of points)."""
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float64)
    acc = np.zeros((height, width))
    for oy in (np.arange(ss) + 0.5) / ss:
        for ox in (np.arange(ss) + 0.5) / ss:
            acc += fn(xs + ox, ys + oy)
    return acc / (ss * ss)


def grey_rgba(grey: np.ndarray) -> np.ndarray:
    """A grey image as RGBA (float64): red ``grey``, green 0.9, blue 0.8 of it, alpha 1."""
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


# -- OpenCV remap (the warps' peers) -------------------------------------------------------
def cv2_border(border: str):
    """OpenCV's border mode for a warp's ``border`` parameter."""
    import cv2  # lazy: OpenCV is optional (test extra); the bench's peers go without it

    return {"edge": cv2.BORDER_REPLICATE, "mirror": cv2.BORDER_REFLECT_101}.get(
        border, cv2.BORDER_CONSTANT)


def cv2_map(sx, sy):
    """cv2.remap's float32 maps from source points in clfx's source-window coordinates:
    OpenCV puts pixel centres at integers; points without a source read the border."""
    return (np.where(np.isfinite(sx), sx - 0.5, -1e6).astype(np.float32),
            np.where(np.isfinite(sy), sy - 0.5, -1e6).astype(np.float32))


# -- the glare family ----------------------------------------------------------------------
def soft_knee_highlight(rgb: np.ndarray, threshold: float, knee: float) -> np.ndarray:
    """Host copy of the soft-knee highlight (``kernels/lib/scatter.h``), for the peers."""
    lum = rgb @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    x = np.clip(lum - threshold + knee, 0.0, 2.0 * knee)
    soft = x * x / (4.0 * knee) if knee > 0 else np.zeros_like(lum)
    safe = np.where(lum > 0, lum, 1.0)
    w = np.where(lum > 0, np.clip(np.maximum(soft, lum - threshold) / safe, 0.0, 1.0), 0.0)
    return (rgb * w[..., None]).astype(np.float32)


# -- the per-pixel line blur (motion_blur's and camera_blur's naive method) ---------------
LINE_BLUR_LABEL = "naive per-pixel line blur"


def line_blur_per_pixel(src: np.ndarray, velocity: np.ndarray, t0: float, t1: float, *,
                        spacing: float = 0.5, max_samples: int = 64) -> np.ndarray:
    """Each pixel averaged along its *own* velocity over ``[t0, t1]`` (float32 NumPy).

    Bilinear reads (clamp to edge) at midpoint-rule instants, one per ``spacing`` px of the
    longest blur (at least 2, at most ``max_samples``); no depth, no tiles, no scatter: what a
    per-pixel directional blur does.
    """
    src = np.where(np.isfinite(src), src, 0.0).astype(np.float32)
    v = np.where(np.isfinite(velocity), velocity, 0.0).astype(np.float32)
    h, w = src.shape[:2]
    longest = float(np.hypot(v[..., 0], v[..., 1]).max()) * abs(t1 - t0) if v.size else 0.0
    n = int(min(max(2, math.ceil(longest / spacing)), max_samples))
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    acc = np.zeros_like(src)
    for i in range(n):
        t = np.float32(t0 + (i + 0.5) / n * (t1 - t0))
        u = xs - v[..., 0] * t
        q = ys - v[..., 1] * t
        u0, q0 = np.floor(u), np.floor(q)
        fu, fq = (u - u0)[..., None], (q - q0)[..., None]
        xa, xb = np.clip(u0, 0, w - 1).astype(np.intp), np.clip(u0 + 1, 0, w - 1).astype(np.intp)
        ya, yb = np.clip(q0, 0, h - 1).astype(np.intp), np.clip(q0 + 1, 0, h - 1).astype(np.intp)
        top = src[ya, xa] + (src[ya, xb] - src[ya, xa]) * fu
        bot = src[yb, xa] + (src[yb, xb] - src[yb, xa]) * fu
        acc += top + (bot - top) * fq
    return acc / np.float32(n)
