"""Bleed: sensor crosstalk, a small-radius glare around bright pixels.

Model
-----
Charge and light leak from a photosite to its neighbours (electrical crosstalk, diffusion in
the silicon, blooming of saturated wells).  The leak falls off roughly exponentially with
distance: PSF ``exp(-d / (r / 3))`` truncated at ``r = size x diagonal`` (a few pixels).
Pixels above ``threshold`` (soft knee, as glare) lose ``strength`` of their light, which lands
on the neighbourhood: ``out = c - strength h + strength tint (PSF * h)`` — energy is kept.
Uses glare's machinery (``ScatterPlugin``, glare.cl helpers, ``clfx.fftconv``); small PSFs
are convolved directly (float32 sums; float64 for ``reference``), large ones by FFT.
"""
from __future__ import annotations

import numpy as np

from clfx import psf as psflib
from clfx.camera import Camera
from clfx.plugin import Descriptor, FloatParam, RGBParam, register
from clfx.plugins.glare import QUALITY, ScatterPlugin


@register
class Bleed(ScatterPlugin):
    descriptor = Descriptor(
        name="bleed", label="Bleed", group="Sensor", kernel="bleed.cl",
        summary="Sensor crosstalk: bright pixels leak a little light into their neighbours.",
        spreads_light=True,
        params=(
            FloatParam("strength", 0.2, min=0.0, max=1.0,
                       hint="Fraction of a bright pixel's light that leaks to its neighbours."),
            FloatParam("threshold", 1.0, min=0.0, max=1e6,
                       hint="Scene-linear luminance where leaking starts (sensor saturation)."),
            FloatParam("knee", 0.25, min=0.0, max=1e6,
                       hint="Width of the soft knee below the threshold, in luminance."),
            FloatParam("size", 0.002, min=0.0, max=0.1,
                       hint="Leak radius as a fraction of the frame diagonal (0.002 = ~4 px at 1080p)."),
            RGBParam("tint", (1.0, 1.0, 1.0), max=100.0,
                     hint="Colour of the leaked light (white keeps energy)."),
        ),
        quality={
            "draft": "PSF <= 21x21 taps: direct float32 gather; larger: " + QUALITY["draft"],
            "preview": "PSF <= 21x21 taps: direct float32 gather; larger: " + QUALITY["preview"],
            "final": "PSF <= 21x21 taps: direct float32 gather; larger: " + QUALITY["final"],
            "reference": "direct gather with float64 weights and accumulation (float64 FFT if huge)",
        },
    )

    def build_psf(self, p, ctx, radius):
        return psflib.exponential(radius, radius / 3.0)


def bench_case(width, height, rng):
    """Bright specks (saturated and 1e3) on a textured mid-grey frame."""
    src = np.empty((height, width, 4), np.float32)
    src[..., :3] = rng.uniform(0.05, 0.5, (height, width, 3))
    src[..., 3] = 1.0
    n = max(1, width * height // 2000)
    ys, xs = rng.integers(0, height, n), rng.integers(0, width, n)
    src[ys, xs, :3] = rng.choice([2.0, 8.0, 1e3], n)[:, None]
    return dict(source=src, depth=None, velocity=None, params={"strength": 0.2, "size": 0.003},
                camera=Camera())
