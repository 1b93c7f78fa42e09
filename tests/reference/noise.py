"""float64 oracle of the alpha coverage shared by the noise effects (clfx/fx/noise.py,
kernels/lib/coverage.h): ``grain`` and ``sensor_noise`` weight their deviation by alpha."""
import numpy as np


def alpha_is_coverage(src, coverage):
    """``coverage`` resolved on ``src`` (h, w, 4): "auto" is alpha unless a finite pixel with
    alpha <= 0 holds light."""
    if coverage != "auto":
        return coverage == "alpha"
    finite = np.isfinite(src).all(axis=-1)
    stray = finite & (src[..., 3] <= 0) & (src[..., :3] != 0).any(axis=-1)
    return not stray.any()


def cover(src, clean, noisy, coverage):
    """RGB ``clean + alpha (noisy - clean)`` where alpha (non-finite: 0) is below 1, with
    alpha clamped to [0, 1]; ``noisy`` elsewhere and when coverage resolves to ignore."""
    if not alpha_is_coverage(src, coverage):
        return noisy
    a = src[..., 3]
    cov = np.clip(np.where(np.isfinite(a), a, 0.0), 0.0, 1.0)[..., None]
    return np.where(cov < 1.0, clean + cov * (noisy - clean), noisy)
