"""float64 NumPy oracle of clfx/plugins/distortion.py (and the resampler shared with
chromatic_aberration and lens): the plainest forms, no shortcuts.

- The inverse map: plain bisection of the radial map on [0, fold) (80 halvings), then, only
  when tangential terms are present, Newton with a finite-difference Jacobian.
- Resampling: direct separable sums of the same filters (bilinear, Keys a=-0.5 bicubic,
  normalised Lanczos-3 with exact sines), texels read through the border rule, non-finite
  texels read as 0, outputs clamped to the min/max of their nearest 2x2 texels.
- Footprints (distortion's levels): the map's Jacobian by central differences of the forward
  model, the per-axis spread h and the sub-footprint count n derived from the box the output
  pixel's preimage covers (:func:`spread`, with each filter's constants stated in
  ``FOOTPRINT_CONSTANTS``), then each tap's weight by its definition (no vector tricks) and
  the clamp to the texels within 1 + h of the point (the quadratic: its 3x3 window); the
  reference's elliptical footprint through an SVD of the Jacobian and n x n Lanczos-3
  samples.
"""
import math

import numpy as np

FOOTPRINT_CONSTANTS = {
    "quadratic": (1.3, 0.75),
    "bicubic": (1.0, 1.0 / 3.0),
    "lanczos3": (1.0, 0.25),
}
"""Each footprint filter's (kappa, cap), the design's per-filter constants: kappa scales the
variance the footprint adds (the draft's 3-tap quadratic attenuates high frequencies less
than the box it stands for, so it takes 1.3 times the box's), cap is the most added
variance (texels^2) one window of the filter holds (3 taps: 0.75, Keys' 4: 1/3, the 8-tap
Lanczos pair: 0.25, h <= 1/2: two samples 2h apart stand for a box at most 2 texels wide).
The oracle states them; tests/test_oracles.py checks that the host's table
(clfx.fx.resample.FOOTPRINTS) says the same."""


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


def sample_range(src, sx, sy, filter_name="bilinear", border="black"):
    """Filtered RGBA of ``src`` (h, w, 4) at continuous points (centres at +0.5) before the
    anti-ringing clamp, and the clamp's bounds: the min/max of the nearest 2x2 texels (+-inf
    for bilinear)."""
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
    lo, hi = np.full(out.shape, -np.inf), np.full(out.shape, np.inf)
    if filter_name != "bilinear":
        quad = [texels(src, ix + a, iy + b, border) for a in (0, 1) for b in (0, 1)]
        lo, hi = np.minimum.reduce(quad), np.maximum.reduce(quad)
    out[bad], lo[bad], hi[bad] = 0.0, 0.0, 0.0
    return out, lo, hi


def sample(src, sx, sy, filter_name="bilinear", border="black"):
    """Filtered RGBA of ``src`` (h, w, 4) at continuous points (centres at +0.5)."""
    out, lo, hi = sample_range(src, sx, sy, filter_name, border)
    return np.clip(out, lo, hi)


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


def map_jacobian(sx, sy, *, k1=0.0, k2=0.0, k3=0.0, p1=0.0, p2=0.0, fx, fy, cx, cy,
                 fit_scale=1.0):
    """d(source point) / d(output pixel) (..., 2, 2): the inverse of the forward model's
    Jacobian, taken by central differences of :func:`project` at the source points."""
    x, y = (sx - cx) / fx, (sy - cy) / fy
    e = 1e-6
    ax, ay = project(x + e, y, k1, k2, k3, p1, p2)
    bx, by = project(x - e, y, k1, k2, k3, p1, p2)
    cxp, cyp = project(x, y + e, k1, k2, k3, p1, p2)
    dxp, dyp = project(x, y - e, k1, k2, k3, p1, p2)
    # output pixels per source pixel: diag(fx, fy) Jp diag(1/fx, 1/fy) / fit_scale
    fwd = np.empty(sx.shape + (2, 2))
    fwd[..., 0, 0] = (ax - bx) / (2 * e)
    fwd[..., 0, 1] = (cxp - dxp) / (2 * e) * fx / fy
    fwd[..., 1, 0] = (ay - by) / (2 * e) * fy / fx
    fwd[..., 1, 1] = (cyp - dyp) / (2 * e)
    fwd /= fit_scale
    ok = np.isfinite(fwd).all(axis=(-2, -1))
    return np.where(ok[..., None, None], np.linalg.inv(np.where(ok[..., None, None], fwd, np.eye(2))),
                    np.nan)


def keys(x):
    x = np.abs(x)
    return np.where(x <= 1, 1.5 * x**3 - 2.5 * x**2 + 1,
                    np.where(x < 2, -0.5 * x**3 + 2.5 * x**2 - 4 * x + 2, 0.0))


def bspline3(x):
    x = np.abs(x)
    return np.where(x < 1, 2 / 3 - x**2 + x**3 / 2, np.where(x < 2, (2 - x)**3 / 6, 0.0))


def lanczos3(x):
    x = np.asarray(x, np.float64)
    safe = np.where(np.abs(x) < 1e-12, 1.0, x)
    return np.where(np.abs(x) < 1e-12, 1.0,
                    np.where(np.abs(x) < 3, 3 * np.sin(np.pi * safe) * np.sin(np.pi * safe / 3)
                             / (np.pi * safe) ** 2, 0.0))


def spread(jac, name):
    """(hx, hy, n): the per-axis spread of footprint filter ``name`` and the sub-footprint
    count, from the box an output pixel's preimage covers.

    The output pixel (a unit square) maps to the parallelogram of sides J e_x and J e_y;
    along the source's x axis it spans the box width W_x with W_x^2 = J11^2 + J12^2 (y:
    J21, J22).  A box of width W has variance W^2 / 12, a texel's own 1 / 12, so reading
    through the footprint adds kappa (W^2 - 1) / 12 where W > 1 (nothing where the map
    magnifies).  One window holds at most ``cap`` of it: a wider pixel is cut into n x n
    equal parts (each J / n, width W / n), n the least whole number with
    kappa ((W / n)^2 - 1) / 12 <= cap on both axes, i.e. n >= W / sqrt(1 + 12 cap / kappa).
    The spread of each part, h = sqrt(kappa max((W / n)^2 - 1, 0) / 12), is stored by the
    kernels' maps as float16 (the nearest half-precision value).  A Jacobian entry that is
    not finite widens nothing (read as 0)."""
    kappa, cap = FOOTPRINT_CONSTANTS[name]
    j = np.where(np.isfinite(jac), jac, 0.0)
    widths = np.sqrt(np.stack([j[..., 0, 0] ** 2 + j[..., 0, 1] ** 2,
                               j[..., 1, 0] ** 2 + j[..., 1, 1] ** 2]))   # W_x, W_y
    widest_part = math.sqrt(1.0 + 12.0 * cap / kappa)       # the widest W / n one window takes
    n = np.maximum(np.ceil(widths.max(axis=0) / widest_part), 1.0)
    added = kappa * np.maximum((widths / n) ** 2 - 1.0, 0.0) / 12.0
    h = np.sqrt(added).astype(np.float16).astype(np.float64)
    return h[0], h[1], n.astype(np.int64)


def footprint_taps(p, h, name, half=None):
    """First tap (texel index) and the weights (..., taps) of a footprint filter along one
    axis at continuous coordinate p (texel centres at +0.5) with spread h.  ``half`` (bool,
    like p): where the quadratic's offset d is read as float16 (its packed map stores d so:
    the fast path), rounded as the host rounds it (float32, then float16)."""
    u = p - 0.5                       # texel k sits at u = k
    if name == "quadratic":           # nearest texel m and its two neighbours
        m = np.floor(p)
        d = p - (m + 0.5)
        if half is not None:
            d = np.where(half, d.astype(np.float32).astype(np.float16), d)
        q = h * h + d * d
        return m.astype(np.int64) - 1, np.stack([(q - d) / 2, 1 - q, (q + d) / 2], -1)
    if name == "bicubic":             # Keys blended with the cubic B-spline, alpha = 3 h^2
        i = np.floor(u)
        t = (u - i)[..., None] - np.arange(-1, 3)
        a = np.minimum(3 * h * h, 1.0)[..., None]
        return i.astype(np.int64) - 1, (1 - a) * keys(t) + a * bspline3(t)
    # lanczos3: the mean of two normalised Lanczos-3 samples at u - h and u + h
    i = np.floor(u - h)
    taps = i[..., None] + np.arange(-2, 6)

    def one(c):
        f = np.floor(c)[..., None]
        w = np.where((taps >= f - 2) & (taps <= f + 3), lanczos3(taps - c[..., None]), 0.0)
        return w / w.sum(-1, keepdims=True)

    return i.astype(np.int64) - 2, 0.5 * (one(u - h) + one(u + h))


def _footprint_one(src, px, py, hx, hy, name, border, half=None):
    x0, wx = footprint_taps(px, hx, name, half)
    y0, wy = footprint_taps(py, hy, name, half)
    taps = wx.shape[-1]
    # clamp: texels within 1 + h of the point (the union of the 2x2 footprints at u +- h);
    # the quadratic: its whole window
    cx0, cx1 = np.floor(px - 0.5 - hx), np.ceil(px - 0.5 + hx)
    cy0, cy1 = np.floor(py - 0.5 - hy), np.ceil(py - 0.5 + hy)
    if name == "quadratic":
        cx0, cx1, cy0, cy1 = x0, x0 + 2, y0, y0 + 2
    acc = np.zeros(px.shape + (src.shape[2],))
    lo = np.full(acc.shape, np.inf)
    hi = np.full(acc.shape, -np.inf)
    for j in range(taps):
        for i in range(taps):
            tx, ty = x0 + i, y0 + j
            t = texels(src, tx, ty, border)
            acc += (wx[..., i] * wy[..., j])[..., None] * t
            inside = ((tx >= cx0) & (tx <= cx1) & (ty >= cy0) & (ty <= cy1))[..., None]
            lo = np.where(inside, np.minimum(lo, t), lo)
            hi = np.where(inside, np.maximum(hi, t), hi)
    return np.clip(acc, lo, hi)


def sample_footprint(src, sx, sy, jac, name="lanczos3", border="black", half=None):
    """Footprint filter ``name`` at continuous points with Jacobians ``jac`` (..., 2, 2):
    the mean of n x n sub-footprints (centres s + J ((a + 1/2) / n - 1/2, (b + 1/2) / n - 1/2),
    Jacobian J / n), each filtered with its spread and clamped.  ``half``: the pixels whose
    quadratic offsets are float16 (``footprint_taps``)."""
    src = np.asarray(src, np.float64)
    bad = ~(np.isfinite(sx) & np.isfinite(sy))
    jac = np.where(bad[..., None, None], np.eye(2), jac)
    hx, hy, n = spread(jac, name)
    out = np.zeros(sx.shape + (src.shape[2],))
    for nn in np.unique(n[~bad]):
        sel = (n == nn) & ~bad
        acc = 0.0
        offs = (np.arange(nn) + 0.5) / nn - 0.5
        for oa in offs:
            for ob in offs:
                px = sx[sel] + jac[sel][:, 0, 0] * oa + jac[sel][:, 0, 1] * ob
                py = sy[sel] + jac[sel][:, 1, 0] * oa + jac[sel][:, 1, 1] * ob
                acc = acc + _footprint_one(src, px, py, hx[sel], hy[sel], name, border,
                                           None if half is None else half[sel])
        out[sel] = acc / nn ** 2
    return out


def elliptical_spread(jac):
    """(Jc, n): the footprint's extra extent J_c = U sqrt(max(S^2 - 1, 0)) V^T (the part of
    the output pixel's preimage wider than a texel, along its principal axes) and the
    samples per axis: 1 where nothing is minified, else max(2, ceil(sqrt(1 + |c|^2))) for
    the longer column c of J_c (neighbouring samples at most 1 texel apart)."""
    u, s, vt = np.linalg.svd(jac)
    e = np.sqrt(np.maximum(s ** 2 - 1.0, 0.0))
    jc = (u * e[..., None, :]) @ vt
    c2 = np.maximum((jc[..., :, 0] ** 2).sum(-1), (jc[..., :, 1] ** 2).sum(-1))
    n = np.where(e.max(-1) > 0, np.maximum(2, np.ceil(np.sqrt(1.0 + c2))), 1).astype(np.int64)
    return jc, n


def sample_elliptical(src, sx, sy, jac, border="black"):
    """The reference footprint: the mean of n x n Lanczos-3 samples at s + J_c (a_i, a_j),
    a_i = ((i + 1/2) / n - 1/2) sqrt(n^2 / (n^2 - 1)) (the samples' spread has exactly the
    covariance J_c J_c^T / 12 of a box over J_c), clamped to the min/max of all the samples'
    nearest 2x2 texels."""
    bad = ~(np.isfinite(sx) & np.isfinite(sy))
    jac = np.where(bad[..., None, None], np.eye(2), jac)
    jc, n = elliptical_spread(jac)
    src = np.asarray(src, np.float64)
    out = np.zeros(sx.shape + (src.shape[2],))
    for nn in np.unique(n[~bad]):
        sel = (n == nn) & ~bad
        offs = ((np.arange(nn) + 0.5) / nn - 0.5) * (math.sqrt(nn * nn / (nn * nn - 1.0))
                                                     if nn > 1 else 0.0)
        acc, lo, hi = 0.0, np.inf, -np.inf
        for oa in offs:
            for ob in offs:
                px = sx[sel] + jc[sel][:, 0, 0] * oa + jc[sel][:, 0, 1] * ob
                py = sy[sel] + jc[sel][:, 1, 0] * oa + jc[sel][:, 1, 1] * ob
                one, l, u = sample_range(src, px, py, "lanczos3", border)
                acc, lo, hi = acc + one, np.minimum(lo, l), np.maximum(hi, u)
        out[sel] = np.clip(acc / nn ** 2, lo, hi)
    return out


def distortion(src, *, filter_name="lanczos3", border="black", footprint=None, half=None,
               **map_args):
    """Distort ``src``: point sampling with ``filter_name``, or the footprint filter
    ``footprint`` ("quadratic", "bicubic", "lanczos3" or "elliptical"; ``half``: see
    ``sample_footprint``)."""
    src = np.asarray(src, np.float64)
    h, w = src.shape[:2]
    sx, sy = distortion_map(w, h, **map_args)
    if footprint is None:
        return sample(src, sx, sy, filter_name, border)
    jac = map_jacobian(sx, sy, **map_args)
    if footprint == "elliptical":
        return sample_elliptical(src, sx, sy, jac, border)
    return sample_footprint(src, sx, sy, jac, footprint, border, half)
