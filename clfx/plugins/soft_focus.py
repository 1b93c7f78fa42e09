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
Uses the glare family's machinery (``clfx.fx.scatter.ScatterPlugin``, ``kernels/lib/scatter.h``,
``clfx.fx.fftconv``; quality levels ``clfx.fx.fftconv.LEVELS``).
"""
from __future__ import annotations

from clfx.core.plugin import Descriptor, FloatParam
from clfx.fx import fftconv
from clfx.fx import psf as psflib
from clfx.fx.scatter import ScatterPlugin, knee_param, tint_param
from clfx.host import Plugin, register


@register
class SoftFocus(ScatterPlugin, Plugin):
    descriptor = Descriptor(
        name="soft_focus", label="Soft focus", group="Lens", kernel="soft_focus.cl",
        summary="Diffusion filter: a wide glow from all moderately bright pixels, blended in.",
        spreads_light=True,
        params=(
            FloatParam("amount", 0.3, min=0.0, max=1.0,
                       hint="Fraction of the light above the threshold that is diffused."),
            FloatParam("threshold", 0.25, min=0.0, max=1e6,
                       hint="Luminance where diffusion starts (low: moderately bright pixels glow)."),
            knee_param(0.25),
            FloatParam("size", 0.03, min=0.0, max=1.0,
                       hint="Glow radius as a fraction of the frame diagonal."),
            tint_param("diffused"),
        ),
        quality=fftconv.LEVELS,
    )
    strength_param = "amount"

    def build_psf(self, p, ctx, radius):
        sig, w = psflib.bloom_sigmas(radius, count=3)
        return psflib.gaussians(radius, sig, w)
