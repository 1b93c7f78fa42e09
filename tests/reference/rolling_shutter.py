"""float64 NumPy oracle of clfx/plugins/rolling_shutter.py: the same model written plainly
(row times per row, velocities sanitised and clamped, tile candidates, fixed-point iteration,
nearest-in-front selection, background search), vectorised over pixels; with both halves of
a vector pass, a point's path is the arc through its three positions (:func:`arc`)."""
import math

import numpy as np


BIG_DEPTH = 1e30
TOL = 0.5
SOFT_Z = 0.02
MAX_RADIUS_PX = 512
MIN_TURN = 1e-3
"""rad/frame: a path turning slower is taken as straight (the arc's limit, :func:`arc`)."""
MAX_TURN = 2.6
"""rad/frame (149 deg): the fastest turn a path is taken to make (tests/test_oracles.py
checks both against the kernels' statement, kernels/lib/arc.h)."""


def _circle(w, t):
    """Position at time ``t`` (frames) of a point turning at ``w`` rad/frame on the unit
    circle about (0, 1), through the origin at t = 0 heading along +x: (sin wt, 1 - cos wt)."""
    return np.stack([np.sin(w * t), 1.0 - np.cos(w * t)], -1)


def arc(forward, backward, t):
    """Displacement (px) at time ``t`` (frames) of a point that moves by ``forward`` over the
    next frame and came by ``backward`` over the last one, on the arc through its positions
    at -1, 0 and +1 frame.

    A point turning at a constant rate w about a centre is at p(t) = (I - R(w t)) c (R a
    rotation, the point at the origin at t = 0).  Its chords to the next and from the
    previous position give s = f + b = p(1) - p(-1), along its heading, and e = f - b =
    p(1) + p(-1), across it, with |e| / |s| = tan(w / 2).  On every such circle p(t) is the
    same combination alpha(t) s + beta(t) e: this takes alpha, beta from one circle turning
    at w (:func:`_circle`: s and e from its positions at +-1, solved for its position at
    t), and w from the part of e across s (a path that speeds up or slows down along a
    straight line has e along s: w = 0), at most ``MAX_TURN``.  Below ``MIN_TURN`` the arc is
    its limit, the parabola alpha = t / 2, beta = t^2 / 2 (so f = b gives the line f t)."""
    f, b = np.asarray(forward, np.float64), np.asarray(backward, np.float64)
    s, e = f + b, f - b
    along = np.sqrt((s * s).sum(-1))
    heading = s / np.where(along > 0, along, 1.0)[..., None]
    across = e - (e * heading).sum(-1)[..., None] * heading
    w = np.minimum(2.0 * np.arctan2(np.sqrt((across * across).sum(-1)), along), MAX_TURN)
    t = np.broadcast_to(np.asarray(t, np.float64)[..., 0] if np.ndim(t) == f.ndim
                        else np.asarray(t, np.float64), w.shape)
    turning = w > MIN_TURN
    wc = np.where(turning, w, 1.0)
    basis = np.stack([_circle(wc, 1.0) - _circle(wc, -1.0),      # s, e of the unit circle
                      _circle(wc, 1.0) + _circle(wc, -1.0)], -1)
    alpha, beta = np.moveaxis(np.linalg.solve(basis, _circle(wc, t)[..., None])[..., 0], -1, 0)
    alpha = np.where(turning, alpha, t / 2.0)
    beta = np.where(turning, beta, t * t / 2.0)
    return alpha[..., None] * s + beta[..., None] * e


def row_times(shape, *, readout, direction="top-down", reference="first", data_window=None,
              display_window=None):
    """t (frames) of every pixel of the data window: readout x (index in reading order /
    count - reference), rows or columns counted in the display window."""
    h, w = shape
    dx0, dy0 = (data_window or (0, 0, w, h))[:2]
    x0, y0, x1, y1 = display_window or (dx0, dy0, dx0 + w, dy0 + h)
    X = dx0 + np.arange(w)[None, :] * np.ones((h, 1))
    Y = dy0 + np.arange(h)[:, None] * np.ones((1, w))
    n = {"top-down": y1 - y0, "bottom-up": y1 - y0}.get(direction, x1 - x0)
    index = {"top-down": Y - y0, "bottom-up": y1 - 1 - Y, "left-right": X - x0,
             "right-left": x1 - 1 - X}[direction]
    r0 = {"first": 0.0, "centre": 0.5, "last": 1.0}[reference] * (n - 1) / n
    return readout * (index / n - r0)


def prepare(velocity, depth, vmax):
    """(vx, vy, z, speed): non-finite velocities -> 0, components clamped to 1e6, speed
    clamped to vmax (direction kept); invalid depth (NaN, <= 0, >= 1e30) -> 1e30; 1 without."""
    v = np.asarray(velocity, np.float64)
    ok = np.isfinite(v).all(axis=2, keepdims=True)
    v = np.where(ok, np.clip(np.nan_to_num(v), -1e6, 1e6), 0.0)
    s = np.hypot(v[..., 0], v[..., 1])
    scale = np.where(s > vmax, vmax / np.where(s > 0, s, 1), 1.0)
    v = v * scale[..., None]
    s = np.minimum(s, vmax)
    if depth is None:
        z = np.ones(s.shape)
    else:
        z = np.asarray(depth, np.float64)
        z = np.where((z > 0) & (z < BIG_DEPTH), z, BIG_DEPTH)
    return np.concatenate([v, z[..., None], s[..., None]], axis=2)


def tile_candidates(aux, k, has_depth):
    """Per tile of k x k px, over its 3 x 3 neighbourhood, the velocities of the fastest
    pixel, of the background (farthest, or slowest without depth) and of the nearest pixel:
    (h_tiles, w_tiles, 3, 2); the first pixel in scan order wins ties."""
    h, w = aux.shape[:2]
    ty, tx = -(-h // k), -(-w // k)
    keys = np.zeros((ty, tx, 3))
    vels = np.zeros((ty, tx, 3, 2))
    for j in range(ty):
        for i in range(tx):
            block = aux[j * k:(j + 1) * k, i * k:(i + 1) * k].reshape(-1, 4)
            for c, key in enumerate((block[:, 3], block[:, 2] if has_depth else -block[:, 3],
                                     -block[:, 2])):
                keys[j, i, c] = key.max()
                vels[j, i, c] = block[np.argmax(key), :2]
    nbr = np.zeros_like(vels)
    for j in range(ty):
        for i in range(tx):
            best = np.full(3, -np.inf)
            for dj in (-1, 0, 1):
                for di in (-1, 0, 1):
                    if 0 <= j + dj < ty and 0 <= i + di < tx:
                        for c in range(3):
                            if keys[j + dj, i + di, c] > best[c]:
                                best[c] = keys[j + dj, i + di, c]
                                nbr[j, i, c] = vels[j + dj, i + di, c]
    return nbr


def _nearest(img, q):
    h, w = img.shape[:2]
    ix = np.clip(np.floor(np.clip(q[..., 0], -1, w)).astype(int), 0, w - 1)
    iy = np.clip(np.floor(np.clip(q[..., 1], -1, h)).astype(int), 0, h - 1)
    return img[iy, ix]


def _bilinear(img, q):
    h, w = img.shape[:2]
    u = np.clip(q[..., 0], -1, w + 1) - 0.5
    v = np.clip(q[..., 1], -1, h + 1) - 0.5
    fu, fv = np.floor(u), np.floor(v)
    ax, ay = (u - fu)[..., None], (v - fv)[..., None]
    xa, xb = np.clip(fu.astype(int), 0, w - 1), np.clip(fu.astype(int) + 1, 0, w - 1)
    ya, yb = np.clip(fv.astype(int), 0, h - 1), np.clip(fv.astype(int) + 1, 0, h - 1)
    return (img[ya, xa] * (1 - ax) * (1 - ay) + img[ya, xb] * ax * (1 - ay)
            + img[yb, xa] * (1 - ax) * ay + img[yb, xb] * ax * ay)


def tile_size(shift):
    return int(max(8, 4 * math.ceil(min(shift, MAX_RADIUS_PX) / 4.0)))


def rolling_shutter(src, velocity, depth=None, *, readout, direction="top-down",
                    reference="first", max_shift=0.1, iterations=3, max_search=64,
                    data_window=None, display_window=None, velocity_back=None):
    """The rolling-shutter output over the data window (see the plugin's notes)."""
    src = np.asarray(src, np.float64)
    col = np.where(np.isfinite(src), src, 0.0)
    h, w = src.shape[:2]
    t = row_times((h, w), readout=readout, direction=direction, reference=reference,
                  data_window=data_window, display_window=display_window)
    dw = display_window or (0, 0, w, h)
    diag = math.hypot(dw[2] - dw[0], dw[3] - dw[1])
    v = np.asarray(velocity, np.float64)
    peak = np.hypot(v[..., 0], v[..., 1])[np.isfinite(v).all(axis=2)].max(initial=0.0)
    t_max = np.abs(t).max()
    shift = min(peak * t_max, max_shift * diag, MAX_RADIUS_PX)
    aux = prepare(velocity, depth, shift / t_max if t_max > 0 else 0.0)
    auxb = None if velocity_back is None else prepare(velocity_back, depth,
                                                      shift / t_max if t_max > 0 else 0.0)

    def disp(q, f):
        """Displacement by t of the point at q moving with f (and, curved, its backward)."""
        if auxb is None:
            return f * tt
        return arc(f, _nearest(auxb, q)[..., :2], tt)

    k = tile_size(shift)
    nbr = tile_candidates(aux, k, depth is not None)
    yy, xx = np.mgrid[0:h, 0:w]
    nb = nbr[yy // k, xx // k]
    p = np.stack([xx + 0.5, yy + 0.5], axis=2)
    tt = t[..., None]

    best = np.full((h, w), -1)
    qb, zb, sb = p.copy(), np.zeros((h, w)), np.zeros((h, w))
    starts = [aux[..., :2], nb[..., 0, :], nb[..., 1, :]] + ([nb[..., 2, :]] if depth is not None else [])
    for c, v0 in enumerate(starts):
        q = p - v0 * tt
        for _ in range(iterations):
            q = p - disp(q, _nearest(aux, q)[..., :2])
        a = _nearest(aux, q)
        d = p - disp(q, a[..., :2]) - q
        valid = (d ** 2).sum(axis=2) <= TOL * TOL
        same = np.abs(a[..., 2] - zb) <= SOFT_Z * np.minimum(a[..., 2], zb)
        front = np.where(same, a[..., 3] > sb, a[..., 2] < zb)
        take = valid & ((best < 0) | front)
        best[take] = c
        qb[take], zb[take], sb[take] = q[take], a[..., 2][take], a[..., 3][take]

    # a winner on an occluder's antialiased rim left behind (a 4-neighbour in front moving
    # away from it by >= 1 px by |t|) counts as uncovered
    aw = _nearest(aux, qb)
    rim = np.zeros((h, w), bool)
    for e in ((1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)):
        nbv = _nearest(aux, qb + np.array(e))
        dvn = nbv[..., :2] - aw[..., :2]
        ln = np.hypot(dvn[..., 0], dvn[..., 1])
        same = np.abs(nbv[..., 2] - zb) <= SOFT_Z * np.minimum(nbv[..., 2], zb)
        front = np.where(same, nbv[..., 3] > sb, nbv[..., 2] < zb)
        rim |= (ln * np.abs(t) >= 1.0) & (dvn @ np.array(e) > 0.5 * ln) & front
    best[(best >= 0) & rim] = -1
    hole = best < 0
    vb = nb[..., 1, :]
    tabs = np.abs(t)
    q0 = p - vb * tt
    vo = _nearest(aux, q0)[..., :2]
    bo = vo if auxb is None else _nearest(auxb, q0)[..., :2]
    bgo = (np.hypot(*(vo - vb).transpose(2, 0, 1)) * tabs <= TOL)[..., None]
    vo = np.where(bgo, nb[..., 0, :], vo)       # the tile's fastest: no backward motion
    bo = np.where(bgo, nb[..., 0, :], bo)
    q1 = p - arc(vo, bo, tt)
    qb[hole] = q1[hole]
    if max_search > 0:
        dv = vo - vb
        ln = np.hypot(dv[..., 0], dv[..., 1])
        direc = np.where((ln > 1e-6)[..., None], dv / np.where(ln > 1e-6, ln, 1)[..., None],
                         np.array([1.0, 0.0]))
        reach = np.minimum(np.ceil(ln * tabs) + 1, max_search)
        todo = hole.copy()
        for j in range(int(reach[hole].max(initial=-1)) + 1):
            for sgn in ((-1,) if j == 0 else (-1, 1)):
                q = q1 + direc * (sgn * j)
                dd = _nearest(aux, q)[..., :2] - vb
                ok = todo & (j <= reach) & (np.hypot(dd[..., 0], dd[..., 1]) * tabs <= TOL)
                qb[ok] = q[ok]
                todo &= ~ok
    return _bilinear(col, qb)
