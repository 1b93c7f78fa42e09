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


def breathing(src, *, m, quality="final", center=(0.0, 0.0), data_origin=(0, 0),
              display_size=None):
    """``src`` (h, w, 4) scaled by ``m`` about the optical centre: the display window's centre
    (``display_size`` (w, h), default the source's) moved by ``center`` half sizes; the source
    sits at ``data_origin`` in the display window's coordinates."""
    src = np.asarray(src, np.float64)
    h, w = src.shape[:2]
    dw, dh = display_size or (w, h)
    cx = dw / 2.0 + center[0] * dw / 2.0
    cy = dh / 2.0 + center[1] * dh / 2.0
    ox, oy = data_origin
    xs, ys = np.meshgrid(np.arange(w) + 0.5 + ox, np.arange(h) + 0.5 + oy)
    sx = cx + (xs - cx) / m - ox
    sy = cy + (ys - cy) / m - oy
    jac = np.zeros((h, w, 2, 2))
    jac[..., 0, 0] = jac[..., 1, 1] = 1.0 / m
    name = FOOTPRINT[quality]
    if name == "elliptical":
        return sample_elliptical(src, sx, sy, jac, border="edge")
    return sample_footprint(src, sx, sy, jac, name, border="edge")
