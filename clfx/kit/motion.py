"""The motion family's band protocol: what motion_blur, camera_blur and rolling_shutter share
between the gather (`clfx.fx.motion`) and the host: the passes a frame brings that line up
with its source, and the rows a band of a tiled render reads beyond its own.
"""
from __future__ import annotations

import math

from clfx.fx.motion import is_static, path_reach, reach_factor


def aligned_passes(ctx):
    """``ctx``'s depth pass and the backward half of its vector pass where they cover the
    source window, else None (an effect then renders without them)."""
    src = ctx.source
    depth = ctx.depth if ctx.depth is not None and ctx.depth.window == src.window else None
    back = getattr(ctx, "velocity_back", None)
    return depth, (back if back is not None and back.window == src.window else None)


REACH_MARGIN_ROWS = 5
"""Rows a band's buffers hold beyond the farthest sample (:func:`band_margin`): the clamped
cubic's taps (2), the sub-pixel closed form's (2 along the path, bilinear), the dilation's
neighbour (1)."""


def band_margin(t0: float, t1: float, radius: float, curved: bool) -> int:
    """Rows beyond a band that its reconstruction reads (its region of interest): the
    farthest sample (:func:`path_reach` at the clamped speed ``radius / reach``) and
    :data:`REACH_MARGIN_ROWS`; 0 when nothing moves."""
    if is_static(t0, t1, radius):
        return 0
    return (int(math.ceil(path_reach(t0, t1, curved) * radius / reach_factor(t0, t1)))
            + REACH_MARGIN_ROWS)
