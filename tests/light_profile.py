"""Profiles of a point light (1e4 on black) through the light-spreading effects: the checks
that their tails fade smoothly and end below 1e-4 of their brightest pixel (issue 25)."""
from __future__ import annotations

import math

import numpy as np

TAIL_LEVEL = 1e-4
"""Where a profile must be by the time its support ends, and the level below which a step
(a truncation, a taper's shoulder) may no longer show: a 1e4 light on black graded up."""


def point_light(h: int = 180, w: int = 320, value: float = 1e4) -> np.ndarray:
    """A black RGBA frame, alpha 1, with one white pixel of ``value`` at (h // 2, w // 2)."""
    src = np.zeros((h, w, 4), np.float32)
    src[..., 3] = 1.0
    src[h // 2, w // 2, :3] = value
    return src


def flame_in_a_dark_room(h: int, w: int, room: float, spread_x: float, spread_y: float,
                         nits: float = 200.0) -> np.ndarray:
    """An RGBA frame, alpha 1: a dark room (every colour ``room``) with a flame at (h // 2,
    w // 2), a light of ``nits`` falling off as exp(-(dx^2 / spread_x + dy^2 / spread_y))
    (issue 25: CandleGlass's candle, ~3 x 6 px at 640 px wide)."""
    y, x = np.mgrid[0:h, 0:w]
    src = np.full((h, w, 4), room, np.float32)
    src[..., 3] = 1.0
    src[..., :3] += (nits * np.exp(-((x - w // 2) ** 2 / spread_x
                                     + (y - h // 2) ** 2 / spread_y)))[..., None]
    return src


def ray(img: np.ndarray, y: int, x: int, dx: int, dy: int, n: int) -> np.ndarray:
    """``n`` green samples from (y, x) in whole-pixel steps (dx, dy) (float64)."""
    return np.array([img[y + i * dy, x + i * dx, 1] for i in range(n)], np.float64)


def assert_smooth_tail(prof, support: float, *, start: int = 8, what: str = "") -> None:
    """Check a profile from the light (index 0) outwards, normalised by its value 1 px out
    (the brightest spread light outside the light itself):

    - monotone: no sample above the one before it (float32 rounding allowed);
    - below TAIL_LEVEL from 0.95 x ``support`` on (the tail has faded before the support
      ends), and 0 beyond ``support`` + 1;
    - no step above TAIL_LEVEL: from ``start`` px on, while the profile is above TAIL_LEVEL,
      the log-profile's second difference is at most max(0.1, 4 / r^2) (a power law r^-n
      has n / r^2, an exponential 0, a Gaussian of sigma 1 / sigma^2; a truncation or a
      taper's shoulder is far above).
    """
    p = np.asarray(prof, np.float64)
    p1 = p[1]
    assert p1 > 0, f"{what}: no light 1 px from the point"
    end = min(len(p) - 1, int(math.ceil(support)) + 1)
    rise = np.diff(p[1:end + 1]) - (1e-5 * p[1:end] + 1e-7 * p1)
    assert (rise <= 0).all(), f"{what}: rises at r = {np.nonzero(rise > 0)[0][:5] + 1}"
    tail = p[int(0.95 * support):end + 1] / p1
    assert tail.max() < TAIL_LEVEL, f"{what}: {tail.max():.2e} of the peak at 0.95 x support"
    if len(p) > end + 1:
        assert np.abs(p[end + 1:]).max() <= 1e-7 * p1, f"{what}: light beyond the support"
    for r in range(max(start, 2), end):
        if p[r + 1] <= TAIL_LEVEL * p1:
            break
        d2 = abs(math.log(p[r + 1]) - 2.0 * math.log(p[r]) + math.log(p[r - 1]))
        assert d2 <= max(0.1, 4.0 / r ** 2), f"{what}: a step at r = {r} (d2 log {d2:.3f})"
