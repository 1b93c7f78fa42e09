"""Bench case of sensor noise: a dark high-ISO frame; NumPy's Poisson and normal generators as
the peer (their own samples: compare times, not pixels)."""
from __future__ import annotations

import numpy as np

from clfx.bench.cases import Case
from clfx.core.camera import Camera
from clfx.plugins.sensor_noise import electrons_per_unit


def make(width, height, rng):
    """A dark, high-ISO frame: most pixels below 30 electrons, so the exact Poisson path runs."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    base = 0.002 + 0.3 * (x / max(width - 1, 1)) ** 2 * (y / max(height - 1, 1))
    src = np.empty((height, width, 4), np.float32)
    src[..., 0], src[..., 1], src[..., 2] = base * 1.2, base, base * 0.7
    src[..., 3] = 1.0
    hot = rng.integers(0, height * width, size=max(1, height * width // 50000))
    src.reshape(-1, 4)[hot, :3] = 1e4
    return dict(source=src, depth=None, velocity=None,
                params={"read_noise": 3.0, "prnu": 0.005,
                        "channel_sensitivity": (0.6, 1.0, 0.45), "seed": 3},
                camera=Camera(iso=6400.0))


def peers(case, params, ctx=None):
    """NumPy's Poisson and normal generators on the host (own samples: compare times)."""
    src = np.asarray(case["source"], np.float32)
    k = electrons_per_unit(params, case["camera"])

    def numpy_poisson():
        gen = np.random.default_rng(0)
        out = src.copy()
        for c in range(3):
            lam = np.minimum(np.maximum(src[..., c], 0.0) * k[c], 1e15)
            out[..., c] = (gen.poisson(lam) + gen.normal(0.0, params.read_noise, lam.shape)) / k[c]
        return out

    return {"numpy Generator.poisson + normal": numpy_poisson}


CASE = Case(make=make, peers=peers)
