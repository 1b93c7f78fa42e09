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

Rendering is the motion family's (`clfx.kit.motion.VelocityGather`: the plan, the frame's
velocity tiles, a band's rows of the canvas, the reconstruction); this module supplies the
velocity pass over a band's rows and its notes.

The passes after the blur (`passes_after`).  The blur moves a surface's colour off its
silhouette (a ball's smear over the empty background around it), while the velocity and depth
passes still describe the sharp frame: there they say "background, static".  An effect after
this one that moves pixels along the velocity (rolling shutter, which phone-pan puts after
the blur so each row's smear moves to the row's time) then left the smear behind while the
ball moved on: a detached arc a few pixels outside the ball, and a dark gap between (issue
32).  So when a later step reads them, the blur realigns the passes with its output: the same
reconstruction gathers, with the beauty's tiles and weights, the velocity (and depth) of the
surfaces that move (at least half a pixel over the shutter, the ones it smears), and each
pixel takes the average of what moved into it (where nothing moving did, its own pass,
extended by the edge past the data window): the smear moves with its surface.  A static
background inside the smear (at most the blur's length) moves with it too: one velocity per
pixel cannot split a mixed pixel.

References
----------
M. McGuire, P. Hennessy, M. Bukowski, B. Osman, "A reconstruction filter for plausible motion
blur", I3D 2012.  J. Jimenez, "Next generation post processing in Call of Duty: Advanced
Warfare", SIGGRAPH 2014 course.
"""
from __future__ import annotations

import math

import numpy as np

from clfx.core.plugin import ChoiceParam, Clip, Descriptor, FloatParam
from clfx.fx.motion import (
    LEVELS,
    MAX_RADIUS_PX,
    MIN_BLUR_PX,
    SHUTTER_OFFSETS,
    reach_px,
    shutter_from,
)
from clfx.host import Plugin, register
from clfx.kit.motion import GatherMotion, VelocityGather, aligned_passes, on_rows


@register
class MotionBlur(VelocityGather, Plugin):
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

    # -- the velocity fields (clfx.kit.motion.VelocityGather renders them) ---------------
    def gather_canvas(self, p, ctx):
        return self.output_window(p, ctx)   # the smear continues past the data window

    def gather_motion(self, p, ctx):
        src, vel = ctx.source, ctx.velocity
        if vel is None or vel.window != src.window:
            return ("motion_blur: the velocity pass must cover the source window "
                    f"{src.window} (it covers {None if vel is None else vel.window})")
        depth, back = aligned_passes(ctx)
        return GatherMotion(ctx.analysis.peak_speed, has_depth=depth is not None,
                            curved=back is not None)

    def velocity_rows(self, rt, p, ctx, plan, rows):
        # the pass over the rows, past the data window moving like its edge
        depth, back = aligned_passes(ctx)
        return on_rows(rt, ctx.velocity, rows), on_rows(rt, depth, rows), on_rows(rt, back, rows)

    def gather_note(self, p, ctx, plan, stats):
        nonfinite = ctx.analysis.nonfinite_count
        whole = ctx.tiling.whole if ctx.tiling is not None else ctx.source.window
        return (f"motion_blur: {stats.moving_tiles}/{stats.tiles} tiles of "
                f"{stats.tile} px moving, radius {stats.radius_px:.1f} px, "
                f"<= {stats.max_samples} samples, "
                + ("curved paths through the previous, current and next positions "
                   "(both halves of the vector pass)" if plan.curved else
                   "straight paths along the forward motion (one half of the vector "
                   "pass)")
                + (f", {nonfinite} non-finite pixels zeroed" if nonfinite else "")
                + (f", grown to {plan.canvas}" if plan.canvas != whole else ""))

    def passes_after(self, rt, p, ctx, out, later):
        """The velocity (and depth) the blurred frame shows, for a later step that reads them
        (module docstring, "The passes after the blur"): the velocity and depth of the
        moving surfaces gathered as the colour was, over ``out.window``."""
        vel, depth = ctx.velocity, ctx.depth
        if "velocity" not in later or vel is None or vel.window != ctx.source.window:
            return {}
        plan = self.planned(p, ctx)
        v = rt.download(vel).astype(np.float64)
        moving = np.hypot(v[..., 0], v[..., 1]) * (plan.t1 - plan.t0) >= MIN_BLUR_PX
        with_depth = "depth" in later and depth is not None and depth.window == vel.window
        z = rt.download(depth).astype(np.float64) if with_depth else np.zeros(moving.shape)
        m = moving.astype(np.float64)
        carried = np.stack([v[..., 0] * m, v[..., 1] * m, np.where(moving, z, 0.0), m], -1)
        spread = rt.download(self.render(rt, p, ctx.over(source=rt.upload(carried, vel.window),
                                                         notes=[], warnings=[])))
        weight = spread[..., 3:4].astype(np.float64)
        took = weight > 1e-6           # something moving reached the pixel
        own = rt.download(rt.reframe(vel, out.window, "clamp"))
        moved = {"velocity": rt.upload(np.where(took, spread[..., :2] / np.where(took, weight, 1.0),
                                                own), out.window)}
        if with_depth:
            own_z = rt.download(rt.reframe(depth, out.window, "clamp"))
            moved["depth"] = rt.upload(np.where(took[..., 0], spread[..., 2] / np.where(
                took[..., 0], weight[..., 0], 1.0), own_z), out.window)
        return moved
