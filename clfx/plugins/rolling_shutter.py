"""Rolling shutter: CMOS rows read one after another, so each row shows its own instant.

Model
-----
A CMOS sensor reads its rows in sequence over the readout time ``R`` (frames): the row at
index ``i`` of ``n`` (in reading order: top-down by default; bottom-up, left-right and
right-left read rows or columns the other way) is exposed at ``t = R (i / n - r0)``, where the
reference ``r0`` puts ``t = 0`` (the frame's own time, when the velocity pass was taken) on
the first row read (0), the middle one ((n - 1) / 2n) or the last ((n - 1) / n).  Rows count
in the display window, so overscan and crops keep their times.

``R`` comes from ``readout_ms`` and the frame rate ``fps`` (``R = readout_ms fps / 1000``;
the camera block has no frame rate) or directly from ``readout_fraction``.  Phones read a
frame in about 10-30 ms; at 30 fps that is 0.3-0.9 of a frame.

A surface point seen at ``q`` at the frame time, moving with the velocity pass ``v`` (forward
px/frame, +x right, +y down), is at ``q + v(q) t`` at time ``t``.  So output pixel ``p``, read
at its row's time ``t(p)``, shows the point ``q`` with ``q + v(q) t(p) = p``: a backward
gather, solved per pixel by fixed-point iteration ``q <- p - v(q) t`` on the velocity field
(nearest-pixel velocities; exact after one step for a uniform velocity, convergent wherever
``|t| |dv/dq| < 1``).  Several points may reach ``p`` (an object passing in front of its
background) or none (the background it uncovers):

- the iteration runs from ``p``'s own velocity and from the velocities of the surrounding
  tiles' fastest pixel, background and (with a depth pass) nearest pixel (tiles as wide as
  the largest shift, 3 x 3 neighbours: the tile classification of McGuire et al. 2012's
  motion blur); a start is valid when its forward map lands within half a pixel of ``p``;
- the nearest valid surface wins (depth pass; at the same depth within 2 %, or without a
  depth pass, the faster one: nearer surfaces move faster under camera motion);
- no valid start is a disocclusion: the background point ``b = p - v_bg t`` (background: the
  farthest surface of the neighbourhood with a depth pass, else the slowest) was hidden at
  the frame time by an occluder moving with ``v_o`` (the surface at ``b`` in the source, else
  the neighbourhood's fastest).  As motion blur fills what a moving edge reveals, the
  background beside the occluder's trailing edge stands in, translated by the occluder's
  relative motion: ``b - (v_o - v_bg) t = p - v_o t``; where that pixel does not move with the
  background, the nearest one that does is searched along the relative motion (away from the
  occluder first).  A translated strip keeps the background's texture; the former fill (the
  nearest background pixel to ``b``) repeated one pixel along each row, a comb of streaks
  that also repeated the occluder's antialiased rim (issue 24);
- a winning background surface on an occluder's *rim* (a 4-neighbour in front of it moves
  away from it by a pixel or more by ``|t|``) counts as uncovered too: renderers write the
  velocity of the surface at the pixel centre, so the rim carries the background's motion
  and part of the occluder's colour, and kept it would outline where the occluder was.

With both halves of the vector pass (``velocity_back``: current - previous position, as
Blender's Vector XY), a point's displacement by time ``t`` is the arc through its
positions a frame before, at and after the frame time at a constant turn rate (the quadratic
``t (f + b) / 2 + t^2 (f - b) / 2`` on a straight path; :func:`clfx.fx.motion.path`), in
the iteration and in the fill: a spinning object shears
along its arcs.  With one half it is ``v t`` (today's straight paths; the note says which).

The colour at ``q`` is read bilinearly.  Velocities are sanitised and
clamped like motion blur's, so no row moves farther than ``max_shift`` x the frame diagonal
(and 512 px); reads outside the source clamp to its edge.  Motion blur within each row's own
exposure is the motion blur effect's: put it before this one in a look (the velocity pass is
aligned with its input, and shearing the blurred frame carries each row's smear to the row's
own time).  Flash banding (a flash lighting part of the rows) is not modelled.  A surface
uncovered from behind a nearer one is filled with the neighbourhood's background, which is
wrong where a middle layer was hidden (a car behind a passing pole).

The region of definition is the source window; the region of interest grows by how far a
pixel's look-ups reach: the largest shift (on arcs, a bound of the path over the row times),
then the uncovered background's search (up to twice the shift) and the taps around it.  The
effect tiles (`clfx.pipeline.look.render_tiled`): the velocity tiles are the frame's, built
once in the step's plan from rows of the passes at a time, and a band's row times, positions
and tile indices are the whole render's (its buffers addressed in canvas rows).  Identity: a
readout of 0, or rows that move less than half a pixel.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from clfx.core.errors import ClipError
from clfx.core.plugin import ChoiceParam, Clip, Descriptor, FloatParam, Level
from clfx.core.rect import Rect
from clfx.fx.motion import GRID_CHUNK_PIXELS, MAX_RADIUS_PX, path_reach
from clfx.fx.motion import KERNEL as MOTION_KERNEL
from clfx.fx.motion import sanitized_copy, tile_size
from clfx.host import Plugin, StepPlan, register
from clfx.kit.motion import aligned_passes, band_rows, on_rows

DIRECTIONS = ("top-down", "bottom-up", "left-right", "right-left")
REFERENCES = {"first": 0.0, "centre": 0.5, "last": 1.0}


@dataclass(frozen=True)
class RollingLevel(Level):
    """A rolling-shutter quality level: fixed-point steps per start, how far (px) a
    disocclusion searches for the background (0: none)."""

    iterations: int = 3
    max_search: int = 64


LEVELS = {
    "draft": RollingLevel("1 fixed-point step per start, uncovered background searched up "
                          "to 4 px, float32", iterations=1, max_search=4),
    "preview": RollingLevel("2 fixed-point steps per start, uncovered background searched "
                            "up to 16 px, float32", iterations=2, max_search=16),
    "final": RollingLevel("3 fixed-point steps per start, uncovered background searched up "
                          "to 64 px, float32", iterations=3, max_search=64),
    "reference": RollingLevel("8 fixed-point steps per start, uncovered background searched "
                              "up to 512 px, float64 positions and bilinear weights",
                              fp64=True, iterations=8, max_search=MAX_RADIUS_PX),
}


@dataclass(frozen=True)
class RowTimes:
    """Row time ``t = tx (x - xr) + ty (y - yr)`` (frames) at pixel (x, y) of the window
    (``(xr, yr)``: on the reference row, so that row's time is exactly 0), and the largest
    ``|t|`` over the window."""

    tx: float
    ty: float
    xr: float
    yr: float
    t_max: float

    def at(self, x, y):
        return self.tx * (x - self.xr) + self.ty * (y - self.yr)


@dataclass(frozen=True)
class RollingPlan(StepPlan):
    """rolling_shutter's plan for one step of a frame: the row times over the whole source
    window, the largest shift, the rows a band reads beyond itself and, when the step renders
    in bands, the frame's velocity tiles they read (`RollingShutter._tiles`: tile size, tiles
    across, the device records; built in the plan from the whole frame, None otherwise)."""

    times: RowTimes | None = None
    shift: float = 0.0
    margin: int = 0
    grid: tuple | None = None


SEARCH_TAP_ROWS = 3
"""Rows past the farthest look-up the gather reads (a rim's 4-neighbours, bilinear taps)."""


@register
class RollingShutter(Plugin):
    whole_frame = None   # a band: the frame's tiles (the plan's), the whole render's row times
    descriptor = Descriptor(
        name="rolling_shutter", label="Rolling shutter", group="Camera",
        kernel="rolling_shutter.cl",
        summary="CMOS rows read one after another: each row moved to its own instant along "
                "the velocity pass (verticals lean under a pan, fast objects shear).",
        clips=(Clip("source"),
               Clip("velocity", channels=2,
                    hint="Forward screen-space motion in px/frame (+x right, +y down)."),
               Clip("depth", optional=True, channels=1,
                    hint="Planar depth (m): the nearer of two surfaces reaching a pixel wins; "
                         "without it, the faster.")),
        params=(
            FloatParam("readout_ms", 20.0, min=0.0, max=10000.0, units="ms",
                       hint="Sensor readout time from the first row to the last, in ms."),
            FloatParam("fps", 24.0, min=1.0, max=10000.0, units="1/s",
                       hint="Frame rate: converts readout_ms to a fraction of the frame."),
            FloatParam("readout_fraction", -1.0, min=-1.0, max=4.0,
                       hint="Readout time as a fraction of the frame interval; -1 = "
                            "readout_ms x fps / 1000."),
            ChoiceParam("direction", "top-down", choices=DIRECTIONS,
                        hint="Order in which rows (or columns) are read."),
            ChoiceParam("reference", "first", choices=tuple(REFERENCES),
                        hint="The row read at the frame's time (t = 0): the first read, the "
                             "middle one or the last."),
            FloatParam("max_shift", 0.1, min=0.001, max=0.5,
                       hint="Largest displacement of a row as a fraction of the frame "
                            "diagonal (faster velocities are clamped to it, and to 512 px)."),
        ),
        quality=LEVELS,
    )

    def readout(self, p) -> float:
        """The readout time in frames."""
        return p.readout_fraction if p.readout_fraction >= 0.0 else p.readout_ms * p.fps / 1000.0

    def row_times(self, p, display: Rect, w: Rect) -> RowTimes:
        """The affine row-time map over the window ``w`` (rows counted in the ``display``
        window, in reading order)."""
        d = display
        r = self.readout(p)
        vertical = p.direction in ("top-down", "bottom-up")
        n = max(d.height if vertical else d.width, 1)
        ref = REFERENCES[p.reference] * (n - 1)     # reading index of the row at t = 0
        # reading index i = Y - d.y0 (top-down), d.y1 - 1 - Y (bottom-up), likewise in x;
        # Y = y + w.y0; t = r (i - ref) / n
        tx = ty = xr = yr = 0.0
        if p.direction == "top-down":
            ty, yr = r / n, ref + d.y0 - w.y0
        elif p.direction == "bottom-up":
            ty, yr = -r / n, d.y1 - 1 - w.y0 - ref
        elif p.direction == "left-right":
            tx, xr = r / n, ref + d.x0 - w.x0
        else:
            tx, xr = -r / n, d.x1 - 1 - w.x0 - ref
        times = RowTimes(tx, ty, xr, yr, 0.0)
        corners = [times.at(x, y) for x in (0, max(w.width - 1, 0))
                   for y in (0, max(w.height - 1, 0))]
        return RowTimes(tx, ty, xr, yr, max(abs(c) for c in corners))

    def max_shift_px(self, p, ctx) -> float:
        """The largest displacement of any row (px): peak speed x largest row time, clamped."""
        if ctx.velocity is None:
            return 0.0
        peak = ctx.analysis.peak_speed
        t_max = self.row_times(p, ctx.display_window, ctx.source.window).t_max
        cap = min(p.max_shift * ctx.diagonal_px, MAX_RADIUS_PX)
        return float(min(peak * t_max, cap)) if math.isfinite(peak * t_max) else cap

    def is_identity(self, p, ctx):
        if self.readout(p) == 0.0:
            return "readout time is 0"
        if ctx.velocity is None:
            return None
        shift = self.max_shift_px(p, ctx)
        if shift < 0.5:
            return (f"rows move less than half a pixel (peak {ctx.analysis.peak_speed:.3g} "
                    f"px/frame, largest row time {self.row_times(p, ctx.display_window, ctx.source.window).t_max:.3g} frame)")
        return None

    def plan(self, p, ctx) -> RollingPlan:
        src, vel = ctx.source, ctx.velocity
        times = self.row_times(p, ctx.display_window, src.window)
        shift = self.max_shift_px(p, ctx)
        if vel is None or vel.window != src.window or times.t_max <= 0.0:
            return RollingPlan(times=times, shift=shift)
        depth, back = aligned_passes(ctx)
        vmax = shift / times.t_max
        # the farthest fixed-point look-up, then the uncovered background's search along the
        # relative motion of two clamped velocities (and the reads around where it ends)
        reach = path_reach(-times.t_max, times.t_max, back is not None) * vmax
        search = min(math.ceil(2.0 * shift) + 1, self.level(ctx).max_search)
        margin = math.ceil(reach) + search + SEARCH_TAP_ROWS
        rt, window, level = ctx.runtime, src.window, self.level(ctx)
        grid = None
        if len(ctx.bands(window)) > 1:   # the bands' frame-wide tiles
            grid = self._tiles(rt, vel, depth, back is not None, window, vmax, shift, level,
                               GRID_CHUNK_PIXELS)
        return RollingPlan(times=times, shift=shift, margin=margin, grid=grid)

    def _defines(self, lvl, has_depth: bool, curved: bool) -> dict:
        return dict(HAS_DEPTH=int(has_depth), ITERATIONS=lvl.iterations,
                    MAX_SEARCH=lvl.max_search, fp64=lvl.fp64, **({"CURVED": 1} if curved else {}))

    def _aux(self, rt, vel, depth, vmax):
        """motion_prepare's records (vx, vy, z, |v|) of ``vel`` over its window."""
        aux = rt.image(vel.window, 4)
        rt.launch(rt.kernel(MOTION_KERNEL, "motion_prepare", HAS_DEPTH=int(depth is not None)),
                  (vel.pitch // 4, vel.height), vel, depth if depth is not None else
                  rt.buffer(16), aux, vel.pitch, vel.height, vmax)
        return aux

    def _tiles(self, rt, vel, depth, curved: bool, window: Rect, vmax, shift, lvl,
               chunk_pixels=None, aux=None):
        """(tile size, tiles across, the 3 x 3 neighbourhoods' records) of the frame's tile
        grid over ``window``: from ``aux`` (the whole window's records), or built from rows of
        about ``chunk_pixels`` of the passes at a time."""
        w, h = window.width, window.height
        k = tile_size(shift)
        ntx, nty = -(-w // k), -(-h // k)
        defines = self._defines(lvl, depth is not None, curved)
        kfile = self.descriptor.kernel
        tiles, nbr = rt.buffer(ntx * nty * 48), rt.buffer(ntx * nty * 48)   # 3 float4 a tile
        step = nty if aux is not None else max(1, chunk_pixels // max(w * k, 1))   # aux: r0 0
        for ty0 in range(0, nty, step):
            ty1 = min(ty0 + step, nty)
            r0, r1 = ty0 * k, min(ty1 * k, h)
            part = aux
            if part is None:
                rows = Rect(window.x0, window.y0 + r0, window.x1, window.y0 + r1)
                part = self._aux(rt, rt.reframe(vel, rows),
                                 None if depth is None else rt.reframe(depth, rows), vmax)
            rt.launch(rt.kernel(kfile, "rolling_shutter_tiles", **defines), (ntx, ty1 - ty0),
                      part, tiles, part.pitch, w, h, r0,
                      ntx, nty, ty0, k)
        rt.launch(rt.kernel(kfile, "rolling_shutter_neighbors", **defines), (ntx, nty), tiles,
                  nbr, ntx, nty)
        return k, ntx, nbr

    def region_of_interest(self, p, ctx, window):
        # the farthest look-up of the band's solves and searches (the frame's largest shift)
        return window.grown(self.planned(p, ctx).margin)

    def render(self, rt, p, ctx):
        src, vel = ctx.source, ctx.velocity
        if vel is None or vel.window != src.window:
            raise ClipError("rolling_shutter: the velocity pass must cover the source window "
                            f"{src.window} (it covers {None if vel is None else vel.window})")
        plan = self.planned(p, ctx)
        depth, back = aligned_passes(ctx)
        lvl = self.level(ctx)
        times, shift = plan.times, plan.shift
        a = ctx.analysis
        whole = ctx.tiling.whole if ctx.tiling is not None else src.window
        band = ctx.tiling.band if ctx.tiling is not None else src.window
        rows = band_rows(ctx, whole, plan.margin)   # a band's rows and the margin its look-ups read
        src, vel = rt.reframe(src, rows), on_rows(rt, vel, rows)
        depth, back = on_rows(rt, depth, rows), on_rows(rt, back, rows)
        col = sanitized_copy(rt, src) if a.nonfinite_count else src
        dst = rt.image(band, 4)
        w, h, pitch = src.width, src.height, src.pitch
        if w == 0 or h == 0:
            return dst
        vmax = shift / times.t_max if times.t_max > 0 else 0.0
        aux = self._aux(rt, vel, depth, vmax)
        auxb = rt.buffer(16)
        if back is not None:   # (bx, by, z, |b|), clamped like the forward motion
            auxb = self._aux(rt, back, depth, vmax)
        if ctx.tiling is None:
            k, ntx, nbr = self._tiles(rt, vel, depth, back is not None, src.window, vmax, shift,
                                      lvl, aux=aux)
        else:
            k, ntx, nbr = plan.grid
        defines = self._defines(lvl, depth is not None, back is not None)
        row0, b0 = src.window.y0 - whole.y0, band.y0 - whole.y0
        rt.launch(rt.kernel(self.descriptor.kernel, "rolling_shutter_gather", **defines),
                  (w, band.height), col, aux, auxb, nbr, dst, pitch, w, row0,
                  row0 + h, b0, b0 + band.height, ntx, k,
                  times.tx, times.ty, times.xr, times.yr)
        ctx.notes.append(f"rolling_shutter: readout {self.readout(p):.3g} frame "
                         f"({p.direction}, t = 0 at the {p.reference} row), largest shift "
                         f"{shift:.1f} px, {k} px tiles, "
                         + ("curved paths through the previous, current and next positions "
                            "(both halves of the vector pass)" if back is not None else
                            "straight paths along the forward motion (one half of the vector "
                            "pass)")
                         + (f", {a.nonfinite_count} non-finite pixels zeroed"
                            if a.nonfinite_count else ""))
        return dst
