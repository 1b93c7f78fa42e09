"""float64 NumPy oracle of clfx/plugins/soft_focus.py: glare's model, a diffusion PSF of three
radial exponentials ended by the tail fade."""
import math

import numpy as np

from tests.reference.glare import glare, tail_fade

SUPPORT = 3.0    # support radius / size


def diffusion_psf(radius):
    """sum_i w_i exp(-d / s_i) / (2 pi s_i^2), s = size / 4, / 8, / 16 (size = radius / 3),
    w = 1, 2, 4; tail-faded and normalised (plain loops)."""
    r = int(radius)
    size = r / SUPPORT
    k = np.zeros((2 * r + 1, 2 * r + 1))
    for s, w in ((size / 4, 1.0), (size / 8, 2.0), (size / 16, 4.0)):
        s = max(s, 0.5)
        for j in range(-r, r + 1):
            for i in range(-r, r + 1):
                k[j + r, i + r] += w * math.exp(-math.hypot(i, j) / s) / (2 * math.pi * s * s)
    k = tail_fade(k, r)
    return k / k.sum()


def soft_focus(src, radius, *, amount, threshold, knee, tint=(1.0, 1.0, 1.0), **kw):
    """``radius``: the PSF's support radius in px (3 x size x the diagonal)."""
    return glare(src, diffusion_psf(radius), strength=amount, threshold=threshold, knee=knee,
                 tint=tint, **kw)
