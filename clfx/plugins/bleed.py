"""Bleed: sensor crosstalk, a small-radius glare around bright pixels.

Model
-----
Charge and light leak from a photosite to its neighbours (electrical crosstalk, diffusion in
the silicon, blooming of saturated wells).  The leak falls off roughly exponentially with
distance: PSF ``exp(-d / (r / 3))`` truncated at ``d <= r + 0.5``, ``r = size x diagonal``
(a few pixels).  Pixels above ``threshold`` (soft knee, as glare) lose ``strength`` of their
light, which lands on the neighbourhood: ``out = c - strength h + strength tint (PSF * h)`` —
energy is kept.

Algorithms
----------
PSF radius <= :data:`MAX_FUSED_RADIUS` px (the usual case: 4 px at 1080p, 9 px at 4K) takes a
fused path in ``kernels/bleed.cl``:

1. the highlight image is written on a zero-padded grid around the output window, with one
   flag per 4 x 8 pixel block telling whether any highlight is non-zero;
2. each 4 x 8 output block is marked active if a non-zero highlight is within ``r`` px;
3. inactive blocks copy the source (nothing arrives, nothing leaves); active blocks gather the
   highlights and mix in the same kernel.  The gather holds 8 output rows x 4 RGBA pixels per
   work-item (float16 vectors, compile-time radius, unrolled, taps outside the disc skipped):

   - final: the exact PSF, float32 weights and sums;
   - reference: the exact PSF, float64 weights and sums;
   - preview / draft: a rank-2 / rank-1 separable approximation of the PSF (its largest
     eigenpairs, ``K ~ sum_k s_k u_k u_k^T``, rescaled to unit sum so energy is kept), float32.
     The exponential's cusp keeps the rank low-pass: the PSF's L1 error (fraction of the leaked
     light misplaced, :func:`separable_psf_error`) is 0 / 0.074 at r = 1, 0.025 / 0.24 at
     r = 2, 0.047 / 0.18 at r = 4, 0.059 / 0.14 at r = 7 (rank 2 / rank 1).

Larger PSFs use the glare family's machinery (``clfx.kit.scatter.ScatterPlugin``,
``clfx.fx.fftconv.spread``).  The quality levels (:data:`LEVELS`) are ``BleedLevel`` data: the
separable rank of the fused path, and ``clfx.fx.fftconv.LEVELS``' settings for larger PSFs.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from clfx.core.plugin import Descriptor, FloatParam
from clfx.fx import fftconv
from clfx.fx import psf as psflib
from clfx.host import Plugin, register
from clfx.kit.scatter import ScatterPlugin, knee_param, tint_param

MAX_FUSED_RADIUS = 10
"""PSF radii (px) up to this (21 x 21 taps) take the fused direct/separable path."""
BLOCK_ROWS = 8
"""Output rows per work-item of the fused gather (and rows per skip block)."""


@dataclass(frozen=True)
class BleedLevel(fftconv.SpreadLevel):
    """A bleed quality level: ``rank`` of the separable PSF approximation on the fused path
    (0: the exact PSF, float64 weights and sums with ``small_fp64``); PSFs larger than
    :data:`MAX_FUSED_RADIUS` go through :func:`clfx.fx.fftconv.spread` with the inherited
    settings."""

    rank: int = 0


LEVELS = {
    q: fftconv.spread_level(BleedLevel, q, f"radius <= 10 px: {fused}; larger: "
                            + fftconv.LEVELS[q].summary, rank=rank)
    for q, (fused, rank) in {
        "draft": ("rank-1 separable PSF (L1 error 0.07-0.24 of the leaked light), float32, "
                  "only blocks near highlights", 1),
        "preview": ("rank-2 separable PSF (L1 error 0-0.06 of the leaked light), float32, "
                    "only blocks near highlights", 2),
        "final": ("exact PSF, direct float32 gather, only blocks near highlights", 0),
        "reference": ("exact PSF, direct gather with float64 weights and sums", 0),
    }.items()
}


def separable_psf(k: np.ndarray, rank: int) -> tuple[np.ndarray, np.ndarray]:
    """Rank-``rank`` separable approximation of a symmetric PSF ``k`` (2r+1 square).

    Returns ``(h, v)``, each (rank, 2r+1): ``k ~ sum_k outer(v[k], h[k])`` with the
    eigenpairs of largest magnitude (the optimal approximation of that rank in the Frobenius
    norm), rescaled so the approximation sums to 1 like ``k`` (energy is kept).
    """
    k = np.asarray(k, np.float64)
    lam, vecs = np.linalg.eigh(0.5 * (k + k.T))
    order = np.argsort(-np.abs(lam))[:rank]
    h = vecs[:, order].T
    v = lam[order, None] * h
    total = float(np.sum(v.sum(axis=1) * h.sum(axis=1)))
    return h, v / total


def separable_psf_error(k: np.ndarray, rank: int) -> float:
    """L1 distance between ``k`` and its rank-``rank`` approximation: the fraction of the
    leaked light that lands on the wrong pixel (an upper bound of the error relative to the
    leaked light)."""
    h, v = separable_psf(k, rank)
    return float(np.abs(np.einsum("ki,kj->ij", v, h) - k).sum())


@register
class Bleed(ScatterPlugin, Plugin):
    whole_frame = ("its FFT path runs in output blocks of bounded memory (clfx.fx.fftconv); "
                   "its fused small-radius gather is not shown to give the same pixels in tiles")
    descriptor = Descriptor(
        name="bleed", label="Bleed", group="Sensor", kernel="bleed.cl",
        summary="Sensor crosstalk: bright pixels leak a little light into their neighbours.",
        spreads_light=True,
        params=(
            FloatParam("strength", 0.2, min=0.0, max=1.0,
                       hint="Fraction of a bright pixel's light that leaks to its neighbours."),
            FloatParam("threshold", 1.0, min=0.0, max=1e6,
                       hint="Scene-linear luminance where leaking starts (sensor saturation)."),
            knee_param(0.25),
            FloatParam("size", 0.002, min=0.0, max=0.1,
                       hint="Leak radius as a fraction of the frame diagonal (0.002 = ~4 px at 1080p)."),
            tint_param("leaked"),
        ),
        quality=LEVELS,
    )

    def build_psf(self, p, ctx, radius, reach=None):
        return psflib.exponential(radius, radius / 3.0, reach)

    # -- fused small-PSF path ---------------------------------------------------------------
    def _weights(self, rt, p, ctx, lvl: BleedLevel):
        """Device weights for ``lvl`` (kept in the runtime's cache): the separable factors
        (h, v), or the exact PSF (float64 where ``small_fp64`` is granted, else float32)."""
        r = self.radius_px(p, ctx)
        fp64 = rt.use_fp64(lvl.small_fp64)

        def build():
            k = self.psf(p, ctx)
            if lvl.rank:
                h, v = separable_psf(k, lvl.rank)
                return rt.to_device(h.astype(np.float32)), rt.to_device(v.astype(np.float32))
            return (rt.to_device(np.ascontiguousarray(k, np.float64 if fp64 else np.float32)),)

        return rt.cache.get(("bleed.weights", r, lvl.rank, fp64), build)

    def render(self, rt, p, ctx):
        r = self.radius_px(p, ctx)
        if r > MAX_FUSED_RADIUS:
            return super().render(rt, p, ctx)
        src = ctx.source
        taps = 2 * r + 1
        self.note_nonfinite(ctx, (taps, taps))
        lvl = self.level(ctx)
        defines = dict(RADIUS=r, ROWS=BLOCK_ROWS, fp64=lvl.small_fp64, **ctx.luminance_defines)
        if lvl.rank:
            defines["RANK"] = lvl.rank
        weights = self._weights(rt, p, ctx, lvl)
        out_window = self.output_window(p, ctx)
        dst = rt.image(out_window, 4)
        # padded highlight grid: output pixel (x, y) <-> hp pixel (x + padx, y + r)
        padx = 4 * math.ceil(r / 4)
        blocks_x, blocks_y = dst.pitch // 4, math.ceil(dst.height / BLOCK_ROWS)
        hpitch, hheight = dst.pitch + 2 * padx, blocks_y * BLOCK_ROWS + 2 * r
        fblocks_y = math.ceil(hheight / BLOCK_ROWS)
        hp = rt.buffer(hpitch * hheight * 16)
        flags = rt.buffer((hpitch // 4) * fblocks_y)
        active = rt.buffer(blocks_x * blocks_y)
        dx, dy = out_window.offset_in(src.window)
        kfile = self.descriptor.kernel
        rt.launch(rt.kernel(kfile, "bleed_pad_highlights", **defines), (hpitch // 4, fblocks_y),
                  src, src.pitch, src.width, src.height, padx - dx, r - dy, hp, hpitch, hheight,
                  flags, p.threshold, p.knee)
        rt.launch(rt.kernel(kfile, "bleed_active", **defines), (blocks_x, blocks_y), flags,
                  hpitch // 4, fblocks_y, active, dst.pitch, blocks_y)
        from pyopencl import cltypes  # lazy: pyopencl is ~0.2 s; listing the effects loads this module

        tint = cltypes.make_float4(*p.tint, 0.0)
        name = "bleed_separable_mix" if lvl.rank else "bleed_direct_mix"
        rows = blocks_y if lvl.rank else dst.height   # direct: one row per work-item
        rt.launch(rt.kernel(kfile, name, **defines), (blocks_x, rows), hp, hpitch, active, src,
                  src.pitch, src.width, src.height, dst, dst.pitch, dst.height, dx, dy, p.strength,
                  tint, *weights)
        return dst
