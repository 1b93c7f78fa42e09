"""Halation: light reflected off the film base re-exposes the emulsion, mostly its red layer.

Model
-----
Light that crosses the emulsion (blue-, green-, then red-sensitive layer) reaches the base;
what the anti-halation layer does not absorb is reflected at the base's back surface and
re-enters the emulsion from behind, where it meets the red-sensitive layer first: a red-orange
glow hugging bright edges and lights.

*Highlights.*  The light that does this is the soft-knee highlight of the glare family
(``clfx.kit.scatter``, ``kernels/lib/scatter.h``): ``h = max(rgb, 0) clamp(max(s, L - t) / L,
0, 1)``, ``s = clamp(L - t + k, 0, 2k)^2 / 4k`` (Rec.709 luminance ``L``, ``threshold`` t,
``knee`` k).  Halation is linear in exposure; the threshold keeps it to where it shows.

*PSF* (:func:`halation_psf`).  Light scattered in the emulsion enters a base of thickness
``b`` and index ``n`` (1.5) diffusely (Lambertian); a ray at angle ``theta`` comes back
``d = 2 b tan(theta)`` away.  Unfolding the path, the returning irradiance at ``d`` is that of
a Lambertian source at distance ``H = 2 b``: ``cos^4(theta) = 1 / (1 + (d / H)^2)^2``.  What
comes back is then spread again: the emulsion is a turbid layer (the light re-enters it from
behind and diffuses sideways before it exposes the red layer), and a bare back returns light
more than once (each bounce between emulsion and back goes further and comes back weaker).
Multiple scattering falls off roughly exponentially, so the PSF is

    P(d) ~ cos^4(theta) exp(-d / (lambda H)),

a centre-peaked glow hugging the light (photographs of CineStill's halation show a glow,
not a ring):

- a *bare* back (no rem-jet; an anti-halation dye layer under the emulsion, or none at all)
  reflects by Fresnel's law, 4 % at normal incidence and totally beyond the critical angle
  ``asin(1 / n)`` = 41.8 degrees: most of the light comes back, bounces again, and travels
  far: ``lambda`` = 1 (the first return alone would be a ring at 0.89 H; the bounces and the
  emulsion's diffusion fill it in);
- a back coated with an absorbing backing in optical contact (Kodak's carbon rem-jet) has no
  total internal reflection; what little returns comes from near the normal: ``lambda`` = 0.4,
  a faint, tight glow.

The support radius is :data:`SUPPORT` H for the back (6 H bare, 4 H backed); the profile is
below 1e-5 of the PSF one pixel out by 0.9 x that radius and ends there smoothly
(``clfx.fx.psf.tail_fade``: no disc edge, no rim).  Pixels are area-integrated (8 x 8 samples
up to 16 px, fewer for larger PSFs: :func:`supersample`) and the PSF is normalised to sum 1.
Its radius is at most half the frame diagonal (a stock on a tiny sensor is clamped to it).

*Mix and energy.*  ``out = c + strength tint (PSF * h)`` per channel, alpha kept.  The PSF sums
to 1 and the region of definition grows by its radius, so the spread itself neither creates
nor loses light: the halo carries exactly ``strength tint_c sum(h_c)`` of each channel.  The
highlight is *not* dimmed by default: on film the reflected light is extra exposure (it
already exposed the layers on its way down; the reflection returns light that would otherwise
leave through the back or be absorbed by the backing), so the total light grows by that
amount.  ``conserve`` instead takes the halo's light from the highlight itself
(``out = c - strength tint h + strength tint (PSF * h)``), so each channel's total is kept
exactly (a redistribution, for footage that must not brighten).

Stocks
------
``stock`` supplies ``strength``, ``tint`` and the physical ``radius`` (from the base
thickness ``b``: SUPPORT x H = SUPPORT x 2 b on the film, converted to pixels through the
camera block's ``sensor_width``); a parameter set explicitly (not -1) overrides the stock's value.
Sources (what they state) and estimates (what they do not):

``vision3-500t`` / ``vision3-250d``
    Kodak VISION3 500T 5219 and 250D 5207 colour negative (Kodak technical data H-1-5219,
    H-1-5207): "clear acetate safety base with rem-jet backing", i.e. an absorbing carbon
    backing on the back of the base: a faint, tight glow.  Base 0.13 mm (acetate motion
    picture bases are 0.12-0.14 mm; Kodak gives 120 micrometres for its ESTAR bases, e.g.
    H-1-5242t): estimate.  Strength 0.02 / 0.015, tint: estimates.
``cinestill-800t``
    CineStill 800T: VISION3 500T with the rem-jet removed at the factory for C-41 processing
    (CineStill's product description): a bare base, the strong red halo the stock is known
    for.  Base 0.13 mm as 5219; strength 0.25 and the red tint: estimates.
``portra-400``
    Kodak Portra 400 (technical data E-4050): a still colour negative with an
    anti-halation layer that processing removes, no rem-jet: a bare base behind a dye that
    absorbs most of the light, a faint orange glow.  Base 0.125 mm, strength 0.03, tint:
    estimates.
``phoenix-200``
    Harman Phoenix 200 colour negative, sold as having strong halation (no anti-halation
    layer; users describe its halos as more orange than CineStill's red).  Base 0.125 mm,
    strength 0.3, tint: estimates.

Every strength and tint above is a by-eye estimate of the stocks' relative look, not a
measurement; no manufacturer publishes halation PSFs.

Implementation: the glare family's highlight kernel (``kernels/lib/scatter.h``), the PSF
spread by ``clfx.fx.fftconv.spread`` at the quality level's settings (``fftconv.LEVELS``:
PSFs up to 21 x 21 taps gathered directly, larger ones by FFT), and ``halation_mix``.
Non-finite input pixels are set to 0 and do not spread (counted in ``ctx.notes``).

References
----------
Kodak publications H-1-5219 (VISION3 500T), H-1-5207 (VISION3 250D), H-1-5242t (ESTAR base
thickness), E-4050 (Portra 400); CineStill 800T product description (rem-jet removed);
Wikipedia, "Anti-halation backing" (the red layer meets the reflected light first).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from clfx.core.errors import ParamError
from clfx.core.plugin import BoolParam, ChoiceParam, Descriptor, FloatParam, RGBParam
from clfx.fx import fftconv
from clfx.fx import psf as psflib
from clfx.host import Plugin, register
from clfx.kit.scatter import ScatterPlugin, knee_param

REFRACTIVE_INDEX = 1.5
"""Refractive index of the film base (cellulose triacetate ~1.48, PET ~1.64): an estimate."""

SUPPORT = {True: 6.0, False: 4.0}
"""PSF support radius in units of the unfolded path H = 2 x base thickness, for a bare back
(True) and a backed one (False)."""

SPREAD = {True: 1.0, False: 0.4}
"""Exponential scale of the multiply scattered return, in units of H (bare, backed)."""

MAX_RADIUS = 0.5
"""Largest PSF radius as a fraction of the frame diagonal (the ``radius`` parameter's maximum,
and the clamp of a stock's physical radius)."""

DEFAULT_STOCK = "vision3-500t"
"""The stock of the default: the common motion-picture negative (rem-jet backed), whose
halation in scans is a tight warm glow hugging highlights (half its light within ~0.1 mm of
the light on the negative, a few % of it); CineStill 800T, the same emulsion with its
rem-jet removed, is a stylised stock chosen on purpose, not a default."""

FROM_STOCK = -1.0
"""Parameter value meaning "the stock's"."""


@dataclass(frozen=True)
class Stock:
    """What a film stock's halation looks like (see the module notes for the sources).

    ``base_mm``: base thickness; ``bare_back``: the base's back surface is bare (total
    internal reflection: a wide glow) rather than coated with an absorbing backing; ``strength``:
    fraction of the highlight light returned; ``tint``: per-channel share of it that reaches
    the layers (red first).
    """

    base_mm: float
    bare_back: bool
    strength: float
    tint: tuple[float, float, float]


STOCKS = {
    "cinestill-800t": Stock(0.13, True, 0.25, (1.0, 0.22, 0.05)),
    "phoenix-200": Stock(0.125, True, 0.3, (1.0, 0.5, 0.15)),
    "portra-400": Stock(0.125, True, 0.03, (1.0, 0.4, 0.1)),
    "vision3-500t": Stock(0.13, False, 0.02, (1.0, 0.3, 0.06)),
    "vision3-250d": Stock(0.13, False, 0.015, (1.0, 0.3, 0.06)),
}


# -- physics ---------------------------------------------------------------------------------
def halation_profile(d_over_h, bare_back: bool):
    """Returning irradiance (unnormalised) at ``d / H`` from the source point:
    ``cos^4(theta) exp(-d / (SPREAD H))``, ``theta = atan(d / H)`` (total internal reflection
    at a bare back, beyond ``asin(1 / REFRACTIVE_INDEX)``, sets how far its light goes)."""
    x = np.asarray(d_over_h, np.float64)
    return np.exp(-x / SPREAD[bool(bare_back)]) / (1.0 + x * x) ** 2


def supersample(radius_px: int) -> int:
    """Samples per pixel and axis for a PSF of ``radius_px``: 8 up to 16 px (the core is a
    pixel or two wide), 4 up to 64 px, 2 up to 256 px, 1 beyond (a smooth profile)."""
    return 8 if radius_px <= 16 else 4 if radius_px <= 64 else 2 if radius_px <= 256 else 1


def halation_psf(radius_px: int, bare_back: bool,
                 reach: tuple[int, int] | None = None) -> np.ndarray:
    """The normalised halation PSF on a (2r + 1)^2 grid (see the module notes); with
    ``reach`` = (dy, dx) only its rows -dy..dy and columns -dx..dx (``psflib.window``).

    Each pixel is the mean of ``supersample(r)^2`` samples of :func:`halation_profile` at
    ``d / H``, ``H = r / SUPPORT``; then ended by ``psflib.tail_fade``.  ``r`` = 0 is the
    single tap 1 (the light returns where it left).  Memory stays (2r + 1)^2 floats.
    """
    r = max(int(radius_px), 0)
    if r == 0:
        return np.ones((1, 1))
    h, ss = r / SUPPORT[bool(bare_back)], supersample(r)

    def cells(x, y):
        k = np.zeros(np.broadcast_shapes(x.shape, y.shape))
        for oy in (np.arange(ss) + 0.5) / ss - 0.5:
            for ox in (np.arange(ss) + 0.5) / ss - 0.5:
                k += halation_profile(np.hypot(x + ox, y + oy) / h, bare_back)
        return k

    if psflib.windowed(r, reach):
        return psflib.window(cells, r, reach)
    c = np.arange(-r, r + 1, dtype=np.float64)
    k = psflib.tail_fade(cells(c[None, :], c[:, None]), r)
    return k / k.sum()


# -- parameters ------------------------------------------------------------------------------
@dataclass(frozen=True)
class StockTintParam(RGBParam):
    """An RGB tint in [0, 1] per channel, or -1 (every channel) for the stock's."""

    def validate(self, value, where=""):
        rgb = super().validate(value, where)
        if any(v < 0.0 for v in rgb) and rgb != (FROM_STOCK,) * 3:
            raise ParamError(f"{where or self.name}: {value!r} is not 3 values in [0, 1] "
                             f"nor -1 (the stock's tint)")
        return rgb


@dataclass(frozen=True)
class Settings:
    """The parameters with the stock's values filled in."""

    strength: float
    tint: tuple[float, float, float]
    radius_px: int
    bare_back: bool


@register
class Halation(ScatterPlugin, Plugin):
    descriptor = Descriptor(
        name="halation", label="Halation", group="Film", kernel="halation.cl",
        summary="Film halation: light reflected off the base re-exposes the red layer, a "
                "red-orange glow hugging bright edges (stock presets); the glow falls "
                "roughly exponentially and ends smoothly at the radius.  Default stock "
                "Kodak VISION3 500T (data sheet H-1-5219: rem-jet backed 0.13 mm acetate "
                "base): half the halo within ~0.1 mm of the light on the negative (0.3 % "
                "of a 36 mm frame's width), 2 % of the highlight's light, as film scans "
                "show a tight warm glow of a few hundred micrometres; CineStill 800T "
                "(rem-jet removed, 25 %, a wide red halo) is a stock to choose.",
        spreads_light=True,
        params=(
            ChoiceParam("stock", DEFAULT_STOCK, choices=tuple(sorted(STOCKS)),
                        hint="Film stock: base thickness, backing (rem-jet: a tight glow; "
                             "bare: a wide one), strength and tint (strengths and tints are "
                             "estimates)."),
            FloatParam("strength", FROM_STOCK, min=FROM_STOCK, max=1.0,
                       hint="Fraction of the highlight light that returns as halation; -1 = "
                            "the stock's."),
            FloatParam("threshold", 1.0, min=0.0, max=1e6,
                       hint="Scene-linear luminance where halation starts to show."),
            knee_param(0.5),
            FloatParam("radius", FROM_STOCK, min=FROM_STOCK, max=MAX_RADIUS,
                       hint="PSF support radius as a fraction of the frame diagonal (6 H "
                            "bare back, 4 H backed; the glow is below 1e-5 of the PSF one "
                            "pixel out by 0.9 x it and ends there); -1 = from the stock's "
                            "base thickness and the camera's sensor width."),
            StockTintParam("tint", (FROM_STOCK,) * 3, min=FROM_STOCK, max=1.0,
                           hint="Per-channel share of the returned light (red first); -1 = "
                                "the stock's."),
            BoolParam("conserve", False,
                      hint="Take the halo's light from the highlight (each channel's total "
                           "kept) instead of adding it (film: extra exposure)."),
        ),
        quality=fftconv.LEVELS,
    )

    def settings(self, p, ctx) -> Settings:
        """``p`` with the stock's values where a parameter says -1."""
        stock = STOCKS[p.stock]
        if p.radius >= 0.0:
            r = psflib.psf_radius_px(p.radius, ctx.diagonal_px)
        else:   # SUPPORT x H = SUPPORT x 2 b on the film, in pixels of the display width
            px_per_mm = ctx.width_px / ctx.camera.sensor_width
            r = int(min(round(SUPPORT[stock.bare_back] * 2.0 * stock.base_mm * px_per_mm),
                        psflib.psf_radius_px(MAX_RADIUS, ctx.diagonal_px)))
        return Settings(strength=stock.strength if p.strength < 0.0 else p.strength,
                        tint=stock.tint if p.tint[0] < 0.0 else p.tint, radius_px=r,
                        bare_back=stock.bare_back)

    def strength(self, p) -> float:
        return STOCKS[p.stock].strength if p.strength < 0.0 else p.strength

    def radius_px(self, p, ctx) -> int:
        return self.settings(p, ctx).radius_px

    def build_psf(self, p, ctx, radius, reach=None):
        return halation_psf(radius, STOCKS[p.stock].bare_back, reach)

    def is_identity(self, p, ctx):
        s = self.settings(p, ctx)
        if s.strength == 0.0:
            return "strength is 0"
        if max(s.tint) == 0.0:
            return "tint is black"
        if p.conserve and s.radius_px < 1:
            return "radius is below one pixel and the light is conserved (it returns where it left)"
        if not ctx.analysis.any_above(self.raw_level(p, ctx)):
            return "no pixel above threshold"
        return None

    def render(self, rt, p, ctx):
        s = self.settings(p, ctx)
        src, kfile = ctx.source, self.descriptor.kernel
        key = self.psf_key(p, ctx)
        k = self.psf(p, ctx, key)
        self.note_nonfinite(ctx, k.shape[:2])
        from pyopencl import cltypes  # lazy: pyopencl is ~0.2 s; listing the effects loads this module

        tint = cltypes.make_float4(*s.tint, 0.0)
        hl = rt.kernel(kfile, "halation_highlights", **ctx.luminance_defines)
        mx = rt.kernel(kfile, "halation_mix", CONSERVE=int(p.conserve), **ctx.luminance_defines)

        def highlights(img, h):
            rt.launch(hl, (img.pitch // 4, max(img.height, 1)), img, h, img.pitch, img.height,
                      p.threshold, p.knee)

        def mix(g, dst, rect):
            dx, dy = rect.offset_in(src.window)
            rt.launch(mx, (dst.pitch // 4, max(dst.height, 1)), src, src.pitch, src.width,
                      src.height, g, dst, dst.pitch, dst.height, dx, dy, s.strength, tint,
                      p.threshold, p.knee)

        split = max(4.0 * p.threshold, 1e-3 * ctx.analysis.peak_luminance)
        dst = self.spread_mixed(rt, p, ctx, k, highlights, mix, split, psf_key=key)
        ctx.notes.append(f"halation: {p.stock}, strength {s.strength:g}, PSF radius "
                         f"{s.radius_px} px ({'bare back' if s.bare_back else 'backed'}), "
                         f"{'conserved' if p.conserve else 'added'}")
        return dst
