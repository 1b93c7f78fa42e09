"""Bench case of bleed: bright specks (saturated and 1e3) on a textured mid-grey frame."""
from __future__ import annotations

import numpy as np

from clfx.bench.cases import Case
from clfx.core.camera import Camera


def make(width, height, rng):
    """Bright specks (saturated and 1e3) on a textured mid-grey frame."""
    src = np.empty((height, width, 4), np.float32)
    src[..., :3] = rng.uniform(0.05, 0.5, (height, width, 3))
    src[..., 3] = 1.0
    n = max(1, width * height // 2000)
    ys, xs = rng.integers(0, height, n), rng.integers(0, width, n)
    src[ys, xs, :3] = rng.choice([2.0, 8.0, 1e3], n)[:, None]
    return dict(source=src, depth=None, velocity=None, params={"strength": 0.2, "size": 0.003},
                camera=Camera())


CASE = Case(make=make)
