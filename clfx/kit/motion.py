"""The motion family's band protocol: what motion_blur, camera_blur, rolling_shutter and shake
share between the gather (`clfx.fx.motion`) and the host: the passes a frame brings that line
up with its source, the rows a band of a tiled render reads beyond its own, and
:class:`VelocityGather`, the base of every effect rendered by the depth-aware reconstruction
(`clfx.fx.motion.reconstruct`) from velocity fields it supplies.

A gather effect (``class MotionBlur(VelocityGather, Plugin)``) answers two questions:

- :meth:`VelocityGather.gather_motion`: over the frame, how fast its fields move at most
  (px/frame, an upper bound), whether they bring a depth pass and a backward half (curved
  paths); or why the frame cannot be gathered (a missing pass);
- :meth:`VelocityGather.velocity_rows`: its forward velocity (and depth, backward velocity)
  over some rows of the canvas, as the whole render sees them;

and says what it did (:meth:`VelocityGather.gather_note`).  The base owns the rest: the
plan (shutter, canvas, clamp radius, the rows a band reads, the frame-wide velocity tiles
of a tiled render, built on the whole frame before any band), the region of interest, a
band's rows of the canvas and its reframes, and the reconstruction's call.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

from clfx.core.errors import ClipError
from clfx.core.plugin import ChoiceParam, FloatParam
from clfx.core.rect import Rect
from clfx.fx.motion import (
    MAX_RADIUS_PX,
    SHUTTER_OFFSETS,
    BlurStats,
    TileGrid,
    is_static,
    path_reach,
    reach_factor,
    reach_px,
    reconstruct,
    sanitized_copy,
    shutter_from,
    tile_grid,
)
from clfx.host import StepPlan

SHUTTER_PARAMS = (
    FloatParam("shutter_angle", -1.0, min=-1.0, max=720.0, units="deg",
               hint="Shutter angle in degrees; -1 = the camera block's."),
    ChoiceParam("shutter_offset", "camera", choices=SHUTTER_OFFSETS,
                hint="Shutter centred on, opening at or closing at the frame time; "
                     "'camera' = the camera block's."),
)
"""The shutter overrides of a blur of the camera's own motion (camera_blur, shake), read by
`clfx.fx.motion.shutter_from`."""


def aligned_passes(ctx):
    """``ctx``'s depth pass and the backward half of its vector pass where they cover the
    source window, else None (an effect then renders without them)."""
    src = ctx.source
    depth = ctx.depth if ctx.depth is not None and ctx.depth.window == src.window else None
    back = getattr(ctx, "velocity_back", None)
    return depth, (back if back is not None and back.window == src.window else None)


REACH_MARGIN_ROWS = 5
"""Rows a band's buffers hold beyond the farthest sample (:func:`band_margin`): the clamped
cubic's taps (2), the sub-pixel closed form's (2 along the path, bilinear), the dilation's
neighbour (1)."""


def band_margin(t0: float, t1: float, radius: float, curved: bool) -> int:
    """Rows beyond a band that its reconstruction reads (its region of interest): the
    farthest sample (:func:`path_reach` at the clamped speed ``radius / reach``) and
    :data:`REACH_MARGIN_ROWS`; 0 when nothing moves."""
    if is_static(t0, t1, radius):
        return 0
    return (int(math.ceil(path_reach(t0, t1, curved) * radius / reach_factor(t0, t1)))
            + REACH_MARGIN_ROWS)


def band_rows(ctx, canvas: Rect, margin: int) -> Rect:
    """The rows of ``canvas`` a render reads: in a band of a tiled render (``ctx.tiling``)
    the band's rows grown by ``margin`` (the farthest look-up), within the canvas; else the
    whole canvas."""
    if ctx.tiling is None:
        return canvas
    band = ctx.tiling.band
    return Rect(canvas.x0, max(band.y0 - margin, canvas.y0), canvas.x1,
                min(band.y1 + margin, canvas.y1))


def on_rows(rt, img, rows: Rect, border: str = "clamp"):
    """``img`` over ``rows`` (None stays None): past its window transparent black
    (``border="zero"``, a beauty) or its edge (``"clamp"``, a pass)."""
    return None if img is None else rt.reframe(img, rows, border)


@dataclass(frozen=True)
class GatherMotion:
    """What a gather effect's velocity fields are over a frame (:meth:`VelocityGather.
    gather_motion`): ``peak_speed``, an upper bound of their speed (px/frame; sizes the tiles,
    clamped to the blur radius); ``has_depth``, a depth pass orders them; ``curved``, a
    backward half makes every path an arc (`clfx.fx.motion.path`)."""

    peak_speed: float
    has_depth: bool = False
    curved: bool = False


@dataclass(frozen=True)
class GatherPlan(StepPlan):
    """A gather effect's plan for one step of a frame (:class:`VelocityGather`): the shutter,
    the clamp radius, what :meth:`VelocityGather.gather_motion` said (``fields``; None with
    ``missing`` the reason when the frame cannot be gathered), the canvas the whole render
    reconstructs over, the rows a band reads beyond itself and, when the step renders in
    bands, the frame's velocity tiles they read (built here from the whole frame; None when
    nothing moves or the render is whole, which builds its own from its buffers)."""

    t0: float = 0.0
    t1: float = 0.0
    max_radius_px: float = 0.0
    canvas: Rect | None = None
    fields: GatherMotion | None = None
    missing: str | None = None
    margin: int = 0
    grid: TileGrid | None = None

    @property
    def curved(self) -> bool:
        return self.fields is not None and self.fields.curved


class VelocityGather:
    """The motion family's base (a Plugin mixin): an effect whose output is the depth-aware
    reconstruction of its velocity fields over the open shutter (module docstring).

    Subclasses implement :meth:`gather_motion`, :meth:`velocity_rows` and
    :meth:`gather_note`; they may override :meth:`shutter` (default the ``shutter_angle`` /
    ``shutter_offset`` params over the camera block), :meth:`max_radius_px` (default the
    ``max_blur`` param) and :meth:`gather_canvas` (default the source window).  An effect
    with a second render (camera_blur's path gather) calls :meth:`gather_plan` and
    :meth:`gather_render` from its own ``plan`` and ``render``."""

    whole_frame: ClassVar[str | None] = None   # a band: the plan's tiles, its rows of the canvas
    plan_type: ClassVar[type] = GatherPlan

    # -- what an effect supplies -----------------------------------------------------------
    def gather_motion(self, p, ctx) -> GatherMotion | str:
        """The fields' :class:`GatherMotion` over ``ctx``'s frame, or why the frame cannot be
        gathered (a pass it needs missing: the render's error message)."""
        raise NotImplementedError

    def velocity_rows(self, rt, p, ctx, plan: GatherPlan, rows: Rect):
        """``(velocity, depth, back)`` over ``rows`` (frame coordinates, rows of
        ``plan.canvas`` within ``ctx``'s source window grown to the canvas) as the whole
        render sees them: 2-channel forward px/frame, depth or None, backward px/frame or
        None (as ``plan.fields`` says)."""
        raise NotImplementedError

    def gather_note(self, p, ctx, plan: GatherPlan, stats: BlurStats) -> str:
        """What one render did (``ctx.notes``)."""
        raise NotImplementedError

    # -- defaults an effect may override ----------------------------------------------------
    def shutter(self, p, ctx) -> tuple[float, float]:
        return shutter_from(p, ctx.camera)

    def shutter_closed(self, p, ctx) -> str | None:
        """The identity reason of a shutter open for no time, else None."""
        t0, t1 = self.shutter(p, ctx)
        return "shutter angle is 0" if t1 - t0 <= 0.0 else None

    def max_radius_px(self, p, ctx) -> float:
        return min(p.max_blur * ctx.diagonal_px, MAX_RADIUS_PX)

    def gather_canvas(self, p, ctx) -> Rect:
        """The window the whole render reconstructs over (beauty past the source window
        transparent black, passes extended by their edges)."""
        return ctx.source.window

    # -- the protocol -----------------------------------------------------------------------
    def gather_plan(self, p, ctx, **own) -> GatherPlan:
        """The step's :attr:`plan_type` (``own``: the effect's own fields)."""
        t0, t1 = self.shutter(p, ctx)
        max_radius = self.max_radius_px(p, ctx)
        motion = self.gather_motion(p, ctx)
        if isinstance(motion, str):
            return self.plan_type(t0=t0, t1=t1, max_radius_px=max_radius,
                                  canvas=ctx.source.window, missing=motion, **own)
        canvas = self.gather_canvas(p, ctx)
        plan = self.plan_type(t0=t0, t1=t1, max_radius_px=max_radius, canvas=canvas,
                              fields=motion, **own)
        grid = None
        if len(ctx.bands(canvas)) > 1:   # the bands' frame-wide tiles
            rt, nonfinite = ctx.runtime, ctx.analysis.nonfinite_count

            def rows_of(r0, r1):
                rows = Rect(canvas.x0, canvas.y0 + r0, canvas.x1, canvas.y0 + r1)
                col = rt.reframe(ctx.source, rows, "zero")
                return ((sanitized_copy(rt, col) if nonfinite else col),
                        *self.velocity_rows(rt, p, ctx, plan, rows))

            grid = tile_grid(rt, rows_of, width=canvas.width, height=canvas.height, t0=t0,
                             t1=t1, max_radius_px=max_radius, peak_speed=motion.peak_speed,
                             level=self.level(ctx), has_depth=motion.has_depth,
                             curved=motion.curved)
        margin = band_margin(t0, t1, reach_px(motion.peak_speed, t0, t1, max_radius),
                             motion.curved)
        return self.plan_type(t0=t0, t1=t1, max_radius_px=max_radius, canvas=canvas,
                              fields=motion, margin=margin, grid=grid, **own)

    def plan(self, p, ctx) -> GatherPlan:
        return self.gather_plan(p, ctx)

    def region_of_interest(self, p, ctx, window):
        # the farthest sample of the gather and the taps around it (the frame's reach)
        return window.grown(self.planned(p, ctx).margin)

    def gather_render(self, rt, p, ctx):
        """The reconstruction of the plan's canvas (a band's rows of it in a tiled render)
        from :meth:`velocity_rows`, with :meth:`gather_note`'s note."""
        plan = self.planned(p, ctx)
        if plan.missing is not None:
            raise ClipError(plan.missing)
        canvas, motion, a = plan.canvas, plan.fields, ctx.analysis
        rows = band_rows(ctx, canvas, plan.margin)
        src = rt.reframe(ctx.source, rows, "zero")  # past the data window: transparent black
        vel, depth, back = self.velocity_rows(rt, p, ctx, plan, rows)
        band = {}
        if ctx.tiling is not None:
            b = ctx.tiling.band
            band = {"grid": plan.grid, "row0": rows.y0 - canvas.y0,
                    "band": (b.y0 - canvas.y0, b.y1 - canvas.y0)}
        out, stats = reconstruct(
            rt, src, vel, depth, t0=plan.t0, t1=plan.t1, max_radius_px=plan.max_radius_px,
            peak_speed=motion.peak_speed, level=self.level(ctx), frame=ctx.frame,
            nonfinite=a.nonfinite_count, velocity_back=back, **band)
        ctx.notes.append(self.gather_note(p, ctx, plan, stats))
        return out

    def render(self, rt, p, ctx):
        return self.gather_render(rt, p, ctx)
