"""Bench case of rolling_shutter: a phone panning past poles while a ball crosses the other way,
against a per-row-time ground truth; peers: a naive per-pixel forward displacement and the
unchanged input.

Ground truth
------------
The layered scene renderer (:func:`clfx.bench.scene.render_sharp`) evaluates the scene at any
instant exactly, so the rolling-shutter frame is assembled row by row: row ``y`` is row ``y``
of the sharp render at that row's time ``t(y)`` (the effect's own row-time formula,
:meth:`RollingShutter.row_times`).  Both the sharp frame and the truth are sampled as a
renderer samples (jittered points in 2 x 2 strata, 64 a pixel, each render its own seed): no
sub-pixel grid is shared by the input and the truth.  Nothing is reconstructed: occlusion, what a moving edge
uncovers and the frame edges all come out of the renders.

Peers
-----
``naive forward splat``: every source pixel moved to ``round(q + v(q) t(q))`` with its own
row's time (the destination row's time is unknown to a splat), nearer pixels winning
(z-buffer on the depth pass), holes left empty; ``... over the input``: the same splat over a
copy of the input (holes keep the input); ``unchanged input``: no correction at all.
"""
from __future__ import annotations

import numpy as np

from clfx.bench import cycles
from clfx.bench.cases import Case
from clfx.bench.groundtruth import JITTER_SEED
from clfx.bench.metrics import error_metrics
from clfx.bench.scene import Layer, Scene, Texture, render_rows, render_sharp
from clfx.core.camera import Camera
from clfx.core.rect import Rect
from clfx.plugins.rolling_shutter import RollingShutter

PARAMS = {"readout_ms": 25.0, "fps": 30.0}
"""A phone sensor: 25 ms readout at 30 fps (0.75 of a frame), top-down, t = 0 at the top."""


def pan_scene(width: int, height: int) -> Scene:
    """A camera panning right (the world moves left, nearer faster: parallax) past a mottled
    wall at 20 m and three poles at 4 m, while a striped ball at 6 m crosses to the right.
    Speeds at 640 px wide: wall 8, poles 24, ball 30 px/frame (scaled with the width)."""
    s = width / 640.0
    wall = Layer(depth=20.0, texture=Texture("noise", (0.5, 0.45, 0.4), (0.05, 0.05, 0.06),
                                             period=12.0 * s, seed=3),
                 shape="full", velocity=(-8.0 * s, 0.0), name="wall")
    poles = tuple(
        Layer(depth=4.0, texture=Texture("stripes", (0.8, 0.8, 0.75), (0.2, 0.1, 0.05),
                                         period=10.0 * s, angle=90.0),
              shape="rect", center=((0.2 + 0.3 * i) * width, 0.5 * height),
              size=(0.05 * width, 1.2 * height), velocity=(-24.0 * s, 0.0), name=f"pole {i}")
        for i in range(3))
    r = 0.14 * height
    ball = Layer(depth=6.0, texture=Texture("stripes", (0.9, 0.25, 0.1), (0.95, 0.9, 0.8),
                                            period=12.0 * s, angle=30.0),
                 shape="disk", center=(0.45 * width, 0.62 * height), size=(2 * r, 2 * r),
                 velocity=(30.0 * s, 0.0), name="ball")
    return Scene(width, height, (wall, ball) + poles, name="rolling shutter pan")   # far to near


def time_map(width: int, height: int, params: dict) -> np.ndarray:
    """The effect's time (frames) of every pixel of a ``width x height`` frame."""
    frame = Rect.from_size(width, height)
    t = RollingShutter().row_times(RollingShutter.params(**params), frame, frame)
    yy, xx = np.mgrid[0:height, 0:width]
    return t.at(xx, yy)


SS = 2
"""Strata per pixel and axis of the case's renders."""

SAMPLES = 64
"""Jittered points per pixel of the sharp frame and of every row of the truth (16 passes
over the 2 x 2 strata)."""

TRUTH_SEED = JITTER_SEED + 2
"""The truth's seed: another render than the sharp frame's (``JITTER_SEED``), as a renderer
would write it; ``TRUTH_SEED + 1`` renders it again for the noise floor."""


def row_time_truth(scene: Scene, times: np.ndarray, ss: int = SS,
                   jitter_seed: int | None = None, samples: int | None = None) -> np.ndarray:
    """The rolling-shutter frame: each row (or column, for sideways readouts) of the sharp
    render at that row's time ``times`` (a per-pixel map, constant along rows or columns),
    with :func:`clfx.bench.scene.render_sharp`'s ``jitter_seed`` and ``samples``."""
    by_rows = bool(np.all(times == times[:, :1]))
    lines = times[:, 0] if by_rows else times[0]
    out = np.empty((scene.height, scene.width, 4), np.float32)
    for i, t in enumerate(lines):
        if by_rows:        # only the row itself: O(pixels), not O(rows x pixels)
            out[i] = render_rows(scene, float(t), i, i + 1, ss=ss, jitter_seed=jitter_seed,
                                 samples=samples)[0]
        else:
            out[:, i] = render_sharp(scene, float(t), ss=ss, jitter_seed=jitter_seed,
                                     samples=samples).rgba[:, i]
    return out


def make(width: int, height: int, rng, *, truth: bool = True, params: dict | None = None) -> dict:
    """The pan scene's sharp frame with its passes and (``truth``) the per-row-time truth,
    both sampled as a renderer does (:data:`SAMPLES` jittered points per pixel, independent
    seeds), with the truth's noise floor (``truth_floor``: a second truth, another seed)."""
    params = dict(PARAMS if params is None else params)
    scene = pan_scene(width, height)
    sharp = render_sharp(scene, 0.0, ss=SS, jitter_seed=JITTER_SEED, samples=SAMPLES)
    case = dict(source=sharp.rgba, depth=sharp.depth, velocity=sharp.velocity, params=params,
                camera=Camera(focal_length=4.3, f_number=1.8, sensor_width=5.6))
    if truth:
        times = time_map(width, height, params)
        case["truth"] = row_time_truth(scene, times, jitter_seed=TRUTH_SEED, samples=SAMPLES)
        again = row_time_truth(scene, times, jitter_seed=TRUTH_SEED + 1, samples=SAMPLES)
        case["truth_floor"] = error_metrics(again, case["truth"])["psnr_log"]
    return case


def forward_splat(src, velocity, depth, times, *, over_input: bool = False) -> np.ndarray:
    """Each source pixel moved to ``round(q + v(q) t(q))`` (its own row's time; ``times``
    per pixel), the nearer winning; holes left empty (transparent black) or, ``over_input``,
    showing the input."""
    h, w = src.shape[:2]
    out = src.copy() if over_input else np.zeros_like(src)
    yy, xx = np.mgrid[0:h, 0:w]
    t = np.asarray(times, np.float64)
    v = np.nan_to_num(np.asarray(velocity, np.float64))
    tx = np.rint(xx + v[..., 0] * t).astype(int)
    ty = np.rint(yy + v[..., 1] * t).astype(int)
    z = np.ones((h, w)) if depth is None else np.nan_to_num(np.asarray(depth, np.float64),
                                                            nan=np.inf)
    inside = (tx >= 0) & (tx < w) & (ty >= 0) & (ty < h)
    order = np.argsort(-z[inside], kind="stable")          # far first: near ones overwrite
    sy, sx = yy[inside][order], xx[inside][order]
    out[ty[inside][order], tx[inside][order]] = src[sy, sx]
    return out


def peers(case, params, ctx):
    """The naive forward splats (holes empty / over the input) and the unchanged input."""
    src = np.asarray(case["source"], np.float32)
    h, w = src.shape[:2]
    times = time_map(w, h, case["params"])
    return {
        "naive forward splat (holes left)": lambda: forward_splat(
            src, case["velocity"], case.get("depth"), times),
        "naive forward splat over the input": lambda: forward_splat(
            src, case["velocity"], case.get("depth"), times, over_input=True),
        "unchanged input": lambda: src.copy(),
    }


CASE = Case(make=make, peers=peers,
            variants={"cycles_truck": cycles.maker("truck_rolling", params=PARAMS)}
            if cycles.available("truck_rolling") else {})
