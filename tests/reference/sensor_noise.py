"""float64 NumPy oracle of clfx/plugins/sensor_noise.py: the plainest form of the model.

Same random streams as the kernel (``clfx_uniform`` re-implemented in tests/reference/grain.py).
"""
import math

import numpy as np

from tests.reference.grain import effect_seed, uniform

SENSOR_SALT = 0x73656E73
PRNU_SALT = 0x70726E75


def poisson_by_inversion(lam, u, max_count=200, u_cap=4e-6):
    """Smallest n with u <= F(n) for Poisson(lam), summing the pmf in float64 (one value).

    u is capped at 1 - u_cap, as in the kernel (it keeps float32 rounding of F from
    leaving F below u)."""
    u = min(u, 1.0 - u_cap)
    p = math.exp(-lam)
    cdf, n = p, 0
    while u > cdf and n < max_count:
        n += 1
        p *= lam / n
        cdf += p
    return n


def sensor_noise(src, *, iso, base_iso, full_well, shot_noise, read_noise, prnu,
                 channel_sensitivity, seed, frame=0, look_seed=0, data_origin=(0, 0),
                 camera_iso=400.0, switch=30.0):
    """Sensor noise on ``src`` (h, w, 4) float64; ``switch`` None = normal approximation only."""
    src = np.asarray(src, np.float64)
    h, w = src.shape[:2]
    gain = (iso if iso > 0 else camera_iso) / base_iso
    s_main = effect_seed(seed, look_seed, SENSOR_SALT)
    s_prnu = effect_seed(seed, look_seed, PRNU_SALT)
    y, x = np.mgrid[0:h, 0:w]
    x = x + data_origin[0]
    y = y + data_origin[1]
    out = src.copy()
    for c in range(3):
        k = full_well * channel_sensitivity[c] / gain
        g = 1.0 / k
        v = np.clip(np.where(np.isfinite(src[..., c]), src[..., c], 0.0), -1e38, 1e38)
        if prnu > 0:
            fa, fb = uniform(s_prnu, 0, x, y, c), uniform(s_prnu, 0, x, y, c + 4)
            v = v * (1 + prnu * np.sqrt(-2 * np.log(fa)) * np.cos(2 * np.pi * fb))
        ua, ub = uniform(s_main, frame, x, y, c), uniform(s_main, frame, x, y, c + 4)
        r = np.sqrt(-2 * np.log(ua))
        res = v.copy()
        if shot_noise:
            vpos = np.maximum(v, 0.0)
            dev = np.sqrt(np.minimum(vpos, 1e30) * g) * r * np.cos(2 * np.pi * ub)
            if switch is not None:
                lam = vpos * k
                uc = uniform(s_main, frame, x, y, c + 8)
                for j, i in zip(*np.nonzero(lam <= switch)):
                    dev[j, i] = (poisson_by_inversion(lam[j, i], uc[j, i]) - lam[j, i]) * g
            res = res + dev
        if read_noise > 0:
            res = res + read_noise * g * r * np.sin(2 * np.pi * ub)
        out[..., c] = res
    return out
