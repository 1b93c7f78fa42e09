"""Vignette: natural cos^4 light falloff plus an artistic radial darkening.

Model
-----
Natural falloff (exact for a pinhole, close for a thin lens): a point at angle ``theta`` off
the optical axis receives ``cos^4(theta)`` of the axial irradiance, with
``tan(theta) = r_mm / f``; ``r_mm`` is the distance to the optical centre on the sensor,
from the camera block's sensor width and focal length (the sensor width spans the display
window; pixel aspect stretches x).  ``natural`` blends it in (1 = physical).

Artistic falloff: ``1 - amount * smoothstep(radius, radius + softness, r)``, where ``r`` is
the distance to the centre normalised so the frame corner is at 1; ``roundness`` = 1 gives
a circle, 0 an ellipse following the frame's aspect.  Both factors multiply RGB; alpha is
kept.  Values are clamped to [0, 1] so far-off-frame coordinates stay finite.  Non-finite
input values (colour or alpha) become 0, counted in ``ctx.notes`` from the frame's shared
analysis.
"""
from __future__ import annotations

import math

from clfx.core.plugin import Descriptor, FloatParam, Level, Vec2Param
from clfx.host import Plugin, register

LEVELS = {
    "draft": Level("float32 per pixel (exact closed form; all levels cost the same)"),
    "preview": Level("float32 per pixel (exact closed form)"),
    "final": Level("float32 per pixel (exact closed form)"),
    "reference": Level("float64 evaluation of the falloff", fp64=True),
}


def vignette_geometry(p, camera, display_window, pixel_aspect):
    """Constants of the kernel: optical centre, mm per pixel, artistic axis scales."""
    w, h = display_window.width, display_window.height
    cx0, cy0 = display_window.center
    cx = cx0 + p.center[0] * w * 0.5
    cy = cy0 + p.center[1] * h * 0.5
    sx = camera.sensor_width / max(w, 1)
    sy = sx / pixel_aspect
    # Artistic radius: corner at r = 1.  Circle: divide by the half diagonal (in square
    # units, pixel aspect applied); ellipse: divide each axis by its half size / sqrt(2).
    half_w, half_h = 0.5 * max(w, 1) * pixel_aspect, 0.5 * max(h, 1)
    half_diag = math.hypot(half_w, half_h)
    ax_circle, ay_circle = pixel_aspect / half_diag, 1.0 / half_diag
    ax_ellipse, ay_ellipse = pixel_aspect / (half_w * math.sqrt(2)), 1.0 / (half_h * math.sqrt(2))
    ax = p.roundness * ax_circle + (1 - p.roundness) * ax_ellipse
    ay = p.roundness * ay_circle + (1 - p.roundness) * ay_ellipse
    return cx, cy, sx, sy, ax, ay


@register
class Vignette(Plugin):
    whole_frame = None   # tiles: the same pixels band by band (tests/contract/test_tiles.py)
    descriptor = Descriptor(
        name="vignette", label="Vignette", group="Lens", kernel="vignette.cl",
        summary="Natural cos^4 falloff from the camera's focal length and sensor, plus an "
                "artistic radial darkening.",
        params=(
            FloatParam("natural", 1.0, min=0.0, max=1.0,
                       hint="Blend of the physical cos^4 falloff (1 = as the camera block predicts)."),
            FloatParam("amount", 0.0, min=-1.0, max=1.0,
                       hint="Artistic darkening at the corners (negative brightens)."),
            FloatParam("radius", 0.5, min=0.0, max=2.0,
                       hint="Where the artistic falloff starts, as a fraction of the centre-to-corner distance."),
            FloatParam("softness", 0.6, min=0.01, max=4.0,
                       hint="Width of the artistic falloff, same units as radius."),
            FloatParam("roundness", 1.0, min=0.0, max=1.0,
                       hint="1 = circular falloff, 0 = elliptical following the frame's aspect."),
            Vec2Param("center", (0.0, 0.0), min=-2.0, max=2.0,
                      hint="Optical centre offset as a fraction of half the frame (x right, y down)."),
        ),
        quality=LEVELS,
    )

    def is_identity(self, p, ctx):
        if p.natural == 0.0 and p.amount == 0.0:
            return "natural and amount are 0"
        return None

    def render(self, rt, p, ctx):
        src = ctx.source
        cx, cy, sx, sy, ax, ay = vignette_geometry(p, ctx.camera, ctx.display_window,
                                                   ctx.pixel_aspect)
        nonfinite = ctx.analysis.nonfinite_count
        if nonfinite:
            ctx.notes.append(f"vignette: {nonfinite} non-finite pixel(s) set to 0")
        knl = rt.kernel("vignette.cl", "vignette_apply", fp64=self.level(ctx).fp64)
        dst = src.like()
        # 8 pixels a work-item
        rt.launch(knl, (-(-src.pitch // 8), src.height), src, dst, src.pitch, src.height,
                  src.window.x0, src.window.y0, cx, cy, sx, sy, 1.0 / ctx.camera.focal_length,
                  p.natural, ax, ay, p.amount, p.radius, 1.0 / p.softness)
        return dst
