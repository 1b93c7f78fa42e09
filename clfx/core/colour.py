"""The working space's primaries as plain data: its RGB -> XYZ matrix, the inverse, and the
luminance weights (the matrix's Y row) that effects build spectral tables and thresholds with.

The pipeline takes the matrix from OCIO (`clfx.io.colour.working_rgb_to_xyz`) and hands it
to effects on the render context (``ctx.rgb_to_xyz``); where none is known (a context
built without one, tests) effects work in linear Rec.709, `REC709_TO_XYZ`.  Nothing
here reads a colour configuration: host, fx and plugins never import OpenImageIO.

For Rec.709 the classic constants stand: the IEC 61966-2-1 XYZ -> RGB matrix (OCIO's built-in
config differs from it by 2e-4) and BT.709's rounded luminance weights (0.2126, 0.7152,
0.0722; the matrix's Y row is 0.212673, 0.715152, 0.072175), so Rec.709 renders keep their
pixels.
"""
from __future__ import annotations

import numpy as np

XYZ_TO_REC709 = np.array([[3.2404542, -1.5371385, -0.4985314],
                          [-0.9692660, 1.8760108, 0.0415560],
                          [0.0556434, -0.2040259, 1.0572252]])
"""Linear Rec.709 RGB = XYZ_TO_REC709 @ XYZ (D65 white; IEC 61966-2-1)."""
XYZ_TO_REC709.setflags(write=False)

REC709_TO_XYZ = np.linalg.inv(XYZ_TO_REC709)
"""CIE XYZ (D65) = REC709_TO_XYZ @ linear Rec.709 RGB: the default working space's matrix."""
REC709_TO_XYZ.setflags(write=False)

REC709_LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
"""BT.709's luminance weights, as the standard rounds them."""
REC709_LUMINANCE.setflags(write=False)


def rgb_to_xyz_matrix(m=None) -> np.ndarray:
    """``m`` as a read-only (3, 3) float64 RGB -> XYZ matrix; None: `REC709_TO_XYZ`.

    Raises
    ------
    ValueError
        Not a finite, invertible 3 x 3 matrix with a positive white (``m @ (1, 1, 1)``).
    """
    if m is None or m is REC709_TO_XYZ:
        return REC709_TO_XYZ
    a = np.array(m, np.float64)
    if a.shape != (3, 3) or not np.isfinite(a).all():
        raise ValueError(f"rgb_to_xyz: {np.asarray(m).tolist()} is not a finite 3 x 3 matrix")
    white = a @ np.ones(3)
    if abs(np.linalg.det(a)) < 1e-9 or not (white > 0).all():
        raise ValueError(f"rgb_to_xyz: {a.tolist()} is not an RGB -> XYZ matrix (singular, "
                         f"or white {white.tolist()} not positive)")
    if np.array_equal(a, REC709_TO_XYZ):
        return REC709_TO_XYZ
    a.setflags(write=False)
    return a


def is_rec709(m) -> bool:
    """Whether ``m`` (None = the default) is the default Rec.709 matrix."""
    return m is None or m is REC709_TO_XYZ or np.array_equal(m, REC709_TO_XYZ)


def xyz_to_rgb(m=None) -> np.ndarray:
    """The working space's XYZ -> RGB matrix (the inverse of ``m``; Rec.709: the IEC one)."""
    return XYZ_TO_REC709 if is_rec709(m) else np.linalg.inv(m)


def luminance_weights(m=None) -> np.ndarray:
    """Luminance Y of the working space's RGB: the Y row of ``m`` (Rec.709: 0.2126, ...)."""
    return REC709_LUMINANCE if is_rec709(m) else np.asarray(m, np.float64)[1].copy()


def matrix_key(m=None) -> tuple:
    """A hashable key of ``m`` for caches: () for Rec.709, else its 9 values."""
    return () if is_rec709(m) else tuple(float(v) for v in np.asarray(m).ravel())


def luminance_defines(m=None) -> dict:
    """Build defines that make ``clfx_luminance`` (kernels/lib/common.h) weigh RGB with the
    working space's luminance: none for Rec.709 (its built-in weights)."""
    if is_rec709(m):
        return {}
    r, g, b = luminance_weights(m)
    return {"CLFX_LUMA_R": f"{r:.9g}f", "CLFX_LUMA_G": f"{g:.9g}f", "CLFX_LUMA_B": f"{b:.9g}f"}


def to_reference(m=None) -> np.ndarray | None:
    """The working space's RGB -> the spectral effects' reference basis, linear Rec.709:
    ``XYZ_TO_REC709 @ m`` (`clfx.kit.spectral.in_reference_basis`); None for Rec.709 itself
    (nothing to convert)."""
    return None if is_rec709(m) else XYZ_TO_REC709 @ np.asarray(m, np.float64)
