"""Defocus: a uniform Gaussian blur, the softness of a cheap or mis-focused camera.

Model
-----
Every channel of the premultiplied RGBA image is convolved with a Gaussian whose standard
deviation on screen is ``size`` times the frame (display window) diagonal, so a half-size
proxy matches the full render.  At 1920x1080 (diagonal 2203 px) ``size`` = 1.4e-4 is 0.3 px
and 0.0908 is 200 px; the hard maximum 0.25 is 550 px.  ``aspect`` = sigma_y / sigma_x gives
an anamorphic (oval) blur.  Pixel aspect (width / height of a pixel) is honoured: sigma in x,
counted in pixels, is divided by it so the blur is round on screen.

``edges`` says how the picture continues past its data window: ``clamp`` repeats the edge
pixels (a full frame keeps its brightness to the border), ``mirror`` reflects them,
``black`` treats the outside as empty, so light spreads out of an element (a CG layer with a
small data window) into transparent surroundings.  The region of definition grows by
3 sigma (light lands outside the frame); the effect renders into ``output_window``.

NaN/Inf pixels would spread over the whole footprint: they are set to 0 first and counted in
``ctx.notes`` (the shared scene analysis tells whether any exist, so a clean frame costs
nothing extra).

Algorithm and accuracy: :mod:`clfx.fx.blur` (direct separable passes below ~4 px, a Gaussian
pyramid with B-spline reconstruction above, cost flat in sigma).  Max error against the
exact discrete Gaussian, relative to the peak of a blurred impulse (per axis; a 2-D impulse
adds both axes): draft <= 7e-3, preview <= 1e-3, final <= 1.5e-4, reference <= 1e-7; on a
unit step: 6e-4, 1e-4, 2.5e-5, 1e-7.
"""
from __future__ import annotations

import math

from clfx.core.plugin import ChoiceParam, Descriptor, FloatParam
from clfx.fx.blur import LEVELS, MIN_SIGMA, gaussian_blur, sanitize_nonfinite
from clfx.host import Plugin, register

EDGES = {"clamp": "clamp", "mirror": "mirror", "black": "zero"}
"""``edges`` choice -> clfx.fx.blur border mode."""

SPREAD_SIGMAS = 3.0
"""The region of definition grows by this many sigma (1% of the peak is left beyond)."""


def defocus_sigmas(p, ctx) -> tuple[float, float]:
    """(sigma_x, sigma_y) in pixels for params ``p`` in render context ``ctx``."""
    s = ctx.size_px(p.size)
    return s / ctx.pixel_aspect, s * p.aspect


@register
class Defocus(Plugin):
    whole_frame = ("large sigmas blur through a decimation pyramid (clfx.fx.blur) whose levels "
                   "lie on the whole frame's grid")
    descriptor = Descriptor(
        name="defocus", label="Defocus", group="Lens", kernel="defocus.cl",
        summary="Uniform Gaussian softness from 0.3 px to hundreds of pixels, resolution-"
                "independent, at a cost that does not grow with the size.",
        params=(
            FloatParam("size", 0.002, min=0.0, max=0.25, display_min=0.0, display_max=0.1,
                       units="frame diagonal",
                       hint="Gaussian sigma as a fraction of the frame diagonal "
                            "(1920x1080: 0.00014 = 0.3 px, 0.0045 = 10 px, 0.091 = 200 px)."),
            FloatParam("aspect", 1.0, min=0.05, max=20.0,
                       hint="Vertical sigma / horizontal sigma (1 = round, 2 = twice as tall)."),
            ChoiceParam("edges", "clamp", choices=tuple(EDGES),
                        hint="Past the data window: clamp repeats edge pixels, mirror reflects "
                             "them, black lets light spread into empty surroundings."),
        ),
        quality=LEVELS,
        spreads_light=True,
    )

    def is_identity(self, p, ctx):
        if p.size == 0.0:
            return "size is 0"
        sx, sy = defocus_sigmas(p, ctx)
        if max(sx, sy) < MIN_SIGMA:
            return f"sigma {max(sx, sy):.3g} px is below {MIN_SIGMA} px"
        return None

    def region_of_definition(self, p, ctx):
        sx, sy = defocus_sigmas(p, ctx)
        gx = math.ceil(SPREAD_SIGMAS * sx) if sx >= MIN_SIGMA else 0
        gy = math.ceil(SPREAD_SIGMAS * sy) if sy >= MIN_SIGMA else 0
        return ctx.source.window.grown(gx, gy)

    def region_of_interest(self, p, ctx, window):
        sx, sy = defocus_sigmas(p, ctx)
        return window.grown(math.ceil(6 * sx), math.ceil(6 * sy))

    def render(self, rt, p, ctx):
        src = ctx.source
        if ctx.analysis.nonfinite_count:
            src, n_bad = sanitize_nonfinite(rt, src)
            if n_bad:
                ctx.notes.append(f"defocus: {n_bad} pixels with NaN/Inf set to 0")
        sx, sy = defocus_sigmas(p, ctx)
        out = rt.image(self.output_window(p, ctx), src.channels)
        return gaussian_blur(rt, src, sx, sy, quality=self.level(ctx), border=EDGES[p.edges],
                             out=out)

