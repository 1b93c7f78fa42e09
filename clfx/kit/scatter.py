"""The glare family's shared base: highlights -> PSF spread -> mix (glare, bleed, soft focus),
and the cheap questions of every effect that spreads its highlights by a PSF (corona).

Effects combine these mixins with ``clfx.host.Plugin``:
``class Glare(ScatterPlugin, Plugin)``.  What differs between effects is declared, not
tested for: the name of the strength parameter (:attr:`SpreadRegions.strength_param`), the
PSF (:meth:`ScatterPlugin.build_psf`), the display-referred boost (:meth:`ScatterPlugin.boost`).

Model (``kernels/lib/scatter.h``; each effect's ``kernels/<effect>.cl`` instantiates
``<effect>_highlights`` and ``<effect>_mix`` from it): per pixel the soft-knee highlight
``h = max(rgb, 0) * clamp(max(s, L - t) / L, 0, 1)``, ``s = clamp(L - t + k, 0, 2k)^2 / 4k``
(luminance ``L``, threshold ``t``, knee ``k``) is convolved with a normalised PSF
(``clfx.fx.fftconv.spread`` at the context's quality level) and mixed back:
``out = c - strength h + strength tint (PSF * h)`` (energy kept); display-referred input is
first expanded by the inverse tone curve of gain ``boost`` and mixed additively
(``out = c + strength tint (PSF * h)``).  Non-finite pixels are set to 0 before the spread and
counted in ``ctx.notes``.
"""
from __future__ import annotations

from typing import ClassVar

import numpy as np

from clfx.core.limits import check_derived
from clfx.core.plugin import FloatParam, RGBParam
from clfx.core.rect import Rect
from clfx.fx import fftconv
from clfx.fx import psf as psflib

SPLIT_RATIO = 1e-3
"""preview: pixels above this fraction of the peak (and above 4 x threshold) are gathered
exactly instead of going through the float32 FFT."""


# -- shared parameter declarations ------------------------------------------------------
def knee_param(default: float) -> FloatParam:
    """The soft knee's width below the threshold."""
    return FloatParam("knee", default, min=0.0, max=1e6,
                      hint="Width of the soft knee below the threshold, in luminance.")


def tint_param(light: str) -> RGBParam:
    """The colour of the spread light (``light``: "scattered", "leaked", ...)."""
    return RGBParam("tint", (1.0, 1.0, 1.0), max=100.0,
                    hint=f"Colour of the {light} light (white keeps energy).")


# -- the cheap questions ----------------------------------------------------------------
class SpreadRegions:
    """Identity and regions of an effect spreading the light above a level by up to
    :meth:`radius_px` pixels (a Plugin mixin).

    Subclasses implement :meth:`radius_px`, and set :attr:`strength_param` when their
    strength parameter is not called ``strength``; :meth:`raw_level` is the source luminance
    above which a pixel contributes (``p.threshold`` unless overridden).
    """

    strength_param: ClassVar[str] = "strength"
    whole_frame: ClassVar[str | None] = (
        "its FFT convolution runs in output blocks of bounded memory (clfx.fx.fftconv: "
        "overlap-save), cheaper than bands that each re-read the PSF radius around them")

    def strength(self, p) -> float:
        return getattr(p, self.strength_param)

    def radius_px(self, p, ctx) -> int:
        raise NotImplementedError

    def raw_level(self, p, ctx) -> float:
        return p.threshold

    def is_identity(self, p, ctx):
        if self.strength(p) == 0.0:
            return f"{self.strength_param} is 0"
        if self.radius_px(p, ctx) < 1:
            return "size is below one pixel"
        if not ctx.analysis.any_above(self.raw_level(p, ctx)):
            return "no pixel above threshold"
        return None

    def region_of_definition(self, p, ctx) -> Rect:
        return ctx.source.window.grown(self.radius_px(p, ctx))

    def region_of_interest(self, p, ctx, window) -> Rect:
        return window.grown(self.radius_px(p, ctx))

    def highlight_support(self, p, ctx) -> Rect:
        """Bounding box of the analysis tiles that hold a contributing pixel."""
        return ctx.analysis.highlight_bounds(self.raw_level(p, ctx))


PSF_BYTES_PER_CELL = 48
"""What building a PSF takes per cell of its (2r + 1)^2 grid: float64 coordinates, radii,
values and the taper's terms (six arrays at the peak)."""


def check_psf(name: str, radius: int, ctx, out_window: Rect) -> tuple[int, int]:
    """The reach of a PSF of ``radius`` px into ``out_window`` (`clfx.fx.fftconv.psf_reach`:
    of a thin 65535x1 frame's 16385^2 cells, 5 rows), refused beyond the frame's memory
    budget before it is built (`clfx.core.limits.check_derived`)."""
    side, win = 2 * int(radius) + 1, ctx.source.window
    reach = fftconv.psf_reach(win, out_window)
    check_derived(psflib.cells_built(radius, reach), PSF_BYTES_PER_CELL, win.width, win.height,
                  ctx.runtime.cache.max_bytes,
                  f"{name}: its {side}x{side} PSF ({radius} px, from the frame's diagonal)")
    return reach


# -- the glare family ------------------------------------------------------------------
class ScatterPlugin(SpreadRegions):
    """Shared machinery of glare, bleed and soft_focus: threshold -> PSF spread -> mix (a
    Plugin mixin).

    Subclasses set ``descriptor`` (its ``kernel`` instantiates ``SCATTER_KERNELS``, its
    quality levels are :class:`clfx.fx.fftconv.SpreadLevel`), implement :meth:`build_psf`,
    and override :meth:`boost` if display-referred input is expanded before spreading.
    """

    # -- parameters -> physics ------------------------------------------------------------
    def boost(self, p, ctx) -> float:
        """Inverse tone curve gain for display-referred input (0: scene-linear)."""
        return 0.0

    def radius_px(self, p, ctx) -> int:
        return psflib.psf_radius_px(p.size, ctx.diagonal_px)

    def build_psf(self, p, ctx, radius: int, reach=None) -> np.ndarray:
        """The PSF of ``radius`` px: the whole (2r + 1)^2, or only its rows and columns within
        ``reach`` = (dy, dx) when ``clfx.fx.psf.windowed`` (normalised as the whole)."""
        raise NotImplementedError

    def psf_key(self, p, ctx) -> tuple:
        """The key :meth:`psf` keeps the PSF under in the runtime's cache: everything it is
        built from (the parameters, radius, reach, frame width and camera), so it names the
        PSF's values; its spectra are cached under it too (``psf_key`` of
        :func:`clfx.fx.fftconv.spread`), not under a hash of its bytes."""
        r = self.radius_px(p, ctx)
        reach = check_psf(self.descriptor.name, r, ctx, self.output_window(p, ctx))
        return (f"{self.descriptor.name}.psf", p.hash_hex(), r, reach, ctx.width_px, ctx.camera)

    def psf(self, p, ctx, key: tuple | None = None) -> np.ndarray:
        """The PSF for this parameter set and frame size (kept in the runtime's cache under
        ``key``, :meth:`psf_key`)."""
        key = key or self.psf_key(p, ctx)
        _, _, r, reach, *_ = key
        return ctx.runtime.cache.get(key, lambda: self.build_psf(p, ctx, r, reach))

    def raw_level(self, p, ctx) -> float:
        """Source luminance above which a pixel contributes (threshold - knee, in input units)."""
        level = max(p.threshold - p.knee, 0.0)
        b = self.boost(p, ctx)
        if b > 0.0:  # invert e(L) = L / (1 - L (1 - 1/B)) on [0, 1)
            level = level / (1.0 + level * (1.0 - 1.0 / b))
        return level

    def note_nonfinite(self, ctx, taps: tuple[int, int]) -> None:
        """Count the frame's non-finite pixels in ``ctx.notes`` (they do not spread)."""
        nonfinite = ctx.analysis.nonfinite_count
        if nonfinite:
            ctx.notes.append(f"{self.descriptor.name}: {nonfinite} non-finite pixel(s) set "
                             f"to 0 before the {taps[1]}x{taps[0]} PSF")

    # -- render ---------------------------------------------------------------------------
    def spread_mixed(self, rt, p, ctx, k: np.ndarray, highlights, mix, split: float,
                     highlights_at=None, psf_key: tuple | None = None):
        """The effect's output: highlights spread by ``k`` (the PSF :meth:`psf` keeps under
        ``psf_key``, when given) and mixed back, block by block.

        ``highlights(src, h)`` launches the effect's highlight kernel (``h`` may be ``src``:
        the kernel works in place), ``mix(g, dst, rect)`` its mix over ``rect`` (``dst`` may
        be ``g``); ``highlights_at(src, h)``, where the effect has one, the highlights of the
        part of ``src`` in ``h``'s window (0 outside it; else a copy of that part takes its
        highlights in place).  :func:`clfx.fx.fftconv.spread` loads each block's highlights from the
        source and hands back each output block, mixed into the output at once: beside the
        source and the output only one block's buffers are on the device (one block, and
        the whole-frame highlight and spread images of old, when the one-grid FFT fits
        :data:`clfx.fx.fftconv.MAX_BLOCK_CELLS`)."""
        src = ctx.source
        out_window = self.output_window(p, ctx)
        out = []                             # the output, made by the first block (one block:
                                             # after its transform's buffers are freed)

        def load(rect):
            if rect == src.window:
                h = rt.image(src.window, 4)
                highlights(src, h)
                return h
            if highlights_at is not None:    # read from the source: no copy of the part
                h = rt.image(rect, 4)
                highlights_at(src, h)
                return h
            sub = rt.reframe(src, rect)      # a copy, replaced by its highlights in place
            highlights(sub, sub)
            return sub

        def emit(rect, g):
            if not out:
                out.append(rt.image(out_window, 4))
            if rect == out_window:
                mix(g, out[0], rect)
                return
            mix(g, g, rect)                  # in place: a work-item reads g, then writes it
            rt.paste(g, out[0], rect)

        info = fftconv.ConvolveInfo()
        fftconv.spread(rt, load, k, self.level(ctx), out_window=out_window,
                       support=self.highlight_support(p, ctx), split_level=split, info=info,
                       emit=emit, psf_key=psf_key)
        ctx.notes.extend(f"{self.descriptor.name}: {note}" for note in info.notes)
        return out[0]

    def render(self, rt, p, ctx):
        name, kfile = self.descriptor.name, self.descriptor.kernel
        src = ctx.source
        key = self.psf_key(p, ctx)
        k = self.psf(p, ctx, key)
        boost = self.boost(p, ctx)
        self.note_nonfinite(ctx, k.shape[:2])
        from pyopencl import cltypes  # lazy: pyopencl is ~0.2 s; `clfx looks` loads this module

        tint = cltypes.make_float4(*p.tint, 0.0)
        hl = rt.kernel(kfile, f"{name}_highlights", **ctx.luminance_defines)
        mx = rt.kernel(kfile, f"{name}_mix", **ctx.luminance_defines)

        def highlights(img, h):
            rt.launch(hl, (img.pitch // 4, max(img.height, 1)), img, h, img.pitch, img.height,
                      p.threshold, p.knee, boost)

        def mix(g, dst, rect):
            dx, dy = rect.offset_in(src.window)
            rt.launch(mx, (dst.pitch // 4, max(dst.height, 1)), src, src.pitch, src.width,
                      src.height, g, dst, dst.pitch, dst.height, dx, dy, self.strength(p), tint,
                      p.threshold, p.knee, boost, boost > 0.0)

        hl_at = rt.kernel(kfile, f"{name}_highlights_at", **ctx.luminance_defines)

        def highlights_at(img, h):
            dx, dy = h.window.offset_in(img.window)
            rt.launch(hl_at, (h.pitch // 4, max(h.height, 1)), img, img.pitch, img.width,
                      img.height, dx, dy, h, h.pitch, h.width, h.height, p.threshold, p.knee,
                      boost)

        split = max(4.0 * p.threshold, SPLIT_RATIO * ctx.analysis.peak_luminance)
        return self.spread_mixed(rt, p, ctx, k, highlights, mix, split, highlights_at, key)
