"""Soft focus: a diffusion filter (Softar, Pro-Mist): strong, wide glare from every moderately
bright pixel, blended with the image.

Model
-----
Every pixel above a low ``threshold`` (soft knee, as glare) gives ``amount`` of its light to a
diffusion PSF: light scattered many times in the filter's turbid layer spreads with a roughly
exponential falloff, so the PSF is a sum of three radial exponentials ``exp(-d / s)``
(``clfx.fx.psf.exponentials``), scales ``size / 4``, ``size / 8`` and ``size / 16`` x the
frame diagonal with weights 1 : 2 : 4 towards the core (a tight glow around every highlight
and a long faint veil).  Its support radius is :data:`SUPPORT` x ``size``; the widest
exponential is below 1e-5 of the PSF one pixel out by 0.9 x the support, and the tail then
ends smoothly (``clfx.fx.psf.tail_fade``): no disc edge, no rim.
``out = c - amount h + amount tint (PSF * h)``.  Energy is kept; highlights get a halo, mid
tones a glow, shadows pick up light from nearby brights (the lifted, low-contrast look).
The default threshold is below 1, so display-referred (8-bit) frames need no expansion.
Uses the glare family's machinery (``clfx.kit.scatter.ScatterPlugin``, ``kernels/lib/scatter.h``,
``clfx.fx.fftconv``; quality levels ``clfx.fx.fftconv.LEVELS``).
"""
from __future__ import annotations

from clfx.core.plugin import Descriptor, FloatParam
from clfx.fx import fftconv
from clfx.fx import psf as psflib
from clfx.host import Plugin, register
from clfx.kit.scatter import ScatterPlugin, knee_param, tint_param


@register
class SoftFocus(ScatterPlugin, Plugin):
    descriptor = Descriptor(
        name="soft_focus", label="Soft focus", group="Lens", kernel="soft_focus.cl",
        summary="Diffusion filter: an exponential glow from all moderately bright pixels, "
                "blended in; the tail is below 1e-5 of the PSF one pixel out by 0.9 x the "
                "support (3 x size) and ends there.",
        spreads_light=True,
        params=(
            FloatParam("amount", 0.3, min=0.0, max=1.0,
                       hint="Fraction of the light above the threshold that is diffused."),
            FloatParam("threshold", 0.25, min=0.0, max=1e6,
                       hint="Luminance where diffusion starts (low: moderately bright pixels glow)."),
            knee_param(0.25),
            FloatParam("size", 0.03, min=0.0, max=1.0,
                       hint="Glow size as a fraction of the frame diagonal (widest "
                            "exponential scale size / 4; the PSF ends at 3 x size)."),
            tint_param("diffused"),
        ),
        quality=fftconv.LEVELS,
    )
    strength_param = "amount"

    def radius_px(self, p, ctx) -> int:
        return psflib.psf_radius_px(SUPPORT * p.size, ctx.diagonal_px)

    def build_psf(self, p, ctx, radius, reach=None):
        scales, weights = diffusion_scales(radius)
        return psflib.exponentials(radius, scales, weights, reach)


SUPPORT = 3.0
"""The PSF's support radius in units of ``size``."""


def diffusion_scales(radius_px: float):
    """Exponential scales (px) and weights of the diffusion PSF of a support ``radius_px``:
    ``size / 4, / 8, / 16`` (size = radius / SUPPORT), weights 1 : 2 : 4."""
    size = radius_px / SUPPORT
    return [size / 4.0, size / 8.0, size / 16.0], [1.0, 2.0, 4.0]
