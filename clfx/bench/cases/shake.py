"""Bench case of shake: a handheld sway (yaw, pitch and roll) over a procedural texture with
fine detail, scored against the exact average of the turned views.

Ground truth
------------
A turning camera sees no parallax, so a view at any instant is the frame's texture through
the homography ``K C(0)^T C(t) K^-1`` (:mod:`clfx.plugins.shake`'s model: its seeded angle
signal and orientation).  The texture (:func:`clfx.bench.cases.shared.texture`, a function
of continuous coordinates, so the views past the frame's edge are the texture's too) is
evaluated at 8 x 8 stratified points of each output pixel, each at its own instant of the
open shutter (64 strata, assigned by a stride coprime to 64: every instant once per pixel),
sent through the view's inverse map, and averaged: a path tracer's estimate of the exposure.
The source is the texture's area average at the frame time.

``naive`` (``LINE_BLUR_LABEL``): every pixel averaged along the straight line of its exact
image velocity at the frame time (`clfx.bench.cases.shared.line_blur_per_pixel`).
"""
from __future__ import annotations

import numpy as np

from clfx.bench.cases import Case, Naive
from clfx.bench.cases.shared import (
    LINE_BLUR_LABEL,
    SUPERSAMPLE,
    box_average,
    edge_mask,
    grey_rgba,
    line_blur_per_pixel,
    texture,
)
from clfx.core.camera import Camera, camera_rotation
from clfx.fx.motion import shutter_from
from clfx.fx.noise import effect_seed
from clfx.plugins.shake import SHAKE_SALT, Shake, angles

TRUTH_DEPENDS = ("clfx.plugins.shake",)
"""The truth turns the views by the plugin's angle signal: a change there rebuilds it."""

PARAMS = dict(yaw=0.6, pitch=0.4, roll=0.3, frequency=2.5, seed=3)
CAMERA = Camera(shutter_angle=180.0, shutter_offset="centered")
FRAME = 1
"""The case's frame (`clfx.bench.cases.shared.case_context`'s default)."""

STRIDE = 37
"""Sub-pixel point ``k`` of 64 takes instant ``k * STRIDE mod 64``."""


def _view(p, width: int, height: int, camera: Camera):
    """(fx, cx, cy, seed32) of the case's frame (display window = the frame)."""
    fx = camera.focal_length_px(width)
    return fx, width / 2.0, height / 2.0, effect_seed(p.seed, 0, SHAKE_SALT)


def truth_image(params: dict, camera: Camera, width: int, height: int,
                ss: int = SUPERSAMPLE) -> np.ndarray:
    """The exposure of the turning camera (float64 RGBA): ss x ss points a pixel, each at its
    own instant of the shutter."""
    p = Shake.params(**params)
    fx, cx, cy, seed32 = _view(p, width, height, camera)
    t0, t1 = shutter_from(p, camera)
    c0 = camera_rotation(*angles(p, seed32, FRAME / p.fps))
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float64)
    acc = np.zeros((height, width))
    n = ss * ss
    for k in range(n):
        oy, ox = (k // ss + 0.5) / ss, (k % ss + 0.5) / ss
        t = t0 + ((k * STRIDE) % n + 0.5) / n * (t1 - t0)
        m = c0.T @ camera_rotation(*angles(p, seed32, (FRAME + t) / p.fps))
        u, v = (xs + ox - cx) / fx, (ys + oy - cy) / fx
        q = np.tensordot(m, np.stack([u, v, np.ones_like(u)]), 1)
        acc += texture(q[0] / q[2] * fx + cx, q[1] / q[2] * fx + cy, width, height)
    return grey_rgba(acc / n)


def image_velocity(params, camera: Camera, width: int, height: int) -> np.ndarray:
    """Each pixel's exact image velocity (px/frame) at the frame time (central differences
    of the turned views, 1e-4 frame)."""
    p = params if not isinstance(params, dict) else Shake.params(**params)
    fx, cx, cy, seed32 = _view(p, width, height, camera)
    c0 = camera_rotation(*angles(p, seed32, FRAME / p.fps))
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float64) + 0.5
    rays = np.stack([(xs - cx) / fx, (ys - cy) / fx, np.ones_like(xs)])
    pos = []
    for dt in (1e-4, -1e-4):
        q = np.tensordot(camera_rotation(*angles(p, seed32, (FRAME + dt) / p.fps)).T @ c0, rays, 1)
        pos.append(np.stack([q[0] / q[2], q[1] / q[2]], -1) * fx)
    return ((pos[0] - pos[1]) / 2e-4).astype(np.float32)


def make(width, height, rng):
    """A handheld sway: yaw 0.6, pitch 0.4, roll 0.3 degrees RMS at 2.5 Hz, 180 degrees."""
    source = grey_rgba(box_average(lambda x, y: texture(x, y, width, height), width, height))
    truth = truth_image(PARAMS, CAMERA, width, height)
    return dict(source=source.astype(np.float32), depth=None, velocity=None,
                params=dict(PARAMS), camera=CAMERA, frame=FRAME, truth=truth,
                edge_mask=edge_mask(truth))


def naive(case, params, ctx):
    """The per-pixel line blur along each pixel's exact velocity at the frame time."""
    src = np.asarray(case["source"], np.float32)
    t0, t1 = shutter_from(params, ctx.camera)
    vel = image_velocity(params, ctx.camera, src.shape[1], src.shape[0])
    return lambda: line_blur_per_pixel(src, vel, t0, t1)


CASE = Case(make=make, naive=Naive(LINE_BLUR_LABEL, naive))
