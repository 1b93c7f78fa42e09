"""Bench case of lens: a real zoom lens with every defect lensfun calibrates."""
from __future__ import annotations

import numpy as np

from clfx.bench.cases import Case
from clfx.core.camera import Camera


def make(width, height, rng):
    """Canon EF 24-70mm f/2.8L II at 24 mm f/2.8: ptlens distortion, poly3 TCA, vignetting."""
    src = rng.uniform(0.0, 1.0, (height, width, 4)).astype(np.float32)
    src[::max(height // 10, 1), :, :3] = 20.0
    src[..., 3] = 1.0
    return dict(source=src, depth=None, velocity=None,
                params=dict(maker="Canon", model="Canon EF 24-70mm f/2.8L II USM"),
                camera=Camera(focal_length=24.0, f_number=2.8, sensor_width=36.0,
                              focus_distance=3.0))


CASE = Case(make=make)
