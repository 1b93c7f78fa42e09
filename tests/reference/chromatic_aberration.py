"""float64 NumPy oracle of clfx/plugins/chromatic_aberration.py: per-pixel bisection of the
radial model for every wavelength bin (no look-up table), the same filters as the kernel
(tests/reference/distortion.py), weights from the CIE 1931 fit integrated per bin, in the
working space whose RGB -> XYZ matrix is ``rgb_to_xyz`` (None: Rec.709, the IEC matrix M)."""
import math

import numpy as np

from tests.reference import XYZ_TO_REC709 as M, cie1931
from tests.reference.distortion import bisect, sample


def response(lam, rgb_to_xyz=None):
    xyz = cie1931(lam)
    to_rgb = M if rgb_to_xyz is None else np.linalg.inv(rgb_to_xyz)
    rgb = np.clip(xyz @ to_rgb.T, 0, None)
    return np.concatenate([rgb, xyz[:, 1:2]], -1)


def delta(lam, amount, rgb_to_xyz=None):
    fine = np.arange(380.125, 720.0, 0.25)
    g = response(fine, rgb_to_xyz)[:, 1]
    green = (g / fine ** 2).sum() / g.sum()          # green channel's mean 1/lambda^2
    return amount * (lam ** -2.0 - green) / (450.0 ** -2 - 650.0 ** -2)


def bins(n, amount, rgb_to_xyz=None):
    lam = np.arange(380.125, 720.0, 0.25)
    resp = response(lam, rgb_to_xyz)
    if n == 3:
        d = [(resp[:, c] * delta(lam, amount, rgb_to_xyz)).sum() / resp[:, c].sum()
             for c in range(3)]
        w = np.zeros((3, 4))
        w[0, 0] = w[1, 1] = w[2, 2] = w[1, 3] = 1.0
        return np.array(d), w
    edges = np.linspace(380.0, 720.0, n + 1)
    w = np.array([resp[(lam >= edges[i]) & (lam < edges[i + 1])].sum(0) for i in range(n)])
    return delta(0.5 * (edges[:-1] + edges[1:]), amount, rgb_to_xyz), w / w.sum(0)


def chromatic_aberration(src, *, amount, cubic, center, n=32, filter_name="bicubic",
                         border="edge", pixel_aspect=1.0, rgb_to_xyz=None, **_):
    src = np.asarray(src, np.float64)
    h, w = src.shape[:2]
    cx, cy = w / 2 + center[0] * w / 2, h / 2 + center[1] * h / 2
    unit = 0.5 * math.hypot(w * pixel_aspect, h)
    xs, ys = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    dx, dy = xs - cx, ys - cy
    rd = np.hypot(dx * pixel_aspect, dy) / unit
    out = np.zeros_like(src)
    for d, wt in zip(*bins(n, amount, rgb_to_xyz)):
        ru = bisect(lambda r: r * (1 + d * ((1 - cubic) + cubic * r * r)), rd, 2 * rd.max() + 1)
        s = np.where(rd > 0, ru / np.where(rd > 0, rd, 1), 1 / (1 + d * (1 - cubic)))
        out += wt * sample(src, cx + dx * s, cy + dy * s, filter_name, border)
    return out
