"""float64 NumPy oracle of clfx/plugins/soft_focus.py: glare's model, a 3-Gaussian bloom PSF."""
import numpy as np

from tests.reference.glare import glare


def bloom_psf(radius):
    r = int(radius)
    y, x = np.mgrid[-r:r + 1, -r:r + 1].astype(np.float64)
    d2 = x * x + y * y
    k = np.zeros_like(d2)
    for i, w in enumerate((0.25, 0.5, 1.0)):       # widest r/3, each next 2x narrower
        s = max(r / 3.0 / 2 ** i, 0.5)
        s = max(s, 0.3)
        g = np.exp(-0.5 * d2 / (s * s))
        k += w * g / g.sum()
    # round support: 1 inside 3/4 of the radius, a raised cosine to 0 at the radius
    t = np.clip((np.sqrt(d2) / max(r, 1) - 0.75) / 0.25, 0.0, 1.0)
    k = k * (0.5 + 0.5 * np.cos(np.pi * t))
    return k / k.sum()


def soft_focus(src, radius, *, amount, threshold, knee, tint=(1.0, 1.0, 1.0), **kw):
    return glare(src, bloom_psf(radius), strength=amount, threshold=threshold, knee=knee,
                 tint=tint, **kw)
