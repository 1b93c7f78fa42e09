"""Motion blur: object motion reconstructed from a velocity pass (and optional depth pass).

Model
-----
During the open shutter ``[t0, t1]`` (frames, relative to the frame time) a surface point seen
at pixel ``y`` at the frame time sits at ``y + v_y t``, with ``v_y`` the velocity pass (forward
px/frame, +x right, +y down; :mod:`clfx.core.frame`).  The shutter interval comes from the camera
block (``shutter_angle / 360`` of a frame, ``shutter_offset`` centred / opening / closing:
:func:`clfx.core.camera.shutter_interval`) or from this effect's overrides.  The blurred pixel
``x`` is the time average of whatever surface covers ``x``; a post-process only knows the
surfaces visible at the frame time, so it reconstructs that average by gathering: the
depth-aware reconstruction filter with tile classification of :mod:`clfx.fx.motion` (McGuire
et al. 2012, Jimenez 2014), whose quality levels this effect declares.

Light leaves the data window: the region of definition grows by the farthest reach of any
pixel's smear (the frame's peak speed over the shutter, from the shared scene analysis,
clamped to ``max_blur``).  When the output window is larger than the source window (a data
window tighter than the display window), the beauty is extended with transparent black and
the passes by their edge values, so a moving object's smear continues past the data window
instead of stopping at a hard edge.  Without a depth pass all pixels count as one depth (no
occlusion ordering).

References
----------
M. McGuire, P. Hennessy, M. Bukowski, B. Osman, "A reconstruction filter for plausible motion
blur", I3D 2012.  J. Jimenez, "Next generation post processing in Call of Duty: Advanced
Warfare", SIGGRAPH 2014 course.
"""
from __future__ import annotations

import math

from clfx.core.errors import ClipError
from clfx.core.plugin import ChoiceParam, Clip, Descriptor, FloatParam
from clfx.fx.motion import (
    LEVELS,
    MAX_RADIUS_PX,
    MIN_BLUR_PX,
    SHUTTER_OFFSETS,
    reach_px,
    reconstruct,
    shutter_from,
)
from clfx.host import Plugin, register


@register
class MotionBlur(Plugin):
    whole_frame = ("its velocity tiles (tile max, neighbour max) lie on a grid from the source "
                   "window's origin and its gather samples at window-relative float32 "
                   "positions (float32 rounding differs per tile)")
    descriptor = Descriptor(
        name="motion_blur", label="Motion blur", group="Camera", kernel="motion_blur.cl",
        summary="Object motion blur reconstructed from the velocity pass (McGuire 2012 "
                "reconstruction filter with tile classification), depth-aware.",
        clips=(Clip("source"),
               Clip("velocity", channels=2,
                    hint="Forward screen-space motion in px/frame (+x right, +y down)."),
               Clip("depth", optional=True, channels=1,
                    hint="Planar depth (m); orders occluders. Without it, one depth is assumed.")),
        params=(
            FloatParam("shutter_angle", -1.0, min=-1.0, max=720.0,
                       hint="Shutter angle in degrees (180 = open half the frame); -1 = the "
                            "camera block's.", units="deg"),
            ChoiceParam("shutter_offset", "camera", choices=SHUTTER_OFFSETS,
                        hint="Shutter interval centred on the frame time, opening at it or "
                             "closing at it; 'camera' = the camera block's."),
            FloatParam("max_blur", 0.05, min=0.001, max=0.25,
                       hint="Largest blur radius (reach of one pixel's smear) as a fraction of "
                            "the frame diagonal; faster pixels are clamped to it (and to "
                            f"{MAX_RADIUS_PX} px)."),
        ),
        quality=LEVELS,
        spreads_light=True,
    )

    def max_radius_px(self, p, ctx) -> float:
        return min(p.max_blur * ctx.diagonal_px, MAX_RADIUS_PX)

    def reach(self, p, ctx) -> int:
        """How far (px) light moves from where it is at the frame time: the frame's peak speed
        over the shutter (clamped like the velocities), plus a pixel for bilinear fetches."""
        if ctx.velocity is None:
            return 0
        t0, t1 = shutter_from(p, ctx.camera)
        r = reach_px(ctx.analysis.peak_speed, t0, t1, self.max_radius_px(p, ctx))
        return int(math.ceil(r)) + 1 if r * (t1 - t0) > 0.0 else 0

    def is_identity(self, p, ctx):
        t0, t1 = shutter_from(p, ctx.camera)
        if t1 - t0 <= 0.0:
            return "shutter angle is 0"
        if ctx.velocity is None:
            return None
        peak = ctx.analysis.peak_speed
        if peak * (t1 - t0) < MIN_BLUR_PX:
            return (f"velocity below {MIN_BLUR_PX:g} px over the shutter everywhere (peak "
                    f"{peak:.3g} px/frame over a {t1 - t0:.3g}-frame shutter)")
        return None

    def region_of_definition(self, p, ctx):
        return ctx.source.window.grown(self.reach(p, ctx))

    def region_of_interest(self, p, ctx, window):
        return window.grown(int(math.ceil(self.max_radius_px(p, ctx))))

    def render(self, rt, p, ctx):
        src, vel = ctx.source, ctx.velocity
        if vel is None or vel.window != src.window:
            raise ClipError("motion_blur: the velocity pass must cover the source window "
                            f"{src.window} (it covers {None if vel is None else vel.window})")
        depth = ctx.depth if ctx.depth is not None and ctx.depth.window == src.window else None
        back = getattr(ctx, "velocity_back", None)
        back = back if back is not None and back.window == src.window else None
        window = self.output_window(p, ctx)
        if window != src.window:
            # past the data window: nothing (transparent black), moving like the edge
            src = rt.reframe(src, window, "zero")
            vel = rt.reframe(vel, window, "clamp")
            depth = None if depth is None else rt.reframe(depth, window, "clamp")
            back = None if back is None else rt.reframe(back, window, "clamp")
        t0, t1 = shutter_from(p, ctx.camera)
        a = ctx.analysis
        out, stats = reconstruct(
            rt, src, vel, depth, t0=t0, t1=t1, max_radius_px=self.max_radius_px(p, ctx),
            peak_speed=a.peak_speed, level=self.level(ctx), frame=ctx.frame,
            nonfinite=a.nonfinite_count, velocity_back=back)
        ctx.notes.append(f"motion_blur: {stats.moving_tiles}/{stats.tiles} tiles of "
                         f"{stats.tile} px moving, radius {stats.radius_px:.1f} px, "
                         f"<= {stats.max_samples} samples, "
                         + ("curved paths through the previous, current and next positions "
                            "(both halves of the vector pass)" if back is not None else
                            "straight paths along the forward motion (one half of the vector "
                            "pass)")
                         + (f", {a.nonfinite_count} non-finite pixels zeroed"
                            if a.nonfinite_count else "")
                         + (f", grown to {window}" if window != ctx.source.window else ""))
        return out
