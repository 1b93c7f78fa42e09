"""Soft focus: a diffusion filter (Softar, Pro-Mist): strong, wide glare from every moderately
bright pixel, blended with the image.

Model
-----
Every pixel above a low ``threshold`` (soft knee, as glare) gives ``amount`` of its light to a
wide bloom PSF, a sum of three Gaussians (Kawase-style, widest sigma = radius / 3,
``clfx.fx.psf.bloom_sigmas``), truncated at ``size`` x the frame diagonal:
``out = c - amount h + amount tint (PSF * h)``.  Energy is kept; highlights get a halo, mid
tones a glow, shadows pick up light from nearby brights (the lifted, low-contrast look).
The default threshold is below 1, so display-referred (8-bit) frames need no expansion.
Uses glare's machinery (``ScatterPlugin``, glare.cl helpers, ``clfx.fx.fftconv``).
"""
from __future__ import annotations

import numpy as np

from clfx.fx import psf as psflib
from clfx.core.camera import Camera
from clfx.core.plugin import Descriptor, FloatParam, RGBParam
from clfx.host import register
from clfx.plugins.glare import QUALITY, ScatterPlugin


@register
class SoftFocus(ScatterPlugin):
    descriptor = Descriptor(
        name="soft_focus", label="Soft focus", group="Lens", kernel="soft_focus.cl",
        summary="Diffusion filter: a wide glow from all moderately bright pixels, blended in.",
        spreads_light=True,
        params=(
            FloatParam("amount", 0.3, min=0.0, max=1.0,
                       hint="Fraction of the light above the threshold that is diffused."),
            FloatParam("threshold", 0.25, min=0.0, max=1e6,
                       hint="Luminance where diffusion starts (low: moderately bright pixels glow)."),
            FloatParam("knee", 0.25, min=0.0, max=1e6,
                       hint="Width of the soft knee below the threshold, in luminance."),
            FloatParam("size", 0.03, min=0.0, max=1.0,
                       hint="Glow radius as a fraction of the frame diagonal."),
            RGBParam("tint", (1.0, 1.0, 1.0), max=100.0,
                     hint="Colour of the diffused light (white keeps energy)."),
        ),
        quality=QUALITY,
    )

    def strength(self, p):
        return p.amount

    def build_psf(self, p, ctx, radius):
        sig, w = psflib.bloom_sigmas(radius, count=3)
        return psflib.gaussians(radius, sig, w)


def bench_case(width, height, rng):
    """A portrait-like frame: mid tones, a bright window and skin-like highlights."""
    src = np.empty((height, width, 4), np.float32)
    src[..., :3] = rng.uniform(0.02, 0.6, (height, width, 3))
    src[: height // 3, width // 2:, :3] = 4.0
    src[..., 3] = 1.0
    return dict(source=src, depth=None, velocity=None, params={"amount": 0.3, "size": 0.03},
                camera=Camera())
