"""Bench case of corona: a street scene at night."""
from __future__ import annotations

import numpy as np

from clfx.bench.cases import Case
from clfx.core.camera import Camera


def make(width, height, rng):
    """A dim frame with a cluster of strong lights (a street scene at night)."""
    src = rng.uniform(0.0, 0.2, (height, width, 4)).astype(np.float32)
    src[..., 3] = 1.0
    for _ in range(6):
        x = int(rng.integers(width // 4, 3 * width // 4))
        y = int(rng.integers(height // 4, 3 * height // 4))
        src[y - 3:y + 4, x - 3:x + 4, :3] = rng.uniform(100, 20000)
    return dict(source=src, depth=None, velocity=None,
                params={"threshold": 2.0},                  # the defaults: rings of 3 %
                camera=Camera(blades=0))


CASE = Case(make=make)
