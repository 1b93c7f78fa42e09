"""Bench case of streaks: a dim noisy frame with a few strong lights; peer OpenCV's filter2D
with each ray's exact exponential line kernel."""
from __future__ import annotations

import math

import numpy as np

from clfx.bench.cases import Case
from clfx.core.camera import Camera
from clfx.plugins.streaks import Streaks, channel_lengths, grid_step, support_steps


def make(width, height, rng):
    """A dim noisy frame with a few strong lights: 4 rays at 1080p-typical length."""
    src = rng.uniform(0.0, 0.3, (height, width, 4)).astype(np.float32)
    src[..., 3] = 1.0
    for _ in range(12):
        x, y = int(rng.integers(0, width)), int(rng.integers(0, height))
        src[max(0, y - 2):y + 3, max(0, x - 2):x + 3, :3] = rng.uniform(50, 5000)
    return dict(source=src, depth=None, velocity=None,
                # core 0: every pixel above threshold streaks, the operation the peers do
                params={"threshold": 2.0, "intensity": 0.3, "streaks": 4, "length": 0.1,
                        "color_shift": 0.3, "core": 0.0},
                camera=Camera(blades=6))


def peers(case, params, ctx):
    """OpenCV's filter2D with each ray's exact exponential line kernel (one bilinear tap per
    step), the operation the Kawase passes approximate: its error against clfx's reference
    includes that kernel difference."""
    try:
        import cv2  # lazy: OpenCV is optional (test extra); the bench's peers go without it
    except ImportError:
        return {}
    plugin = Streaks()
    src = np.nan_to_num(np.asarray(case["source"], np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    clean = np.maximum(src, 0.0)
    lum = clean[..., :3] @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    k = np.where(lum > params.threshold, (lum - params.threshold) / np.where(lum > 0, lum, 1.0), 0.0)
    bright = np.ascontiguousarray(clean[..., :3] * k[..., None], np.float32)
    angles = plugin.angles(params, ctx)
    gain = params.intensity * np.asarray(params.tint) / max(len(angles), 1)
    kernels = []
    for ang in angles:
        sx, sy, step_len = grid_step(ang)
        lengths = channel_lengths(plugin.length_px(params, ctx), params.color_shift) / step_len
        a = 0.01 ** (1.0 / np.maximum(lengths, 1e-3))
        support = support_steps(float(lengths.max()))
        radius = int(math.ceil(support * max(abs(sx), abs(sy)))) + 1
        kern = np.zeros((3, 2 * radius + 1, 2 * radius + 1), np.float64)
        for step in range(support):
            x, y = radius + step * sx, radius + step * sy
            x0, y0 = int(math.floor(x)), int(math.floor(y))
            fx, fy = x - x0, y - y0
            for dy_, wy in ((0, 1 - fy), (1, fy)):
                for dx_, wx in ((0, 1 - fx), (1, fx)):
                    if wx * wy > 0:
                        kern[:, y0 + dy_, x0 + dx_] += wx * wy * a ** step
        total = (1 - a ** support) / (1 - a)
        kernels.append((kern * (gain / total)[:, None, None]).astype(np.float32))

    def line_kernels():
        out = clean.copy()
        for kern in kernels:
            for c in range(3):
                out[..., c] += cv2.filter2D(bright[..., c], -1, kern[c], borderType=cv2.BORDER_CONSTANT)
        return out

    cv2.setNumThreads(2)
    return {f"cv2.filter2D exact line kernels ({len(angles)} rays x 3 channels)": line_kernels}


CASE = Case(make=make, peers=peers)
