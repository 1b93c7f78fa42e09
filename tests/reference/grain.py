"""float64 NumPy oracle of clfx/plugins/grain.py: the plainest form of the model.

The white noise is the same hash as kernels/lib/common.h (``clfx_uniform``), re-implemented on
uint32 arrays, so the oracle reproduces the device's noise exactly up to float rounding.
"""
import math

import numpy as np

from tests.reference.noise import cover

M32 = 0xFFFFFFFF


def hash32(x):
    """lowbias32 on uint32 arrays (wrapping multiplication)."""
    x = np.asarray(x, np.uint32)
    with np.errstate(over="ignore"):  # uint32 multiplication wraps, as in C
        x = x ^ (x >> np.uint32(16))
        x = x * np.uint32(0x7FEB352D)
        x = x ^ (x >> np.uint32(15))
        x = x * np.uint32(0x846CA68B)
        x = x ^ (x >> np.uint32(16))
    return x


def u32(v):
    return np.asarray(np.asarray(v, np.int64) & M32, np.uint32)


def uniform(seed, frame, x, y, c):
    """clfx_uniform(seed, frame, x, y, c) as float64 in (0, 1); x, y arrays."""
    with np.errstate(over="ignore"):
        h = hash32(u32(seed) ^ np.uint32(0x9E3779B9))
        h = hash32(h ^ u32(frame))
        h = hash32(h ^ u32(x))
        h = hash32(h ^ (u32(y) * np.uint32(0x85EBCA6B)))
        h = hash32(h ^ (u32(c) * np.uint32(0xC2B2AE35)))
    return ((h >> np.uint32(8)).astype(np.float64) + 0.5) / 16777216.0


def effect_seed(param_seed, look_seed, salt):
    s = hash32(u32(look_seed) ^ np.uint32(salt))
    return int(hash32(u32(param_seed) ^ s))


def white_noise(seed, frame, x0, y0, w, h, monochrome):
    """(h, w, 3) unit Gaussian noise at frame pixels x0.., y0.. (Box-Muller)."""
    y, x = np.mgrid[y0:y0 + h, x0:x0 + w]
    u = [uniform(seed, frame, x, y, c) for c in range(4)]
    r01 = np.sqrt(-2.0 * np.log(u[0]))
    r23 = np.sqrt(-2.0 * np.log(u[2]))
    n = np.stack([r01 * np.cos(2 * np.pi * u[1]), r01 * np.sin(2 * np.pi * u[1]),
                  r23 * np.cos(2 * np.pi * u[3])], axis=-1)
    if monochrome:
        n = np.repeat(n[..., :1], 3, axis=-1)
    return n


def taps(sigma, radius):
    """Pixel-integrated Gaussian taps -radius..radius, unit sum of squares."""
    k = np.arange(-radius, radius + 1)
    if sigma < 1e-6:
        t = (k == 0).astype(np.float64)
    else:
        t = np.array([0.5 * (math.erf((i + 0.5) / (sigma * math.sqrt(2)))
                             - math.erf((i - 0.5) / (sigma * math.sqrt(2)))) for i in k])
    return t / np.sqrt(np.sum(t * t))


def grain_noise(h, w, *, sigmas, seed, frame, monochrome, data_origin=(0, 0),
                truncation=6.0):
    """(h, w, 3) unit-variance grain: white noise filtered per channel (None: unfiltered)."""
    x0, y0 = data_origin
    if truncation is None:
        return white_noise(seed, frame, x0, y0, w, h, monochrome)
    radii = [int(math.ceil(truncation * s)) if s >= 1e-6 else 0 for s in sigmas]
    big = max(radii)
    white = white_noise(seed, frame, x0 - big, y0 - big, w + 2 * big, h + 2 * big, monochrome)
    out = np.zeros((h, w, 3))
    for c in range(3):
        t = taps(sigmas[c], radii[c])
        r = radii[c]
        field = white[..., c]
        horiz = np.zeros((h + 2 * big, w))
        for i, wt in enumerate(t):
            dx = big - r + i
            horiz += wt * field[:, dx:dx + w]
        for i, wt in enumerate(t):
            dy = big - r + i
            out[..., c] += wt * horiz[dy:dy + h]
    return out


GAMMA, FOG, TOE = 0.6, 0.1, 2.0 ** -4


def pixel_variance_1d(a, sigma):
    """Per-axis variance of the unit field (autocorrelation exp(-u^2 / 4 sigma^2)) averaged
    over a pixel of side a, by plain numerical integration of (2/a^2) int_0^a (a - u)
    rho(u) du (Simpson, 2001 points)."""
    u = np.linspace(0.0, a, 2001)
    f = (a - u) * np.exp(-u * u / (4 * sigma * sigma))
    h = u[1] - u[0]
    simpson = h / 3 * (f[0] + f[-1] + 4 * f[1:-1:2].sum() + 2 * f[2:-1:2].sum())
    return 2.0 / (a * a) * simpson


def selwyn(sigma, ref):
    """Deviation of the field seen by a 1-px pixel relative to a ref-px pixel."""
    if sigma < 1e-6 * max(1.0, ref):
        return ref
    return pixel_variance_1d(1.0, sigma) / pixel_variance_1d(ref, sigma)


def meter(src, tile=32):
    """Metered middle grey: the mean of the log of the 32 x 32 tile mean luminances
    (non-finite pixels count as 0) over the tiles with light (mean > 0), each log clamped to
    the 25th-75th percentiles of theirs; 0.18 when no tile has light."""
    h, w = src.shape[:2]
    rgb = np.where(np.isfinite(src).all(-1, keepdims=True), src[..., :3], 0.0)
    lum = rgb @ np.array([0.2126, 0.7152, 0.0722])
    means = [lum[y:y + tile, x:x + tile].mean() for y in range(0, h, tile)
             for x in range(0, w, tile)]
    m = np.array(means)
    m = m[m > 0]
    if not m.size:
        return 0.18
    logs = np.log(m)
    lo, hi = np.percentile(logs, 25), np.percentile(logs, 75)
    return float(np.exp(np.mean(np.clip(logs, lo, hi))))


def grain(src, *, stock, amount, diameter, middle_grey, response, channel_amount,
          channel_size, monochrome, size, seed, coverage="auto", frame=0, look_seed=0,
          data_origin=(0, 0), display_width=None, sensor_width=36.0, truncation=6.0):
    """Film grain on ``src`` (h, w, 4) float64; same parameters as the plugin, but ``stock``
    is the stock's data (the descriptor's table of by-eye ratios, given by the test): per
    channel ``size`` and ``amount`` ratios, ``monochrome``, ``diameter`` (um)."""
    src = np.asarray(src, np.float64)
    h, w = src.shape[:2]
    display_width = display_width or w
    st = stock
    sizes = [a * b for a, b in zip(st.size, channel_size)]
    amounts = [a * b for a, b in zip(st.amount, channel_amount)]
    mono = monochrome or st.monochrome
    if mono:
        sizes = [sizes[1]] * 3
    if size >= 0:
        cloud_um = size * sensor_width * 1000 / 2048
    else:
        cloud_um = (diameter or st.diameter) / 4
    px_per_um = display_width / (sensor_width * 1000)
    sigmas = [s * cloud_um * px_per_um for s in sizes]
    ref = display_width / 2048
    amt = [amount * a * selwyn(s, ref) / (1 + TOE) for a, s in zip(amounts, sigmas)]
    n = grain_noise(h, w, sigmas=sigmas, seed=effect_seed(seed, look_seed, 0x6772616E),
                    frame=frame, monochrome=mono, data_origin=data_origin,
                    truncation=truncation)
    grey = middle_grey if middle_grey > 0 else meter(src)
    finite = np.isfinite(src)
    v = np.clip(np.where(finite[..., :3], src[..., :3], 0.0), -1e30, 1e30)
    e = np.clip(v / grey, 0.0, 1e30)
    if mono:
        lum = np.maximum(e @ np.array([0.2126, 0.7152, 0.0722]), 0.0)
        ed = np.repeat(lum[..., None], 3, axis=-1)
    else:
        ed = e
    density = FOG + GAMMA * np.log10(1 + ed / TOE)
    d_grey = FOG + GAMMA * np.log10(1 + 1 / TOE)
    out = np.where(finite, src, 0.0)
    grainy = np.empty_like(v)
    for c in range(3):
        s = amt[c] * (density[..., c] / d_grey) ** response
        factor = np.exp(np.clip(s * n[..., c] - s * s / 2, -87, 80))
        grainy[..., c] = v[..., c] + grey * (e[..., c] + TOE) * (factor - 1)
    out[..., :3] = np.clip(cover(src, v, grainy, coverage),
                           -3.4028234663852886e38, 3.4028234663852886e38)
    return out
