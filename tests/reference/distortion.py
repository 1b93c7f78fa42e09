"""float64 NumPy oracle of clfx/plugins/distortion.py (and the resampler shared with
chromatic_aberration and lens): the plainest forms, no shortcuts.

- The inverse map: plain bisection of the radial map on [0, fold) (80 halvings), then, only
  when tangential terms are present, Newton with a finite-difference Jacobian.
- Resampling: direct separable sums of the same filters (bilinear, Keys a=-0.5 bicubic,
  normalised Lanczos-3 with exact sines), texels read through the border rule, non-finite
  texels read as 0, outputs clamped to the min/max of their nearest 2x2 texels.
"""
import math

import numpy as np


def mirror_index(i, n):
    if n <= 1:
        return np.zeros_like(i)
    period = 2 * (n - 1)
    m = np.mod(i, period)
    return np.where(m < n, m, period - m)


def texels(src, ix, iy, border):
    h, w = src.shape[:2]
    if border == "black":
        ok = (ix >= 0) & (iy >= 0) & (ix < w) & (iy < h)
        v = src[np.clip(iy, 0, h - 1), np.clip(ix, 0, w - 1)]
        v = np.where(ok[..., None], v, 0.0)
    elif border == "edge":
        v = src[np.clip(iy, 0, h - 1), np.clip(ix, 0, w - 1)]
    else:
        v = src[mirror_index(iy, h), mirror_index(ix, w)]
    return np.where(np.isfinite(v), v, 0.0)


def weights(t, filter_name):
    """(offsets, weights[..., taps]) for fractional positions t."""
    if filter_name == "bilinear":
        return np.array([0, 1]), np.stack([1 - t, t], -1)
    if filter_name == "bicubic":
        a = -0.5
        def k(x):
            x = np.abs(x)
            return np.where(x <= 1, (a + 2) * x**3 - (a + 3) * x**2 + 1,
                            np.where(x < 2, a * x**3 - 5 * a * x**2 + 8 * a * x - 4 * a, 0.0))
        offs = np.array([-1, 0, 1, 2])
        return offs, np.stack([k(t - o) for o in offs], -1)
    offs = np.arange(-2, 4)
    def lanczos(x):
        return np.where(np.abs(x) < 1e-12, 1.0, 3 * np.sin(np.pi * x) * np.sin(np.pi * x / 3)
                        / (np.pi ** 2 * np.where(np.abs(x) < 1e-12, 1.0, x) ** 2))
    wts = np.stack([lanczos(t - o) for o in offs], -1)
    return offs, wts / wts.sum(-1, keepdims=True)


def sample(src, sx, sy, filter_name="bilinear", border="black"):
    """Filtered RGBA of ``src`` (h, w, 4) at continuous points (centres at +0.5)."""
    src = np.asarray(src, np.float64)
    bad = ~(np.isfinite(sx) & np.isfinite(sy))
    sx = np.where(bad, 0.0, sx)
    sy = np.where(bad, 0.0, sy)
    fx, fy = sx - 0.5, sy - 0.5
    ix, iy = np.floor(fx).astype(np.int64), np.floor(fy).astype(np.int64)
    offs, wx = weights(fx - ix, filter_name)
    _, wy = weights(fy - iy, filter_name)
    out = np.zeros(sx.shape + (src.shape[2],))
    for j, oj in enumerate(offs):
        for i, oi in enumerate(offs):
            out += (wx[..., i] * wy[..., j])[..., None] * texels(src, ix + oi, iy + oj, border)
    if filter_name != "bilinear":
        quad = [texels(src, ix + a, iy + b, border) for a in (0, 1) for b in (0, 1)]
        out = np.clip(out, np.minimum.reduce(quad), np.maximum.reduce(quad))
    out[bad] = 0.0
    return out


def project(x, y, k1, k2, k3, p1, p2):
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3
    return (x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
            y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)


def bisect(f, target, hi, n=80):
    lo = np.zeros_like(target)
    hi = np.full_like(target, hi)
    for _ in range(n):
        mid = (lo + hi) / 2
        below = f(mid) < target
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    return (lo + hi) / 2


def undistort(xd, yd, k1, k2, k3, p1, p2, r_hi):
    """Radial bisection on [0, r_hi], then finite-difference Newton for tangential terms."""
    rd = np.hypot(xd, yd)
    f = lambda r: r * (1 + k1 * r**2 + k2 * r**4 + k3 * r**6)
    ru = bisect(f, rd, r_hi)
    ru = np.where(rd <= f(r_hi), ru, np.nan)
    s = np.where(rd > 0, ru / np.where(rd > 0, rd, 1), 1.0)
    x, y = xd * s, yd * s
    if p1 or p2:
        h = 1e-7
        for _ in range(20):
            ex, ey = project(x, y, k1, k2, k3, p1, p2)
            ex, ey = ex - xd, ey - yd
            ax, ay = project(x + h, y, k1, k2, k3, p1, p2)
            bx, by = project(x, y + h, k1, k2, k3, p1, p2)
            j11, j21 = (ax - ex - xd) / h, (ay - ey - yd) / h
            j12, j22 = (bx - ex - xd) / h, (by - ey - yd) / h
            det = j11 * j22 - j12 * j21
            x, y = x - (j22 * ex - j12 * ey) / det, y - (j11 * ey - j21 * ex) / det
    return x, y


def fold_radius(k1, k2, k3, r_max):
    r = np.linspace(0, r_max, 200001)
    d = 1 + 3 * k1 * r**2 + 5 * k2 * r**4 + 7 * k3 * r**6
    bad = np.nonzero(d <= 0)[0]
    return r[bad[0]] if bad.size else math.inf


def distortion_map(width, height, *, k1=0.0, k2=0.0, k3=0.0, p1=0.0, p2=0.0, fx, fy, cx, cy,
                   fit_scale=1.0):
    """Source points (pixel coordinates, centres at +0.5) of each output pixel."""
    xs, ys = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    xd, yd = (xs - cx) / fx * fit_scale, (ys - cy) / fy * fit_scale
    r_need = float(np.hypot(xd, yd).max())
    r_fold = fold_radius(k1, k2, k3, 4 * max(r_need, 1e-3))
    r_hi = r_fold if math.isfinite(r_fold) else 4 * max(r_need, 1e-3) + 1
    x, y = undistort(xd, yd, k1, k2, k3, p1, p2, r_hi)
    return x * fx + cx, y * fy + cy


def distortion(src, *, filter_name="lanczos3", border="black", **map_args):
    src = np.asarray(src, np.float64)
    h, w = src.shape[:2]
    sx, sy = distortion_map(w, h, **map_args)
    return sample(src, sx, sy, filter_name, border)
