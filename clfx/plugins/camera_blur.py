"""Camera blur: the blur of the camera's own motion during the shutter.

Model
-----
The camera's motion over one frame interval is described in image terms, per frame
(forward, like clfx's velocity pass), and integrated over the open shutter ``[t0, t1]`` (the
camera block's shutter angle and offset, or this effect's overrides):

- pan / tilt: the image shifts by ``length`` x frame diagonal per frame in the image-plane
  direction ``direction`` (degrees; 0 = content moves right (+x), 90 = down (+y)).  Panning the
  camera right moves the content left: direction 180.
- roll: the image turns by ``roll`` degrees per frame about ``center`` (positive turns +x
  towards +y, i.e. clockwise on screen).
- zoom: the image scale grows by ``zoom`` per frame about ``center`` (0.02 = 2% per frame;
  negative zooms out).
- trucking: the camera translates by ``truck`` (x right, y down) and ``dolly`` (forward)
  scene units (m) per frame.  A point at planar depth z moves by ``-f_px * truck / z``
  (near things move more) and expands by ``dolly / (z - dolly)`` about the centre; this needs
  the depth pass (points at +inf do not move).

Without trucking the image at time t is the sharp image under the similarity map
``p -> c + (1 + zoom t) R(roll t) (p - c) + shift t``: nothing is occluded or revealed, so
the exact result is the average of the inverse look-ups along each pixel's path (linear,
spin and radial gathers in one kernel; arcs for roll, not tangents).  With trucking, the
motion is turned into a velocity field and rendered by the depth-aware reconstruction of
:mod:`clfx.fx.motion` (the gather motion_blur uses), which handles the parallax's occlusions;
there a roll gives both halves of a vector pass (``v +- a/2``, ``a`` the second derivative of
the similarity at the frame time), so the gather's paths are ``v t + a t^2 / 2``, the roll's
arcs to second order (the tangent alone was a straight line).

Reads outside the source window clamp to its edge (the blur does not grow the frame).  The
effect tiles: a band samples its paths at the whole render's coordinates, from the rows its
look-ups reach (its region of interest); trucking is the motion family's gather
(`clfx.kit.motion.VelocityGather`: the frame's velocity tiles, a band's rows, the
reconstruction), this module supplying the camera's velocity fields over a band's rows.
Non-finite input pixels are set to 0 before they are spread (counted in ``ctx.notes``); finite
input stays finite, however large (a sum that overflows float32 is taken again with each
sample scaled first).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from types import MappingProxyType
from typing import Mapping

import numpy as np

from clfx.core.plugin import Clip, Descriptor, FloatParam, Vec2Param
from clfx.fx.motion import (
    CUBIC_MAX_PX,
    LEVELS,
    MAX_RADIUS_PX,
    MotionLevel,
    sanitized_copy,
    shutter_from,
)
from clfx.host import Plugin, register
from clfx.kit.motion import (
    SHUTTER_PARAMS,
    GatherMotion,
    GatherPlan,
    VelocityGather,
    on_rows,
)

KERNEL = "camera_blur.cl"

FAST_LEVELS = ("draft", "preview")
"""Levels whose path gather reads the nearest pixel rather than bilinearly (its long, smooth
paths hide it; the speed is what these levels are for).  Trucking's motion gather keeps
its fetches at every level (:data:`QUALITY`: bilinear, the clamped cubic under
:data:`CAMERA_CUBIC_MAX_PX`)."""


def camera_motion(p, ctx):
    """Image-plane motion per frame: (cx, cy) centre in frame px, (sx, sy) shift px/frame,
    roll rad/frame, zoom /frame, truck in px*m (f_px * truck), dolly m/frame."""
    dw = ctx.display_window
    cx0, cy0 = dw.center
    cx = cx0 + p.center[0] * dw.width * 0.5
    cy = cy0 + p.center[1] * dw.height * 0.5
    shift = p.length * ctx.diagonal_px
    a = math.radians(p.direction)
    f_px = ctx.camera.focal_length_px(dw.width)
    return dict(cx=cx, cy=cy, sx=shift * math.cos(a), sy=shift * math.sin(a),
                roll=math.radians(p.roll), zoom=p.zoom,
                truck_x=f_px * p.truck[0], truck_y=f_px * p.truck[1], dolly=p.dolly)


def needs_depth(p) -> bool:
    return p.truck[0] != 0.0 or p.truck[1] != 0.0 or p.dolly != 0.0


def farthest_corner(window, cx, cy) -> float:
    """Largest distance (px) from (cx, cy) to a corner of ``window``."""
    return max(math.hypot(x - cx, y - cy) for x in (window.x0, window.x1)
               for y in (window.y0, window.y1))


def peak_speed_bound(m, window, min_depth) -> float:
    """An upper bound of the camera motion's image speed (px/frame) over ``window``."""
    r = farthest_corner(window, m["cx"], m["cy"])
    v = math.hypot(m["sx"], m["sy"]) + (abs(m["roll"]) + abs(m["zoom"])) * r
    if min_depth is not None and min_depth > 0 and math.isfinite(min_depth):
        iz = 1.0 / min_depth
        v += math.hypot(m["truck_x"], m["truck_y"]) * iz
        v += r * min(abs(m["dolly"]) * iz / max(1.0 - abs(m["dolly"]) * iz, 1e-3), 1.0)
    elif min_depth is not None and (m["truck_x"] or m["truck_y"] or m["dolly"]):
        v = MAX_RADIUS_PX * 4.0   # unknown nearest depth: let the clamp decide
    return v


def path_reach_px(m, window, t0: float, t1: float) -> tuple[float, float]:
    """The farthest (px, in x and in y) the similarity's look-ups lie from their pixels over
    ``window`` and the open shutter: the inverse of ``p -> c + (1 + zoom t) R(roll t)(p - c) +
    shift t``, ``q - p``, is affine in ``p`` (largest at a corner) and smooth in ``t``
    (sampled finely, 1 % and a pixel of slack)."""
    t = np.linspace(t0, t1, 513)[:, None]
    px = np.array([window.x0, window.x1, window.x0, window.x1], np.float64)[None, :] - m["cx"]
    py = np.array([window.y0, window.y0, window.y1, window.y1], np.float64)[None, :] - m["cy"]
    qx, qy = px - m["sx"] * t, py - m["sy"] * t
    c, s = np.cos(m["roll"] * t), np.sin(m["roll"] * t)
    inv_k = 1.0 / np.maximum(1.0 + m["zoom"] * t, 1e-3)
    dx = (c * qx + s * qy) * inv_k - px
    dy = (-s * qx + c * qy) * inv_k - py
    return (float(np.abs(dx).max()) * 1.01 + 1.0, float(np.abs(dy).max()) * 1.01 + 1.0)


GATHER_TAP_ROWS = 2
"""Rows past a look-up the path gather reads (the bilinear taps, the floor)."""


@dataclass(frozen=True)
class CameraPlan(GatherPlan):
    """camera_blur's plan for one step of a frame: the motion gather's with trucking
    (`clfx.kit.motion.GatherPlan`), and the camera's own: ``motion``, the read-only mapping
    of :func:`camera_motion`; without trucking, the path gather's samples and how far a
    band's look-ups reach (``path_reach``, x and y px: its region of interest)."""

    motion: Mapping | None = None
    samples: int = 0
    path_reach: tuple | None = None

    @property
    def reach(self) -> tuple:
        """How far a band's look-ups reach (x, y px): the path gather's, or the motion
        gather's margin."""
        return self.path_reach if self.path_reach is not None else (self.margin, self.margin)


CAMERA_CUBIC_MAX_PX = CUBIC_MAX_PX
"""Trucking: tiles whose blur is shorter than this read through the clamped cubic, longer
ones bilinearly: motion_blur's threshold (8 px).  It was 2 px, tuned against a truth sampled
on the sharp frame's own 4 x 4 sub-pixel grid (the cubic then lost to the bilinear line blur
on the far wall's blur of a few pixels, 36.1 vs 36.3 dB at 480x270); against a truth
sampled as a renderer samples (jittered points and instants, issue 24) the cubic up to 8 px
wins on the bench case (final 39.37 vs 38.88 dB at 480x270, 37.69 vs 36.67 at 320x180) and
on Cycles' truck (48.6 vs 48.5; pan level)."""


@dataclass(frozen=True)
class CameraLevel(MotionLevel):
    """One level of camera_blur: its two renders in one place.  Trucking's motion gather
    (`clfx.fx.motion.reconstruct`) reads the :class:`~clfx.fx.motion.MotionLevel` fields;
    the pan/roll/zoom path gather reads ``max_samples``, ``jitter`` and ``fp64`` with its
    own sample spacing and fetch (``path_spacing``, ``path_bilinear``)."""

    path_spacing: float = 0.5    # path gather: target distance between samples, px
    path_bilinear: bool = True   # path gather: bilinear fetches (else nearest)


CAMERA_SPACING = {"draft": 0.5, "preview": 0.5, "final": 0.25, "reference": 0.25}
"""Trucking's sample spacing (px of blur) per level, short blurs included.  ``final`` used
half a pixel like the faster levels and ended the worst level on Cycles' pan (rel. error
0.0477 against draft's 0.0459 and reference's 0.0437, 320x180): its samples half a pixel
apart along the pan's 10 px blur read the texture at two sub-pixel offsets, both blurred by
the bilinear read; a quarter pixel scores 0.0437 (truck 0.0416 -> 0.0414, issue 35)."""


def _summary(lvl: CameraLevel) -> str:
    return (f"pan/roll/zoom: exact path gather, up to {lvl.max_samples} samples (one per "
            f"{lvl.path_spacing:g} px of the longest path), "
            f"{'bilinear' if lvl.path_bilinear else 'nearest'}, "
            f"{'float64' if lvl.fp64 else 'float32'} accumulation"
            f"{'' if lvl.jitter else ', midpoint rule'}; trucking: the motion gather "
            f"(motion_blur's), up to {lvl.max_samples} samples (one per {lvl.spacing:g} px), "
            f"clamped cubic under {lvl.cubic_max_px:g} px, "
            f"{'bilinear' if lvl.bilinear else 'nearest'} above")


def _level(name: str, lvl: MotionLevel) -> CameraLevel:
    """camera_blur's ``name`` level from the motion gather's: trucking with the cubic only
    under :data:`CAMERA_CUBIC_MAX_PX` and a sample per :data:`CAMERA_SPACING` px (short
    blurs too); the path gather with the motion level's spacing, nearest at
    :data:`FAST_LEVELS`; 10 samples at most for draft instead of 8 (both renders)."""
    out = CameraLevel("", fp64=lvl.fp64, jitter=lvl.jitter, bilinear=lvl.bilinear,
                      max_samples=10 if name == "draft" else lvl.max_samples,
                      spacing=CAMERA_SPACING[name], cubic_max_px=CAMERA_CUBIC_MAX_PX,
                      short_spacing=0.0, path_spacing=lvl.spacing,
                      path_bilinear=lvl.bilinear and name not in FAST_LEVELS)
    return replace(out, summary=_summary(out))


QUALITY = {name: _level(name, lvl) for name, lvl in LEVELS.items()}
"""camera_blur's levels, one table for both renders (what ``clfx describe`` shows is what
runs).  Trucking: the motion gather's levels (:data:`clfx.fx.motion.LEVELS`) with the cubic
only under :data:`CAMERA_CUBIC_MAX_PX`, a sample per half pixel of blur or less at every level
(:data:`CAMERA_SPACING`; short blurs too: motion_blur's ``short_spacing`` is not used; the
background's blurs of a few pixels took 3 samples at draft and preview, which ended below the
naive line blur's 5: 36.1 vs 36.3 dB at 480x270; 36.4 with them, the cap still bounding
long blurs) and 10 samples at most for draft instead of 8: on the bench case
at 1920x1080 (blurs up to 32 px) 8 samples lie 4 px apart, and the ghost copies of the
texture left draft 0.08 dB below the naive per-pixel line blur (39.07 vs 39.14 dB log-PSNR);
10 samples score 39.48 dB, level with preview's 16 (39.49), for 81% of preview's CPU time
(9 samples: 39.08)."""


@register
class CameraBlur(VelocityGather, Plugin):
    # pan/roll/zoom: a band samples its paths at the whole render's coordinates; trucking:
    # the motion family's gather (clfx.kit.motion.VelocityGather) of the camera's velocities
    plan_type = CameraPlan
    descriptor = Descriptor(
        name="camera_blur", label="Camera blur", group="Camera", kernel=KERNEL,
        summary="Blur of the camera's pan, tilt, roll, zoom and trucking during the shutter "
                "(trucking uses depth: near things move more).",
        clips=(Clip("source"),
               Clip("depth", optional=True, channels=1,
                    hint="Planar depth (m); needed only when truck or dolly is not 0.")),
        params=(
            FloatParam("length", 0.0, min=0.0, max=0.5,
                       hint="Pan/tilt: image shift per frame as a fraction of the frame diagonal."),
            FloatParam("direction", 0.0, min=-360.0, max=360.0, units="deg",
                       hint="Direction the image content moves, degrees (0 = right, 90 = down)."),
            FloatParam("roll", 0.0, min=-90.0, max=90.0, units="deg",
                       hint="Roll per frame about the centre, degrees (positive = clockwise on screen)."),
            FloatParam("zoom", 0.0, min=-0.5, max=0.5,
                       hint="Image scale growth per frame (0.02 = 2% per frame; negative zooms out)."),
            Vec2Param("truck", (0.0, 0.0), min=-1000.0, max=1000.0, units="m",
                      hint="Camera translation per frame parallel to the sensor (x right, y down), "
                           "scene units; needs depth."),
            FloatParam("dolly", 0.0, min=-1000.0, max=1000.0, units="m",
                       hint="Camera translation per frame along the view axis (forward > 0), "
                            "scene units; needs depth."),
            Vec2Param("center", (0.0, 0.0), min=-2.0, max=2.0,
                      hint="Centre of roll, zoom and dolly as a fraction of half the frame (x right, y down)."),
            *SHUTTER_PARAMS,
            FloatParam("max_blur", 0.05, min=0.001, max=0.25,
                       hint="Largest blur radius with trucking, as a fraction of the frame "
                            f"diagonal (at most {MAX_RADIUS_PX} px)."),
        ),
        quality=QUALITY,
    )

    def is_identity(self, p, ctx):
        t0, t1 = shutter_from(p, ctx.camera)
        if t1 - t0 <= 0.0:
            return "shutter angle is 0"
        if not needs_depth(p) and p.length == 0.0 and p.roll == 0.0 and p.zoom == 0.0:
            return "no camera motion"
        if needs_depth(p):
            return None
        m = camera_motion(p, ctx)
        if peak_speed_bound(m, ctx.source.window, None) * (t1 - t0) < 0.5:
            return "camera motion below half a pixel over the shutter"
        return None

    def plan(self, p, ctx) -> CameraPlan:
        t0, t1 = shutter_from(p, ctx.camera)
        m = MappingProxyType(camera_motion(p, ctx))
        if needs_depth(p):   # trucking: the motion family's gather
            return self.gather_plan(p, ctx, motion=m)
        level = self.level(ctx)
        window = ctx.source.window
        length = peak_speed_bound(m, window, None) * (t1 - t0)
        n = int(np.clip(math.ceil(length / level.path_spacing), 2, level.max_samples))
        rx, ry = path_reach_px(m, window, t0, t1)
        return CameraPlan(t0=t0, t1=t1, motion=m, samples=n,
                          path_reach=(math.ceil(rx) + GATHER_TAP_ROWS,
                                      math.ceil(ry) + GATHER_TAP_ROWS))

    @staticmethod
    def _peak(m, window, analysis) -> float:
        """The trucking's speed bound over ``window`` from the frame's nearest depth."""
        a = analysis
        finite = a.min_depth[np.isfinite(a.min_depth)] if a.min_depth is not None else None
        zmin = float(finite.min()) if finite is not None and finite.size else math.inf
        return peak_speed_bound(m, window, zmin)

    # -- trucking's velocity fields (clfx.kit.motion.VelocityGather renders them) ----------
    def gather_motion(self, p, ctx):
        src, depth = ctx.source, ctx.depth
        if depth is None or depth.window != src.window:
            return ("camera_blur: truck/dolly need a depth pass covering the source "
                    f"window {src.window}")
        return GatherMotion(self._peak(camera_motion(p, ctx), src.window, ctx.analysis),
                            has_depth=True, curved=p.roll != 0.0)

    def velocity_rows(self, rt, p, ctx, plan, rows):
        depth = on_rows(rt, ctx.depth, rows)
        vel, back = self._velocities(rt, depth, plan.motion, plan.canvas,
                                     rows.y0 - plan.canvas.y0, plan.curved)
        return vel, depth, back

    def gather_note(self, p, ctx, plan, stats):
        return (f"camera_blur: velocity reconstruction, {stats.moving_tiles}/"
                f"{stats.tiles} tiles moving, radius {stats.radius_px:.1f} px, "
                + ("the roll along its arcs (circular paths through the previous, "
                   "current and next positions)" if plan.curved else "straight paths"))

    @staticmethod
    def _velocities(rt, depth, m, whole, row0: int, curved: bool):
        """(forward, backward or None) velocity fields of the camera motion over ``depth``'s
        rows, the rows ``row0`` on of the whole render's ``whole`` window (its coordinates):
        with a roll the chords to the positions a frame after and before (the gather's paths
        follow the arcs), else the tangent."""
        fields = []
        for chord in ((1.0, -1.0) if curved else (0.0,)):
            vel = rt.image(depth.window, 2)
            rt.launch(rt.kernel(KERNEL, "camera_blur_velocity", HAS_DEPTH=1),
                      (depth.pitch // 4, depth.height), depth, vel, depth.pitch,
                      depth.width, depth.height, row0, whole.x0,
                      whole.y0, m["cx"], m["cy"], m["sx"], m["sy"],
                      m["roll"], m["zoom"], m["truck_x"], m["truck_y"],
                      m["dolly"], chord)
            fields.append(vel)
        return fields[0], (fields[1] if curved else None)

    def region_of_interest(self, p, ctx, window):
        # the farthest look-up of a band's paths (and the taps around it)
        rx, ry = self.planned(p, ctx).reach
        return window.grown(rx, ry)

    def render(self, rt, p, ctx):
        src = ctx.source
        plan = self.planned(p, ctx)
        t0, t1, m = plan.t0, plan.t1, plan.motion
        nonfinite = ctx.analysis.nonfinite_count
        if nonfinite:
            ctx.notes.append(f"camera_blur: {nonfinite} non-finite pixels set to 0")
        whole = ctx.tiling.whole if ctx.tiling is not None else src.window
        band = ctx.tiling.band if ctx.tiling is not None else src.window
        if not needs_depth(p):
            level = self.level(ctx)
            col = sanitized_copy(rt, src) if nonfinite else src
            dst = rt.image(band, 4)
            r0 = src.window.y0 - whole.y0
            rt.launch(rt.kernel(KERNEL, "camera_blur_similarity",
                                BILINEAR=int(level.path_bilinear), JITTER=int(level.jitter),
                                fp64=level.fp64),
                      (src.pitch // 4, band.height), col, dst, src.pitch, src.width,
                      r0, r0 + src.height, band.y0 - whole.y0,
                      band.y1 - whole.y0, whole.x0, whole.y0, m["cx"],
                      m["cy"], m["sx"], m["sy"], m["roll"], m["zoom"],
                      t0, t1, plan.samples, ctx.frame)
            ctx.notes.append(f"camera_blur: direct path gather, {plan.samples} samples")
            return dst
        return self.gather_render(rt, p, ctx)
