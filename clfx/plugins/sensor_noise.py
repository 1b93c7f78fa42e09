"""Sensor noise in linear light: Poisson shot noise, Gaussian read noise, fixed-pattern PRNU,
through a Bayer mosaic and a demosaic, with optional low-frequency chroma noise.

A separate effect from ``grain``: digital noise is per-pixel (no grain size), its variance
follows the photon count, and it is driven by the camera block's ISO, while film grain is a
band-limited field with a film-stock character.  Looks combine them as needed.

Model
-----
Gain relative to base ISO: ``G = iso / base_iso``.  A scene-linear value ``v`` of channel c
collects ``lambda = max(v, 0) * k_c`` electrons, with ``k_c = full_well * s_c / G``
electrons per unit of linear value (``s_c`` = ``channel_sensitivity``: channels that need a
larger white-balance gain collect fewer electrons and are noisier).  Then::

    v_p   = v * (1 + prnu * z_fixed)                  fixed pattern (same every frame)
    N     ~ Poisson(max(v_p, 0) * k_c)                shot noise, electrons
    out   = v_p + (N - lambda) / k_c + read * z / k_c

so ``E[out] = v_p`` (mean preserved; negative inputs keep their value) and::

    Var[out] = g_c * max(v_p, 0) + (g_c * read)^2,     g_c = 1 / k_c = G / (full_well s_c)

Full well.  A photosite holds at most ``full_well`` electrons (``v_sat = full_well g_c`` in
linear units: 1.0 at base ISO on a plate at 0.18, ``G`` times that at gain ``G``).  A site at
or above it reads exactly full: no shot noise and no PRNU (a saturated light is clean, as a
camera's clipped highlight), only read noise; below it the count is capped at the well.  The
output keeps the plate's value (HDR above the well stays for the comp): the well limits the
noise, not the image.  Without it a 1e3 light carried shot noise of ~30 x its surroundings'
and the demosaic spread it into coloured, negative rings round every light (issue 32).

i.e. in linear units, variance = gain * signal + read^2 with gain ``g_c`` and read noise
``g_c * read`` (read noise is given in electrons at the sensor, so its linear size grows
with ISO, as in a real camera's output).  The Poisson count is sampled exactly by CDF
inversion while ``lambda <= 30`` electrons (final/reference; 10 in preview; the uniform is
capped at 1 - 4e-6 so float32 rounding of the summed CDF, <= ~1.2e-6 here, can never stall
the search: only the top 4e-6 quantile is moved to its lower edge), and by the
normal approximation ``lambda + sqrt(lambda) z`` above (same mean and variance; the skew
of a Poisson at 30 counts is 0.18).  Draft uses the normal approximation at every count.

Exposure.  A real camera is exposed for its ISO: middle grey lands on the same fraction of
the full well whatever the scene's light, so its noise depends on the ISO, not on how bright
the scene was.  A scene-linear plate has no such scale (a night plate may sit at 0.01), so
``k_c`` is stated for a plate whose middle grey is 0.18 and scaled by ``0.18 / E``, with ``E``
= ``middle_grey`` when stated, or (``auto``, the default; 0 means the same) metered from the
frame as grain meters it (`clfx.fx.analysis.meter`: the mean log of the tile mean
luminances, each clamped to the frame's quartiles, so lights and black borders do not count;
once per step from the whole frame, bands included; ``--explain`` prints the value).
Metered, scaling a plate by any factor scales the output (noise included) by that factor:
the same look at any exposure.  The meter reads each frame (deterministic, stable to ~1e-4
on a static shot); state ``middle_grey`` for a shot whose light changes.  Taking 0.18 as
middle grey, as the default did, buried ScanLines' CandleGlass (mean 0.0004, ~9 stops under)
in saturated colour noise four times its signal.

Mosaic and demosaic (``mosaic = "bayer"``, the default).  A camera measures one colour per
photosite (an RGGB Bayer pattern at frame coordinates: R at even X and even Y, B at odd X
and odd Y) and interpolates the other two.  Each photosite keeps the deviation above for its
CFA colour (with that colour's electrons and gain); the mosaic of deviations is then
demosaiced with Malvar, He and Cutler's gradient-corrected bilinear filters (5 x 5, each
interpolated colour corrected by the centre site's Laplacian), and added to the clean
plate (the signal is not demosaiced: the plate keeps its detail).  So a pixel's colours are
correlated and neighbouring pixels are correlated.  The filters interpolate the *unit*
field of site deviations (each divided by the model's deviation at its site, with the full
well), each interpolated colour is divided by its filter's norm (its deviation on unit
white noise: sqrt(63.5) / 8 for R or B at a green site, 6 / 8 for green at R or B, sqrt(61)
/ 8 for B at R or R at B) and then scaled by the pixel's own model deviation for that colour.
So every colour of every pixel has exactly the photon-transfer variance of its own value: no
period-2 lattice of noise amplitude (plain MHC gave green 0.56 of the site variance at red
and blue sites; over a saturated red its Laplacian term carried the red sites' noise into
their green and blue, a lattice of dots every other pixel), and a dark pixel beside a light
gets its own noise, not the light's.  On a flat field the exact linear model gives channel
correlations R-G 0.64, G-B 0.64, R-B 0.60 and lag-1 autocorrelations 0.38 (R, B) and 0.33
(G); at a site its own colour is its photosite's deviation.  Sites
outside the data window are mirrored about its edge, so within 2 px of the edge a crop
differs from a full render (elsewhere they agree).  ``mosaic = "none"`` keeps the
per-pixel, per-channel independent noise.

Chroma blotches (``chroma_noise`` > 0): low-frequency colour noise, as the shadows of a
high-ISO frame show (banding and low-frequency read noise, after the camera's colour
processing).  Two value-noise fields ``a, b`` (unit Gaussians at the nodes of a grid of
``chroma_size`` x the frame diagonal, in frame coordinates and new every frame, blended with
smoothstep weights) shift the colour without changing luminance: ``dR = k a``,
``dB = k b``, ``dG = -(wR dR + wB dB) / wG`` with ``k = chroma_noise x`` the model's green
deviation at the pixel (so blotches follow the noise: strongest in the shadows at high ISO,
none past the well).

Random numbers come from ``clfx_uniform(seed, frame, X, Y, c)`` at frame coordinates, so
the noise is identical for a frame rendered alone, in a batch, cropped, or on any thread
count; the PRNU pattern uses frame 0 and its own seed, so it stays fixed over a sequence
(it is computed once per parameter set and data window and kept in the runtime's cache:
one frame-sized float buffer).
Coverage (``coverage = "alpha"``): the deviation (shot, read, PRNU, chroma) is weighted by
the pixel's alpha clamped to [0, 1], ``out = v + alpha (noisy - v)``, so the transparent
part of a CG element stays empty: without it read noise fills the whole data window, a
visible rectangle around a tight-windowed element (OpenEXR's Beachball), and the comp would
add it on top of the plate's own noise.  Opaque pixels (alpha >= 1, and every pixel of a
plate without alpha) get the full model bit for bit.  ``"ignore"`` adds noise to every
pixel of the data window.  ``"auto"`` (the default) reads alpha as coverage when the scene
analysis of the look's input (before earlier effects' fringes and glow) finds no light in
a pixel whose alpha is <= 0 (premultiplied, empty background),
else ignores it (a photograph whose alpha is a matte, ScanLines' CandleGlass: light where
alpha is 0; an additive element), and says so in ``--explain``.  Either way nothing is
added outside the data window.
Non-finite inputs become 0 (then get read noise where covered) and values are clamped to
+-1e38 so nothing overflows; alpha is kept bit for bit (0 where it was not finite).

References: Malvar, He, Cutler 2004, "High-quality linear interpolation for demosaicing of
Bayer-patterned color images"; EMVA Standard 1288 (linear photon-transfer model: variance = K (mu - mu_dark)
+ sigma_read^2, PRNU); Foi et al. 2008, "Practical Poissonian-Gaussian noise modeling and
fitting for single-image raw-data".
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from clfx.core.plugin import BoolParam, ChoiceParam, Descriptor, FloatParam, Level, RGBParam
from clfx.fx.analysis import MID_GREY, MIDDLE_GREY_AUTO
from clfx.fx.noise import COVERAGE_PARAM, SEED_PARAM, effect_seed
from clfx.host import ExposurePlan, Plugin, register
from clfx.kit.noise import alpha_is_coverage, exposure_reference

SENSOR_SALT = 0x73656E73  # "sens"
PRNU_SALT = 0x70726E75    # "prnu"
DEMOSAIC_REACH = 2
"""Pixels the Malvar-He-Cutler demosaic reads on each side (its 5 x 5 neighbourhood)."""


@dataclass(frozen=True)
class SensorNoiseLevel(Level):
    """A quality level of sensor noise: the largest expected electron count whose Poisson
    count is sampled exactly (``poisson_switch``; None: normal approximation everywhere)."""

    poisson_switch: float | None = 30.0


LEVELS = {
    "draft": SensorNoiseLevel("normal approximation of the shot noise at every count, float32",
                              poisson_switch=None),
    "preview": SensorNoiseLevel("exact Poisson inversion up to 10 expected electrons, normal "
                                "above; float32", poisson_switch=10.0),
    "final": SensorNoiseLevel("exact Poisson inversion up to 30 expected electrons, normal "
                              "above; float32", poisson_switch=30.0),
    "reference": SensorNoiseLevel("as final, with all arithmetic (Box-Muller, CDF sums, the "
                                  "PRNU pattern's Gaussian) in float64", fp64=True,
                                  poisson_switch=30.0),
}

MAX_COUNT = 200
"""Bound of the inversion loop, in CDF terms (never reached: with u <= 1 - 4e-6 and
lambda <= 30 the search ends by n ~ 60)."""


def sensor_gain(p, camera) -> float:
    """Gain relative to base ISO, from the param or (iso = 0) the camera block."""
    iso = p.iso if p.iso > 0 else camera.iso
    return iso / p.base_iso


def electrons_per_unit(p, camera, reference: float = MID_GREY) -> tuple[float, float, float]:
    """``k_c``: electrons collected per unit of scene-linear value, per channel, for a plate
    whose middle grey is the scene-linear value ``reference`` (`exposure_reference`; the
    default 0.18 is the model's own scale: ``full_well`` electrons at 1.0 and base ISO)."""
    gain = sensor_gain(p, camera)
    scale = MID_GREY / reference
    return tuple(p.full_well * s / gain * scale for s in p.channel_sensitivity)


def noise_variance(v, p, camera, channel=1, reference: float = MID_GREY):
    """The model's variance of the output at clean linear value ``v``: shot noise and PRNU
    below the full well (a full site reads full: neither at or above it), read noise."""
    g = 1.0 / electrons_per_unit(p, camera, reference)[channel]
    below = np.where(np.asarray(v) >= p.full_well * g, 0.0, np.maximum(v, 0.0))
    shot = g * below if p.shot_noise else 0.0
    return shot + (g * p.read_noise) ** 2 + (p.prnu * below) ** 2


@register
class SensorNoise(Plugin):
    """Photon shot noise, read noise and PRNU; see the module docstring for the model."""

    whole_frame = None   # noise hashed on frame coordinates, pixel by pixel
    descriptor = Descriptor(
        name="sensor_noise", label="Sensor noise", group="Camera", kernel="sensor_noise.cl",
        summary="Poisson shot noise and Gaussian read noise in linear light from the ISO, "
                "relative to the plate's own exposure (metered, or a stated middle grey), "
                "up to the full well (saturated lights are clean), a fixed photo-response "
                "non-uniformity pattern, a Bayer mosaic demosaiced by Malvar-He-Cutler "
                "(colour noise correlated across channels and neighbours, each pixel with "
                "its own value's variance: no lattice, no rings round lights) and optional "
                "low-frequency chroma blotches.",
        frame_varying=True,
        params=(
            FloatParam("iso", 0.0, min=0.0, max=1e6,
                       hint="Sensor ISO; 0 = the camera block's iso."),
            FloatParam("base_iso", 100.0, min=1.0, max=1e5,
                       hint="ISO at which the sensor collects full_well electrons per unit "
                            "of linear value (unity analogue gain)."),
            FloatParam("full_well", 10000.0, min=1.0, max=1e7, units="e-",
                       hint="A photosite's capacity: the electrons it collects for a "
                            "scene-linear value of 1.0 at base ISO on a plate whose middle grey "
                            "is 0.18 (see middle_grey); a full site reads full (no shot "
                            "noise above it)."),
            FloatParam("middle_grey", 0.0, min=0.0, max=1e6, auto=MIDDLE_GREY_AUTO,
                       hint="Scene-linear value the camera exposed as middle grey: electrons "
                            "scale by 0.18 / middle_grey, so a plate at any exposure gets the "
                            "same noise; auto (or 0) = meter each frame as grain does "
                            "(--explain prints the value)."),
            BoolParam("shot_noise", True,
                      hint="Poisson photon noise (variance proportional to the signal)."),
            FloatParam("read_noise", 3.0, min=0.0, max=1e4, units="e-",
                       hint="Gaussian read noise, RMS electrons at the sensor."),
            FloatParam("prnu", 0.0, min=0.0, max=0.1,
                       hint="Photo-response non-uniformity: RMS of a fixed per-pixel gain "
                            "error (0.01 = 1 %), the same on every frame."),
            RGBParam("channel_sensitivity", (1.0, 1.0, 1.0), min=0.01, max=100.0,
                     hint="Relative electrons per unit per channel (e.g. 0.5 = that channel "
                          "needs twice the white-balance gain and is noisier)."),
            ChoiceParam("mosaic", "bayer", choices=("bayer", "none"),
                        hint="bayer: one colour per photosite (RGGB), demosaiced (correlated "
                             "colour noise, as a camera's output); none: independent noise "
                             "per pixel and channel."),
            FloatParam("chroma_noise", 0.0, min=0.0, max=10.0,
                       hint="Low-frequency chroma blotches: their deviation relative to the "
                            "pixel's green noise deviation (0 = none)."),
            FloatParam("chroma_size", 0.02, min=1e-4, max=1.0,
                       hint="Grid spacing of the chroma blotches as a fraction of the frame "
                            "diagonal."),
            COVERAGE_PARAM,
            SEED_PARAM,
        ),
        quality=LEVELS,
    )

    def region_of_interest(self, p, ctx, window):
        # every value is hashed on the pixel's frame coordinates (the same for a crop at the
        # same place); the Bayer demosaic reads 2 photosites around each pixel
        return window.grown(DEMOSAIC_REACH) if p.mosaic == "bayer" else window

    def is_identity(self, p, ctx):
        if not p.shot_noise and p.read_noise == 0.0 and p.prnu == 0.0:
            return "shot noise is off, read noise and prnu are 0"
        return None

    def plan(self, p, ctx):
        return ExposurePlan(middle_grey=exposure_reference(p, ctx, "sensor_noise"))

    def prnu_pattern(self, rt, p, ctx, fp64):
        """The fixed pattern ``prnu * z`` on ``ctx.source``'s window, kept in ``rt.cache`` per
        parameter set, window and precision.

        The pattern is the same on every frame, so a sequence computes it once: its
        Box-Muller pair per value (~40 % of a draft render at 1080p) becomes one read.

        Parameters
        ----------
        rt : Runtime
        p : Params
            Uses ``prnu`` and ``seed`` (with the look's seed, ``ctx.seed``).
        ctx : RenderContext
            Its source's window and pitch place the pattern in frame coordinates.
        fp64 : bool
            Compute ``z`` in float64 where the device can (the level's ``fp64``); stored as
            float32 either way.

        Returns
        -------
        DeviceImage
            Same layout as ``ctx.source``; colour lanes hold ``prnu * z`` (the relative gain
            error), alpha lanes 0.
        """
        src = ctx.source
        seed = effect_seed(p.seed, ctx.seed, PRNU_SALT)

        def build():
            pattern = src.like()
            knl = rt.kernel("sensor_noise.cl", "sensor_noise_prnu", fp64=fp64)
            rt.launch(knl, (src.pitch // 4, src.height), pattern, src.pitch, src.height,
                      src.window.x0, src.window.y0, seed, p.prnu)
            return pattern

        key = ("sensor_noise.prnu", seed, float(p.prnu), src.window, src.pitch,
               rt.use_fp64(fp64))
        return rt.cache.get(key, build)

    def render(self, rt, p, ctx):
        src = ctx.source
        lvl = self.level(ctx)
        switch = lvl.poisson_switch
        defines = {"SHOT": int(p.shot_noise), "READ": int(p.read_noise > 0),
                   "PRNU": int(p.prnu > 0), "INVERT": int(switch is not None),
                   "SWITCH": repr(float(switch or 0.0)), "MAX_COUNT": MAX_COUNT}
        pattern = self.prnu_pattern(rt, p, ctx, lvl.fp64) if p.prnu > 0 else src  # src: unread
        kr, kg, kb = electrons_per_unit(p, ctx.camera, self.planned(p, ctx).middle_grey)
        well, prnu, read = p.full_well, p.prnu, p.read_noise
        seed = effect_seed(p.seed, ctx.seed, SENSOR_SALT)
        x0, y0 = src.window.x0, src.window.y0
        demosaic, chroma = p.mosaic == "bayer", p.chroma_noise > 0
        # bayer: the first pass writes each photosite's deviation (one float per pixel)
        dst = rt.buffer(src.pitch * src.height * 4) if demosaic else src.like()
        coverage = int(alpha_is_coverage(p.coverage, ctx, "sensor_noise"))
        last = not (demosaic or chroma)          # the apply pass writes the output itself
        knl = rt.kernel("sensor_noise.cl", "sensor_noise_apply", fp64=lvl.fp64,
                        MOSAIC=int(demosaic), COVERAGE=coverage * int(last), **defines)
        rt.launch(knl, (src.pitch // 4, src.height), src, dst, pattern, src.pitch, src.height, x0,
                  y0, seed, ctx.frame, kr, kg, kb, read, well, prnu)
        if last:
            return dst
        out = src.like()
        cell = max(p.chroma_size * ctx.diagonal_px, 1.0)
        knl = rt.kernel("sensor_noise.cl", "sensor_noise_demosaic", DEMOSAIC=int(demosaic),
                        CHROMA=int(chroma), COVERAGE=coverage, SHOT=defines["SHOT"],
                        **ctx.luminance_defines)
        rt.launch(knl, (src.pitch, src.height), src, dst, out, src.pitch, src.window.width,
                  src.height, x0, y0, seed, ctx.frame, kr, kg, kb, read, prnu, well,
                  p.chroma_noise, 1.0 / cell)
        return out
