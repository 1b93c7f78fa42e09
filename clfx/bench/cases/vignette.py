"""Bench case of vignette: a textured HDR frame under a wide lens."""
from __future__ import annotations

import numpy as np

from clfx.bench.cases import Case
from clfx.core.camera import Camera


def make(width, height, rng):
    """A textured HDR frame under a wide lens with a strong artistic falloff."""
    src = rng.uniform(0.0, 4.0, (height, width, 4)).astype(np.float32)
    src[..., 3] = 1.0
    return {"source": src, "camera": Camera(focal_length=18.0),
            "params": {"natural": 1.0, "amount": 0.4, "radius": 0.3, "softness": 0.6}}


CASE = Case(make=make)
