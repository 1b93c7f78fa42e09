"""float64 NumPy oracle of clfx/plugins/bleed.py: glare's model with an exponential PSF."""
import numpy as np

from tests.reference.glare import glare


def exponential_psf(radius):
    r = int(radius)
    y, x = np.mgrid[-r:r + 1, -r:r + 1].astype(np.float64)
    d = np.hypot(x, y)
    k = np.exp(-d / max(r / 3.0, 1e-3))
    k[d > r + 0.5] = 0
    return k / k.sum()


def bleed(src, radius, *, strength, threshold, knee, tint=(1.0, 1.0, 1.0), **kw):
    return glare(src, exponential_psf(radius), strength=strength, threshold=threshold,
                 knee=knee, tint=tint, **kw)
