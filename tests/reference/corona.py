"""float64 NumPy oracle of clfx/plugins/corona.py: direct convolution of the highlights with
the PSF (the PSF itself is checked separately against the Airy pattern and the physics).
Luminance is the working space's: the Y row of ``rgb_to_xyz`` (None: BT.709's weights)."""
import numpy as np


def luminance_weights(rgb_to_xyz=None):
    return (0.2126, 0.7152, 0.0722) if rgb_to_xyz is None else tuple(np.asarray(rgb_to_xyz)[1])


def highlights(src, threshold, rgb_to_xyz=None):
    """(highlights, clean source): the bright-pass of the source's non-negative part (a
    channel's negative light, outside the reference basis's gamut, is not scattered: it stays
    in place), and the source with non-finite values set to 0, negatives kept."""
    clean = np.where(np.isfinite(src), src, 0.0).astype(np.float64)
    c = np.maximum(clean, 0.0)
    wr, wg, wb = luminance_weights(rgb_to_xyz)
    lum = wr * c[..., 0] + wg * c[..., 1] + wb * c[..., 2]
    k = np.where(lum > threshold, (lum - threshold) / np.where(lum > 0, lum, 1.0), 0.0)
    out = c * k[..., None]
    out[..., 3] = 0.0
    return out, clean


def corona(src, psf, *, threshold, intensity, pad=0, rgb_to_xyz=None, **_):
    """out = clean source - intensity * highlights + intensity * (highlights conv psf) over the
    source grown by pad: the diffracted light moves into the pattern."""
    src = np.asarray(src, np.float64)
    bright, clean = highlights(src, threshold, rgb_to_xyz)
    h, w = src.shape[:2]
    out = np.pad(clean - intensity * bright, ((pad, pad), (pad, pad), (0, 0)))
    r = psf.shape[0] // 2
    ys, xs = np.nonzero(bright[..., :3].max(axis=2) > 0)
    for y, x in zip(ys, xs):              # splat each highlight pixel (plainest form)
        for c in range(3):
            y0, x0 = y + pad - r, x + pad - r
            # clip the PSF footprint to the output
            oy0, ox0 = max(y0, 0), max(x0, 0)
            oy1, ox1 = min(y0 + 2 * r + 1, h + 2 * pad), min(x0 + 2 * r + 1, w + 2 * pad)
            if oy0 >= oy1 or ox0 >= ox1:
                continue
            out[oy0:oy1, ox0:ox1, c] += intensity * bright[y, x, c] * \
                psf[oy0 - y0:oy1 - y0, ox0 - x0:ox1 - x0, c]
    return out
