"""float64 NumPy oracle of clfx/plugins/keystone.py: the plainest forms, no shortcuts.

- The turned camera: its optical axis and image axes built by Rodrigues' rotation formula,
  first the swing about the plate camera's vertical axis, then the tilt about the swung
  camera's own horizontal axis; each output pixel's ray expressed in the plate camera's
  frame by those axes, intersected with the plate's image plane (z = 1), and shifted so the
  frame's centre sees what it saw.  Rays more than 80 degrees off the plate's axis see
  nothing (NaN).
- The Jacobian d(source) / d(output) by central differences of that map (1e-4 px).
- Resampling: the shared footprint filters' oracle (tests/reference/distortion.py:
  ``sample_footprint`` and the reference's ``sample_elliptical``).
"""
import math

import numpy as np

from tests.reference.distortion import sample_elliptical, sample_footprint

HORIZON_DEG = 80.0


def rodrigues(axis, angle_deg, v):
    """``v`` (..., 3) rotated by ``angle_deg`` about the unit ``axis`` (right-handed in
    image coordinates: +x right, +y down, +z along the plate camera's axis)."""
    k = np.asarray(axis, np.float64)
    k = k / np.linalg.norm(k)
    a = math.radians(angle_deg)
    v = np.asarray(v, np.float64)
    return (v * math.cos(a) + np.cross(k, v) * math.sin(a)
            + k * (v @ k)[..., None] * (1.0 - math.cos(a)))


def camera_axes(tilt, swing):
    """The turned camera's x, y and z axes in the plate camera's frame: swung about the
    plate's vertical axis (+: the axis turns right, +x), then tilted about its own x axis
    (+: the axis turns up, -y)."""
    axes = [rodrigues((0.0, 1.0, 0.0), swing, e) for e in np.eye(3)]
    return [rodrigues(axes[0], tilt, e) for e in axes]


def keystone_points(ox, oy, *, tilt, swing, fx, fy, cx, cy, fit_scale=1.0):
    """Source points (frame coordinates) that output points ``(ox, oy)`` show."""
    ex, ey, ez = camera_axes(tilt, swing)
    x = (np.asarray(ox, np.float64) - cx) / fx * fit_scale
    y = (np.asarray(oy, np.float64) - cy) / fy * fit_scale
    ray = x[..., None] * ex + y[..., None] * ey + ez          # in the plate camera's frame
    centre_x, centre_y = ez[0] / ez[2], ez[1] / ez[2]        # where the centre's ray lands
    cos_off_axis = ray[..., 2] / np.linalg.norm(ray, axis=-1)
    seen = cos_off_axis > math.cos(math.radians(HORIZON_DEG))
    with np.errstate(divide="ignore", invalid="ignore"):
        sx = (ray[..., 0] / ray[..., 2] - centre_x) * fx + cx
        sy = (ray[..., 1] / ray[..., 2] - centre_y) * fy + cy
    return np.where(seen, sx, np.nan), np.where(seen, sy, np.nan)


def keystone_map(width, height, **args):
    """Source points of each output pixel's centre (+0.5) and their Jacobians."""
    xs, ys = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    sx, sy = keystone_points(xs, ys, **args)
    e = 1e-4
    ax, ay = keystone_points(xs + e, ys, **args)
    bx, by = keystone_points(xs - e, ys, **args)
    cx_, cy_ = keystone_points(xs, ys + e, **args)
    dx_, dy_ = keystone_points(xs, ys - e, **args)
    jac = np.empty(sx.shape + (2, 2))
    jac[..., 0, 0] = (ax - bx) / (2 * e)
    jac[..., 0, 1] = (cx_ - dx_) / (2 * e)
    jac[..., 1, 0] = (ay - by) / (2 * e)
    jac[..., 1, 1] = (cy_ - dy_) / (2 * e)
    return sx, sy, jac


def keystone(src, *, footprint="lanczos3", border="edge", half=None, **map_args):
    """Keystone ``src`` with the footprint filter ``footprint`` ("quadratic", "bicubic",
    "lanczos3" or "elliptical"; ``half``: the float16-offset pixels of the draft filter,
    ``sample_footprint``)."""
    src = np.asarray(src, np.float64)
    h, w = src.shape[:2]
    sx, sy, jac = keystone_map(w, h, **map_args)
    jac = np.where(np.isfinite(jac), jac, 0.0)
    if footprint == "elliptical":
        return sample_elliptical(src, sx, sy, jac, border)
    return sample_footprint(src, sx, sy, jac, footprint, border, half)
