"""Bench case of lens flare: the sun near a corner and seven street lamps (eight lights),
through the twelve-element zoom prescription (its 210 ghosts, physical model)."""
from __future__ import annotations

import numpy as np

from clfx.bench.cases import Case
from clfx.core.camera import Camera

LIGHTS = [(0.8, 0.2, 12, 1e5)] + [(0.1 + 0.11 * i, 0.3 + 0.08 * (i % 4), 4, 3000.0 / (i + 1))
                                  for i in range(7)]
"""(x, y as fractions of the frame, half-size px at 1920 wide, radiance): a sun of 1e5
(diffuse white = 1) and lamps of 3000 down to 430."""


def make(width, height, rng):
    """A dim frame with a sun-like light near a corner and seven street lamps."""
    src = rng.uniform(0.0, 0.2, (height, width, 4)).astype(np.float32)
    src[..., 3] = 1.0
    for fx, fy, r, v in LIGHTS:
        r = max(1, int(r * width / 1920))
        x, y = int(fx * width), int(fy * height)
        src[max(y - r, 0):y + r, max(x - r, 0):x + r, :3] = v
    return dict(source=src, depth=None, velocity=None,
                params={"threshold": 5.0, "model": "physical", "lens": "zoom-80-200mm"},
                camera=Camera(blades=6, blade_rotation=15.0, f_number=8.0))


CASE = Case(make=make)
