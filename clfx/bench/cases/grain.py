"""Bench case of grain: 500T-like colour grain over an HDR gradient; OpenCV's randn and
GaussianBlur as the peer; scored by the grain's statistics, not its pixels.

Why pixels are not compared: grain is noise, and what a level must get right is the noise's
*distribution* (how strong it is at each brightness, how large its grains are), not the
value each pixel happened to draw.  A pixel metric scores a level by how closely it repeats
the reference's samples: the draft level, white noise without the grain-size filter, has
the right amplitude but a different field, so its pixel error is about the grain's own
standard deviation, as large as leaving the grain out altogether, and the pixel table
flagged it as losing to the unchanged input (log-PSNR 59.0 vs 59.4).  A peer drawing its
own random numbers (OpenCV) fares even worse.  ``grain_statistics_metrics`` compares
what grain is instead: the residual's standard deviation per block (the brightness
response) and its normalised autocorrelation at small lags (the grain size), so that
no grain scores 0 dB, white noise of the right strength scores in between, and the
filtered levels score high.
"""
from __future__ import annotations

import math

import numpy as np

from clfx.bench.cases import Case
from clfx.core.camera import Camera
from clfx.fx.analysis import meter
from clfx.plugins.grain import D_GREY, FOG, GAMMA, STOCKS, TOE, grain_amounts, grain_sigmas_px


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
                params={"stock": "fast-500t", "amount": stock.nominal_amount, "seed": 7},
                camera=Camera())


def peers(case, params, ctx=None):
    """OpenCV doing the same operation (its own random samples: scored by statistics)."""
    try:
        import cv2  # lazy: OpenCV is optional (test extra); the bench's peers go without it
    except ImportError:
        return {}
    src = np.asarray(case["source"], np.float32)
    width, fmt = src.shape[1], case["camera"].sensor_width
    sigmas = grain_sigmas_px(params, width, fmt)
    amounts = grain_amounts(params, width, fmt)

    def opencv_grain():
        rgb = src[..., :3]
        noise = np.empty(rgb.shape, np.float32)
        # per-channel mean and deviation: scalars 0.0, 1.0 would mean (1, 0, 0, 0), i.e. no
        # noise in green and blue (the statistics metric found that)
        cv2.randn(noise, (0.0,) * 3, (1.0,) * 3)
        finite = np.isfinite(rgb).all(-1)
        lum = np.where(finite, rgb @ np.array([0.2126, 0.7152, 0.0722], np.float32), 0.0)
        h, w = lum.shape
        tiles = [lum[y:y + 32, x:x + 32].mean() for y in range(0, h, 32) for x in range(0, w, 32)]
        grey = params.middle_grey or meter(tiles)
        e = np.clip(rgb / grey, 0.0, 1e30)
        s = np.asarray(amounts, np.float32) * ((FOG + GAMMA * np.log10(1 + e / TOE)) / D_GREY) \
            ** params.response
        out = src.copy()
        for c in range(3):
            # continuous-limit normalisation of Gaussian-filtered white noise: 2 sqrt(pi) sigma
            field = cv2.GaussianBlur(np.ascontiguousarray(noise[..., c]), (0, 0), sigmas[c])
            n = field * 2 * math.sqrt(math.pi) * sigmas[c]
            sc = s[..., c]
            out[..., c] = rgb[..., c] + grey * (e[..., c] + TOE) * np.expm1(sc * n - sc * sc / 2)
        return out

    return {"opencv randn + GaussianBlur + mix": opencv_grain}


# -- statistics metric -----------------------------------------------------------------------
BLOCK_PX = 32
"""Side of the square blocks the residual's standard deviation is measured in."""

LAGS_PX = (1, 2, 4)
"""Horizontal and vertical lags of the residual's autocorrelation (the grain size)."""

HOT = 1e3
"""Source values at or above this (the case's 1e4 hot pixels) exclude their block."""


def _blocks(a: np.ndarray, b: int) -> np.ndarray:
    """(h, w, ...) -> (rows, cols, b, b, ...): the whole b x b blocks of ``a``."""
    ny, nx = a.shape[0] // b, a.shape[1] // b
    a = a[:ny * b, :nx * b]
    return a.reshape(ny, b, nx, b, *a.shape[2:]).swapaxes(1, 2)


def _autocorrelation(z: np.ndarray, valid: np.ndarray, lags) -> np.ndarray:
    """Normalised autocorrelation per channel, shape (3, len(lags), 2) (horizontal,
    vertical), of block residuals ``z`` (rows, cols, b, b, 3) over the ``valid`` (rows,
    cols, 3) blocks; pairs stay inside a block.  A residual of zero has correlation 0."""
    zv = np.where(valid[:, :, None, None, :], z, 0.0)
    power = np.sum(zv * zv, axis=(0, 1, 2, 3))
    rho = np.zeros((3, len(lags), 2))
    for i, lag in enumerate(lags):
        rho[:, i, 0] = np.sum(zv[:, :, :, :-lag] * zv[:, :, :, lag:], axis=(0, 1, 2, 3))
        rho[:, i, 1] = np.sum(zv[:, :, :-lag] * zv[:, :, lag:], axis=(0, 1, 2, 3))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(power[:, None, None] > 0, rho / power[:, None, None], 0.0)


def grain_statistics_metrics(out, ref, case) -> dict:
    """Score a grain output by its statistics against the reference's, not pixel by pixel.

    From the RGB residuals ``r_out = out - source`` and ``r_ref = ref - source`` (the grain
    each added), over whole ``BLOCK_PX`` blocks, leaving out blocks that hold a hot pixel
    (source >= ``HOT``) or a non-finite value, and blocks where the reference adds nothing:

    * amplitude (the brightness response): per block b and channel c the standard
      deviations s_out, s_ref of the residuals;
      ``e_std = sqrt(mean_{b,c} (s_out / s_ref - 1)^2)``;
    * grain size: per channel c, lag l in ``LAGS_PX`` and direction d (horizontal,
      vertical) the normalised autocorrelation rho of the residual divided by s_ref of its
      block (every block weighs the same; pairs within a block; a zero residual has rho
      0); ``e_acf = sqrt(mean_{c,l,d} (rho_out - rho_ref)^2)``,
      ``R^2 = mean_{c,l,d} rho_ref^2``;
    * one relative error ``e = sqrt((e_std^2 + e_acf^2) / (1 + R^2))``.

    The normaliser 1 + R^2 is what no grain scores (s_out = 0: e_std = 1; rho_out = 0:
    e_acf = R), so the unchanged input has e = 1 exactly; the reference against itself has
    e = 0; white noise of the right strength has e ~ R / sqrt(1 + R^2) < 0.71 (its rho is 0
    at every lag); grain twice too strong scores like none.  Grain's levels all draw the
    reference's white noise, so they are compared sample for sample; an output with its
    own samples (the OpenCV peer) has a floor of a few per cent from the block estimates
    (the relative error of a standard deviation over n samples is ~ 1 / sqrt(2 n)).

    Returns the keys the runner's tables and flags read: ``rel_rmse`` = e; ``psnr_log``,
    here the *statistics PSNR* ``20 log10(1 / max(e, 1e-12))`` dB (inf for e = 0; the
    input scores 0 dB, so ``beats input`` means better statistics than no grain);
    ``rmse`` = e_std and ``max_err`` = the largest |s_out / s_ref - 1| of a block; plus
    ``std_rel_err`` (e_std), ``acf_err`` (e_acf) and ``blocks`` (blocks x channels
    compared).  With no block to compare, e is NaN (and every flag says NO).
    """
    src = np.asarray(case["source"], np.float64)[..., :3]
    o = np.asarray(out, np.float64)[..., :3]
    r = np.asarray(ref, np.float64)[..., :3]
    bad = ~(np.isfinite(src) & np.isfinite(o) & np.isfinite(r)).all(-1) | (np.abs(src) >= HOT).any(-1)
    keep = ~bad[..., None]
    res_o = np.where(keep, o - src, 0.0)
    res_r = np.where(keep, r - src, 0.0)
    b = min(BLOCK_PX, *src.shape[:2])
    bo, br = _blocks(res_o, b), _blocks(res_r, b)
    s_o, s_r = bo.std(axis=(2, 3)), br.std(axis=(2, 3))          # (rows, cols, 3)
    valid = ~_blocks(bad, b).any(axis=(2, 3))[..., None] & (s_r > 0)
    n = int(valid.sum())
    if n == 0:
        nan = float("nan")
        return {"rmse": nan, "max_err": nan, "rel_rmse": nan, "psnr_log": nan,
                "std_rel_err": nan, "acf_err": nan, "blocks": 0}
    scale = np.where(valid, s_r, 1.0)[:, :, None, None, :]
    ratio_err = np.abs(s_o / np.where(valid, s_r, 1.0) - 1.0)[valid]
    e_std = float(np.sqrt(np.mean(ratio_err ** 2)))
    lags = [lag for lag in LAGS_PX if lag < b]
    rho_o = _autocorrelation((bo - bo.mean(axis=(2, 3), keepdims=True)) / scale, valid, lags)
    rho_r = _autocorrelation((br - br.mean(axis=(2, 3), keepdims=True)) / scale, valid, lags)
    e_acf = float(np.sqrt(np.mean((rho_o - rho_r) ** 2))) if lags else 0.0
    r2 = float(np.mean(rho_r ** 2)) if lags else 0.0
    e = math.sqrt((e_std ** 2 + e_acf ** 2) / (1.0 + r2))
    psnr = float("inf") if e == 0 else 20 * math.log10(1.0 / max(e, 1e-12))
    return {"rmse": e_std, "max_err": float(ratio_err.max()), "rel_rmse": e, "psnr_log": psnr,
            "std_rel_err": e_std, "acf_err": e_acf, "blocks": n}


CASE = Case(make=make, peers=peers, metrics=grain_statistics_metrics)
