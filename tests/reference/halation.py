"""float64 NumPy oracle of clfx/plugins/halation.py: the halation PSF from its formula (a
Lambertian return times an exponential spread, tail-faded), the
glare family's highlight and convolution (tests/reference/glare.py), the additive or
conserving mix."""
import math

import numpy as np

from tests.reference.glare import convolve, highlight, sanitise, tail_fade

SUPPORT = {True: 6.0, False: 4.0}    # support radius / H (bare back, backed)
SPREAD = {True: 1.0, False: 0.4}     # exponential scale of the return / H


def psf(radius, bare_back, ss=8):
    """Pixel-integrated (ss x ss samples) cos^4(theta) exp(-d / (SPREAD H)), theta =
    atan(d / H), H = radius / SUPPORT, tail-faded and normalised (plain loops)."""
    r = int(radius)
    if r == 0:
        return np.ones((1, 1))
    h = r / SUPPORT[bare_back]
    k = np.zeros((2 * r + 1, 2 * r + 1))
    for j in range(-r, r + 1):
        for i in range(-r, r + 1):
            acc = 0.0
            for sj in range(ss):
                for si in range(ss):
                    d = math.hypot(i + (si + 0.5) / ss - 0.5, j + (sj + 0.5) / ss - 0.5)
                    theta = math.atan(d / h)
                    acc += math.cos(theta) ** 4 * math.exp(-d / h / SPREAD[bare_back])
            k[j + r, i + r] = acc / ss ** 2
    k = tail_fade(k, r)
    return k / k.sum()


def halation(src, radius, bare_back, *, strength, threshold, knee, tint, conserve=False,
             data_window=None, out_window=None):
    """Halation output covering out_window (x0, y0, x1, y1)."""
    s = sanitise(src)
    h, w = s.shape[:2]
    dw = data_window or (0, 0, w, h)
    ow = out_window or dw
    hl = highlight(s, threshold, knee)
    ss = 8 if radius <= 16 else 4 if radius <= 64 else 2 if radius <= 256 else 1
    g = convolve(hl, psf(radius, bare_back, ss), dw[:2], ow)
    out = np.zeros((ow[3] - ow[1], ow[2] - ow[0], 4))
    c = np.zeros_like(out)
    hh = np.zeros(out.shape[:2] + (3,))
    xa, xb = max(ow[0], dw[0]), min(ow[2], dw[2])
    ya, yb = max(ow[1], dw[1]), min(ow[3], dw[3])
    c[ya - ow[1]:yb - ow[1], xa - ow[0]:xb - ow[0]] = s[ya - dw[1]:yb - dw[1], xa - dw[0]:xb - dw[0]]
    hh[ya - ow[1]:yb - ow[1], xa - ow[0]:xb - ow[0]] = hl[ya - dw[1]:yb - dw[1], xa - dw[0]:xb - dw[0]]
    st = strength * np.asarray(tint, np.float64)
    out[..., :3] = c[..., :3] + st * g
    if conserve:
        out[..., :3] -= st * hh
    out[..., 3] = c[..., 3]
    return out
