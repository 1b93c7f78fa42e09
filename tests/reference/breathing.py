"""float64 NumPy oracle of clfx/plugins/breathing.py: the plainest forms, no shortcuts.

- The scale: the thin-lens image distances v = f S / (S - f) written out in mm, their ratio,
  m = 1 + amount (ratio - 1) (no clamps: callers stay within 1:1 macro).
- The map: every output pixel centre u reads c + (u - c) / m, in float64, and its Jacobian
  (1 / m) I, built per pixel like any map.
- Resampling: the footprint and elliptical filters of the distortion oracle
  (``tests.reference.distortion``: each tap's weight by its definition), edge border.
"""
import numpy as np

from tests.reference.distortion import sample_elliptical, sample_footprint

FOOTPRINT = {"draft": "quadratic", "preview": "bicubic", "final": "lanczos3",
             "reference": "elliptical"}
"""The footprint filter of each quality level."""


def scale(focus, reference, focal_length, amount):
    """m for focus distances in metres and a focal length in mm."""
    f = focal_length
    v = f * (focus * 1000.0) / (focus * 1000.0 - f)
    v0 = f * (reference * 1000.0) / (reference * 1000.0 - f)
    return 1.0 + amount * (v / v0 - 1.0)


def breathing(src, *, m, quality="final", center=(0.0, 0.0), data_window=None,
              display_window=None):
    """``src`` (h, w, 4) over ``data_window`` (x0, y0, x1, y1; default the image at 0, 0)
    scaled by ``m`` about the optical centre: the centre of ``display_window`` (default the
    data window) moved by ``center`` half sizes.  Inside the display window, pixels outside
    the data window are 0; past both, the nearest pixel repeats.  Returns the data window."""
    src = np.asarray(src, np.float64)
    h, w = src.shape[:2]
    dx0, dy0, dx1, dy1 = data_window or (0, 0, w, h)
    px0, py0, px1, py1 = display_window or (dx0, dy0, dx1, dy1)
    cx = (px0 + px1) / 2.0 + center[0] * (px1 - px0) / 2.0
    cy = (py0 + py1) / 2.0 + center[1] * (py1 - py0) / 2.0
    # the source padded with zeros to the display window
    ox, oy = min(dx0, px0), min(dy0, py0)
    padded = np.zeros((max(dy1, py1) - oy, max(dx1, px1) - ox, src.shape[2]))
    padded[dy0 - oy: dy1 - oy, dx0 - ox: dx1 - ox] = src
    xs, ys = np.meshgrid(np.arange(dx0, dx1) + 0.5, np.arange(dy0, dy1) + 0.5)
    sx = cx + (xs - cx) / m - ox
    sy = cy + (ys - cy) / m - oy
    jac = np.zeros((h, w, 2, 2))
    jac[..., 0, 0] = jac[..., 1, 1] = 1.0 / m
    name = FOOTPRINT[quality]
    if name == "elliptical":
        return sample_elliptical(padded, sx, sy, jac, border="edge")
    return sample_footprint(padded, sx, sy, jac, name, border="edge")
