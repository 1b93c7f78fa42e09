"""float64 NumPy oracle of clfx/plugins/vignette.py: the plainest form of the model."""
import math

import numpy as np


def vignette(src, *, natural, amount, radius, softness, roundness, center,
             focal_length=35.0, sensor_width=36.0, pixel_aspect=1.0,
             data_origin=(0, 0), display_size=None):
    src = np.asarray(src, np.float64)
    h, w = src.shape[:2]
    dw, dh = display_size or (w, h)
    cx = dw / 2 + center[0] * dw / 2
    cy = dh / 2 + center[1] * dh / 2
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    px = xs + data_origin[0] + 0.5 - cx
    py = ys + data_origin[1] + 0.5 - cy
    mm_x = px * sensor_width / dw
    mm_y = py * sensor_width / dw / pixel_aspect
    theta = np.arctan(np.hypot(mm_x, mm_y) / focal_length)
    nat = 1 - natural * (1 - np.cos(theta) ** 4)
    # corner at r = 1: circle uses the half diagonal, ellipse each half axis * sqrt 2
    hw, hh = dw * pixel_aspect / 2, dh / 2
    ax = roundness * pixel_aspect / math.hypot(hw, hh) + (1 - roundness) * pixel_aspect / (hw * math.sqrt(2))
    ay = roundness / math.hypot(hw, hh) + (1 - roundness) / (hh * math.sqrt(2))
    r = np.hypot(px * ax, py * ay)
    t = np.clip((r - radius) / softness, 0, 1)
    art = 1 - amount * t * t * (3 - 2 * t)
    g = np.clip(nat * art, 0, 1)
    out = src.copy()
    out[..., :3] *= g[..., None]
    return out
