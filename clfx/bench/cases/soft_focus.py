"""Bench case of soft focus: a portrait-like frame with a bright window."""
from __future__ import annotations

import numpy as np

from clfx.bench.cases import Case
from clfx.core.camera import Camera


def make(width, height, rng):
    """A portrait-like frame: mid tones, a bright window and skin-like highlights."""
    src = np.empty((height, width, 4), np.float32)
    src[..., :3] = rng.uniform(0.02, 0.6, (height, width, 3))
    src[: height // 3, width // 2:, :3] = 4.0
    src[..., 3] = 1.0
    return dict(source=src, depth=None, velocity=None, params={"amount": 0.3, "size": 0.03},
                camera=Camera())


CASE = Case(make=make)
