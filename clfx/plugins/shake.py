"""Shake: the blur of a handheld camera's shake, its small random turns during the shutter.

Model
-----
The camera turns about its centre (no translation: a hand's tremor and sway turn it far more
than they move it, and a turn has no parallax).  Its orientation is ``C(s) = R_y(yaw(s))
R_x(pitch(s)) R_z(roll(s))`` (camera axes: +x right, +y down, +z forward; yaw turns +z
towards +x, pitch towards -y (up), roll +x towards +y), each angle a smooth random signal of
the time ``s = (frame + t) / fps`` seconds: three sines at ``0.57, 1.0, 1.73`` x
``frequency`` (Hz), with weights ``sqrt(2/3)`` so the angle's RMS over time is the
parameter (degrees), and phases ``2 pi h / 2^32``, ``h = lowbias32(seed32 ^ lowbias32(3 k + i
+ 1))`` for axis ``k`` (yaw 0, pitch 1, roll 2) and sine ``i`` (``lowbias32``: the 32-bit
integer hash of kernels/lib/common.h; ``seed32``: the ``seed`` param combined with the
look's, `clfx.fx.noise.effect_seed`, salt ``"shak"``).  The signal runs on from frame to
frame: the same (seed, frame) gives the same blur, and consecutive frames shake as one
continuous motion.

A pixel ``p`` sees the direction ``C(0) K^-1 p`` at the frame time (``K``: focal length
``fx`` = the camera block's in pixels, ``fy = fx`` x pixel aspect, the principal point at the
display window's centre); at time ``t`` (frames) that direction is at ``P(K C(t)^T C(0) K^-1
p)``.  Over the open shutter ``[t0, t1]`` (the camera block's angle and offset, or this
effect's overrides) each pixel's content is taken along the straight chord through its
positions at the opening and the closing (``shake_velocity``, kernels/shake.cl; float64
rotations on the host), and the blur is the motion family's depth-less reconstruction of
that velocity field (`clfx.kit.motion.VelocityGather`, `clfx.fx.motion.reconstruct`).  The
chord, not the arc: with both halves of a vector pass (the velocity and acceleration at the
frame time, the gather's curved paths) the gather ended twice as far from the exact turns
(interior RMSE 0.0139 against the chord's 0.0072 on a 4 / 3 degree yaw / pitch sway at
final, 0.0120 against 0.0060 on a fast shake with roll), ahead only on a roll alone (0.0033
against 0.0040): the gather reads a pixel's own surface at ``x + d(-t)``, exact for a steady
flow (a turning or translating surface), while a shake's image motion is the same
everywhere and changes in time (a uniform field speeding up by 8 px/frame per frame through
motion_blur with both halves: RMSE 0.0084 against the straight mean velocity's 0.0047, and
0.0023 against the steady flow's answer, its ``t^2`` term of the other sign).  The frame's
own framing is kept (the plate is the frame time's view); reads outside the source window
clamp to its edge (the blur does not grow the frame).
Non-finite input pixels are set to 0 before they are spread.

This module holds the model only: no band, tile or canvas code.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from types import MappingProxyType
from typing import Mapping

import numpy as np

from clfx.core.camera import camera_rotation
from clfx.core.plugin import Descriptor, FloatParam, IntParam
from clfx.fx.motion import LEVELS, MAX_RADIUS_PX, shutter_from
from clfx.fx.noise import effect_seed, lowbias32
from clfx.fx.resample import rect_boundary
from clfx.host import Plugin, register
from clfx.kit.motion import SHUTTER_PARAMS, GatherMotion, GatherPlan, VelocityGather

KERNEL = "shake.cl"

AXES = ("yaw", "pitch", "roll")
RATIOS = (0.57, 1.0, 1.73)
"""The three sines' frequencies, relative to ``frequency`` (no two in a simple ratio: the
signal never repeats within a shot)."""

WEIGHT = math.sqrt(2.0 / 3.0)
"""Each sine's amplitude, relative to the axis's RMS angle (three sines of RMS 1/sqrt(2))."""

SHAKE_SALT = 0x7368616B   # "shak": independent of the noise effects with the same seed

MAX_ANGLE_DEG = 10.0


def phases(seed32: int) -> np.ndarray:
    """(3 axes, 3 sines) phases in radians of the seed's signal."""
    return np.array([[2.0 * math.pi * lowbias32(seed32 ^ lowbias32(3 * k + i + 1)) / 2.0 ** 32
                      for i in range(len(RATIOS))] for k in range(len(AXES))])


def angles(p, seed32: int, seconds) -> np.ndarray:
    """(yaw, pitch, roll) in radians at ``seconds`` (..., 3)."""
    s = np.asarray(seconds, np.float64)[..., None, None]
    ph = phases(seed32)
    amp = np.radians([p.yaw, p.pitch, p.roll])[:, None]
    w = 2.0 * math.pi * p.frequency * np.asarray(RATIOS)
    return (amp * WEIGHT * np.sin(w * s + ph)).sum(-1)


def geometry(p, ctx) -> dict:
    """The frame's intrinsics, the open shutter ``(t0, t1)`` and the rotations ``M(t) = C(t)^T
    C(0)`` at its opening and closing (``turns``: M0 then M1, 18 floats, row-major)."""
    dw = ctx.display_window
    fx = ctx.camera.focal_length_px(max(dw.width, 1))
    cx, cy = dw.center
    t0, t1 = shutter_from(p, ctx.camera)
    seed32 = effect_seed(p.seed, ctx.seed, SHAKE_SALT)
    a = angles(p, seed32, (ctx.frame + np.array([0.0, t0, t1])) / p.fps)
    c0 = camera_rotation(*a[0])
    turns = [camera_rotation(*a[j]).T @ c0 for j in (1, 2)]
    return dict(fx=fx, fy=fx * ctx.pixel_aspect, cx=cx, cy=cy, t0=t0, t1=t1, seed32=seed32,
                angles=tuple(map(tuple, a)), turns=tuple(np.concatenate(
                    [m.ravel() for m in turns]).tolist()))


def velocity_px(g, x, y) -> np.ndarray:
    """The velocity (px/frame, (..., 2)) at frame points ``(x, y)``: the chord through the
    positions at the shutter's opening and closing, per frame (kernels/shake.cl)."""
    u = (np.asarray(x, np.float64) - g["cx"]) / g["fx"]
    v = (np.asarray(y, np.float64) - g["cy"]) / g["fy"]
    d = []
    for j in (0, 1):
        m = np.asarray(g["turns"][9 * j: 9 * j + 9]).reshape(3, 3)
        q = m @ np.stack([u, v, np.ones_like(u)]).reshape(3, -1)
        d.append(np.stack([(q[0] / q[2] - u.ravel()) * g["fx"],
                           (q[1] / q[2] - v.ravel()) * g["fy"]], -1).reshape(u.shape + (2,)))
    dt = g["t1"] - g["t0"]
    return (d[1] - d[0]) / dt if dt > 0.0 else np.zeros_like(d[0])


def peak_speed(g, window) -> float:
    """An upper bound (px/frame) of the velocity's speed over ``window``: the displacement of
    a small turn is nearly affine in the pixel, largest on the window's outline (sampled, 2 %
    and half a pixel of slack)."""
    xs, ys = rect_boundary(window, 64)
    v = velocity_px(g, xs, ys)
    return float(np.hypot(v[..., 0], v[..., 1]).max() * 1.02 + 0.5)


@dataclass(frozen=True)
class ShakePlan(GatherPlan):
    """shake's plan for one step of a frame: the motion gather's (`clfx.kit.motion.
    GatherPlan`) and the turns' geometry (:func:`geometry`, read-only)."""

    geometry: Mapping | None = None


@register
class Shake(VelocityGather, Plugin):
    plan_type = ShakePlan
    descriptor = Descriptor(
        name="shake", label="Camera shake", group="Camera", kernel=KERNEL,
        summary="Blur of a handheld camera's shake: smooth random yaw, pitch and roll during "
                "the shutter (seeded, continuous from frame to frame), each pixel blurred "
                "along its own motion by the motion family's gather.",
        params=(
            FloatParam("yaw", 0.3, min=0.0, max=MAX_ANGLE_DEG, units="deg",
                       hint="RMS side-to-side turn of the camera, degrees."),
            FloatParam("pitch", 0.3, min=0.0, max=MAX_ANGLE_DEG, units="deg",
                       hint="RMS up-and-down turn of the camera, degrees."),
            FloatParam("roll", 0.15, min=0.0, max=MAX_ANGLE_DEG, units="deg",
                       hint="RMS turn about the lens axis, degrees (pixels turn about the "
                            "centre: more blur in the corners)."),
            FloatParam("frequency", 2.0, min=0.01, max=100.0, units="Hz",
                       hint="Middle frequency of the shake in Hz (a hand: 1-5; a vehicle "
                            "mount: higher)."),
            FloatParam("fps", 24.0, min=1.0, max=10000.0, units="1/s",
                       hint="Frame rate: converts frames to the shake's seconds."),
            IntParam("seed", 0, min=0, max=2 ** 31 - 1,
                     hint="Shake seed, combined with the look's seed."),
            *SHUTTER_PARAMS,
            FloatParam("max_blur", 0.05, min=0.001, max=0.25,
                       hint="Largest blur radius as a fraction of the frame diagonal (at "
                            f"most {MAX_RADIUS_PX} px); faster pixels are clamped to it."),
        ),
        quality=LEVELS,
        frame_varying=True,
    )

    def is_identity(self, p, ctx):
        closed = self.shutter_closed(p, ctx)
        if closed:
            return closed
        if p.yaw == 0.0 and p.pitch == 0.0 and p.roll == 0.0:
            return "yaw, pitch and roll are 0"
        return None

    def plan(self, p, ctx) -> ShakePlan:
        return self.gather_plan(p, ctx, geometry=MappingProxyType(geometry(p, ctx)))

    # -- the velocity fields (clfx.kit.motion.VelocityGather renders them) -------------------
    def gather_motion(self, p, ctx):
        return GatherMotion(peak_speed(geometry(p, ctx), ctx.source.window))

    def velocity_rows(self, rt, p, ctx, plan, rows):
        g = plan.geometry
        vel = rt.image(rows, 2)
        rt.launch(rt.kernel(KERNEL, "shake_velocity"), (vel.pitch // 4, rows.height), vel,
                  rt.to_device(np.asarray(g["turns"], np.float32)), vel.pitch, rows.width,
                  rows.height, rows.x0, rows.y0, g["cx"], g["cy"], g["fx"], g["fy"],
                  1.0 / (g["t1"] - g["t0"]) if g["t1"] > g["t0"] else 0.0)
        return vel, None, None

    def gather_note(self, p, ctx, plan, stats):
        g = plan.geometry
        (y0, p0, r0), (y1, p1, r1) = g["angles"][1], g["angles"][2]
        return (f"shake: turning {math.degrees(y1 - y0):+.3f} yaw, {math.degrees(p1 - p0):+.3f} "
                f"pitch, {math.degrees(r1 - r0):+.3f} roll deg over the shutter "
                f"({g['t0']:g} to {g['t1']:g} frame), up to {plan.fields.peak_speed:.1f} "
                "px/frame; "
                f"{stats.moving_tiles}/{stats.tiles} tiles moving, radius "
                f"{stats.radius_px:.1f} px, <= {stats.max_samples} samples along straight paths"
                + (f", {ctx.analysis.nonfinite_count} non-finite pixels zeroed"
                   if ctx.analysis.nonfinite_count else ""))
