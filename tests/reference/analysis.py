"""float64 NumPy oracle of the per-tile scene statistics (clfx/fx/analysis.py)."""
import numpy as np


def tile_stats(rgba, depth=None, velocity=None, tile=32):
    """Per tile: max luminance, mean luminance (non-finite channels as 0 / tile area), non-finite
    count, max speed, min / max valid depth, invalid-depth count, max alpha."""
    rgba = np.asarray(rgba, np.float64)
    h, w = rgba.shape[:2]
    ty, tx = max(1, -(-h // tile)), max(1, -(-w // tile))
    out = np.zeros((ty, tx, 8))
    for j in range(ty):
        for i in range(tx):
            sl = np.s_[j * tile:(j + 1) * tile, i * tile:(i + 1) * tile]
            c = rgba[sl]
            ok = np.isfinite(c).all(axis=-1)
            lum = 0.2126 * c[..., 0] + 0.7152 * c[..., 1] + 0.0722 * c[..., 2]
            out[j, i, 0] = max(0.0, lum[ok].max()) if ok.any() else 0.0
            cz = np.where(np.isfinite(c), c, 0.0)
            lum_z = 0.2126 * cz[..., 0] + 0.7152 * cz[..., 1] + 0.0722 * cz[..., 2]
            out[j, i, 1] = lum_z.sum() / max(c.shape[0] * c.shape[1], 1)
            out[j, i, 2] = (~ok).sum()
            out[j, i, 7] = max(0.0, c[..., 3][ok].max()) if ok.any() else 0.0
            if velocity is not None:
                v = np.asarray(velocity, np.float64)[sl]
                s = np.hypot(v[..., 0], v[..., 1])
                s = s[np.isfinite(s)]
                out[j, i, 3] = s.max() if s.size else 0.0
            if depth is not None:
                z = np.asarray(depth, np.float64)[sl]
                valid = z > 0
                out[j, i, 4] = z[valid].min() if valid.any() else np.inf
                out[j, i, 5] = z[valid].max() if valid.any() else 0.0
                out[j, i, 6] = (~valid).sum()
    return out
