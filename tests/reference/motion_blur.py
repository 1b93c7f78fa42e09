"""float64 NumPy oracles of clfx/plugins/motion_blur.py (camera_blur has its own:
tests/reference/camera_blur.py).

Every function averages the source, read bilinearly with clamp-to-edge at continuous
positions (pixel centres at +0.5), over ``n`` instants of the open shutter ``[t0, t1]``
(midpoint rule).  With ``n`` large this is the exact time integral of the bilinear image.

- ``line_blur``: one constant velocity (the exact box line blur; camera pan); ``interp =
  "cubic"`` reads through the clamped Catmull-Rom the gather uses on short blurs (``beta``:
  its blend with the tent, as ``mb_beta``).
- ``short_smear``: the closed form of a sub-pixel smear along one velocity (``mb_short_smear``),
  ``step_smear``: the step model of flat patches with hard edges (``mb_step_smear`` along the
  pixel axes) and its weight, and ``short_blur``: what the gather makes of one velocity under
  1.5 px of smear through a centred shutter, the closed form blended with the cubic line blur
  by the smear's length, the step model over both by its weight.
- ``naive_blur``: the naive baseline — each pixel blurred along its *own* velocity (no
  tiles, no depth, no scatter): what a per-pixel directional blur does.
"""
import math

import numpy as np


def bilinear(src, px, py):
    """``src`` (h, w, c) read at continuous positions (pixel centres at +0.5), clamp-to-edge."""
    h, w = src.shape[:2]
    u, v = px - 0.5, py - 0.5
    u0, v0 = np.floor(u), np.floor(v)
    fu, fv = (u - u0)[..., None], (v - v0)[..., None]
    xa = np.clip(u0, 0, w - 1).astype(np.int64)
    xb = np.clip(u0 + 1, 0, w - 1).astype(np.int64)
    ya = np.clip(v0, 0, h - 1).astype(np.int64)
    yb = np.clip(v0 + 1, 0, h - 1).astype(np.int64)
    top = src[ya, xa] * (1 - fu) + src[ya, xb] * fu
    bot = src[yb, xa] * (1 - fu) + src[yb, xb] * fu
    return top * (1 - fv) + bot * fv


def _catmull_rom(a):
    a2, a3 = a * a, a * a * a
    return (-0.5 * a3 + a2 - 0.5 * a, 1.5 * a3 - 2.5 * a2 + 1.0,
            -1.5 * a3 + 2.0 * a2 + 0.5 * a, 0.5 * a3 - 0.5 * a2)


def _blended(a, beta):
    lin = (0.0 * a, 1.0 - a, a, 0.0 * a)
    return tuple(l + (c - l) * beta for l, c in zip(lin, _catmull_rom(a)))


def cubic(src, px, py, beta=1.0):
    """``src`` read through a Catmull-Rom (4 x 4 taps; ``beta`` < 1 blends its weights with
    the tent's), clamp-to-edge, each channel clamped to the range of the 2 x 2 pixels around
    the position (no ringing)."""
    h, w = src.shape[:2]
    u, v = px - 0.5, py - 0.5
    u0, v0 = np.floor(u), np.floor(v)
    wx, wy = _blended(u - u0, beta), _blended(v - v0, beta)
    xs = [np.clip(u0 + i, 0, w - 1).astype(np.int64) for i in (-1, 0, 1, 2)]
    ys = [np.clip(v0 + j, 0, h - 1).astype(np.int64) for j in (-1, 0, 1, 2)]
    acc = 0.0
    for j in range(4):
        acc = acc + wy[j][..., None] * sum(wx[i][..., None] * src[ys[j], xs[i]] for i in range(4))
    inner = [src[ys[j], xs[i]] for j in (1, 2) for i in (1, 2)]
    return np.clip(acc, np.minimum.reduce(inner), np.maximum.reduce(inner))


def _times(t0, t1, n):
    return t0 + (np.arange(n) + 0.5) / n * (t1 - t0)


def _sanitise(src):
    src = np.asarray(src, np.float64)
    return np.where(np.isfinite(src), src, 0.0)


def line_blur(src, velocity, *, t0, t1, n=1024, interp="linear", beta=1.0):
    """Box line blur: mean over t of ``src(x - v t)`` for one velocity ``v`` (px/frame),
    read bilinearly (``interp="linear"``) or through :func:`cubic` (blend ``beta``)."""
    src = _sanitise(src)
    h, w = src.shape[:2]
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64) + 0.5
    acc = np.zeros(src.shape)
    for t in _times(t0, t1, n):
        px, py = xs - velocity[0] * t, ys - velocity[1] * t
        acc += cubic(src, px, py, beta) if interp == "cubic" else bilinear(src, px, py)
    return acc / n


SHORT_SMOOTH = 16.0   # c = L^2 / SHORT_SMOOTH on smooth texture
SHORT_KAPPA = 0.05    # alternation tolerance, fraction of the second difference


def short_smear(src, velocity, *, t0, t1):
    """A smear of length ``L = |v| (t1 - t0)`` < 1 px centred on each pixel, to second order
    along the unit direction ``u`` of ``v``: ``p0 + c (p-1 + p1 - 2 p0)`` with ``pk`` the
    image at ``x + k u`` (bilinear); ``c = L^2 / SHORT_SMOOTH``, or the tent's ``L / 8``
    where the samples alternate along ``u`` (``p-1 = p1`` and ``p0`` repeated at ``p-2`` or
    ``p2``, within ``SHORT_KAPPA`` of the second difference; blended linearly)."""
    src = _sanitise(src)
    h, w = src.shape[:2]
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64) + 0.5
    v = np.asarray(velocity, np.float64)
    speed = math.hypot(v[0], v[1])
    length = speed * (t1 - t0)
    u = v / speed
    p = {k: bilinear(src, xs + k * u[0], ys + k * u[1]) for k in (-2, -1, 1, 2)}
    d2 = p[-1] + p[1] - 2.0 * src
    e = np.abs(p[-1] - p[1]) + np.minimum(np.abs(p[-2] - src), np.abs(p[2] - src))
    with np.errstate(divide="ignore", invalid="ignore"):
        alt = np.clip(1.0 - e / np.maximum(SHORT_KAPPA * np.abs(d2), 1e-300), 0.0, 1.0)
    smooth = length * length / SHORT_SMOOTH
    return src + (smooth + alt * (0.125 * length - smooth)) * d2


STEP_KAPPA = 0.001    # a plateau: neighbouring pixels within this fraction of the largest step
STEP_RAMP = 0.1      # three steps the same way, each over this fraction of the largest: a ramp
STEP_MAX_PX = 1.5     # the step model fades out between 1 px and this smear


def _step_mean(pm, pk, pp, a, b):
    """Mean over ``[a, b]`` (cell coordinates -1/2 .. 1/2) of the running integral, from the
    cell's left side, of the cell ``pk`` rebuilt as a step between its neighbours ``pm`` and
    ``pp`` (monotone cells; extrema and plateaus stay flat), the step placed so that the cell
    keeps its mean."""
    mono = (pm - pk) * (pk - pp) > 0.0
    left, right = np.where(mono, pm, pk), np.where(mono, pp, pk)
    with np.errstate(divide="ignore", invalid="ignore"):
        xe = np.where(mono, (right - pk) / np.where(mono, right - left, 1.0) - 0.5, 0.0)
    ra, rb = np.maximum(a - xe, 0.0), np.maximum(b - xe, 0.0)
    return (left * ((b + 0.5) ** 2 - (a + 0.5) ** 2) / 2 + (right - left) * (rb ** 2 - ra ** 2)
            / 2) / (b - a)


def _step_along(p, length):
    """Change of ``p[0]`` under a centred box of ``length`` <= 1 px along one axis, every
    cell a step (:func:`_step_mean`): the mean over ``tau`` in ``[0, length / 2]`` of the
    row moved by ``+tau`` and by ``-tau``."""
    if length < 1e-3:
        return 0.0 * p[0]
    h = 0.5 * min(length, 1.0)
    plus = (p[-1] - _step_mean(p[-2], p[-1], p[0], 0.5 - h, 0.5)
            + _step_mean(p[-1], p[0], p[1], 0.5 - h, 0.5))
    minus = (_step_mean(p[0], p[1], p[2], -0.5, h - 0.5) + p[0]
             - _step_mean(p[-1], p[0], p[1], -0.5, h - 0.5))
    return 0.5 * (plus + minus) - p[0]


def _stepness(p):
    """1 where the smallest step between neighbouring pixels (summed RGB) is under
    ``STEP_KAPPA`` of the largest (a plateau beside an edge), falling to 0 at it; times 0
    where three steps in a row go the same way by ``STEP_RAMP`` of the largest (a ramp)."""
    d = [(p[k + 1] - p[k])[..., :3].sum(-1) for k in (-2, -1, 0, 1)]
    a = np.abs(np.stack(d))
    lo, hi = a.min(0), a.max(0)
    s1, s2 = np.where(d[1] >= 0, 1.0, -1.0), np.where(d[2] >= 0, 1.0, -1.0)
    ramp = np.maximum(np.minimum(np.minimum(s1 * d[0], a[1]), s1 * d[2]),
                      np.minimum(np.minimum(s2 * d[1], a[2]), s2 * d[3]))
    with np.errstate(divide="ignore", invalid="ignore"):
        plateau = np.clip(1.0 - lo / np.maximum(STEP_KAPPA * hi, 1e-300), 0.0, 1.0)
        return plateau * np.clip(1.0 - np.maximum(ramp, 0.0) / (STEP_RAMP * np.maximum(
            hi, 1e-300)), 0.0, 1.0)


def step_smear(src, velocity, *, t0, t1):
    """The step model of a sub-pixel smear of flat patches with hard edges, one depth: the
    smear's parts ``L |ux|`` and ``L |uy|`` along the pixel axes (:func:`_step_along`, the
    pixels at +-1 and +-2, clamp-to-edge) added, plus the cross term of a diagonal smear
    (``Lx Ly / 24`` times the mixed differences with the diagonal neighbours ahead and
    behind); and its weight (the stepness of each axis carrying over a quarter of the smear,
    the least of them; an axis with less counts in proportion).  Returns (smear, weight)."""
    src = _sanitise(src)
    h, w = src.shape[:2]
    ys, xs = np.mgrid[0:h, 0:w]
    v = np.asarray(velocity, np.float64)
    speed = math.hypot(v[0], v[1])
    length = speed * (t1 - t0)
    ux, uy = v[0] / speed, v[1] / speed
    lx, ly = length * abs(ux), length * abs(uy)

    def at(dx, dy):
        return src[np.clip(ys + dy, 0, h - 1), np.clip(xs + dx, 0, w - 1)]

    px = {k: at(k, 0) for k in (-2, -1, 0, 1, 2)}
    py = {k: at(0, k) for k in (-2, -1, 0, 1, 2)}
    ox, oy = (1 if ux >= 0 else -1), (1 if uy >= 0 else -1)
    cross = ((at(ox, oy) - px[ox] - py[oy] + src) + (at(-ox, -oy) - px[-ox] - py[-oy] + src))
    out = src + _step_along(px, lx) + _step_along(py, ly) + (lx * ly / 24.0) * cross
    gx, gy = (min(max(4.0 * part / max(lx + ly, 1e-300), 0.0), 1.0) for part in (lx, ly))
    weight = np.minimum(1.0 - gx * (1.0 - _stepness(px)), 1.0 - gy * (1.0 - _stepness(py)))
    return out, weight


def short_blur(src, velocity, *, t0, t1, n):
    """The gather on one velocity whose smear ``L`` is under 1.5 px, centred shutter, one
    depth: the closed form :func:`short_smear` where the fetch would be the tent (``L`` <=
    3/8 px), the line blur of ``n`` midpoint samples read through the tent-blended cubic from
    1/2 px on, linearly between (``beta = clip((L - 3/8) 8, 0, 1)``); then the step model
    (:func:`step_smear`) blended in by its weight, in full up to a pixel of smear and fading
    out by ``STEP_MAX_PX``."""
    length = math.hypot(*velocity) * (t1 - t0)
    beta = min(max((length - 0.375) * 8.0, 0.0), 1.0)
    line = line_blur(src, velocity, t0=t0, t1=t1, n=n, interp="cubic", beta=beta)
    base = line + (1.0 - beta) * (short_smear(src, velocity, t0=t0, t1=t1) - line)
    step, weight = step_smear(src, velocity, t0=t0, t1=t1)
    fade = min(max((STEP_MAX_PX - length) / (STEP_MAX_PX - 1.0), 0.0), 1.0)
    return base + (weight * fade)[..., None] * (step - base)


def naive_blur(src, velocity, *, t0, t1, n=256):
    """Each pixel averaged along its own velocity over the shutter (no depth, no scatter)."""
    src = _sanitise(src)
    v = np.where(np.isfinite(velocity), np.asarray(velocity, np.float64), 0.0)
    h, w = src.shape[:2]
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64) + 0.5
    acc = np.zeros(src.shape)
    for t in _times(t0, t1, n):
        acc += bilinear(src, xs - v[..., 0] * t, ys - v[..., 1] * t)
    return acc / n


SOFT_Z = 0.02         # relative depth difference over which "in front" fades in
DILATE_RATIO = 10.0   # a rim pixel is this many times brighter than the background beside it
MIN_BLUR = 0.1        # px over the shutter: slower relative motion is no motion


def rim_dilation(velocity, depth, rgb, duration):
    """Which (velocity, depth) each pixel's record carries after the rim dilation: a pixel
    ``p`` of an antialiased rim, mostly the colour of a small bright surface ``q`` in front of
    it, takes ``q``'s motion and depth.  ``q`` is the nearest of the 8 neighbours that lie in
    front of ``p`` (depth under ``(1 - SOFT_Z)`` of ``p``'s) and move differently (at least
    ``MIN_BLUR`` px apart over ``duration`` frames), the first in scan order (rows, then
    columns) among equal depths; ``p`` takes it when the neighbour ``b`` on the other side,
    ``p - (q - p)``, lies at ``p``'s depth or behind, ``p`` is more than ``DILATE_RATIO``
    times brighter than ``b`` (RGB sums) and ``q`` brighter than ``p``.  Returns the new
    (h, w, 2) velocity and (h, w) depth; velocities and depths are taken as given (finite,
    positive depths)."""
    v = np.asarray(velocity, np.float64)
    z = np.asarray(depth, np.float64)
    lum = np.asarray(rgb, np.float64)[..., :3].sum(-1)
    h, w = z.shape
    out_v, out_z = v.copy(), z.copy()
    for y in range(h):
        for x in range(w):
            best, at = z[y, x] * (1.0 - SOFT_Z), None
            for dy in (-1, 0, 1):
                for dx in (-1, 0, 1):
                    qy, qx = y + dy, x + dx
                    if (dx, dy) == (0, 0) or not (0 <= qy < h and 0 <= qx < w):
                        continue
                    moves = math.hypot(*(v[qy, qx] - v[y, x])) * duration >= MIN_BLUR
                    if z[qy, qx] < best and moves:
                        best, at = z[qy, qx], (qy, qx)
            if at is None:
                continue
            by, bx = 2 * y - at[0], 2 * x - at[1]
            if not (0 <= by < h and 0 <= bx < w):
                continue
            if (z[by, bx] >= z[y, x] * (1.0 - SOFT_Z)
                    and lum[y, x] - lum[by, bx] > DILATE_RATIO * max(lum[by, bx], 0.0)
                    and lum[at] > lum[y, x]):
                out_v[y, x], out_z[y, x] = v[at], z[at]
    return out_v, out_z
