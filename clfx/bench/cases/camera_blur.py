"""Bench case of camera_blur: a handheld-style pan with a slight roll and trucking over the
layered test scene, against a multisample ground truth.

The camera's motion is turned into the motion of every layer of the scene
(:mod:`clfx.bench.scene`): a layer at depth ``z`` moves with the pan, the trucking parallax
``-f_px truck / z`` and the roll about the frame centre (its centre on the tangent of the
arc, the layer spinning with the roll: the arc's sagitta over half a frame is far below a
thousandth of a pixel here).  The truth is rendered like the motion_blur cases (beauty and
truth at jittered sub-pixel points, depth from the pixel centre;
:func:`clfx.bench.groundtruth.make_case`).

``naive(case, params, ctx)`` (``LINE_BLUR_LABEL``): every pixel averaged along its own image
velocity under the camera motion (:func:`clfx.bench.cases.shared.line_blur_per_pixel`).

What limits the score (issue 24, measured with ``scripts/motion_cases.py --effect
camera_blur`` and the case at 256 rays): the naive blur is given each pixel's exact camera
velocity (it equals the scene's own to 1e-6 px/frame), and on 85% of the frame (the wall's
interior) that line blur is what the gather does too, so camera_blur wins mostly in the 4 px
edge band around the parallax (6% of the pixels) and through its read of short blurs.  The
truth used to be sampled on the sharp frame's own 4 x 4 sub-pixel grid: the wall's 0.4-0.6 px
gaps between "words" were covered in quarter pixels by the sharp frame but in every phase by
the moving truth, so input, naive and final carried one mean offset on the wall and the
ranking of the reads flipped with the frame size (final 36.37 vs naive 36.28 dB at 480x270,
32.66 vs 33.30 at 240x135).  Both renders are now sampled as a path tracer samples
(:func:`clfx.bench.groundtruth.jittered_truth`, :data:`clfx.bench.groundtruth.JITTER_SEED`):
the wall's mean offset is gone (naive and final within 0.0003 of the truth's mean on the
wall interior at 480x270, log units; -0.0065 before), and the clamped
cubic up to 8 px (:data:`clfx.plugins.camera_blur.CAMERA_CUBIC_MAX_PX`, 2 px before) wins:
final 39.37 vs naive 38.67 dB at 480x270 (edge band RMSE 0.0137 vs 0.0176; the truth's noise
floor 45.2 dB), 37.69 vs 36.19 at 320x180 (floor 43.7).  At 240x135 the wall's "words" are
1.5 px cells with 0.3 px gaps, past the pixel grid's Nyquist limit: the input aliases them,
and the bilinear line blur's extra smoothing of the aliases ends closer to the truth on the
wall (final 32.86 vs naive 32.89 dB; bilinear everywhere 32.96, which costs 1.4 dB at
320x180 and 0.5 at 480x270), while final's edge band stays 17% closer (0.0181 vs 0.0218).
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from clfx.bench import cycles
from clfx.bench.cases import Case, Naive
from clfx.bench.cases.shared import LINE_BLUR_LABEL, line_blur_per_pixel
from clfx.bench.groundtruth import JITTER_SEED, RENDER_SS, case_dict, make_case
from clfx.bench.metrics import edge_band
from clfx.bench.scene import Scene, moving_scene, render_sharp
from clfx.core.camera import Camera
from clfx.fx.motion import shutter_from

__all__ = ["CASE", "PARAMS", "camera_scene", "make", "naive"]

PARAMS = dict(length=0.01, direction=200.0, roll=0.3, truck=(0.02, 0.0))
"""The case's camera motion: a pan of 1% of the diagonal per frame, 0.3 degrees of roll and
2 cm of trucking per frame (near things move more)."""

CAMERA = Camera(shutter_angle=180.0)


def _motion(width: int, height: int, params: dict, camera: Camera):
    """(shift px/frame, centre, roll rad/frame, f_px * truck) as camera_blur reads them
    (centre of roll: the frame centre)."""
    a = math.radians(params.get("direction", 0.0))
    shift = params.get("length", 0.0) * math.hypot(width, height)
    f_px = camera.focal_length_px(width)
    truck = params.get("truck", (0.0, 0.0))
    return ((shift * math.cos(a), shift * math.sin(a)), (0.5 * width, 0.5 * height),
            math.radians(params.get("roll", 0.0)), (f_px * truck[0], f_px * truck[1]))


def camera_scene(width: int, height: int, params: dict = PARAMS,
                 camera: Camera = CAMERA) -> Scene:
    """The layered test scene with the camera's motion given to every layer."""
    (sx, sy), (cx, cy), om, (tx, ty) = _motion(width, height, params, camera)
    layers = []
    for layer in moving_scene(width, height, 0.0).layers:
        iz = 0.0 if math.isinf(layer.depth) else 1.0 / layer.depth
        lx, ly = layer.center
        v = (sx - tx * iz - om * (ly - cy), sy - ty * iz + om * (lx - cx))
        layers.append(replace(layer, velocity=v, spin=math.degrees(om)))
    return Scene(width, height, tuple(layers), name="camera motion")


def make(width: int, height: int, rng=None, *, truth: bool = True,
         truth_samples: int = 256) -> dict:
    """A handheld-style pan with a slight roll and trucking, with its ground truth."""
    scene = camera_scene(width, height)
    if not truth:
        f = render_sharp(scene, 0.0, ss=RENDER_SS, passes="centre", jitter_seed=JITTER_SEED,
                         samples=truth_samples)
        return dict(source=f.rgba, depth=f.depth, velocity=None, params=dict(PARAMS),
                    camera=CAMERA)
    gt = make_case(scene, CAMERA, samples=truth_samples, dof=False, motion=True, ss=RENDER_SS,
                   jitter_seed=JITTER_SEED, noise_floor=True)
    case = case_dict(gt, PARAMS, scene=scene.name)
    case["velocity"] = None   # camera_blur reads the camera's motion, not a velocity pass
    case["edge_mask"] = edge_band(gt.sharp.depth, gt.sharp.velocity)
    return case


def image_velocity(depth: np.ndarray, params, camera: Camera) -> np.ndarray:
    """Per-pixel image velocity (px/frame) of the camera motion over a depth pass."""
    h, w = depth.shape
    p = params if isinstance(params, dict) else {k: getattr(params, k) for k in PARAMS}
    (sx, sy), (cx, cy), om, (tx, ty) = _motion(w, h, p, camera)
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64) + 0.5
    with np.errstate(divide="ignore"):
        iz = np.where(np.isfinite(depth) & (depth > 0), 1.0 / depth, 0.0)
    return np.stack([sx - tx * iz - om * (ys - cy), sy - ty * iz + om * (xs - cx)],
                    axis=-1).astype(np.float32)


def naive(case: dict, params, ctx) -> np.ndarray:
    """The naive baseline (:data:`LINE_BLUR_LABEL`): the per-pixel line blur along the image
    velocity of the camera motion."""
    t0, t1 = shutter_from(params, ctx.camera)
    vel = image_velocity(np.asarray(case["depth"], np.float64), params, ctx.camera)
    return line_blur_per_pixel(np.asarray(case["source"], np.float32), vel, t0, t1)


def cycles_params() -> dict:
    """camera_blur's parameters of the Cycles scenes' camera moves: ``truck`` (the truck) and
    ``pan`` (the pan, trucking the other way at half the speed)."""
    f_px = cycles.camera().focal_length_px(cycles.WIDTH)
    diag = math.hypot(cycles.WIDTH, cycles.HEIGHT)
    truck = cycles.truck_m_per_frame()
    return {"truck": dict(length=0.0, roll=0.0, truck=(truck, 0.0)),
            "pan": dict(length=f_px * math.radians(cycles.PAN_DEG) / diag, direction=180.0,
                        roll=0.0, truck=(-0.5 * truck, 0.0))}


CASE = Case(make=make,
            naive=Naive(LINE_BLUR_LABEL, lambda case, params, ctx: lambda: naive(case, params, ctx)),
            variants={f"cycles_{k}": cycles.maker(k, params=p, velocity=False)
                      for k, p in cycles_params().items() if cycles.available(k)})
