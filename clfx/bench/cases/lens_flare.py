"""Bench case of lens flare: a sun-like light near a corner and two street lamps."""
from __future__ import annotations

import numpy as np

from clfx.bench.cases import Case
from clfx.core.camera import Camera


def make(width, height, rng):
    """A dim frame with a sun-like light near a corner and two street lamps."""
    src = rng.uniform(0.0, 0.2, (height, width, 4)).astype(np.float32)
    src[..., 3] = 1.0
    for fx, fy, r, v in ((0.8, 0.2, 12, 5000.0), (0.3, 0.6, 4, 300.0), (0.55, 0.7, 3, 150.0)):
        x, y = int(fx * width), int(fy * height)
        src[y - r:y + r, x - r:x + r, :3] = v
    return dict(source=src, depth=None, velocity=None,
                params={"threshold": 5.0, "intensity": 0.05, "ghost_count": 8},
                camera=Camera(blades=6, blade_rotation=15.0))


CASE = Case(make=make)
