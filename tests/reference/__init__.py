import numpy as np

XYZ_TO_REC709 = np.array([[3.2404542, -1.5371385, -0.4985314],
                          [-0.9692660, 1.8760108, 0.0415560],
                          [0.0556434, -0.2040259, 1.0572252]])
"""Linear Rec.709 RGB from CIE XYZ (D65): the sRGB standard's matrix (IEC 61966-2-1, to 7
decimals as B. Lindbloom tabulates it)."""

REC709_Y = np.array([0.2126, 0.7152, 0.0722])
"""Luminance of linear Rec.709 RGB (ITU-R BT.709's weights, as the standard rounds them)."""


def cie1931(lam):
    """CIE 1931 2-degree colour matching functions (x-bar, y-bar, z-bar) at ``lam`` (nm), shape
    (..., 3): the multi-lobe piecewise Gaussian fit of Wyman, Sloan and Shirley (JCGT 2(2),
    2013, table 1), each lobe a Gaussian of its own width left and right of its centre."""
    lam = np.asarray(lam, np.float64)

    def lobe(mu, left, right):
        return np.exp(-0.5 * ((lam - mu) / np.where(lam < mu, left, right)) ** 2)

    return np.stack([1.056 * lobe(599.8, 37.9, 31.0) + 0.362 * lobe(442.0, 16.0, 26.7)
                     - 0.065 * lobe(501.1, 20.4, 26.2),
                     0.821 * lobe(568.8, 46.9, 40.5) + 0.286 * lobe(530.9, 16.3, 31.1),
                     1.217 * lobe(437.0, 11.8, 36.0) + 0.681 * lobe(459.0, 26.0, 13.8)], -1)


def in_reference_basis(oracle, rgba, rgb_to_xyz):
    """A spectral effect's float64 oracle in another working space: ``rgba`` carried into the
    reference basis (linear Rec.709) by ``B = XYZ_TO_REC709 @ rgb_to_xyz``, the Rec.709
    oracle ``oracle(rgba_ref)``, and its output carried back by ``B^-1`` (alpha kept), as
    clfx.kit.spectral.in_reference_basis does on the device."""
    b = XYZ_TO_REC709 @ np.asarray(rgb_to_xyz, np.float64)
    src = np.array(rgba, np.float64)
    src[..., :3] = src[..., :3] @ b.T
    out = np.array(oracle(src), np.float64)
    out[..., :3] = out[..., :3] @ np.linalg.inv(b).T
    return out
