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
            core_px: int = 4) -> np.ndarray:
    """Normalised Spencer eye PSF on a (2r + 1)^2 grid (see module notes)."""
    r = max(int(radius_px), 0)
    x, y = _radial_grid(r)
    k = spencer_value(np.hypot(x, y) * deg_per_px)
    # area-integrate the centre: the Gaussian core and the 1/t^3 term vary within a pixel;
    # the integrated disc reaches past the Gaussian core (3.5 x 0.02 degrees: exp(-12)), or
    # a long lens shows the switch to point samples as a kink in the profile
    c = min(max(core_px, math.ceil(0.07 / max(deg_per_px, 1e-9))), r)
    n = supersample
    off = (np.arange(n) + 0.5) / n - 0.5
    su, sv = np.meshgrid(off, off)
    for j in range(-c, c + 1):
        for i in range(-c, c + 1):
            k[r + j, r + i] = spencer_value(np.hypot(i + su, j + sv) * deg_per_px).mean()
    # a round support whose tail is below 1e-5 of the PSF one pixel out before it fades to
    # 0: neither the array's square nor the rim of a truncated power law shows, even on a
    # 1e4 light graded up
    return _normalise(tail_fade(k, r)[..., None])[..., 0]


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
              start: float = TAIL_TAPER, roll: float = TAIL_ROLL) -> np.ndarray:
    """End a centred, radially decreasing (2r + 1)^2 kernel smoothly inside its support.

    Its physical tail is kept where it is above ``floor`` x its value one pixel from the
    centre (``k1``) at ``roll`` x r; where it is not (a power law on a small support, a wide
    Gaussian), it is multiplied by the Gaussian roll-off ``exp(-(d / rho)^2)`` that brings it
    there (smooth and monotone: no kink, no step).  Then a raised cosine takes it from
    ``start`` x r to 0 at r (below ``floor`` x ``k1`` from ``roll`` x r on).  Returns the product
    (not normalised).
    """
    r = int(radius)
    if r < 2:
        return k
    k1 = float(k[r, r + 1])
    i0 = int(math.floor(roll * r))
    ke = float(k[r, r + i0])
    x, y = _radial_grid(r)
    d = np.hypot(x, y)
    out = k * radial_taper(r, start)
    if k1 > 0.0 and ke > floor * k1:
        rho = i0 / math.sqrt(math.log(ke / (floor * k1)))
        out = out * np.exp(-(d / rho) ** 2)
    return out


def radial_taper(radius: int, start: float = 0.75) -> np.ndarray:
    """1 inside ``start * radius``, a raised cosine to 0 at ``radius``: a PSF truncated at
    ``radius`` ends in a soft circle instead of the (visible, on tone-mapped shadows) square
    of its array or a hard rim."""
    o = np.arange(-radius, radius + 1, dtype=np.float64)
    r = np.hypot(o[None, :], o[:, None]) / max(radius, 1)
    t = np.clip((r - start) / (1.0 - start), 0.0, 1.0)
    return 0.5 + 0.5 * np.cos(np.pi * t)


def gaussians(radius_px: int, sigmas_px, weights) -> np.ndarray:
    """Normalised sum of Gaussians (bloom): sum_i w_i N(0, sigma_i^2), ended by
    :func:`tail_fade` (below 1e-5 of the PSF one pixel out before the taper: a 1e5 sun shows
    neither the array's square nor a rim)."""
    r = max(int(radius_px), 0)
    x, y = _radial_grid(r)
    d2 = x * x + y * y
    k = np.zeros_like(d2)
    for s, w in zip(sigmas_px, weights):
        s = max(float(s), 0.3)
        g = np.exp(-0.5 * d2 / (s * s))
        k += float(w) * g / g.sum()
    return _normalise(tail_fade(k, r)[..., None])[..., 0]


def exponentials(radius_px: int, scales_px, weights) -> np.ndarray:
    """Normalised sum of radial exponentials ``sum_i w_i exp(-d / s_i) / (2 pi s_i^2)``
    (diffusion: each term integrates to ``w_i`` over the plane), ended by :func:`tail_fade`."""
    r = max(int(radius_px), 0)
    x, y = _radial_grid(r)
    d = np.hypot(x, y)
    k = np.zeros_like(d)
    for s, w in zip(scales_px, weights):
        s = max(float(s), 0.5)
        k += float(w) * np.exp(-d / s) / (2.0 * np.pi * s * s)
    return _normalise(tail_fade(k, r)[..., None])[..., 0]


def bloom_sigmas(radius_px: float, count: int = 4, ratio: float = 2.0, falloff: float = 0.5):
    """Sigmas (px) and weights of a Kawase-like bloom: ``count`` Gaussians, the widest at
    radius / 3, each next ``ratio`` times narrower, weights multiplied by ``1 / falloff``
    towards the core."""
    sig = [max(radius_px / 3.0 / ratio ** i, 0.5) for i in range(count)]
    w = [falloff ** (count - 1 - i) for i in range(count)]
    return sig, w


def from_image(pixels: np.ndarray, radius_px: int) -> np.ndarray:
    """A kernel image's pixels (h, w): grey, or (h, w, 3 or 4): RGB(A), alpha ignored, as a
    normalised (2r+1, 2r+1, 3) PSF; negative and non-finite values count as 0."""
    rgb = np.asarray(pixels, np.float64)
    if rgb.ndim == 2:
        rgb = np.repeat(rgb[..., None], 3, axis=2)
    rgb = rgb[..., :3]
    rgb = np.where(np.isfinite(rgb), np.maximum(rgb, 0.0), 0.0)
    return resample_kernel(rgb, radius_px)


def resample_kernel(rgb: np.ndarray, radius_px: int) -> np.ndarray:
    """Resample an (h, w, 3) kernel image (its centre at the image centre) to (2r+1)^2,
    keeping its aspect (bilinear; area-averaged when shrinking a lot), then normalise."""
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
    out = np.zeros((n, n, 3))
    c = np.arange(n) - r
    # output tap (j, i) samples the image at its centre + offset / scale
    ys = (h - 1) / 2.0 + c / scale
    xs = (w - 1) / 2.0 + c / scale
    y0 = np.floor(ys).astype(int)
    x0 = np.floor(xs).astype(int)
    fy, fx = ys - y0, xs - x0

    def take(yy, xx):
        ok = (yy[:, None] >= 0) & (yy[:, None] < h) & (xx[None, :] >= 0) & (xx[None, :] < w)
        v = rgb[np.clip(yy, 0, h - 1)[:, None], np.clip(xx, 0, w - 1)[None, :]]
        return np.where(ok[..., None], v, 0.0)

    out = ((1 - fy)[:, None, None] * ((1 - fx)[None, :, None] * take(y0, x0) + fx[None, :, None] * take(y0, x0 + 1))
           + fy[:, None, None] * ((1 - fx)[None, :, None] * take(y0 + 1, x0) + fx[None, :, None] * take(y0 + 1, x0 + 1)))
    if not (out.sum(axis=(0, 1)) > 0).any():
        out[r, r] = 1.0            # an all-black kernel image: no spread rather than 0/0
    return _normalise(out)


def psf_radius_px(size: float, diagonal_px: float, limit: int = 8192) -> int:
    """Support radius in pixels for a size given as a fraction of the frame diagonal."""
    return int(min(max(round(size * diagonal_px), 0), limit))


def exponential(radius_px: int, scale_px: float) -> np.ndarray:
    """Normalised radial exponential ``exp(-d / scale)`` (charge diffusion / crosstalk between
    neighbouring photosites), truncated at r."""
    r = max(int(radius_px), 0)
    x, y = _radial_grid(r)
    d = np.hypot(x, y)
    k = np.exp(-d / max(float(scale_px), 1e-3))
    k[d > r + 0.5] = 0.0
    return _normalise(k[..., None])[..., 0]
