"""Film grain: dye clouds of a stated size on the negative, in density, relative to exposure;
deterministic per (seed, frame, pixel).

Model
-----
**Spatial: a Poisson shot-noise field of Gaussian dye clouds.**  A colour negative's grain is
dye clouds (each a soft, roughly Gaussian blob where a developed silver-halide crystal left
its dye) scattered at random (Poisson) over each layer.  Summed over many clouds the density
fluctuation is a Gaussian random field (central limit theorem) whose autocorrelation is the
cloud profile convolved with itself: for clouds of standard deviation ``s`` (micrometres on
the negative) ::

    rho(tau) = exp(-tau^2 / (4 s^2))          Wiener spectrum  W(f) ~ exp(-(2 pi f s)^2)

(a Gaussian spectrum, flat at low frequencies as Selwyn's law needs).  ``diameter`` is the
clouds' equivalent disc diameter ``d = 4 s`` (a disc of diameter d has the same second
moment), in micrometres *on the negative*: it becomes pixels through the film format's width
(the camera block's ``sensor_width``, e.g. 24.89 mm for Super 35) and the display window's
width, ``s_px = s * width_px / (sensor_width * 1000)``.  So the same stock is finer on a
larger format or a higher-resolution scan, as on film.  On the device the field is white
noise filtered by a separable pixel-integrated Gaussian of ``s_px`` per channel, normalised
to unit variance (``integrated_gaussian_taps``).

**Amplitude: Selwyn's law.**  A pixel averages the field over its area on the negative, so
the grain a pixel sees shrinks as pixels grow: sigma^2 * area is constant while the pixel
is much larger than the clouds (Selwyn), and tends to the field's own deviation when it is
much smaller.  The exact pixel-averaged variance of the field above, per axis, for a pixel
of side ``a`` (px) is ``V1(a) = (2/a^2) int_0^a (a - u) exp(-u^2 / (4 s^2)) du`` (closed
form in ``selwyn_factor``); ``amount`` is stated for the pixel of a 2048-wide scan of the
same format (side ``r = width_px / 2048`` px here), and a pixel of this render gets
``amount * V1(1) / V1(r)``.  A render at half resolution therefore equals the
full-resolution render averaged 2 x 2 (grain-wise), and at 2K ``amount`` means what it did.

**Tone: density on a characteristic curve, relative to exposure.**  Grain lives in the
negative's density, so it is relative to the plate's exposure, not to absolute linear
values.  With ``E`` the exposure reference (``middle_grey``: a stated scene-linear value,
or 0 = metered from the frame, below) each channel's relative exposure ``e = max(v, 0) / E``
(monochrome: the luminance's) develops to the density ::

    D(e) = FOG + GAMMA * log10(1 + e / TOE)      (toe at TOE = 2^-4, 4 stops under grey)

and the density fluctuation has the deviation of Nutting's formula for a Poisson grain
model, ``sigma_D^2 = 0.434 a D / A`` (so sigma_D ~ D^0.5), generalised to
``sigma_D ~ D^response`` (response 0.5 = Nutting, the default).  Mapped back through the
curve, the grain is a log-normal factor on the exposure plus toe::

    s_c   = amount * A_c * selwyn_c / (1 + TOE) * (D(e) / D(1))^response
    out_c = v_c + E * (e_c + TOE) * (exp(s_c n_c - s_c^2 / 2) - 1)

``n_c`` is the unit field above; ``exp(s n - s^2/2)`` has mean exactly 1, so the mean of
every pixel is kept.  At middle grey (e = 1) the relative deviation is ``amount`` (to
first order); well above the toe it grows slowly with density (Nutting); in the shadows
(e << TOE) the grain is the fog's, a small constant in linear terms (under-exposed film is
grainier relative to its signal, never coloured speckle).  Scaling a plate by k and its
``middle_grey`` by k scales the output by k exactly: **the same look at any exposure**.

**Exposure reference.**  ``middle_grey`` > 0 states the scene-linear value the negative was
exposed for as middle grey (0.18 for a scene-referred plate normalised to 18 % grey).
``auto`` (or 0; the default) meters the frame (`clfx.fx.analysis.meter`, shared with
``sensor_noise``): the mean of the log of the shared scene analysis' 32 x 32 tile mean
luminances, each clamped to the quartiles of the frame's (lights, empty background and black
borders do not count; a frame with no light falls back to 0.18).  The meter reads the whole
frame once per step (its plan), also when the effect renders in bands; it is
scale-equivariant (k times the plate gives k times the reference), deterministic (a frame
alone meters as in a batch) and robust, so a static shot's frames meter alike (the plate's
own noise moves it by ~1e-4) and a moving one drifts smoothly with its content (OpenEXR's
Beachball: ~3 % a frame).  It meters each frame, as a camera's auto exposure would: for a
shot whose light changes (a lamp switched on) state ``middle_grey`` (``--explain`` prints
the metered value), so the grain does not follow the content.

``A_c`` and per-channel diameters come from a film ``stock`` (blue-sensitive layers of a
colour negative have the largest, most visible clouds) times ``channel_amount`` /
``channel_size``; ``monochrome`` uses one field (green's size) and the luminance's density
for every channel (one silver layer: neutral grain).

Noise ``w`` is white Gaussian N(0, 1) from a hash of (seed, frame, X, Y, channel)
(``clfx_uniform`` in kernels/lib/common.h, Box-Muller) at frame coordinates, so a frame
rendered alone, in a batch, cropped or with overscan gives the same noise at the same frame
pixel, and every frame differs.  Alpha is kept bit for bit; non-finite inputs become 0 first.
Values are clamped to +-1e30 before the grain and the result to the float range.

Coverage (``coverage``, as ``sensor_noise``'s: `clfx.kit.noise.alpha_is_coverage`).  With
``"alpha"`` the grain is weighted by the pixel's alpha clamped to [0, 1], ``out = v + alpha
(grainy - v)``: the empty, alpha-0 background of a CG element with a tight data window
(OpenEXR's Beachball) stays empty instead of showing a rectangle of grain (the fog's grain
lands on black too), and a half-covered edge gets half the grain.  Opaque pixels (alpha >=
1, every pixel of a plate without alpha) get the grain bit for bit.  ``"ignore"`` grains
every pixel of the data window; ``"auto"`` (the default) is alpha unless the scene analysis
of the look's input finds light where alpha is 0 (a matte in a photograph's alpha; the
fringes and glow earlier effects put there do not count), and says so in ``--explain``.

Migration from version 1 (pixel-sized grain in absolute linear units):

* ``size`` (px at 2K, a Gaussian standard deviation) is still read when >= 0 (default -1 =
  unset): it sets the cloud standard deviation ``s = size * sensor_width / 2048`` mm, i.e.
  the same grain size on a 2048-wide scan of the format (``diameter = 4 s``).
* ``response`` keeps its range and default but is now the exponent of density in
  sigma_D (0.5 = Nutting) instead of the exponent of linear luminance.
* ``amount`` keeps its meaning at middle grey on a 2K scan of the format (relative
  deviation), now relative to ``middle_grey`` instead of to 0.18 absolute.

Quality levels: every level draws the same white noise (levels compare pixel by pixel) and
differs only in the filter: draft none (white noise, one pass), preview truncated at 2 s,
final at 4 s, reference at 6 s in float64.  On the device the colour channels run as
float16 planes, 16 pixels a work-item (noise: 8; alpha has no grain); float32 levels use
polynomial log / sin / cos / exp2 (relative error ~2e-7).  Film grain and
digital sensor noise are separate effects (``sensor_noise``).

References: Newson, Delon, Galerne 2017, "A stochastic film grain model for
resolution-independent rendering" (grain as a Boolean/Poisson model fixed on the film, not
in pixels); Selwyn 1935 and Nutting 1913 (granularity sigma_D sqrt(A) constant; sigma_D^2 =
0.434 a D / A); Bayer 1964 / Dainty & Shaw, "Image Science" (Wiener spectra of grain).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from clfx.core.plugin import BoolParam, ChoiceParam, Descriptor, FloatParam, Level, RGBParam
from clfx.fx.analysis import MIDDLE_GREY_AUTO
from clfx.fx.noise import COVERAGE_PARAM, SEED_PARAM, effect_seed
from clfx.host import ExposurePlan, Plugin, register
from clfx.kit.noise import alpha_is_coverage, exposure_reference

REFERENCE_WIDTH = 2048
"""``amount`` is stated for a pixel of a scan this wide (of the same format); the legacy
``size`` is in pixels of such a scan."""

GAMMA = 0.6
"""Slope of the negative's characteristic curve, density per decade of exposure (colour
negative film: ~0.55-0.65)."""

FOG = 0.1
"""Density above base at zero exposure (fog)."""

TOE = 2.0 ** -4
"""Exposure (relative to middle grey) where the curve's toe bends: 4 stops under grey."""

D_GREY = FOG + GAMMA * math.log10(1.0 + 1.0 / TOE)
"""Density of middle grey, D(1)."""

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
                            "buffers, tap sums and the tone mapping in float64", fp64=True,
                            truncation=6.0),
}

GRAIN_SALT = 0x6772616E  # "gran": keeps grain independent of other noise with the same seed


@dataclass(frozen=True)
class FilmStock:
    """Per-channel character of a stock: dye-cloud size and amount ratios (green = 1).

    ``diameter`` (um on the negative, equivalent disc diameter of the dye clouds) is used
    when the ``diameter`` param is 0; ``nominal_amount`` is a suggestion for ``amount`` (the
    presets use it), not applied automatically.  Values are by-eye choices in the range
    where 35 mm colour negatives' grain Wiener spectra fall to half (~10-25 cycles/mm:
    ``W(f) = 1/2`` at ``f = 0.83 / (2 pi s)``, s = d / 4), not measurements of the named
    stocks.
    """

    size: tuple[float, float, float]
    amount: tuple[float, float, float]
    monochrome: bool = False
    diameter: float = 32.0
    nominal_amount: float = 0.03


STOCKS = {
    "custom": FilmStock((1.0, 1.0, 1.0), (1.0, 1.0, 1.0)),
    # fine-grain daylight stock (Vision3 50D class)
    "fine-50d": FilmStock((1.1, 1.0, 1.3), (0.9, 1.0, 1.4), diameter=24.0, nominal_amount=0.02),
    # medium-speed daylight stock (Vision3 250D class)
    "medium-250d": FilmStock((1.15, 1.0, 1.4), (1.0, 1.0, 1.5), diameter=32.0,
                             nominal_amount=0.03),
    # fast tungsten stock (Vision3 500T class)
    "fast-500t": FilmStock((1.2, 1.0, 1.5), (1.05, 1.0, 1.6), diameter=40.0,
                           nominal_amount=0.045),
    # black-and-white ISO 400 (Tri-X / HP5 class): one silver layer
    "mono-400": FilmStock((1.0, 1.0, 1.0), (1.0, 1.0, 1.0), monochrome=True, diameter=36.0,
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


def cloud_sigma_um(p, sensor_width_mm: float) -> float:
    """Green's dye-cloud standard deviation ``s`` in um on the negative: ``diameter / 4``
    (0: the stock's), or from the legacy ``size`` (px at 2K) when that is >= 0."""
    if p.size >= 0.0:
        return p.size * sensor_width_mm * 1000.0 / REFERENCE_WIDTH
    return (p.diameter or STOCKS[p.stock].diameter) / 4.0


def grain_sigmas_px(p, display_width: int, sensor_width_mm: float) -> tuple[float, float, float]:
    """Per-channel standard deviation of the grain filter in pixels of a frame
    ``display_width`` pixels wide on a format ``sensor_width_mm`` wide."""
    sizes, _, _ = channel_ratios(p)
    scale = cloud_sigma_um(p, sensor_width_mm) * display_width / (sensor_width_mm * 1000.0)
    return tuple(s * scale for s in sizes)


def pixel_variance_1d(a: float, sigma: float) -> float:
    """Per-axis variance ``V1(a)`` of the unit field (autocorrelation exp(-u^2 / 4 sigma^2))
    averaged over a pixel of side ``a`` (same units as sigma): ``(2/a^2) int_0^a (a - u)
    exp(-u^2/c^2) du`` with ``c = 2 sigma``.  For sigma -> 0 it behaves as ``c sqrt(pi) /
    a`` (Selwyn: variance x area constant)."""
    c = 2.0 * sigma
    return (2.0 / (a * a)) * (a * c * math.sqrt(math.pi) / 2.0 * math.erf(a / c)
                              - c * c / 2.0 * -math.expm1(-(a / c) ** 2))


def selwyn_factor(sigma_px: float, ref_px: float) -> float:
    """Grain deviation a 1-px pixel sees relative to a pixel of side ``ref_px`` (px): the
    square root of the ratio of their pixel-averaged variances, ``V1(1) / V1(ref_px)``
    (2-D variance = V1^2).  ``ref_px`` for sigma -> 0 (white grain, Selwyn's law exactly)."""
    if sigma_px < 1e-6 * max(1.0, ref_px):
        return ref_px
    return pixel_variance_1d(1.0, sigma_px) / pixel_variance_1d(ref_px, sigma_px)


def grain_amounts(p, display_width: int, sensor_width_mm: float) -> tuple[float, float, float]:
    """Per-channel log-exposure deviation at middle grey, ``s_c(e = 1)``: amount x the
    stock's and channel ratio x the Selwyn factor / (1 + TOE)."""
    _, amounts, _ = channel_ratios(p)
    sigmas = grain_sigmas_px(p, display_width, sensor_width_mm)
    ref_px = display_width / REFERENCE_WIDTH
    return tuple(p.amount * a * selwyn_factor(s, ref_px) / (1.0 + TOE)
                 for a, s in zip(amounts, sigmas))


@register
class Grain(Plugin):
    """Deterministic film grain; see the module docstring for the model."""

    whole_frame = None   # tiles: the same pixels band by band (tests/contract/test_tiles.py)
    descriptor = Descriptor(
        name="grain", label="Film grain", group="Film", kernel="grain.cl",
        version=(2, 1),   # 2.1: coverage (alpha weights the grain)
        summary="Film grain as Poisson dye clouds of a stated diameter on the negative (um, "
                "through the camera's format width), a Gaussian Wiener spectrum, Selwyn's "
                "law for the pixel's area, and a density-dependent amplitude (Nutting) on a "
                "characteristic curve relative to the exposure (metered or a stated middle "
                "grey): the same look at any exposure or resolution, for a frame alone or in "
                "a batch, new every frame.",
        frame_varying=True,
        params=(
            ChoiceParam("stock", "custom", choices=tuple(STOCKS),
                        hint="Per-channel size/amount character and cloud diameter of a film "
                             "stock (custom = all 1, 32 um); channel_size and channel_amount "
                             "multiply it."),
            FloatParam("amount", 0.03, min=0.0, max=1.0, display_min=0.0, display_max=0.15,
                       hint="Grain deviation relative to the signal at middle grey, as a pixel "
                            "of a 2048-wide scan of the format sees it (0.03 = 3 %)."),
            FloatParam("diameter", 0.0, min=0.0, max=1000.0, units="um",
                       hint="Dye-cloud diameter on the negative (equivalent disc, 4 x the "
                            "Gaussian cloud's sigma) in micrometres; pixels follow from the "
                            "camera's sensor_width; 0 = the stock's."),
            FloatParam("middle_grey", 0.0, min=0.0, max=1e6, auto=MIDDLE_GREY_AUTO,
                       hint="Scene-linear value exposed as middle grey (0.18 for a plate "
                            "normalised to 18 % grey); auto (or 0) = meter each frame "
                            "(--explain prints the value, to pin it for a shot whose light "
                            "changes)."),
            FloatParam("response", 0.5, min=0.0, max=1.0,
                       hint="Exponent of density in the grain's density deviation: 0.5 = "
                            "Nutting's Poisson-grain law, 0 = the same in density everywhere, "
                            "1 = proportional to density."),
            RGBParam("channel_amount", (1.0, 1.0, 1.0), min=0.0, max=4.0,
                     hint="Per-channel amount ratios (multiply the stock's)."),
            RGBParam("channel_size", (1.0, 1.0, 1.0), min=0.0, max=4.0,
                     hint="Per-channel size ratios (multiply the stock's)."),
            BoolParam("monochrome", False,
                      hint="One grain field and the luminance's density for R, G and B "
                           "(black-and-white film); else independent colour grain per layer."),
            FloatParam("size", -1.0, min=-1.0, max=20.0, units="px at 2K",
                       hint="Legacy (version 1) grain size: Gaussian sigma in pixels of a "
                            "2048-wide scan of the format; when >= 0 it replaces diameter "
                            "(diameter = 4 x size x sensor_width / 2048); -1 = unset."),
            COVERAGE_PARAM,
            SEED_PARAM,
        ),
        quality=LEVELS,
    )

    # cheap questions ---------------------------------------------------------------------
    def is_identity(self, p, ctx):
        if p.amount == 0.0:
            return "amount is 0"
        if not any(channel_ratios(p)[1]):
            return "every channel amount is 0"
        return None

    def plan(self, p, ctx):
        return ExposurePlan(middle_grey=exposure_reference(p, ctx, "grain"))

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
        mode = {0.0: 0, 0.5: 1, 1.0: 2}.get(p.response, 3)   # build variants: no pow
        defines = {"MONO": int(mono), "RESPONSE_MODE": mode, "GRAIN_GAMMA": repr(GAMMA),
                   "GRAIN_FOG": repr(FOG),
                   "GRAIN_TOE": repr(TOE), "GRAIN_D_GREY": repr(D_GREY),
                   "COVERAGE": int(alpha_is_coverage(p.coverage, ctx, "grain")),
                   **ctx.luminance_defines}
        seed = effect_seed(p.seed, ctx.seed, GRAIN_SALT)
        frame = ctx.frame
        fmt = ctx.camera.sensor_width
        ar, ag, ab = grain_amounts(p, ctx.width_px, fmt)
        grey = self.planned(p, ctx).middle_grey
        tone = (p.response, grey, 1.0 / grey)
        dst = src.like()
        pitch, height = src.pitch, src.height
        x0, y0 = src.window.x0, src.window.y0
        truncation = lvl.truncation
        sigmas = grain_sigmas_px(p, ctx.width_px, fmt)
        if truncation is None or max(sigmas) < 1e-6:
            # draft, or size 0: the filter is the single tap 1, so skip the two passes
            knl = rt.kernel("grain.cl", "grain_apply_white", fp64=lvl.fp64, **defines)
            # 16 pixels a work-item
            rt.launch(knl, (-(-pitch // 16), height), src, dst, pitch, height, x0, y0, seed,
                      frame, ar, ag, ab, *tone)
            return dst

        radius, weights = self._device_weights(rt, sigmas, truncation, use64)
        defines["RADIUS"] = radius
        real_bytes = 8 if use64 else 4
        rows = height + 2 * radius
        # three planes (R, G, B: alpha has no grain), 16 pixels a work-item: tmp rows of whole
        # 16s, noise rows (written 8 pixels a work-item) wide enough for their taps' vload16s
        tpitch = -(-pitch // 16) * 16
        npitch = tpitch + -(-2 * radius // 8) * 8
        noise = rt.buffer(3 * rows * npitch * real_bytes)
        tmp = rt.buffer(3 * rows * tpitch * real_bytes)
        def knl(name):
            return rt.kernel("grain.cl", name, fp64=lvl.fp64, **defines)

        rt.launch(knl("grain_noise"), (npitch // 8, rows), noise, npitch, rows, x0 - radius,
                  y0 - radius, seed, frame)
        rt.launch(knl("grain_blur_h"), (tpitch // 16, rows), noise, tmp, weights, npitch,
                  tpitch, rows)
        rt.launch(knl("grain_apply"), (tpitch // 16, height), src, dst, tmp, weights, pitch,
                  tpitch, height, ar, ag, ab, *tone)
        return dst
