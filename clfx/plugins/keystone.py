"""Keystone: the perspective of a tilted camera (converging verticals), as a shift lens keeps
the subject centred.

Model
-----
The plate is what a camera whose sensor faced the subject saw (verticals parallel).  Keystone
renders what the same camera sees when it is turned: ``swing`` degrees about the vertical
axis (+ to the right), then ``tilt`` degrees about its own horizontal axis (+ upwards), the
rotation ``R = R_y(swing) R_x(tilt)`` (image coordinates: +x right, +y down, the optical
axis +z).  An output pixel's ray ``(x, y, 1)`` (normalised: ``x = (u - cx) / fx``,
``y = (v - cy) / fy``) is ``R (x, y, 1)`` in the plate camera's frame, and the plate point it
sees is the projection ``P(R (x, y, 1))``, ``P(a, b, c) = (a / c, b / c)``: a homography
``K R K^-1``.  Tilted upwards the top rows read a wider span of the plate (verticals
converge towards the top); swung right, the right side recedes.  As a shift lens does, the
image is shifted so that the frame's centre shows what it showed: the source point is
``P(R (x, y, 1)) - P(R (0, 0, 1))``, so only the perspective changes, not the framing.

Rays more than ``HORIZON_DEG`` (80 degrees) from the plate camera's axis see no source: the
plate is a picture, not the world behind it, and near the horizon one output pixel would
average thousands of texels.  Those pixels are transparent, with a note.

Defaults: ``fx`` = the camera block's focal length in pixels (``camera.focal_length_px``),
fy = fx * pixel_aspect, the principal point at the display window's centre.  ``fit`` and
``border`` are distortion's: ``crop`` (the default) scales up just enough that no pixel of
the display window reads past the plate (overscan first), ``edge`` repeats the frame's edge
texel for taps past it.

Rendering is the warp family's (`clfx.kit.warp.FootprintWarp`): the inverse map and its
analytic Jacobian in float64 on the host, footprints that follow the Jacobian (so the
compressed side is area-averaged, not aliased), kernels from kernels/lib/footprint_warp.h.
This module holds the model only: no band, tile or canvas code.

References: R. Hartley and A. Zisserman, "Multiple View Geometry in Computer Vision", 2nd
ed., 2004, section 8.4.2 (the homography ``K R K^-1`` of a rotating camera).
"""
from __future__ import annotations

import math

import numpy as np

from clfx.core.camera import camera_rotation
from clfx.core.plugin import ChoiceParam, Descriptor, FloatParam
from clfx.fx.resample import BORDERS, FITS, fit_scale, rect_boundary
from clfx.host import Plugin, register
from clfx.kit.warp import FOOTPRINT_LEVELS, FootprintWarp

HORIZON_DEG = 80.0
"""Output rays farther than this from the plate camera's axis have no source."""

MAX_ANGLE_DEG = 60.0
"""The largest tilt and swing accepted."""


def rotation(tilt_deg: float, swing_deg: float) -> np.ndarray:
    """``R = R_y(swing) R_x(tilt)``: the turned camera's axes in the plate camera's frame
    (+y down: a positive tilt turns the axis upwards, a positive swing to the right)."""
    return camera_rotation(math.radians(swing_deg), math.radians(tilt_deg))


def geometry(p, camera, display_window, window, pixel_aspect, plate=None) -> dict:
    """The map's intrinsics, rotation, centring shift and ``fit`` scale for output points in
    ``display_window`` and ``window``; ``plate``: the frame the source's pixels cover
    (default ``display_window`` and ``window``), whose imaged outline ``fit=crop`` fills the
    display window with."""
    fx = p.fx if p.fx > 0 else camera.focal_length_px(max(display_window.width, 1))
    fy = fx * pixel_aspect
    cx, cy = display_window.center
    r = rotation(p.tilt, p.swing)
    g = dict(fx=fx, fy=fy, cx=cx, cy=cy, r=r, shift=(r[0, 2] / r[2, 2], r[1, 2] / r[2, 2]),
             fit_scale=1.0)
    frame = display_window.union(window)
    bx, by = rect_boundary(frame if plate is None else plate) if p.fit == "crop" \
        else rect_boundary(display_window)
    ox, oy = forward_points(g, bx, by)
    g["fit_scale"] = fit_scale(p.fit, display_window, cx, cy, ox, oy)
    return g


def source_points(g, ox, oy, jacobian: bool = False):
    """Source points (frame coordinates, float64; NaN = no source) of output points
    ``(ox, oy)`` (frame coordinates), with ``jacobian`` their Jacobians d(source) /
    d(output) (..., 2, 2)."""
    fx, fy, cx, cy, s = g["fx"], g["fy"], g["cx"], g["cy"], g["fit_scale"]
    m = g["r"]
    x = (np.asarray(ox, np.float64) - cx) / fx * s
    y = (np.asarray(oy, np.float64) - cy) / fy * s
    a = m[0, 0] * x + m[0, 1] * y + m[0, 2]
    b = m[1, 0] * x + m[1, 1] * y + m[1, 2]
    c = m[2, 0] * x + m[2, 1] * y + m[2, 2]
    seen = c > math.cos(math.radians(HORIZON_DEG)) * np.sqrt(x * x + y * y + 1.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        inv_c = np.where(seen, 1.0 / np.where(seen, c, 1.0), np.nan)
    sx = (a * inv_c - g["shift"][0]) * fx + cx
    sy = (b * inv_c - g["shift"][1]) * fy + cy
    if not jacobian:
        return sx, sy
    u, v = a * inv_c, b * inv_c            # d(a / c) / dx = (m00 - (a / c) m20) / c
    jac = np.empty(np.shape(sx) + (2, 2))
    jac[..., 0, 0] = (m[0, 0] - u * m[2, 0]) * inv_c * s
    jac[..., 0, 1] = (m[0, 1] - u * m[2, 1]) * inv_c * s * fx / fy
    jac[..., 1, 0] = (m[1, 0] - v * m[2, 0]) * inv_c * s * fy / fx
    jac[..., 1, 1] = (m[1, 1] - v * m[2, 1]) * inv_c * s
    return sx, sy, jac


def forward_points(g, sx, sy):
    """Where the output shows the source points ``(sx, sy)`` (frame coordinates): the
    rotation's inverse ``R^T`` (NaN where the point is behind the turned camera)."""
    fx, fy, cx, cy, s = g["fx"], g["fy"], g["cx"], g["cy"], g["fit_scale"]
    m = g["r"]
    u = (np.asarray(sx, np.float64) - cx) / fx + g["shift"][0]
    v = (np.asarray(sy, np.float64) - cy) / fy + g["shift"][1]
    a = m[0, 0] * u + m[1, 0] * v + m[2, 0]
    b = m[0, 1] * u + m[1, 1] * v + m[2, 1]
    c = m[0, 2] * u + m[1, 2] * v + m[2, 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        inv_c = np.where(c > 0.0, 1.0 / np.where(c > 0.0, c, 1.0), np.nan)
    return cx + a * inv_c * fx / s, cy + b * inv_c * fy / s


@register
class Keystone(FootprintWarp, Plugin):
    no_source_note = f"seeing more than {HORIZON_DEG:g} degrees off the plate's axis"
    descriptor = Descriptor(
        name="keystone", label="Keystone (tilted camera)", group="Lens", kernel="keystone.cl",
        summary="The perspective of a tilted or swung camera: converging verticals, with the "
                "frame's centre kept as a shift lens keeps it.",
        params=(
            FloatParam("tilt", 0.0, min=-MAX_ANGLE_DEG, max=MAX_ANGLE_DEG, units="deg",
                       hint="Camera tilted up (> 0: verticals converge towards the top) or "
                            "down (< 0), about the frame's horizontal axis."),
            FloatParam("swing", 0.0, min=-MAX_ANGLE_DEG, max=MAX_ANGLE_DEG, units="deg",
                       hint="Camera swung right (> 0: the right side recedes) or left (< 0), "
                            "about the frame's vertical axis."),
            FloatParam("fx", 0.0, min=0.0, max=1e7, units="px",
                       hint="Focal length in pixels along x (a wider lens converges more for "
                            "the same tilt); 0 = from the camera block and frame width."),
            ChoiceParam("fit", "crop", choices=FITS,
                        hint="crop = scale up just enough that no pixel of the display window "
                             "reads past the plate (its overscan used first); none = keep the "
                             "scale (the receding side reads past the plate: border); "
                             "fit-all = the whole plate stays visible; fill = the imaged "
                             "plate touches the frame."),
            ChoiceParam("border", "edge", choices=BORDERS,
                        hint="What points and filter taps outside the frame (display window, "
                             "or the overscan where larger) read: edge (the edge texel "
                             "repeated), mirror, black (transparent)."),
        ),
        quality=FOOTPRINT_LEVELS,
    )

    def is_identity(self, p, ctx):
        if p.tilt == 0.0 and p.swing == 0.0:
            return "tilt and swing are 0"
        return None

    # -- the model (clfx.kit.warp.FootprintWarp renders it) ----------------------------------
    def warp_geometry(self, p, ctx, plate):
        return geometry(p, ctx.camera, ctx.display_window, ctx.source.window, ctx.pixel_aspect,
                        plate)

    def warp_points(self, g, ox, oy, jacobian):
        return source_points(g, ox, oy, jacobian)

    def warp_forward(self, g, sx, sy):
        return forward_points(g, sx, sy)

    def warp_info(self, g):
        return dict(fx=g["fx"], fy=g["fy"], cx=g["cx"], cy=g["cy"], fit_scale=g["fit_scale"])

    def reads_anywhere(self, g, rect):
        # part of the window behind the turned camera: its content lands anywhere
        ox, oy = forward_points(g, *rect_boundary(rect, 64))
        return not (np.isfinite(ox).all() and np.isfinite(oy).all())
