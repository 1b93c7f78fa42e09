"""Spectral helpers: CIE 1931 2-degree colour matching functions and XYZ -> the working space.

The colour matching functions use the multi-lobe piecewise-Gaussian fit of Wyman, Sloan and
Shirley (2013), "Simple analytic approximations to the CIE XYZ color matching functions",
JCGT 2(2): a sum of Gaussians whose width differs left and right of each lobe's centre.  Its
error against the tabulated CIE 1931 2-degree observer is below the tables' own precision
for rendering purposes (the paper reports errors comparable to the differences between
observer datasets); the peaks come out at x 1.056 (~600 nm), y 1.0 (~555 nm), z 1.78
(~445 nm).

Every function takes an RGB -> XYZ matrix ``rgb_to_xyz`` (None = linear Rec.709, whose
XYZ -> RGB is the IEC 61966-2-1 matrix ``XYZ_TO_REC709``, `clfx.core.colour`).  Spectral
colours lie outside any RGB gamut with real primaries (less far outside ACEScg's than
Rec.709's), so converted spectra have negative components; :func:`to_gamut` brings them
inside while keeping that space's luminance.

Spectral effects (chromatic aberration, corona, lens flare's physical model) define their
spectral model once, in one reference basis, linear Rec.709 (their tables are built with
the default matrix); `clfx.kit.spectral.in_reference_basis` runs them on pixels of any
other working space as ``B^-1 effect(B rgb)`` with ``B = XYZ_TO_REC709 @ ctx.rgb_to_xyz``,
so the result is the same light in any space.
"""
from __future__ import annotations

import numpy as np

from clfx.core import colour
from clfx.core.colour import REC709_LUMINANCE, XYZ_TO_REC709  # noqa: F401 (re-exported)

VISIBLE_NM = (380.0, 780.0)


def _lobe(lam, mu, sigma_left, sigma_right):
    """A Gaussian with different widths left and right of its centre ``mu`` (nm)."""
    sigma = np.where(lam < mu, sigma_left, sigma_right)
    return np.exp(-0.5 * ((lam - mu) / sigma) ** 2)


def cie1931_cmf(wavelength_nm) -> np.ndarray:
    """CIE 1931 2-degree colour matching functions x, y, z at ``wavelength_nm``.

    Parameters
    ----------
    wavelength_nm : array_like
        Wavelengths in nanometres.

    Returns
    -------
    ndarray, shape (..., 3)
        x-bar, y-bar, z-bar (Wyman-Sloan-Shirley 2013 multi-lobe fit).
    """
    lam = np.asarray(wavelength_nm, np.float64)
    x = (1.056 * _lobe(lam, 599.8, 37.9, 31.0) + 0.362 * _lobe(lam, 442.0, 16.0, 26.7)
         - 0.065 * _lobe(lam, 501.1, 20.4, 26.2))
    y = 0.821 * _lobe(lam, 568.8, 46.9, 40.5) + 0.286 * _lobe(lam, 530.9, 16.3, 31.1)
    z = 1.217 * _lobe(lam, 437.0, 11.8, 36.0) + 0.681 * _lobe(lam, 459.0, 26.0, 13.8)
    return np.stack([x, y, z], axis=-1)


def xyz_to_rec709(xyz) -> np.ndarray:
    """Linear Rec.709 RGB (D65) of CIE XYZ, shape (..., 3) -> (..., 3)."""
    return xyz_to_rgb(xyz)


def xyz_to_rgb(xyz, rgb_to_xyz=None) -> np.ndarray:
    """The working space's RGB of CIE XYZ (D65), shape (..., 3) -> (..., 3)."""
    return np.asarray(xyz, np.float64) @ colour.xyz_to_rgb(rgb_to_xyz).T


def wavelengths(count: int, lo: float = VISIBLE_NM[0], hi: float = VISIBLE_NM[1]) -> np.ndarray:
    """``count`` wavelength sample centres (nm) of equal-width bins covering [lo, hi]."""
    width = (hi - lo) / count
    return lo + width * (np.arange(count) + 0.5)


def spectral_rgb_weights(wavelength_nm, rgb_to_xyz=None) -> np.ndarray:
    """Working-space RGB of each wavelength sample of an equal-energy spectrum, shape (n, 3).

    Each row is ``xyz_to_rgb(cmf(lambda)) * d_lambda``; rows sum to the RGB of the
    equal-energy illuminant E over the sampled band.  Rows may have negative components
    (spectral colours are outside the gamut).
    """
    lam = np.asarray(wavelength_nm, np.float64)
    d_lambda = (VISIBLE_NM[1] - VISIBLE_NM[0]) / lam.size
    return xyz_to_rgb(cie1931_cmf(lam), rgb_to_xyz) * d_lambda


def to_gamut(rgb: np.ndarray, rgb_to_xyz=None) -> np.ndarray:
    """Desaturate each RGB triple toward its own luminance until no component is negative.

    Keeps the working space's luminance (``rgb_to_xyz``'s Y row; Rec.709's by default) and
    hue direction; triples with negative luminance become 0.
    """
    rgb = np.asarray(rgb, np.float64)
    lum = rgb @ colour.luminance_weights(rgb_to_xyz)
    lo = rgb.min(axis=-1)
    # mix(rgb, lum, t) >= 0 needs t >= -lo / (lum - lo) where lo < 0
    t = np.where(lo < 0, -lo / np.maximum(lum - lo, 1e-300), 0.0)
    t = np.clip(t, 0.0, 1.0)[..., None]
    out = rgb * (1 - t) + lum[..., None] * t
    out[lum <= 0] = 0.0
    return np.maximum(out, 0.0)


def channel_weights(wavelength_nm, rgb_to_xyz=None) -> np.ndarray:
    """How a camera's R, G and B channels spread over wavelength samples, shape (n, 3).

    Each column is the channel's sensitivity in the working space (:func:`spectral_rgb_weights`
    with ``rgb_to_xyz``; Rec.709 by default) with its negative lobes dropped, normalised to
    sum 1 over the samples: light of one channel is carried by the wavelengths that channel
    sees, and a spectrally flat (white) light keeps its RGB.  In Rec.709, three samples at
    the primaries' dominant wavelengths (610, 550, 465 nm) give the identity; more samples
    spread each channel over its band (the coloured fringes of lens flare ghosts are then
    graded, not three hard copies).
    """
    w = np.maximum(spectral_rgb_weights(wavelength_nm, rgb_to_xyz), 0.0)
    s = w.sum(axis=0, keepdims=True)
    if np.any(s <= 0.0):
        raise ValueError(f"wavelengths {np.asarray(wavelength_nm).tolist()} leave a colour "
                         f"channel without a sample it sees")
    return w / s


def rgb_matrix(rt, img, m):
    """A new RGBA device image: ``m @ rgb`` of ``img``'s pixels, alpha copied
    (kernels/lib/image.cl ``image_rgb_matrix``, float32)."""
    from pyopencl import cltypes  # lazy: pyopencl is ~0.2 s; `clfx looks` loads this module

    out = img.like()
    f4 = [cltypes.make_float4(*(float(v) for v in r), 0.0) for r in np.asarray(m)]
    rt.launch(rt.kernel("lib/image.cl", "image_rgb_matrix", CH=4, BORDER=0),
              (img.pitch, max(img.height, 1)), img, out, img.pitch, img.height, *f4)
    return out
