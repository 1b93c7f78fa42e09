"""Error metrics against ground truth, overall and near depth/velocity discontinuities.

Post-process depth of field and motion blur fail at edges (partial occlusion, bleeding), so
errors are reported over the whole frame and over an *edge band*: the pixels within
``radius_px`` (Euclidean) of a discontinuity of the depth or velocity pass.  Errors are taken
over RGB (alpha is reported by the effects unchanged or trivially).

``psnr_log`` compares after a log tone map ``log(1 + max(x, 0))``, so a 1e3 highlight does not
drown the error of the shadows.
"""
from __future__ import annotations

import math

import numpy as np

EDGE_BAND_PX = 4.0
"""Pixels within this distance of a depth or velocity discontinuity form the bench's edge
band (`edge_band`'s ``radius_px`` wherever a case or a level is scored)."""


def _edges(values: np.ndarray, is_jump) -> np.ndarray:
    """Both pixels of every 4-neighbour pair (along rows and columns) where
    ``is_jump(a, b)`` holds for their values."""
    out = np.zeros(values.shape[:2], bool)
    for axis in (0, 1):
        n = values.shape[axis]
        a = np.take(values, np.arange(0, n - 1), axis=axis)
        b = np.take(values, np.arange(1, n), axis=axis)
        with np.errstate(invalid="ignore"):
            jump = is_jump(a, b)
        lo, hi = [slice(None)] * 2, [slice(None)] * 2
        lo[axis], hi[axis] = slice(0, -1), slice(1, None)
        out[tuple(lo)] |= jump
        out[tuple(hi)] |= jump
    return out


def depth_edges(depth: np.ndarray, rel_tol: float = 0.02) -> np.ndarray:
    """Pixels next to a depth discontinuity (4-neighbourhood).

    Compared in inverse depth (disparity), in which the CoC is linear: a jump larger than
    ``rel_tol`` of the larger disparity is an edge; +inf (background) is disparity 0; NaN,
    0 and negatives count as edges against anything.
    """
    z = np.asarray(depth, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.where(z > 0, 1.0 / z, np.nan)
    d = np.where(np.isposinf(z), 0.0, d)
    return _edges(d, lambda a, b: ~(np.abs(a - b) <= rel_tol * np.maximum(np.abs(a), np.abs(b))))


def velocity_edges(velocity: np.ndarray, tol_px: float = 0.5) -> np.ndarray:
    """Pixels next to a jump of more than ``tol_px`` px/frame in the velocity pass."""
    v = np.asarray(velocity, np.float64)
    return _edges(v, lambda a, b: ~(np.hypot(*np.moveaxis(a - b, -1, 0)) <= tol_px))


def dilate(mask: np.ndarray, radius_px: float) -> np.ndarray:
    """Binary dilation by a Euclidean disk of ``radius_px`` (rows of horizontal dilations)."""
    mask = np.asarray(mask, bool)
    r = int(math.floor(radius_px))
    if r <= 0 or not mask.any():
        return mask.copy()
    h, w = mask.shape
    horiz = [mask]
    for k in range(1, r + 1):   # horiz[k] = mask dilated by k pixels along x
        prev = horiz[-1].copy()
        prev[:, k:] |= mask[:, :-k] if k < w else False
        prev[:, :-k] |= mask[:, k:] if k < w else False
        horiz.append(prev)
    out = np.zeros_like(mask)
    for dy in range(-r, r + 1):
        hw = int(math.floor(math.sqrt(max(radius_px ** 2 - dy * dy, 0.0))))
        src = horiz[min(hw, r)]
        if abs(dy) >= h:
            continue
        if dy >= 0:
            out[dy:] |= src[:h - dy]
        else:
            out[:dy] |= src[-dy:]
    return out


def edge_band(depth, velocity=None, radius_px: float = EDGE_BAND_PX, *, rel_tol: float = 0.02,
              tol_px: float = 0.5) -> np.ndarray:
    """Boolean mask of the pixels within ``radius_px`` of a depth or velocity discontinuity.

    Either pass may be None (then only the other one counts).
    """
    if depth is None and velocity is None:
        raise ValueError("edge_band needs a depth or a velocity pass")
    shape = (depth if depth is not None else velocity).shape[:2]
    edges = np.zeros(shape, bool)
    if depth is not None:
        edges |= depth_edges(depth, rel_tol)
    if velocity is not None:
        edges |= velocity_edges(velocity, tol_px)
    return dilate(edges, radius_px)


def _rgb_diff(a, b, mask):
    a = np.asarray(a, np.float64)[..., :3]
    b = np.asarray(b, np.float64)[..., :3]
    d = a - b
    if mask is not None:
        d = d[np.asarray(mask, bool)]
    return d


def rmse(a, b, mask=None) -> float:
    """Root-mean-square RGB difference (over ``mask`` if given; NaN if it is empty)."""
    d = _rgb_diff(a, b, mask)
    return float(np.sqrt(np.mean(d * d))) if d.size else math.nan


def max_err(a, b, mask=None) -> float:
    """Largest absolute RGB difference (over ``mask``)."""
    d = _rgb_diff(a, b, mask)
    return float(np.abs(d).max()) if d.size else math.nan


def log_tonemap(x):
    """``log(1 + max(x, 0))``: compresses HDR highlights; NaN stays NaN."""
    return np.log1p(np.maximum(np.asarray(x, np.float64), 0.0))


def psnr_log(a, reference, mask=None) -> float:
    """PSNR (dB) of ``a`` against ``reference`` after :func:`log_tonemap`.

    The peak is the reference's largest tone-mapped RGB value.  Identical images give +inf.
    """
    ta, tr = log_tonemap(np.asarray(a)[..., :3]), log_tonemap(np.asarray(reference)[..., :3])
    e = rmse(ta, tr, mask)
    peak = float(tr.max()) if tr.size else 0.0
    if e == 0.0:
        return math.inf
    return 20.0 * math.log10(max(peak, 1e-12) / e)


def compare(result, truth, depth=None, velocity=None, radius_px: float = EDGE_BAND_PX) -> dict:
    """Overall and edge-band RMSE, max error and log-PSNR of ``result`` against ``truth``."""
    band = edge_band(depth, velocity, radius_px) if (depth is not None or velocity is not None) else None
    d = {"rmse": rmse(result, truth), "max_err": max_err(result, truth),
         "psnr_log": psnr_log(result, truth)}
    if band is not None:
        d.update(edge_rmse=rmse(result, truth, band), edge_max_err=max_err(result, truth, band),
                 edge_psnr_log=psnr_log(result, truth, band), edge_fraction=float(band.mean()))
    return d


# -- the bench's scores of a level, a baseline or a peer ------------------------------------
def _rgb(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, np.float64)
    return a[..., :3] if a.ndim == 3 else a


def error_metrics(out: np.ndarray, ref: np.ndarray, edge: np.ndarray | None = None) -> dict:
    """RMSE / max in linear light, relative RMSE, RMSE and PSNR after log(1 + x) (what an
    eye sees of HDR errors: linear RMSE is dominated by the brightest pixels), edge-band RMSE."""
    o, r = _rgb(out), _rgb(ref)
    finite = np.isfinite(r)
    o = np.where(finite, np.nan_to_num(o, nan=1e30, posinf=1e30, neginf=-1e30), 0.0)
    r = np.where(finite, r, 0.0)
    diff = o - r
    rmse = float(np.sqrt(np.mean(diff ** 2))) if diff.size else 0.0
    rms_ref = float(np.sqrt(np.mean(r ** 2))) if r.size else 0.0
    lo, lr = np.log1p(np.maximum(o, 0)), np.log1p(np.maximum(r, 0))
    peak = max(float(lr.max()) if lr.size else 0.0, 1e-12)
    mse_log = float(np.mean((lo - lr) ** 2)) if lo.size else 0.0
    psnr = float("inf") if mse_log == 0 else 10 * math.log10(peak ** 2 / mse_log)
    m = {"rmse": rmse, "max_err": float(np.abs(diff).max()) if diff.size else 0.0,
         "rel_rmse": rmse / rms_ref if rms_ref > 0 else rmse, "psnr_log": psnr,
         "log_rmse": math.sqrt(mse_log)}
    if edge is not None and edge.any():
        m["edge_rmse"] = float(np.sqrt(np.mean(diff[edge] ** 2)))
    return m
