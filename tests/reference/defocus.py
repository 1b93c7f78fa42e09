"""float64 NumPy oracle of clfx/fx/blur.py and clfx/plugins/defocus.py: the plainest formula.

The blur is the exact discrete Gaussian ``exp(-k^2 / 2 sigma^2)``, truncated at 10 sigma (the
tail beyond is < 1e-22) and normalised, applied separably as dense matrices whose rows sum
the weights of every tap onto the pixel the border mode maps it to.
"""
import math

import numpy as np

MIN_SIGMA = 0.3


def border_index(i, n, border):
    """(index, weight factor) of positions ``i`` on a line of ``n`` pixels."""
    i = np.asarray(i)
    if border == "mirror":
        if n == 1:
            return np.zeros_like(i), np.ones(i.shape)
        period = 2 * (n - 1)
        m = np.mod(i, period)
        return np.where(m < n, m, period - m), np.ones(i.shape)
    idx = np.clip(i, 0, n - 1)
    if border == "zero":
        return idx, ((i >= 0) & (i < n)).astype(np.float64)
    return idx, np.ones(i.shape)


def blur_matrix(n_in, n_out, offset, sigma, border, truncate=10.0):
    """(n_out, n_in) matrix: output pixel o is input position o + offset blurred."""
    if sigma < MIN_SIGMA:
        k, g = np.zeros(1, np.int64), np.ones(1)
    else:
        r = math.ceil(truncate * sigma)
        k = np.arange(-r, r + 1)
        g = np.exp(-0.5 * (k / sigma) ** 2)
        g /= g.sum()
    m = np.zeros((n_out, n_in))
    for o in range(n_out):
        idx, inside = border_index(o + offset + k, n_in, border)
        np.add.at(m[o], idx, g * inside)
    return m


def gaussian_blur(src, sigma_x, sigma_y=None, *, border="clamp", offset=(0, 0), out_shape=None):
    """Blur ``src`` (h, w) or (h, w, c); output pixel (x, y) is input position
    (x + offset[0], y + offset[1]) and the output has ``out_shape`` (h, w) (default: src's)."""
    a = np.asarray(src, np.float64)
    sigma_y = sigma_x if sigma_y is None else sigma_y
    h, w = a.shape[:2]
    oh, ow = out_shape or (h, w)
    my = blur_matrix(h, oh, offset[1], sigma_y, border)
    mx = blur_matrix(w, ow, offset[0], sigma_x, border)
    flat = a.reshape(h, w, -1)
    out = np.einsum("oy,yxc->oxc", my, flat, optimize=True)
    out = np.einsum("oxc,px->opc", out, mx, optimize=True)
    return out.reshape((oh, ow) + a.shape[2:])


def defocus_sigmas(size, aspect, diagonal_px, pixel_aspect=1.0):
    """(sigma_x, sigma_y) in pixels: ``size`` x frame diagonal on screen, x divided by the
    pixel aspect so the blur is round on screen, y scaled by ``aspect``."""
    s = size * diagonal_px
    return s / pixel_aspect, s * aspect


def defocus(src, *, size, aspect=1.0, edges="clamp", diagonal_px=None, pixel_aspect=1.0,
            offset=(0, 0), out_shape=None):
    """Defocus of an RGBA image: NaN/Inf set to 0, then a Gaussian blur of every channel."""
    a = np.asarray(src, np.float64)
    a = np.where(np.isfinite(a), a, 0.0)
    h, w = a.shape[:2]
    diag = diagonal_px if diagonal_px is not None else math.hypot(w, h)
    sx, sy = defocus_sigmas(size, aspect, diag, pixel_aspect)
    border = {"black": "zero"}.get(edges, edges)
    return gaussian_blur(a, sx, sy, border=border, offset=offset, out_shape=out_shape)
