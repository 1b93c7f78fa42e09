"""Sensor noise in linear light: Poisson shot noise, Gaussian read noise, fixed-pattern PRNU.

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

i.e. in linear units, variance = gain * signal + read^2 with gain ``g_c`` and read noise
``g_c * read`` (read noise is given in electrons at the sensor, so its linear size grows
with ISO, as in a real camera's output).  The Poisson count is sampled exactly by CDF
inversion while ``lambda <= 30`` electrons (final/reference; 10 in preview; the uniform is
capped at 1 - 4e-6 so float32 rounding of the summed CDF, <= ~1.2e-6 here, can never stall
the search: only the top 4e-6 quantile is moved to its lower edge), and by the
normal approximation ``lambda + sqrt(lambda) z`` above (same mean and variance; the skew
of a Poisson at 30 counts is 0.18).  Draft uses the normal approximation at every count.

Random numbers come from ``clfx_uniform(seed, frame, X, Y, c)`` at frame coordinates, so
the noise is identical for a frame rendered alone, in a batch, cropped, or on any thread
count; the PRNU pattern uses frame 0 and its own seed, so it stays fixed over a sequence
(it is computed once per parameter set and data window and kept in the runtime's cache:
one frame-sized float buffer).
Non-finite inputs become 0 (then get read noise) and values are clamped to +-1e38 so
nothing overflows; alpha is kept bit for bit (0 where it was not finite).

References: EMVA Standard 1288 (linear photon-transfer model: variance = K (mu - mu_dark)
+ sigma_read^2, PRNU); Foi et al. 2008, "Practical Poissonian-Gaussian noise modeling and
fitting for single-image raw-data".
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from clfx.core.plugin import BoolParam, Descriptor, FloatParam, Level, RGBParam
from clfx.fx.noise import SEED_PARAM, effect_seed
from clfx.host import Plugin, register

SENSOR_SALT = 0x73656E73  # "sens"
PRNU_SALT = 0x70726E75    # "prnu"


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


def electrons_per_unit(p, camera) -> tuple[float, float, float]:
    """``k_c``: electrons collected per unit of scene-linear value, per channel."""
    gain = sensor_gain(p, camera)
    return tuple(p.full_well * s / gain for s in p.channel_sensitivity)


def noise_variance(v, p, camera, channel=1):
    """The model's variance of the output at linear value ``v`` (PRNU aside)."""
    g = 1.0 / electrons_per_unit(p, camera)[channel]
    shot = g * np.maximum(v, 0.0) if p.shot_noise else 0.0
    return shot + (g * p.read_noise) ** 2


@register
class SensorNoise(Plugin):
    """Photon shot noise, read noise and PRNU; see the module docstring for the model."""

    descriptor = Descriptor(
        name="sensor_noise", label="Sensor noise", group="Camera", kernel="sensor_noise.cl",
        summary="Poisson shot noise and Gaussian read noise in linear light from the ISO, plus "
                "a fixed photo-response non-uniformity pattern.",
        frame_varying=True,
        params=(
            FloatParam("iso", 0.0, min=0.0, max=1e6,
                       hint="Sensor ISO; 0 = the camera block's iso."),
            FloatParam("base_iso", 100.0, min=1.0, max=1e5,
                       hint="ISO at which the sensor collects full_well electrons per unit "
                            "of linear value (unity analogue gain)."),
            FloatParam("full_well", 10000.0, min=1.0, max=1e7, units="e-",
                       hint="Electrons collected for a scene-linear value of 1.0 at base ISO."),
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
            SEED_PARAM,
        ),
        quality=LEVELS,
    )

    def is_identity(self, p, ctx):
        if not p.shot_noise and p.read_noise == 0.0 and p.prnu == 0.0:
            return "shot noise is off, read noise and prnu are 0"
        return None

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
            rt.launch(knl, (src.pitch // 4, src.height), pattern, np.int32(src.pitch),
                      np.int32(src.height), np.int32(src.window.x0), np.int32(src.window.y0),
                      np.uint32(seed), np.float32(p.prnu))
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
        kr, kg, kb = (np.float32(k) for k in electrons_per_unit(p, ctx.camera))
        dst = src.like()
        knl = rt.kernel("sensor_noise.cl", "sensor_noise_apply", fp64=lvl.fp64, **defines)
        rt.launch(knl, (src.pitch // 4, src.height), src, dst, pattern, np.int32(src.pitch),
                  np.int32(src.height), np.int32(src.window.x0), np.int32(src.window.y0),
                  np.uint32(effect_seed(p.seed, ctx.seed, SENSOR_SALT)), np.int32(ctx.frame),
                  kr, kg, kb, np.float32(p.read_noise))
        return dst
