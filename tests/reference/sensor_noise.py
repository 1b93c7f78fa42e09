"""float64 NumPy oracle of clfx/plugins/sensor_noise.py: the plainest form of the model.

Same random streams as the kernel (``clfx_uniform`` re-implemented in tests/reference/grain.py).
"""
import math

import numpy as np

from tests.reference.grain import effect_seed, meter, uniform
from tests.reference.noise import cover

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


def electrons(src, *, iso, base_iso, full_well, camera_iso=400.0, middle_grey=0.0, **_):
    """Electrons per unit of linear value before channel sensitivity: ``full_well`` at base
    ISO for a plate whose middle grey is 0.18, scaled by 0.18 / the plate's middle grey
    (``middle_grey``, or 0: the frame metered as grain meters it)."""
    gain = (iso if iso > 0 else camera_iso) / base_iso
    grey = middle_grey if middle_grey > 0 else meter(np.asarray(src, np.float64))
    return full_well / gain * (0.18 / grey)


def site_noise(src, *, iso, base_iso, full_well, shot_noise, read_noise, prnu,
               channel_sensitivity, seed, frame=0, look_seed=0, data_origin=(0, 0),
               camera_iso=400.0, switch=30.0, middle_grey=0.0):
    """Per-site sensor noise on ``src`` (h, w, 4) float64 (every pixel, every channel
    independent: mosaic "none"); ``switch`` None = normal approximation only.  A site holds
    at most ``full_well`` electrons (``vsat = full_well / k`` in linear units): at or above
    it the site reads exactly full (no shot noise, no PRNU), below it the count is capped
    there."""
    src = np.asarray(src, np.float64)
    h, w = src.shape[:2]
    k_unit = electrons(src, iso=iso, base_iso=base_iso, full_well=full_well,
                       camera_iso=camera_iso, middle_grey=middle_grey)
    s_main = effect_seed(seed, look_seed, SENSOR_SALT)
    s_prnu = effect_seed(seed, look_seed, PRNU_SALT)
    y, x = np.mgrid[0:h, 0:w]
    x = x + data_origin[0]
    y = y + data_origin[1]
    out = src.copy()
    for c in range(3):
        k = k_unit * channel_sensitivity[c]
        g = 1.0 / k
        vsat = full_well * g
        v = np.clip(np.where(np.isfinite(src[..., c]), src[..., c], 0.0), -1e38, 1e38)
        if prnu > 0:
            fa, fb = uniform(s_prnu, 0, x, y, c), uniform(s_prnu, 0, x, y, c + 4)
            vc = v
            v = v * (1 + prnu * np.sqrt(-2 * np.log(fa)) * np.cos(2 * np.pi * fb))
            v = np.where(np.maximum(v, vc) >= vsat,
                         vc + np.minimum(v, vsat) - np.minimum(vc, vsat), v)
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
            dev = np.where(vpos >= vsat, 0.0, np.minimum(dev, vsat - vpos))
            res = res + dev
        if read_noise > 0:
            res = res + read_noise * g * r * np.sin(2 * np.pi * ub)
        out[..., c] = res
    return out


def sigma(v, *, g, full_well, read_noise, prnu, shot_noise=True):
    """The model's deviation of the output at clean linear values ``v`` of a channel with
    ``g`` linear units per electron: shot noise and PRNU below the full well, read noise."""
    below = np.where(v >= full_well * g, 0.0, np.maximum(v, 0.0))
    var = (read_noise * g) ** 2 + (prnu * below) ** 2
    if shot_noise:
        var = var + g * below
    return np.sqrt(var)


def cfa(fx, fy):
    """RGGB colour index of frame pixels: 0 R (even, even), 2 B (odd, odd), 1 G."""
    ox, oy = fx & 1, fy & 1
    return np.where(ox == oy, np.where(ox == 1, 2, 0), 1)


def mirror(i, n):
    i = np.abs(i)
    i = np.where(i >= n, 2 * (n - 1) - i, i)
    return np.clip(i, 0, n - 1)


def demosaic_deviation(dev, data_origin=(0, 0)):
    """Malvar-He-Cutler demosaic of the site mosaic of ``dev`` (h, w, 3): each pixel keeps
    its CFA colour's deviation; sites outside the window mirrored about its edge.  The plain
    filters: the model's demosaic is `demosaic_unit`."""
    h, w = dev.shape[:2]
    y, x = np.mgrid[0:h, 0:w]
    fx, fy = x + data_origin[0], y + data_origin[1]

    def site(dx, dy):
        xx, yy = mirror(x + dx, w), mirror(y + dy, h)
        # the mirrored pixel's own CFA colour (the kernel reads the site it lands on)
        return dev[yy, xx, cfa(xx + data_origin[0], yy + data_origin[1])]

    s0 = site(0, 0)
    ax, ay = site(-1, 0) + site(1, 0), site(0, -1) + site(0, 1)
    bx, by = site(-2, 0) + site(2, 0), site(0, -2) + site(0, 2)
    dg = site(-1, -1) + site(1, -1) + site(-1, 1) + site(1, 1)
    c = cfa(fx, fy)
    hor = (5 * s0 + 4 * ax - bx - dg + 0.5 * by) / 8
    ver = (5 * s0 + 4 * ay - by - dg + 0.5 * bx) / 8
    g = (4 * s0 + 2 * (ax + ay) - (bx + by)) / 8
    o = (6 * s0 + 2 * dg - 1.5 * (bx + by)) / 8
    rrow = (fy & 1) == 0
    out = np.empty_like(dev)
    out[..., 0] = np.where(c == 0, s0, np.where(c == 2, o, np.where(rrow, hor, ver)))
    out[..., 1] = np.where(c == 1, s0, g)
    out[..., 2] = np.where(c == 2, s0, np.where(c == 0, o, np.where(rrow, ver, hor)))
    return out


def demosaic_unit(dev, sd, data_origin=(0, 0)):
    """The model's demosaic: the site deviations over the model's deviation at each site (a
    unit field), demosaiced, each interpolated colour divided by its filter's norm (R or B
    at a green site sqrt(63.5) / 8, green at R or B 6 / 8, B at R or R at B sqrt(61) / 8),
    times the pixel's own deviation ``sd`` (h, w, 3) per colour."""
    unit = np.where(sd > 0, dev / np.where(sd > 0, sd, 1.0), 0.0)
    d = demosaic_deviation(unit, data_origin)
    h, w = dev.shape[:2]
    y, x = np.mgrid[0:h, 0:w]
    c = cfa(x + data_origin[0], y + data_origin[1])
    norm = np.ones((h, w, 3))
    green = c == 1
    norm[..., 0] = np.where(green, 8 / math.sqrt(63.5), np.where(c == 2, 8 / math.sqrt(61), 1))
    norm[..., 2] = np.where(green, 8 / math.sqrt(63.5), np.where(c == 0, 8 / math.sqrt(61), 1))
    norm[..., 1] = np.where(green, 1.0, 8 / 6)
    return d * norm * sd


def value_noise(seed, frame, px, py, stream):
    """Unit Gaussians at integer nodes (Box-Muller of streams s, s + 1), smoothstep-blended."""
    gx, gy = np.floor(px), np.floor(py)
    tx, ty = px - gx, py - gy
    sx, sy = tx * tx * (3 - 2 * tx), ty * ty * (3 - 2 * ty)
    ix, iy = gx.astype(np.int64), gy.astype(np.int64)

    def node(i, j):
        u1 = uniform(seed, frame, i, j, stream)
        u2 = uniform(seed, frame, i, j, stream + 1)
        return np.sqrt(-2 * np.log(u1)) * np.cos(2 * np.pi * u2)

    a, b, c, d = node(ix, iy), node(ix + 1, iy), node(ix, iy + 1), node(ix + 1, iy + 1)
    return (a + (b - a) * sx) * (1 - sy) + (c + (d - c) * sx) * sy


def sensor_noise(src, *, mosaic="bayer", chroma_noise=0.0, chroma_size=0.02, diagonal=None,
                 coverage="auto", **kw):
    """The full model: per-site noise (``sensor_noise``), the Bayer demosaic of the
    deviations, the chroma blotches and the alpha coverage; same parameters as the plugin."""
    src = np.asarray(src, np.float64)
    h, w = src.shape[:2]
    noisy = site_noise(src, **kw)
    v = np.clip(np.where(np.isfinite(src[..., :3]), src[..., :3], 0.0), -1e38, 1e38)
    dev = noisy[..., :3] - v
    x0, y0 = kw.get("data_origin", (0, 0))
    k_unit = electrons(src, **kw)
    sd = np.stack([sigma(v[..., c], g=1.0 / (k_unit * kw["channel_sensitivity"][c]),
                         full_well=kw["full_well"], read_noise=kw["read_noise"],
                         prnu=kw["prnu"], shot_noise=kw["shot_noise"]) for c in range(3)], -1)
    if mosaic == "bayer":
        dev = demosaic_unit(dev, sd, (x0, y0))
    out = noisy.copy()
    out[..., :3] = v + dev
    if chroma_noise > 0:
        cell = max(chroma_size * (diagonal or np.hypot(w, h)), 1.0)
        y, x = np.mgrid[0:h, 0:w]
        seed = effect_seed(kw["seed"], kw.get("look_seed", 0), SENSOR_SALT)
        px, py = (x + x0) / cell, (y + y0) / cell
        a = value_noise(seed, kw.get("frame", 0), px, py, 12)
        b = value_noise(seed, kw.get("frame", 0), px, py, 14)
        dr, db = chroma_noise * sd[..., 1] * a, chroma_noise * sd[..., 1] * b
        out[..., 0] += dr
        out[..., 2] += db
        out[..., 1] -= (0.2126 * dr + 0.0722 * db) / 0.7152
    out[..., :3] = cover(src, v, out[..., :3], coverage)
    out[..., :3] = np.clip(out[..., :3], -3.4028234663852886e38, 3.4028234663852886e38)
    return out
