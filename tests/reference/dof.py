"""float64 NumPy oracles for clfx/plugins/dof.py.

``dof``: the plainest float64 form of the plugin's full-resolution gather (same taps, same
near/far weights), for images small enough that one neighbourhood radius covers them.
``naive_dof``: the classic post-process baseline the plugin must beat against ground truth:
every pixel averages the source over its own CoC disk (no near/far layering, no occlusion).
"""
import math

import numpy as np

NEAR_EPS = 0.25


def coc_radius(depth, *, k_half, focus, clamp_r):
    """Signed CoC radius (px): K/2 (1 - S/z); +inf -> K/2; NaN, 0, < 0 -> 0; clamped."""
    z = np.asarray(depth, np.float64)
    r = np.zeros(z.shape)
    ok = z > 0
    r[ok] = k_half * (1.0 - focus / z[ok])
    return np.clip(r, -clamp_r, clamp_r)


def _clamped(img, ys, xs):
    h, w = img.shape[:2]
    return img[np.clip(ys, 0, h - 1), np.clip(xs, 0, w - 1)]


def dof(src, depth, *, k_half, focus, clamp_r, taps):
    """Gather with near/far fields over ``taps`` ((n, 8) rows: ox, oy, d_near, d_far, area).

    Per pixel p and tap q = p + o (clamp-to-edge), radii r (signed, px):
    near taps (r_q < -0.25): w = clamp(|r_q| - d_near + 0.5, 0, 1) / max(pi r_q^2, 1),
    alpha += w * area; far taps: rf = max(|r_q|, |r_p|) if p is near, else min(|r_q|, max(r_p, 0))
    if q is behind p (r_q > r_p), else |r_q|; w = clamp(rf - d_far + 0.5, 0, 1) / max(pi rf^2, 1).
    out = far + clamp(alpha, 0, 1) (near - far), each field normalised; empty fields fall
    back to the other field, then to the centre pixel.
    """
    src = np.asarray(src, np.float64)
    src = np.where(np.isfinite(src), src, 0.0)
    r = coc_radius(depth, k_half=k_half, focus=focus, clamp_r=clamp_r)
    h, w = r.shape
    ys, xs = np.mgrid[0:h, 0:w]
    p_near = r < -NEAR_EPS
    fn = np.zeros(src.shape)
    ff = np.zeros(src.shape)
    wn_sum = np.zeros((h, w))
    wf_sum = np.zeros((h, w))
    alpha = np.zeros((h, w))
    for ox, oy, d_near, d_far, area in np.asarray(taps, np.float64)[:, :5]:
        c = _clamped(src, ys + int(oy), xs + int(ox))
        rq = _clamped(r, ys + int(oy), xs + int(ox))
        arq = np.abs(rq)
        q_near = rq < -NEAR_EPS
        wn = np.where(q_near, np.clip(arq - d_near + 0.5, 0, 1) / np.maximum(math.pi * arq ** 2, 1), 0)
        rf = np.where(p_near, np.maximum(arq, np.abs(r)),
                      np.where(rq > r, np.minimum(arq, np.maximum(r, 0)), arq))
        wf = np.where(q_near, 0, np.clip(rf - d_far + 0.5, 0, 1) / np.maximum(math.pi * rf ** 2, 1))
        fn += c * wn[..., None]
        ff += c * wf[..., None]
        wn_sum += wn
        wf_sum += wf
        alpha += wn * area
    tiny = 1e-20
    near = np.where((wn_sum > tiny)[..., None], fn / np.maximum(wn_sum, tiny)[..., None], src)
    far = np.where((wf_sum > tiny)[..., None], ff / np.maximum(wf_sum, tiny)[..., None], near)
    a = np.where(wf_sum > tiny, np.clip(alpha, 0, 1), 1.0)[..., None]
    return far + (near - far) * a


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
