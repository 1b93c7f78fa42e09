"""float64 NumPy oracles for clfx/plugins/dof.py.

``dof``: the plainest float64 form of the plugin's full-resolution gather (same taps, same
edge-aware radii, same near/far weights and hidden-background caps), for images small enough
that one neighbourhood radius covers them.
``dof_chromatic``: axial chromatic aberration, ``dof`` once per channel radius offset.
``cateye_centres``: the barrel circle's centre per pixel (optical vignetting; the front
rim's with a negative strength).
``naive_dof``: the classic post-process baseline the plugin must beat against ground truth:
every pixel averages the source over its own CoC disk (no near/far layering, no occlusion).
"""
import math

import numpy as np

NEAR_EPS = 0.25
EDGE_PX = 1.0
EDGE_TAU = 0.5
MIX_MIN = 0.02
MIX_TOL = 0.25
MIX_GAP = 2.0
CAP_FACTOR = 4.0
TILE = 32


def coc_radius(depth, *, k_half, focus, clamp_r, offset=0.0):
    """Signed CoC radius (px): K/2 (1 - S/z) + offset; +inf -> K/2 + offset; NaN, 0, < 0 ->
    offset (the focus plane); clamped."""
    z = np.asarray(depth, np.float64)
    r = np.zeros(z.shape)
    ok = z > 0
    r[ok] = k_half * (1.0 - focus / z[ok])
    return np.clip(r + offset, -clamp_r, clamp_r)


def cateye_centres(shape, strength, *, centre=None, aspect=1.0):
    """Barrel circle centre (aperture radii) of every pixel of an image of ``shape`` (its
    display window): strength * (pixel centre - image centre) / half diagonal, y over the
    pixel aspect (x pixels)."""
    h, w = shape
    cx, cy = centre if centre is not None else (0.5 * w, 0.5 * h)
    hd = 0.5 * math.hypot(w, h / aspect)
    ys, xs = np.mgrid[0:h, 0:w] + 0.5
    return strength * (xs - cx) / hd, strength * (ys - cy) / (aspect * hd)


def open_fraction(d):
    """Area of the unit disk inside a unit circle ``d`` away, over pi (at least 1e-3)."""
    d = np.minimum(np.asarray(d, np.float64), 2.0)
    return np.maximum((2 * np.arccos(d / 2) - d / 2 * np.sqrt(4 - d * d)) / math.pi, 1e-3)


def _clamped(img, ys, xs):
    h, w = img.shape[:2]
    return img[np.clip(ys, 0, h - 1), np.clip(xs, 0, w - 1)]


def _log_lum(src):
    lum = 0.2126 * src[..., 0] + 0.7152 * src[..., 1] + 0.0722 * src[..., 2]
    return np.log1p(np.maximum(lum, 0.0))


def edge_radius(src, r):
    """Edge-aware radii: a pixel whose 3 x 3 radii span >= 1 px, whose log luminance is more
    than 0.5 from the lower median of its own layer's neighbours (layers split at the mid-range
    radius; its own is its centre's), takes the radius of the other layer's neighbour closest
    in log luminance (first in row order on ties) when that one is sharper."""
    h, w = r.shape
    ys, xs = np.mgrid[0:h, 0:w]
    lg = _log_lum(src)
    offs = [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1)]
    R = np.stack([_clamped(r, ys + dy, xs + dx) for dy, dx in offs])
    L = np.stack([_clamped(lg, ys + dy, xs + dx) for dy, dx in offs])
    out = r.copy()
    for y, x in zip(*np.nonzero(R.max(0) - R.min(0) >= EDGE_PX)):
        rr, ll = R[:, y, x], L[:, y, x]
        mid = 0.5 * (rr.min() + rr.max())
        own_near = rr[4] < mid
        own = sorted(ll[j] for j in range(9) if j != 4 and (rr[j] < mid) == own_near)
        d_own = abs(ll[4] - own[(len(own) - 1) // 2]) if own else 0.0
        best, r_oth = math.inf, rr[4]
        for j in range(9):
            if j != 4 and (rr[j] < mid) != own_near and abs(ll[j] - ll[4]) < best:
                best, r_oth = abs(ll[j] - ll[4]), rr[j]
        if d_own > EDGE_TAU and abs(r_oth) < abs(rr[4]):
            out[y, x] = r_oth
    return out


def hidden_caps(src):
    """Per pixel, the cap of hidden-background colours: CAP_FACTOR x expm1 of the largest
    mean log luminance (every 4th pixel and row of a 32 px tile) over the 3 x 3 tiles around
    the pixel's tile."""
    h, w = src.shape[:2]
    lg = _log_lum(src)
    ty, tx = -(-h // TILE), -(-w // TILE)
    g = np.array([[lg[j * TILE:(j + 1) * TILE:4, i * TILE:(i + 1) * TILE:4].mean()
                   for i in range(tx)] for j in range(ty)])
    gp = np.pad(g, 1, mode="edge")
    gd = np.max([gp[1 + dy:1 + dy + ty, 1 + dx:1 + dx + tx]
                 for dy in (-1, 0, 1) for dx in (-1, 0, 1)], axis=0)
    cap = CAP_FACTOR * np.expm1(gd)
    return np.repeat(np.repeat(cap, TILE, 0), TILE, 1)[:h, :w]


def prefilter_pyramid(src, levels, pad=0):
    """Planes 0..``levels`` of the image extended by ``pad`` px each side (clamp-to-edge):
    the image, then plane L = plane L - 1 filtered with (1/4, 1/2, 1/4) at a spacing of
    2^(L - 1) px along x, then along y (clamp-to-edge): the binomial a-trous pyramid, whose
    plane L is the tent of half-width 2^L (plain loops over the offsets)."""
    src = np.asarray(src, np.float64)
    planes = [np.pad(src, ((pad, pad), (pad, pad)) + ((0, 0),) * (src.ndim - 2), mode="edge")]
    h, w = planes[0].shape[:2]
    ys, xs = np.mgrid[0:h, 0:w]
    for lv in range(1, levels + 1):
        s = 2 ** (lv - 1)
        p = planes[-1]
        p = sum(k * _clamped(p, ys, xs + o) for k, o in ((0.25, -s), (0.5, 0), (0.25, s)))
        p = sum(k * _clamped(p, ys + o, xs) for k, o in ((0.25, -s), (0.5, 0), (0.25, s)))
        planes.append(p)
    return planes


def mixed_pixels(src, r):
    """Mixed edge pixels (``dof_mixed``): per pixel whose 3 x 3 radii ``r`` (edge-aware:
    :func:`edge_radius`) have a gap (sorted) >= 1 px and >= MIX_GAP times the rest of
    their range, with its neighbours (clamp-to-edge) split into a near layer
    (radius below the mid-range) and a far one: over every pair (near n, far f), in row
    order of n then f, C = f + a (n - f) + e (RGBA); a pair explains C when
    MIX_MIN < a < 1 - MIX_MIN and |e| <= MIX_TOL min(|C - f|, |C - n|); the explaining pair
    with the largest |n - f| (strictly) wins.  Its parts, far C - a d and near
    C + (1 - a) d with d = n - f, estimate the layers' colours: a part below
    lo = min(0, C, n, f) in a channel is set to lo and the other takes up the difference
    (they mix back to C), i.e. d there is (C - lo) / a (far part at lo) or
    -(C - lo) / (1 - a) (near part at lo).  Returns (a, rn, rf, d); a = 0: not mixed."""
    h, w = r.shape
    a = np.zeros((h, w))
    rn = np.zeros((h, w))
    rf = np.zeros((h, w))
    d = np.zeros((h, w, 4))
    ys, xs = np.mgrid[0:h, 0:w]
    offs = [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1)]
    R = np.stack([_clamped(r, ys + dy, xs + dx) for dy, dx in offs])
    C = np.stack([_clamped(src, ys + dy, xs + dx) for dy, dx in offs])
    gap = np.diff(np.sort(R, axis=0), axis=0).max(axis=0)
    edge = (gap >= EDGE_PX) & (gap >= MIX_GAP * (R.max(0) - R.min(0) - gap))
    for y, x in zip(*np.nonzero(edge)):
        rr, cc = R[:, y, x], C[:, y, x]
        mid = 0.5 * (rr.min() + rr.max())
        best = 0.0
        for jn in range(9):
            if jn == 4 or not rr[jn] < mid:
                continue
            for jf in range(9):
                if jf == 4 or rr[jf] < mid:
                    continue
                dd, ef, en = cc[jn] - cc[jf], cc[4] - cc[jf], cc[4] - cc[jn]
                l2 = dd @ dd
                if not l2 > best:
                    continue
                t = (ef @ dd) / l2
                if not MIX_MIN < t < 1 - MIX_MIN:
                    continue
                e = ef - t * dd
                if e @ e > MIX_TOL ** 2 * min(ef @ ef, en @ en):
                    continue
                best, a[y, x], d[y, x], rn[y, x], rf[y, x] = l2, t, dd, rr[jn], rr[jf]
                lo = np.minimum(np.minimum(cc[jn], cc[jf]), np.minimum(cc[4], 0.0))
        if a[y, x] > 0:
            t, span = a[y, x], cc[4] - lo
            dd = np.where(cc[4] - t * d[y, x] < lo, span / t, d[y, x])
            d[y, x] = np.where(cc[4] + (1 - t) * d[y, x] < lo, -span / (1 - t), dd)
    return a, rn, rf, d


def padded_source(src, pad):
    """The image extended by ``pad`` px each side: the edge pixel repeated (clamp-to-edge),
    its colour scaled down to the luminance :func:`hidden_caps` of the edge pixel it
    repeats where brighter (what lies past the frame is a guess: a light on the edge row is
    not repeated into a streak)."""
    src = np.asarray(src, np.float64)
    h, w = src.shape[:2]
    out = np.pad(src, ((pad, pad), (pad, pad), (0, 0)), mode="edge")
    cap = np.pad(hidden_caps(src), pad, mode="edge")
    lum = 0.2126 * out[..., 0] + 0.7152 * out[..., 1] + 0.0722 * out[..., 2]
    k = np.where(lum > cap, cap / np.where(lum > cap, lum, 1.0), 1.0)
    outside = np.ones(out.shape[:2], bool)
    outside[pad:pad + h, pad:pad + w] = False
    return np.where(outside[..., None], out * k[..., None], out)


def dof(src, depth, *, k_half, focus, clamp_r, taps, offset=0.0, cateye=None,
        cateye_front=None, sharp_taps=None, sharp_radius=0.0):
    """Gather with near/far fields over ``taps`` ((n, 8) rows: ox, oy, d_near, d_far, area,
    aperture-space ox, oy, level L).  A tap of level L reads plane L of
    :func:`prefilter_pyramid` of :func:`padded_source` (colour and luminance) and every
    coverage ramp below is ``s = 2^L`` px wide: ``clamp((a - b) / s + 0.5, 0, 1)`` for
    ``clamp(a - b + 0.5, 0, 1)``.  ``offset``: added to every signed radius (axial CA).
    ``sharp_taps``: the table of pixels in focus or nearly (the plugin's per-tile sharp
    table; a far distance or a near distance of 1e30 never covers), used by the pixels of a
    group of 4 (x // 4 of a row) whose every radius lies in [-0.25, ``sharp_radius``), and
    with a sparse ``taps`` (any L > 0) by every such pixel of a group whose others are not.
    ``cateye``: (cx, cy) per pixel (:func:`cateye_centres`): every coverage below is also
    clipped by the barrel, near taps by clamp(|r_q| - |a - c |r_q|| + 0.5, 0, 1), far ones by
    clamp(rf - |a + c rf| + 0.5, 0, 1) (a: the tap's aperture-space offset), and the near
    weights divide by pi r_q^2 * :func:`open_fraction` (|c|) instead of pi r_q^2.
    ``cateye_front``: the front rim's centres (:func:`cateye_centres` of minus its strength),
    clipping every coverage the same way (alone, or with ``cateye``: the minimum of both
    circles' coverages, the open fraction that of the two circles |c - c_front| apart).

    Per pixel p and tap q = p + o (clamp-to-edge), radii r (signed, px, :func:`edge_radius`):
    near taps (r_q < -0.25): w = clamp(|r_q| - d_near + 0.5, 0, 1) / max(pi r_q^2, 1),
    alpha += w * area; far taps: rf = max(|r_q|, |r_p|) if p is near, else min(|r_q|, max(r_p, 0))
    if q is behind p (r_q > r_p), else |r_q|; w = clamp(rf - d_far + 0.5, 0, 1) / max(pi rf^2, 1),
    where for a near p the part of w beyond q's own coverage clamp(|r_q| - d_far + 0.5, 0, 1)
    takes q's colour capped at :func:`hidden_caps` in luminance.
    out = far (1 - a) + near a, a = clamp(alpha, 0, 1), each field normalised; empty fields
    fall back to the other field, then to the centre pixel.

    Mixed edge pixels (:func:`mixed_pixels` of the depth's radii; level-0 taps only): a
    mixed tap q (coverage a_q, radii rn_q, rf_q, d_q) is two taps, its far part
    C_q - a_q d_q of radius rf_q weighing 1 - a_q and its near part C_q + (1 - a_q) d_q of
    radius rn_q weighing a_q (every weight above times its part's weight).  With a dense
    table (every tap L = 0) a group of 4 holding a mixed pixel is gathered twice, as its far
    part (r_p = rf_p, centre C_p - a_p d_p, its own centre tap only its far part with weight
    1) and as its near part (likewise): (1 - a_p) far + a_p near; with the sharp table when
    it is dense and both radii of every mixed pixel of the group lie in the sharp range.
    """
    src = np.asarray(src, np.float64)
    src = np.where(np.isfinite(src), src, 0.0)
    r = edge_radius(src, coc_radius(depth, k_half=k_half, focus=focus, clamp_r=clamp_r,
                                    offset=offset))
    taps = np.asarray(taps, np.float64)
    tables = [taps] + ([np.asarray(sharp_taps, np.float64)] if sharp_taps is not None else [])
    every = np.concatenate(tables)
    # the pyramid of the image extended past every tap (the kernel's padded buffer): a tap
    # outside reads the prefiltered extension, not the prefiltered image's edge
    pad = int(np.abs(every[:, :2]).max()) + 1 if len(every) else 0
    level = int(every[:, 7].max()) if len(every) else 0
    planes = prefilter_pyramid(padded_source(src, pad), level, 0)
    cap = hidden_caps(src)
    h, w = r.shape
    ys, xs = np.mgrid[0:h, 0:w]
    mix_a, mix_rn, mix_rf, mix_d = mixed_pixels(src, r)
    circles = [tuple(np.asarray(v, np.float64) for v in c)
               for c in (cateye, cateye_front) if c is not None]
    if circles:
        (cx, cy), (fx, fy) = circles[0], circles[-1] if len(circles) > 1 else (0.0, 0.0)
        frac = open_fraction(np.hypot(cx - fx, cy - fy))

    def gather(r0, c0, layer, taps):
        """Both fields of every pixel with radii ``r0`` (centre colours ``c0``) over
        ``taps``; ``layer`` 1 (2): a mixed pixel's own centre tap is only its far (near)
        part."""
        p_near = r0 < -NEAR_EPS
        fn = np.zeros(src.shape)
        ff = np.zeros(src.shape)
        wn_sum = np.zeros((h, w))
        wf_sum = np.zeros((h, w))
        alpha = np.zeros((h, w))
        for ox, oy, d_near, d_far, area, ax, ay, lv in taps:
            inv_s = 2.0 ** -lv

            def ramp(v):   # the coverage ramp of this tap's lattice
                return np.clip(v * inv_s + 0.5, 0, 1)

            def barrel(rad, sign):   # coverage of the clipping circles for radius rad
                return np.minimum.reduce([ramp(rad - np.hypot(ax + sign * ux * rad,
                                                              ay + sign * uy * rad))
                                          for ux, uy in circles])

            c = _clamped(planes[int(lv)], ys + int(oy) + pad, xs + int(ox) + pad)
            rq = _clamped(r, ys + int(oy), xs + int(ox))
            aq = _clamped(mix_a, ys + int(oy), xs + int(ox)) * (lv == 0)
            dq = _clamped(mix_d, ys + int(oy), xs + int(ox))
            sq = aq > 0
            an = aq
            if layer and ox == 0 and oy == 0:
                an = np.where(sq, 1.0 if layer == 2 else 0.0, aq)
            parts = ((c - dq * aq[..., None],
                      np.where(sq, _clamped(mix_rf, ys + int(oy), xs + int(ox)), rq), 1 - an),
                     (c + dq * (1 - aq)[..., None],
                      np.where(sq, _clamped(mix_rn, ys + int(oy), xs + int(ox)), rq), an))
            for cp, rp, fp in parts:
                arq = np.abs(rp)
                q_near = rp < -NEAR_EPS
                rf = np.where(p_near, np.maximum(arq, np.abs(r0)),
                              np.where(rp > r0, np.minimum(arq, np.maximum(r0, 0)), arq))
                cov_n = ramp(arq - d_near)
                cov_f = ramp(rf - d_far)
                cov_q = ramp(arq - d_far)
                area_n = math.pi * arq ** 2
                if circles:
                    cov_n = np.minimum(cov_n, barrel(arq, -1))
                    cov_f = np.minimum(cov_f, barrel(rf, +1))
                    cov_q = np.minimum(cov_q, barrel(arq, +1))
                    area_n = area_n * frac
                wn = np.where(q_near, cov_n / np.maximum(area_n, 1), 0) * fp
                norm = np.where(q_near, 0, 1 / np.maximum(math.pi * rf ** 2, 1)) * fp
                wf = cov_f * norm
                fill = np.where(p_near, cov_f - np.minimum(cov_q, cov_f), 0) * norm
                lq = 0.2126 * cp[..., 0] + 0.7152 * cp[..., 1] + 0.0722 * cp[..., 2]
                k = np.minimum(1.0, cap / np.maximum(lq, 1e-30))   # p's cap, the part's lum
                fn += cp * wn[..., None]
                ff += cp * (wf - fill + fill * k)[..., None]
                wn_sum += wn
                wf_sum += wf
                alpha += wn * area
        tiny = 1e-20
        near = np.where((wn_sum > tiny)[..., None], fn / np.maximum(wn_sum, tiny)[..., None],
                        c0)
        far = np.where((wf_sum > tiny)[..., None], ff / np.maximum(wf_sum, tiny)[..., None],
                       near)
        a = np.where(wf_sum > tiny, np.clip(alpha, 0, 1), 1.0)[..., None]
        return far * (1 - a) + near * a

    split = mix_a > 0
    am = mix_a[..., None]

    def once(taps):
        return gather(r, src, 0, taps)

    def twice(taps):
        out_f = gather(np.where(split, mix_rf, r), src - mix_d * am, 1, taps)
        out_n = gather(np.where(split, mix_rn, r), src + mix_d * (1 - am), 2, taps)
        return np.where(split[..., None], out_f * (1 - am) + out_n * am, out_f)

    def groups(mask, how):   # per pixel, ``how`` (np.any / np.all) over its group of 4
        g = np.pad(mask, ((0, 0), (0, -w % 4)), mode="edge").reshape(h, -1, 4)
        return np.repeat(how(g, axis=2), 4, axis=1)[:, :w]

    def dense(t):
        return not len(t) or t[:, 7].max() == 0

    g_split = groups(split, np.any)
    if sharp_taps is None:
        return twice(taps) if g_split.any() and dense(taps) else once(taps)
    near_eps = NEAR_EPS
    rn_, rf_ = np.where(split, mix_rn, r), np.where(split, mix_rf, r)
    both = groups((np.minimum(rn_, rf_) >= -near_eps) & (np.maximum(rn_, rf_) < sharp_radius),
                  np.all)
    own_px = (r >= -near_eps) & (r < sharp_radius)
    own = groups(own_px, np.all)
    sharp = tables[1]
    cases = [(g_split & both & dense(sharp), lambda: twice(sharp)),
             (g_split & dense(taps), lambda: twice(taps)),
             (own, lambda: once(sharp)),
             (own_px & (not dense(taps)), lambda: once(sharp)),
             (np.ones((h, w), bool), lambda: once(taps))]
    out = np.zeros(src.shape)
    left = np.ones((h, w), bool)
    for sel, make in cases:
        sel = sel & left
        if sel.any():
            out = np.where(sel[..., None], make(), out)
        left &= ~sel
    return out


def dof_chromatic(src, depth, *, offsets, **kw):
    """Axial chromatic aberration: red, green and blue each from :func:`dof` with its own
    radius offset (``offsets`` = (red, blue) px; green's is 0), alpha from green's."""
    out = dof(src, depth, **kw)
    for ch, off in zip((0, 2), offsets):
        out[..., ch] = dof(src, depth, offset=off, **kw)[..., ch]
    return out


def naive_dof(src, depth, *, k_half, focus, clamp_r):
    """Per-pixel-CoC gather without layering: the mean of the source over the disk of the
    pixel's own CoC radius (pixel centres within r + 0.5; clamp-to-edge)."""
    src = np.asarray(src, np.float64)
    src = np.where(np.isfinite(src), src, 0.0)
    ar = np.abs(coc_radius(depth, k_half=k_half, focus=focus, clamp_r=clamp_r))
    h, w = ar.shape
    ys, xs = np.mgrid[0:h, 0:w]
    rmax = int(math.ceil(ar.max())) if ar.size else 0
    acc = np.zeros(src.shape)
    cnt = np.zeros((h, w))
    for oy in range(-rmax, rmax + 1):
        for ox in range(-rmax, rmax + 1):
            inside = math.hypot(ox, oy) <= ar + 0.5
            if not inside.any():
                continue
            acc += np.where(inside[..., None], _clamped(src, ys + oy, xs + ox), 0)
            cnt += inside
    return acc / cnt[..., None]
