"""Film grain: band-limited, luminance-dependent noise, deterministic per (seed, frame, pixel).

Model
-----
For every pixel at frame coordinates (X, Y) and channel c in R, G, B::

    n_c   = (g_c * w)(X, Y)                      band-limited unit-variance noise
    L     = Rec.709 luminance of the pixel, clamped to [1e-30, 1e30]
    out_c = in_c + amount * a_c * 0.18 * (L / 0.18)^response * n_c

* ``w`` is white Gaussian noise N(0, 1) from a hash of (seed, frame, X, Y, channel)
  (``clfx_uniform`` in kernels/lib/common.h, Box-Muller), so a frame rendered alone, in a batch,
  cropped or with overscan gives the same value at the same frame pixel, and every frame
  differs.  Alpha is kept bit for bit; noise goes on RGB only.
* ``g_c`` is a separable pixel-integrated Gaussian of standard deviation
  ``sigma_c = size * s_c * display_width / 2048`` pixels: grain sizes are given in pixels
  at 2K (as Nuke's and SeGrain's stock presets are), which is resolution-independent.
  Pixel aspect is ignored on purpose: film grain is round on the negative, i.e. in pixels of
  the (squeezed) scan.  The discrete 1-D kernel is normalised to unit sum of squares, so
  the filtered noise has exactly unit variance (the continuous 2-D limit of the
  un-normalised Gaussian would be 1 / (4 pi sigma^2)) and ``amount`` is the standard
  deviation.
* ``amount`` is the grain's standard deviation relative to the signal at mid-grey
  (0.03 = 3 % at L = 0.18).  ``response`` shapes it over luminance: 0 = the same
  absolute grain everywhere (additive), 1 = proportional to luminance (constant in
  log / density terms, like grain on a negative), 0.5 in between (the default).
* ``s_c``, ``a_c``: per-channel size and amount ratios.  A named ``stock`` supplies them
  (blue-sensitive layers of colour negative are the grainiest); ``channel_size`` and
  ``channel_amount`` multiply the stock's ratios, so explicit values still apply.
  ``monochrome`` uses one noise field (filtered with the green size) for all channels.

The grain is zero-mean: the expected value of every pixel is unchanged, and nothing is
clamped (dark pixels with large grain may go slightly negative, as with any additive noise).
Non-finite inputs are replaced by 0 before the grain is added (alpha too: alpha is otherwise
kept bit for bit).

Implementation and quality levels: every level draws the same white noise (so levels can be
compared pixel by pixel) and differs only in the filter: draft none (white noise, one pass),
preview truncated at 2 sigma, final at 4 sigma, reference at 6 sigma in float64.  On the
device, four pixels are one 16-lane vector; float32 levels use polynomial log / sin / cos /
exp2 (relative error ~2e-7) because PoCL runs its libm calls lane by lane.  Film grain and
digital sensor noise are separate effects (``sensor_noise``): different models, parameters
and costs.

References: Nuke Grain / F_ReGrain (per-channel size and intensity at 2K); Newson et al.
2017, "A stochastic film grain model for resolution-independent rendering" (grain as a
band-limited random field whose size is fixed on the film, not in pixels).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from clfx.core.plugin import BoolParam, ChoiceParam, Descriptor, FloatParam, Level, RGBParam
from clfx.fx.noise import SEED_PARAM, effect_seed
from clfx.host import Plugin, register

MID_GREY = 0.18
"""Grain ``amount`` is relative to the signal at this scene-linear luminance."""

REFERENCE_WIDTH = 2048
"""Grain sizes are in pixels at this display width (a 2K scan)."""



@dataclass(frozen=True)
class GrainLevel(Level):
    """A quality level of grain: the Gaussian filter's radius in standard deviations
    (``truncation``; None: white noise, no filter)."""

    truncation: float | None = 4.0


LEVELS = {
    "draft": GrainLevel("white noise without the size filter (one pass, float32)",
                        truncation=None),
    "preview": GrainLevel("separable Gaussian truncated at 2 sigma, float32", truncation=2.0),
    "final": GrainLevel("separable Gaussian truncated at 4 sigma, float32", truncation=4.0),
    "reference": GrainLevel("separable Gaussian truncated at 6 sigma; noise, intermediate "
                            "buffers and tap sums in float64", fp64=True, truncation=6.0),
}

GRAIN_SALT = 0x6772616E  # "gran": keeps grain independent of other noise with the same seed


@dataclass(frozen=True)
class FilmStock:
    """Per-channel character of a stock: size and amount ratios (green = 1).

    ``nominal_size`` (px at 2K) and ``nominal_amount`` are suggestions for ``size`` and
    ``amount`` (used by the presets); they are not applied automatically.  Values are
    by-eye approximations of the published stocks' relative granularity, not measurements.
    """

    size: tuple[float, float, float]
    amount: tuple[float, float, float]
    monochrome: bool = False
    nominal_size: float = 1.0
    nominal_amount: float = 0.03


STOCKS = {
    "custom": FilmStock((1.0, 1.0, 1.0), (1.0, 1.0, 1.0)),
    # fine-grain daylight stock (Vision3 50D class)
    "fine-50d": FilmStock((1.1, 1.0, 1.3), (0.9, 1.0, 1.4), nominal_size=0.6, nominal_amount=0.02),
    # medium-speed daylight stock (Vision3 250D class)
    "medium-250d": FilmStock((1.15, 1.0, 1.4), (1.0, 1.0, 1.5), nominal_size=0.8,
                             nominal_amount=0.03),
    # fast tungsten stock (Vision3 500T class)
    "fast-500t": FilmStock((1.2, 1.0, 1.5), (1.05, 1.0, 1.6), nominal_size=1.0,
                           nominal_amount=0.045),
    # black-and-white ISO 400 (Tri-X / HP5 class): one silver layer
    "mono-400": FilmStock((1.0, 1.0, 1.0), (1.0, 1.0, 1.0), monochrome=True, nominal_size=1.1,
                          nominal_amount=0.05),
}


# -- filter ---------------------------------------------------------------------------------
def integrated_gaussian_taps(sigma: float, radius: int) -> np.ndarray:
    """Taps k = -radius..radius of a Gaussian integrated over each pixel, unit sum of squares.

    Integrating over the pixel (erf differences) instead of sampling makes small sizes blend
    smoothly into white noise: sigma -> 0 gives the single tap 1.
    """
    k = np.arange(-radius, radius + 1, dtype=np.float64)
    if sigma < 1e-6:
        taps = (k == 0).astype(np.float64)
    else:
        s = sigma * math.sqrt(2.0)
        taps = np.array([0.5 * (math.erf((t + 0.5) / s) - math.erf((t - 0.5) / s)) for t in k])
    return taps / math.sqrt(float(np.sum(taps * taps)))


def grain_weights(sigmas, truncation: float) -> tuple[int, np.ndarray]:
    """Per-channel tap table for the separable filter.

    Returns ``(radius, weights)``: ``weights`` has shape (2 radius + 1, 4), column c holding
    channel c's taps (zero beyond its own radius ``ceil(truncation * sigma_c)``), column 3
    (alpha) zero.  Each column has unit sum of squares, so the 2-D separable filter turns
    unit white noise into unit-variance grain.
    """
    radii = [int(math.ceil(truncation * s)) if s >= 1e-6 else 0 for s in sigmas]
    radius = max(radii)
    weights = np.zeros((2 * radius + 1, 4), np.float64)
    for c, (s, r) in enumerate(zip(sigmas, radii)):
        weights[radius - r:radius + r + 1, c] = integrated_gaussian_taps(s, r)
    return radius, weights


def channel_ratios(p) -> tuple[tuple[float, ...], tuple[float, ...], bool]:
    """(size ratios, amount ratios, monochrome) from the stock times the explicit ratios."""
    stock = STOCKS[p.stock]
    sizes = tuple(a * b for a, b in zip(stock.size, p.channel_size))
    amounts = tuple(a * b for a, b in zip(stock.amount, p.channel_amount))
    mono = bool(p.monochrome or stock.monochrome)
    if mono:
        sizes = (sizes[1],) * 3  # one silver layer: one grain size (green's) for every channel
    return sizes, amounts, mono


def grain_sigmas_px(p, display_width: int) -> tuple[float, float, float]:
    """Per-channel Gaussian standard deviation of the grain filter, in pixels."""
    sizes, _, _ = channel_ratios(p)
    scale = p.size * display_width / REFERENCE_WIDTH
    return tuple(s * scale for s in sizes)


def grain_amounts(p) -> tuple[float, float, float]:
    """Per-channel absolute standard deviation at mid-grey (amount * ratio * 0.18)."""
    _, amounts, _ = channel_ratios(p)
    return tuple(p.amount * a * MID_GREY for a in amounts)


@register
class Grain(Plugin):
    """Deterministic film grain; see the module docstring for the model."""

    descriptor = Descriptor(
        name="grain", label="Film grain", group="Film", kernel="grain.cl",
        summary="Band-limited film grain with per-channel size and amount, luminance response "
                "and film-stock presets; the same for a frame alone or in a batch, new every "
                "frame.",
        frame_varying=True,
        params=(
            ChoiceParam("stock", "custom", choices=tuple(STOCKS),
                        hint="Per-channel size/amount character of a film stock (custom = all 1); "
                             "channel_size and channel_amount multiply it."),
            FloatParam("amount", 0.03, min=0.0, max=1.0, display_min=0.0, display_max=0.15,
                       hint="Grain standard deviation relative to the signal at mid-grey "
                            "(0.03 = 3 % at luminance 0.18)."),
            FloatParam("size", 1.0, min=0.0, max=20.0, units="px at 2K",
                       hint="Grain size: Gaussian standard deviation in pixels of a 2048-wide "
                            "frame (scaled with the display width; 0 = white noise)."),
            FloatParam("response", 0.5, min=0.0, max=1.0,
                       hint="Exponent of the luminance dependence: 0 = same grain everywhere, "
                            "1 = proportional to luminance."),
            RGBParam("channel_amount", (1.0, 1.0, 1.0), min=0.0, max=4.0,
                     hint="Per-channel amount ratios (multiply the stock's)."),
            RGBParam("channel_size", (1.0, 1.0, 1.0), min=0.0, max=4.0,
                     hint="Per-channel size ratios (multiply the stock's)."),
            BoolParam("monochrome", False,
                      hint="One grain field for R, G and B (black-and-white film); else "
                           "independent colour grain per channel."),
            SEED_PARAM,
        ),
        quality=LEVELS,
    )

    # cheap questions ---------------------------------------------------------------------
    def is_identity(self, p, ctx):
        if p.amount == 0.0:
            return "amount is 0"
        if not any(grain_amounts(p)):
            return "every channel amount is 0"
        return None

    # render ------------------------------------------------------------------------------
    def _device_weights(self, rt, sigmas, truncation, use64):
        """(radius, device buffer) of the tap table, kept in ``rt.cache`` per size and
        level."""
        def build():
            radius, weights = grain_weights(sigmas, truncation)
            return radius, rt.to_device(weights.astype(np.float64 if use64 else np.float32))

        key = ("grain.weights", tuple(round(s, 12) for s in sigmas), truncation, use64)
        return rt.cache.get(key, build)

    def render(self, rt, p, ctx):
        src = ctx.source
        _, _, mono = channel_ratios(p)
        lvl = self.level(ctx)
        use64 = rt.use_fp64(lvl.fp64)
        defines = {"MONO": int(mono)}
        seed = np.uint32(effect_seed(p.seed, ctx.seed, GRAIN_SALT))
        frame = np.int32(ctx.frame)
        ar, ag, ab = (np.float32(a) for a in grain_amounts(p))
        response = np.float32(p.response)
        i32 = np.int32
        dst = src.like()
        pitch, height = src.pitch, src.height
        x0, y0 = src.window.x0, src.window.y0
        truncation = lvl.truncation
        sigmas = grain_sigmas_px(p, ctx.width_px)
        if truncation is None or max(sigmas) < 1e-6:
            # draft, or size 0: the filter is the single tap 1, so skip the two passes
            knl = rt.kernel("grain.cl", "grain_apply_white", fp64=lvl.fp64, **defines)
            rt.launch(knl, (pitch // 4, height), src, dst, i32(pitch), i32(height), i32(x0),
                      i32(y0), seed, frame, ar, ag, ab, response)
            return dst

        radius, weights = self._device_weights(rt, sigmas, truncation, use64)
        defines["RADIUS"] = radius
        real_bytes = 8 if use64 else 4
        rows = height + 2 * radius
        npitch = -(-(pitch + 2 * radius) // 4) * 4   # every vload16 of the taps stays inside
        noise = rt.buffer(rows * npitch * 4 * real_bytes)
        tmp = rt.buffer(rows * pitch * 4 * real_bytes)
        def knl(name):
            return rt.kernel("grain.cl", name, fp64=lvl.fp64, **defines)

        rt.launch(knl("grain_noise"), (npitch // 4, rows), noise, i32(npitch), i32(rows),
                  i32(x0 - radius), i32(y0 - radius), seed, frame)
        rt.launch(knl("grain_blur_h"), (pitch // 4, rows), noise, tmp, weights, i32(npitch),
                  i32(pitch), i32(rows))
        rt.launch(knl("grain_apply"), (pitch // 4, height), src, dst, tmp, weights, i32(pitch),
                  i32(height), ar, ag, ab, response)
        return dst
