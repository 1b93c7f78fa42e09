"""Point spread functions for glare, bleed and soft focus (host NumPy, once per parameter set).

Every builder returns a float64 array of shape (2r + 1, 2r + 1) or (2r + 1, 2r + 1, 3), centre
at index r, normalised so each plane sums to 1 (the convolution then conserves energy), and
truncated at radius r pixels.

Models
------
``spencer``
    Spencer, Shirley, Zimmerman & Greenberg 1995, "Physically-based glare effects for digital
    images" (SIGGRAPH), photopic eye PSF as a function of the angle t in degrees::

        P(t) = 2.61e6 exp(-(t / 0.02)^2) + 20.91 / (t + 0.02)^3 + 72.37 / (t + 0.02)^2

    Angles come from the camera block (degrees per pixel at the optical centre,
    ``degrees(atan(sensor_width / (width_px * focal_length)))``) or from a given horizontal
    field of view.  Pixels within 4 px of the centre, and as far as the Gaussian core reaches
    (0.07 degrees), are integrated over their area (8 x 8 sub-samples): the core is narrower
    than a pixel at usual focal lengths.  The power-law
    tail ends through :func:`tail_fade` (below 1e-5 of the PSF one pixel out before the
    support's outer tenth, faded by a raised cosine from half the radius to zero at it).
``gaussians``
    Bloom as a sum of Gaussians (Kawase-style), sigmas in pixels and relative weights, ended
    by :func:`tail_fade`.
``exponentials``
    Diffusion (soft focus, Pro-Mist-like filters): a sum of radial exponentials
    ``exp(-d / s)`` (light scattered many times in a turbid layer falls off exponentially),
    ended by :func:`tail_fade`.
``image``
    A user-supplied kernel image (its pixels: the caller reads the file, e.g. glare through
    ``ctx.read_image``), resampled so its larger side spans 2r + 1 pixels; each colour plane
    normalised separately.

Host maths only: nothing here reads files.
"""
from __future__ import annotations

import math

import numpy as np


def spencer_value(t_deg):
    """Spencer et al. 1995 photopic PSF at angle ``t_deg`` (degrees), unnormalised."""
    t = np.asarray(t_deg, np.float64)
    return 2.61e6 * np.exp(-(t / 0.02) ** 2) + 20.91 / (t + 0.02) ** 3 + 72.37 / (t + 0.02) ** 2


def degrees_per_pixel(camera, width_px: float, fov_deg: float = 0.0) -> float:
    """Angle subtended by one pixel at the optical centre.

    ``fov_deg`` > 0 overrides the camera with a horizontal field of view in degrees.
    """
    width_px = max(float(width_px), 1.0)
    if fov_deg > 0.0:
        return math.degrees(2.0 * math.tan(math.radians(fov_deg) / 2.0) / width_px)
    return math.degrees(math.atan(camera.sensor_width / (width_px * camera.focal_length)))


def _radial_grid(radius: int):
    r = int(radius)
    y, x = np.mgrid[-r:r + 1, -r:r + 1].astype(np.float64)
    return x, y


def _normalise(k: np.ndarray) -> np.ndarray:
    s = k.sum(axis=(0, 1), keepdims=True)
    return k / np.where(s > 0, s, 1.0)


def spencer(radius_px: int, deg_per_px: float, *, supersample: int = 8,
            core_px: int = 4, reach: tuple[int, int] | None = None) -> np.ndarray:
    """Normalised Spencer eye PSF on a (2r + 1)^2 grid (see module notes); with ``reach``
    = (dy, dx) only its rows -dy..dy and columns -dx..dx (:func:`window`)."""
    r = max(int(radius_px), 0)
    # area-integrate the centre: the Gaussian core and the 1/t^3 term vary within a pixel;
    # the integrated disc reaches past the Gaussian core (3.5 x 0.02 degrees: exp(-12)), or
    # a long lens shows the switch to point samples as a kink in the profile
    c = min(max(core_px, math.ceil(0.07 / max(deg_per_px, 1e-9))), r)
    n = supersample
    off = (np.arange(n) + 0.5) / n - 0.5
    su, sv = np.meshgrid(off, off)

    def cells(x, y):
        k = spencer_value(np.hypot(x, y) * deg_per_px)
        rows = np.nonzero(np.abs(y[:, 0]) <= c)[0]
        cols = np.nonzero(np.abs(x[0]) <= c)[0]
        for a in rows:
            for b in cols:
                i, j = x[0, b], y[a, 0]
                k[a, b] = spencer_value(np.hypot(i + su, j + sv) * deg_per_px).mean()
        return k

    if windowed(r, reach):
        return window(cells, r, reach, core=c)
    x, y = _radial_grid(r)
    # a round support whose tail is below 1e-5 of the PSF one pixel out before it fades to
    # 0: neither the array's square nor the rim of a truncated power law shows, even on a
    # 1e4 light graded up
    return _normalise(tail_fade(cells(x, y), r)[..., None])[..., 0]


TAIL_FLOOR = 1e-5
"""Where :func:`tail_fade`'s taper starts, a PSF is at most this fraction of its value one
pixel from the centre: 1e-4 of a point light's spread light is the level a graded-up 1e4 light
on black shows, so every truncation happens below it."""

TAIL_ROLL = 0.9
""":func:`tail_fade` brings a tail to ``TAIL_FLOOR`` by this fraction of the radius."""

TAIL_TAPER = 0.5
""":func:`tail_fade`'s raised-cosine taper runs from this fraction of the radius to the
radius.  Over the outer tenth only (as before issue 25) it cut a power-law tail that an
exposure for a dark room lifts (a candle flame's glare: ten times the room at 0.9 radius)
to nothing within a few pixels: a disc with a rim; from half the radius it fades."""


def tail_fade(k: np.ndarray, radius: int, *, floor: float = TAIL_FLOOR,
              start: float = TAIL_TAPER, roll: float = TAIL_ROLL, xy=None,
              edge: tuple[float, float] | None = None) -> np.ndarray:
    """End a centred, radially decreasing (2r + 1)^2 kernel smoothly inside its support.

    Its physical tail is kept where it is above ``floor`` x its value one pixel from the
    centre (``k1``) at ``roll`` x r; where it is not (a power law on a small support, a wide
    Gaussian), it is multiplied by the Gaussian roll-off ``exp(-(d / rho)^2)`` that brings it
    there (smooth and monotone: no kink, no step).  Then a raised cosine takes it from
    ``start`` x r to 0 at r (below ``floor`` x ``k1`` from ``roll`` x r on).  Returns the product
    (not normalised).  ``k`` may be part of the kernel: its offsets ``xy`` = (x, y) from the
    centre and ``edge`` = (``k1``, the value at ``roll`` x r) then given.
    """
    r = int(radius)
    if r < 2:
        return k
    i0 = int(math.floor(roll * r))
    if xy is None:
        x, y = _radial_grid(r)
        edge = float(k[r, r + 1]), float(k[r, r + i0])
    else:
        x, y = xy
    k1, ke = edge
    d = np.hypot(x, y)
    out = k * _taper(x, y, r, start)
    if k1 > 0.0 and ke > floor * k1:
        rho = i0 / math.sqrt(math.log(ke / (floor * k1)))
        out = out * np.exp(-(d / rho) ** 2)
    return out


def radial_taper(radius: int, start: float = 0.75) -> np.ndarray:
    """1 inside ``start * radius``, a raised cosine to 0 at ``radius``: a PSF truncated at
    ``radius`` ends in a soft circle instead of the (visible, on tone-mapped shadows) square
    of its array or a hard rim."""
    o = np.arange(-radius, radius + 1, dtype=np.float64)
    return _taper(o[None, :], o[:, None], radius, start)


def _taper(x, y, radius: int, start: float) -> np.ndarray:
    """:func:`radial_taper` at offsets ``x``, ``y`` from the centre."""
    r = np.hypot(x, y) / max(radius, 1)
    t = np.clip((r - start) / (1.0 - start), 0.0, 1.0)
    return 0.5 + 0.5 * np.cos(np.pi * t)


def gaussians(radius_px: int, sigmas_px, weights,
              reach: tuple[int, int] | None = None) -> np.ndarray:
    """Normalised sum of Gaussians (bloom): sum_i w_i N(0, sigma_i^2), ended by
    :func:`tail_fade` (below 1e-5 of the PSF one pixel out before the taper: a 1e5 sun shows
    neither the array's square nor a rim); with ``reach``, only its rows and columns within
    it (:func:`window`)."""
    r = max(int(radius_px), 0)
    terms = [(max(float(s), 0.3), float(w)) for s, w in zip(sigmas_px, weights)]
    if windowed(r, reach):
        o = np.arange(-r, r + 1, dtype=np.float64)
        # each Gaussian's sum over the whole grid, a separable one: its axis's sum squared
        sums = [np.exp(-0.5 * o * o / (s * s)).sum() ** 2 for s, _ in terms]

        def cells(x, y):
            d2 = x * x + y * y
            return sum(w * np.exp(-0.5 * d2 / (s * s)) / g for (s, w), g in zip(terms, sums))

        return window(cells, r, reach)
    x, y = _radial_grid(r)
    d2 = x * x + y * y
    k = np.zeros_like(d2)
    for s, w in terms:
        g = np.exp(-0.5 * d2 / (s * s))
        k += w * g / g.sum()
    return _normalise(tail_fade(k, r)[..., None])[..., 0]


def exponentials(radius_px: int, scales_px, weights,
                 reach: tuple[int, int] | None = None) -> np.ndarray:
    """Normalised sum of radial exponentials ``sum_i w_i exp(-d / s_i) / (2 pi s_i^2)``
    (diffusion: each term integrates to ``w_i`` over the plane), ended by :func:`tail_fade`;
    with ``reach``, only its rows and columns within it (:func:`window`)."""
    r = max(int(radius_px), 0)

    def cells(x, y):
        d = np.hypot(x, y)
        k = np.zeros_like(d)
        for s, w in zip(scales_px, weights):
            s = max(float(s), 0.5)
            k += float(w) * np.exp(-d / s) / (2.0 * np.pi * s * s)
        return k

    if windowed(r, reach):
        return window(cells, r, reach)
    return _normalise(tail_fade(cells(*_radial_grid(r)), r)[..., None])[..., 0]


# -- the part of a large PSF that reaches a frame ---------------------------------------------
WINDOW_MIN_CELLS = 2 ** 20
"""A PSF of more cells than this (a radius over 511 px) is built only over the rows and
columns that reach the frame when they are fewer (:func:`window`); a smaller one is built
whole (and cut by ``clfx.fx.fftconv.reachable``), as before thin frames had their path."""

CORE_BLEND = 64
"""Pixels over which :func:`window`'s normalisation passes from the exact sum over the
kernel's cells near the centre to the integral over its radial profile."""


def windowed(radius: int, reach: tuple[int, int] | None) -> bool:
    """Whether a PSF of ``radius`` is built only over ``reach`` (:func:`window`)."""
    n = 2 * radius + 1
    return reach is not None and n * n > WINDOW_MIN_CELLS and min(reach) < radius


def cells_built(radius: int, reach: tuple[int, int] | None) -> int:
    """The most cells a PSF of ``radius`` asked for over ``reach`` holds at once while it is
    built: the whole (2r + 1)^2, or its window and 256 rows of its sum (:func:`window`)."""
    n = 2 * int(radius) + 1
    if not windowed(radius, reach):
        return n * n
    dy, dx = min(reach[0], radius), min(reach[1], radius)
    return (2 * dy + 1) * (2 * dx + 1) + 256 * n


def window(cells, radius: int, reach: tuple[int, int], *, core: int = 0,
           fade: bool = True) -> np.ndarray:
    """The rows -dy..dy and columns -dx..dx (``reach`` = (dy, dx), at most the radius) of a
    radially symmetric kernel of ``radius`` ended by :func:`tail_fade`, normalised as the
    whole (2r + 1)^2 kernel is, without building it: a 65535x1 frame's glare PSF is 16385^2
    cells (12 GiB to build), of which the 5 rows around the centre reach the frame.

    ``cells(x, y)``: the kernel before its fade at offsets ``x`` (1, m) and ``y`` (n, 1)
    (whole numbers; within ``core`` px of the centre on both axes it may be what no radial
    profile gives, e.g. an area integral; ``core`` >= r / 1.5 sums every cell, in rows);
    ``fade``: end it by :func:`tail_fade` (else it is used as it is).  The whole kernel's sum is its exact sum over the
    cells within ``a`` = max(32, 1.5 ``core`` + 2) + :data:`CORE_BLEND` px of the centre,
    weighted by a smooth step from 1 at ``a`` - blend to 0 at ``a``, plus the integral of its
    radial profile times the rest (a smooth radial function's sum over the pixel grid is its
    integral to within its Fourier transform at one cycle a pixel: ~1e-12 of it here)."""
    r = int(radius)
    dy, dx = min(int(reach[0]), r), min(int(reach[1]), r)
    i0 = int(math.floor(TAIL_ROLL * r))
    row = cells(np.array([[1.0, float(i0)]]), np.zeros((1, 1)))[0]
    edge = float(row[0]), float(row[1])

    def faded(x, y):
        return tail_fade(cells(x, y), r, xy=(x, y), edge=edge) if fade else cells(x, y)

    inner = max(32, math.ceil(1.5 * core) + 2)
    outer = inner + CORE_BLEND
    if outer >= r:
        blend, total = None, 0.0
        outer = r
    else:
        def blend(d):   # 1 up to inner, a C-infinity step to 0 at outer
            t = np.clip((d - inner) / (outer - inner), 0.0, 1.0)
            a = np.where(t < 1.0, np.exp(-1.0 / np.maximum(1.0 - t, 1e-300)), 0.0)
            b = np.where(t > 0.0, np.exp(-1.0 / np.maximum(t, 1e-300)), 0.0)
            return a / (a + b)

        rho = np.linspace(inner, r, 8 * (r - inner) + 1)
        f = 2.0 * np.pi * rho * faded(rho[None, :], np.zeros((1, 1)))[0] * (1.0 - blend(rho))
        h = rho[1] - rho[0]
        total = float(h / 3.0 * (f[0] + f[-1] + 4.0 * f[1:-1:2].sum() + 2.0 * f[2:-1:2].sum()))
    o = np.arange(-outer, outer + 1, dtype=np.float64)
    for y0 in range(0, o.size, 256):   # the cells near the centre, 256 rows at a time
        y = o[y0:y0 + 256, None]
        part = faded(o[None, :], y)
        if blend is not None:
            part = part * blend(np.hypot(o[None, :], y))
        total += float(part.sum())
    y = np.arange(-dy, dy + 1, dtype=np.float64)[:, None]
    x = np.arange(-dx, dx + 1, dtype=np.float64)[None, :]
    return faded(x, y) / (total if total > 0.0 else 1.0)


def bloom_sigmas(radius_px: float, count: int = 4, ratio: float = 2.0, falloff: float = 0.5):
    """Sigmas (px) and weights of a Kawase-like bloom: ``count`` Gaussians, the widest at
    radius / 3, each next ``ratio`` times narrower, weights multiplied by ``1 / falloff``
    towards the core."""
    sig = [max(radius_px / 3.0 / ratio ** i, 0.5) for i in range(count)]
    w = [falloff ** (count - 1 - i) for i in range(count)]
    return sig, w


def from_image(pixels: np.ndarray, radius_px: int,
               reach: tuple[int, int] | None = None) -> np.ndarray:
    """A kernel image's pixels (h, w): grey, or (h, w, 3 or 4): RGB(A), alpha ignored, as a
    normalised (2r+1, 2r+1, 3) PSF (with ``reach``: its rows and columns within it, see
    :func:`resample_kernel`); negative and non-finite values count as 0."""
    rgb = np.asarray(pixels, np.float64)
    if rgb.ndim == 2:
        rgb = np.repeat(rgb[..., None], 3, axis=2)
    rgb = rgb[..., :3]
    rgb = np.where(np.isfinite(rgb), np.maximum(rgb, 0.0), 0.0)
    return resample_kernel(rgb, radius_px, reach)


def resample_kernel(rgb: np.ndarray, radius_px: int,
                    reach: tuple[int, int] | None = None) -> np.ndarray:
    """Resample an (h, w, 3) kernel image (its centre at the image centre) to (2r+1)^2,
    keeping its aspect (bilinear; area-averaged when shrinking a lot), then normalise.  With
    ``reach`` = (dy, dx) only the rows -dy..dy and columns -dx..dx, normalised as the whole
    (the bilinear weights are separable: the whole's sum is the image weighted by their
    column and row sums, without building it)."""
    r = max(int(radius_px), 0)
    n = 2 * r + 1
    h, w = rgb.shape[:2]
    scale = n / max(h, w)          # output px per input px
    # box pre-filter when shrinking by more than 2x, so small bright details keep their energy
    step = int(1.0 / scale) if scale < 0.5 else 1
    if step > 1:
        hh, ww = h // step * step, w // step * step
        rgb = rgb[:hh, :ww].reshape(hh // step, step, ww // step, step, 3).mean(axis=(1, 3))
        h, w = rgb.shape[:2]
        scale = n / max(h, w)

    def taps(c, size):
        # output tap offsets c sample the image at its centre + c / scale
        s = (size - 1) / 2.0 + c / scale
        i0 = np.floor(s).astype(int)
        return i0, s - i0

    def take(yy, xx):
        ok = (yy[:, None] >= 0) & (yy[:, None] < h) & (xx[None, :] >= 0) & (xx[None, :] < w)
        v = rgb[np.clip(yy, 0, h - 1)[:, None], np.clip(xx, 0, w - 1)[None, :]]
        return np.where(ok[..., None], v, 0.0)

    def cells(cy, cx):
        (y0, fy), (x0, fx) = taps(cy, h), taps(cx, w)
        return ((1 - fy)[:, None, None] * ((1 - fx)[None, :, None] * take(y0, x0) + fx[None, :, None] * take(y0, x0 + 1))
                + fy[:, None, None] * ((1 - fx)[None, :, None] * take(y0 + 1, x0) + fx[None, :, None] * take(y0 + 1, x0 + 1)))

    c = np.arange(n) - r
    if not windowed(r, reach):
        out = cells(c, c)
        if not (out.sum(axis=(0, 1)) > 0).any():
            out[r, r] = 1.0            # an all-black kernel image: no spread rather than 0/0
        return _normalise(out)

    def weights(size):             # each image row's (column's) total bilinear weight
        i0, f = taps(c, size)
        wsum = np.zeros(size)
        for i, wt in ((i0, 1 - f), (i0 + 1, f)):
            ok = (i >= 0) & (i < size)
            np.add.at(wsum, i[ok], wt[ok])
        return wsum

    total = np.einsum("a,abp,b->p", weights(h), rgb, weights(w))
    dy, dx = min(int(reach[0]), r), min(int(reach[1]), r)
    out = cells(np.arange(-dy, dy + 1), np.arange(-dx, dx + 1))
    if not (total > 0).any():
        out[dy, dx] = 1.0
        return out
    return out / np.where(total > 0, total, 1.0)


def psf_radius_px(size: float, diagonal_px: float, limit: int = 8192) -> int:
    """Support radius in pixels for a size given as a fraction of the frame diagonal."""
    return int(min(max(round(size * diagonal_px), 0), limit))


def exponential(radius_px: int, scale_px: float,
                reach: tuple[int, int] | None = None) -> np.ndarray:
    """Normalised radial exponential ``exp(-d / scale)`` (charge diffusion / crosstalk between
    neighbouring photosites), truncated at r; with ``reach``, only its rows and columns within
    it (:func:`window`: a cut, not a fade, so the whole's sum is summed exactly, in rows)."""
    r = max(int(radius_px), 0)

    def cells(x, y):
        d = np.hypot(x, y)
        k = np.exp(-d / max(float(scale_px), 1e-3))
        k[np.broadcast_to(d > r + 0.5, k.shape)] = 0.0
        return k

    if windowed(r, reach):
        return window(cells, r, reach, core=r, fade=False)
    return _normalise(cells(*_radial_grid(r))[..., None])[..., 0]
