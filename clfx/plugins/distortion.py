"""Distortion: Brown-Conrady lens distortion with OpenCV's conventions (barrel, pincushion,
tangential), rendered through a robustly inverted map.

Model (OpenCV, ``cv2.projectPoints``)
-------------------------------------
An undistorted point u_u (pixels) has normalised coordinates x = (u - cx) / fx,
y = (v - cy) / fy.  The lens images it at

    x_d = x R + 2 p1 x y + p2 (r^2 + 2 x^2),   y_d = y R + p1 (r^2 + 2 y^2) + 2 p2 x y,
    R = 1 + k1 r^2 + k2 r^4 + k3 r^6,           r^2 = x^2 + y^2,

and u_d = (fx x_d + cx, fy y_d + cy).  Coefficients from an OpenCV calibration
(``cv2.calibrateCamera``'s ``dist = [k1, k2, p1, p2, k3]`` and its camera matrix) can be
pasted as they are: ``cx, cy`` are then in OpenCV's pixel convention (pixel centres at
integers, relative to the display window's origin).

Rendering (adding the defect): out(u_d) = src(u_u) with model(u_u) = u_d, i.e. every output
pixel shows the undistorted point whose OpenCV projection lands on it.  The inverse is solved
per parameter set on the host in float64: a radial start from a monotonic 1D table of the
radial map (bracketed: only the branch before the fold), then 2D Newton on the full model
including the tangential terms, and a residual check (points that do not converge to 1e-6 px
get no source).  The map is kept in the runtime's cache and reused for every frame.

Resampling follows the map's local scale.  Where the lens compresses the source (barrel
towards the corners: up to 2x here for k1 = -0.35), an output pixel's preimage spans several
texels and a fixed kernel read at one point aliases.  The map's Jacobian J = d(source) /
d(output) is analytic (the inverse of the model's Jacobian at the source point); every level
widens its filter by the variance the preimage adds beyond a texel, (W^2 - 1) / 12 along each
axis (``clfx.fx.resample.footprint_spread``), and splits footprints too wide for its window
into sub-footprints.  Where the map magnifies nothing is added: preview, final and reference
are then exactly the point filters (Keys, Lanczos-3).  The reference spreads n x n Lanczos-3
samples along J's principal axes (the covariance of the preimage, rotated), in float64.
Scored on the bench's ground truth (the area-averaged exact distortion of a procedural
texture), every level beats bilinear remap on the exact map.

Defaults: fx = the camera block's focal length in pixels (``camera.focal_length_px``), fy =
fx * pixel_aspect (pixels taller than wide need fewer of them per mm vertically), principal
point at the display window's centre.  ``amount`` adds a resolution-independent barrel (< 0)
or pincushion (> 0): k1 += amount / r_c^2, where r_c is the normalised radius of the frame
corner, so the corner moves by ``amount`` of its radius.

Parameters whose radial map folds over (d r_d / d r_u <= 0) inside the frame are refused
with a ParamError: a real lens images each point once, and a folded map has two answers.
Output points beyond the largest radius the lens reaches have no source and are transparent;
points whose source lies outside the frame (the display window, or the data window where it
is larger) are filled by ``border`` at the frame's edge.  Inside the frame, pixels outside
the data window (an element's tight bounding box) are transparent black, never an edge to
repeat.

The frame's edge (issue 32): a barrel reads past the plate towards the frame's edge (cinema's
k1 = -0.02 by 1-3 px on a 1000 px frame), and a filter centred near the edge reaches past it
with its outer taps.  Until ``fit`` and ``border`` defaulted to ``crop`` and ``edge`` both
read transparent black there: a 1-2 px dark frame round every render (CandleGlass through
cinema: column 0 at ~0, column 1 at 44 % of the interior).  ``crop`` scales the output up
just enough that the display window reads inside the plate (overscan included, so a plate
with margin keeps its scale; a pincushion never scales), and ``edge`` gives the taps past the
edge the edge texel, so the border is as bright as the interior.  ``fit=none,
border=black`` renders the lens model unscaled with a transparent outside.

Windows: the output covers where the data window's content lands (``region_of_definition``:
the data window's outline, grown by the filters' reach, mapped forward), within the output
limit, so a magnified element grows its window instead of being cut at it; a window whose
content shrinks (barrel, fit) keeps the data window.  The map is built for that window's
pixels (``clfx.kit.warp.on_canvas``).

``fit``: ``crop`` (default) scales up just enough that no pixel of the display window reads
past the plate (``fill`` with the plate's outline, overscan included, and never below 1);
``none`` keeps the scale; ``fit-all`` scales the output so the whole source frame stays
visible (its imaged outline touches the frame); ``fill`` so that the imaged display window
touches the frame (no undefined border; a pincushion is scaled down to touch it).

References: D. C. Brown, "Decentering distortion of lenses", 1966; OpenCV camera
calibration documentation (calib3d).
"""
from __future__ import annotations

import math

import numpy as np

from clfx.core.plugin import ChoiceParam, Descriptor, FloatParam
from clfx.fx.resample import (BORDERS, FITS, check_fold, fit_scale, fold_radius,
                              pixel_centres, rect_boundary)
from clfx.host import Plugin, register
from clfx.kit.warp import FOOTPRINT_LEVELS, FootprintWarp

NEWTON_STEPS = 8
RESIDUAL_TOL_PX = 1e-6

def intrinsics(p, camera, display_window, pixel_aspect):
    """(fx, fy, cx, cy) with cx, cy in clfx frame coordinates (pixel centres at +0.5)."""
    fx = p.fx if p.fx > 0 else camera.focal_length_px(max(display_window.width, 1))
    fy = p.fy if p.fy > 0 else fx * pixel_aspect
    dcx, dcy = display_window.center
    cx = display_window.x0 + p.cx + 0.5 if p.cx != 0 else dcx
    cy = display_window.y0 + p.cy + 0.5 if p.cy != 0 else dcy
    return fx, fy, cx, cy


def corner_radius(rect, fx, fy, cx, cy) -> float:
    """Largest normalised radius of the corners of ``rect``."""
    return max(math.hypot((x - cx) / fx, (y - cy) / fy)
               for x in (rect.x0, rect.x1) for y in (rect.y0, rect.y1))


def coefficients(p, camera, display_window, pixel_aspect):
    """(k1, k2, k3, p1, p2) with ``amount`` folded into k1."""
    fx, fy, cx, cy = intrinsics(p, camera, display_window, pixel_aspect)
    k1 = p.k1
    if p.amount != 0.0:
        rc = corner_radius(display_window, fx, fy, cx, cy)
        k1 += p.amount / max(rc * rc, 1e-12)
    return (k1, p.k2, p.k3, p.p1, p.p2)


def project(x, y, k):
    """OpenCV's distortion of normalised points: (x_d, y_d)."""
    k1, k2, k3, p1, p2 = k
    r2 = x * x + y * y
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    return (x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
            y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)


def radial_forward(k):
    k1, k2, k3 = k[:3]
    return lambda r: r * (1 + r * r * (k1 + r * r * (k2 + r * r * k3)))


def radial_derivative(k):
    k1, k2, k3 = k[:3]
    return lambda r: 1 + r * r * (3 * k1 + r * r * (5 * k2 + r * r * 7 * k3))


def monotonic_range(k, r_needed: float) -> float:
    """Upper end of the increasing branch of the radial map, searched to 4 r_needed."""
    return fold_radius(radial_derivative(k), max(4.0 * r_needed, 1e-6))


def undistort(xd, yd, k, r_hi: float, fx: float):
    """Inverse of :func:`project`: normalised (x_u, y_u), NaN where there is no source.

    Radial start: the radial map r_u -> r_d tabulated on its increasing branch [0, r_hi]
    and inverted by interpolation (a bracket, so Newton cannot jump to the other branch or
    a negative radius); then ``NEWTON_STEPS`` steps of 2D Newton on the full model.  Points
    whose residual exceeds ``RESIDUAL_TOL_PX`` (in pixels, via fx) or whose radius leaves
    [0, r_hi] get NaN.
    """
    k1, k2, k3, p1, p2 = k
    fwd = radial_forward(k)
    r_tab = np.linspace(0.0, r_hi, 65537)
    rd_tab = fwd(r_tab)
    r_d = np.hypot(xd, yd)
    r_u = np.interp(r_d, rd_tab, r_tab, right=np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(r_d > 0, r_u / np.where(r_d > 0, r_d, 1.0), 1.0)
    x, y = xd * s, yd * s
    active = np.ones(np.shape(x), bool)
    for _ in range(NEWTON_STEPS):
        r2 = x * x + y * y
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        dradial = k1 + r2 * (2 * k2 + r2 * 3 * k3)        # dR / d(r^2)
        ex, ey = project(x, y, k)
        ex, ey = ex - xd, ey - yd
        j11 = radial + 2 * x * x * dradial + 2 * p1 * y + 6 * p2 * x
        j12 = 2 * x * y * dradial + 2 * p1 * x + 2 * p2 * y
        j21 = j12
        j22 = radial + 2 * y * y * dradial + 6 * p1 * y + 2 * p2 * x
        det = j11 * j22 - j12 * j21
        with np.errstate(invalid="ignore", divide="ignore"):
            step_x = (j22 * ex - j12 * ey) / det
            step_y = (j11 * ey - j21 * ex) / det
        x = np.where(active, x - step_x, x)
        y = np.where(active, y - step_y, y)
        # quadratic convergence: a point stops once its step is far below the tolerance (each
        # point's own, so a point's source is the same whatever else is mapped with it: the
        # bands of a tiled render)
        active &= (np.abs(step_x) * fx > 1e-9) | (np.abs(step_y) * fx > 1e-9)
        if not active.any():
            break
    ex, ey = project(x, y, k)
    residual = np.hypot(ex - xd, ey - yd) * fx
    bad = ~(residual <= RESIDUAL_TOL_PX) | ~(np.hypot(x, y) <= r_hi)
    x = np.where(bad, np.nan, x)
    y = np.where(bad, np.nan, y)
    return x, y


def _geometry(p, camera, display_window, window, pixel_aspect, name, plate=None):
    """Intrinsics, coefficients, fit scale and the radial bracket [0, r_hi] for output
    points inside ``display_window`` and ``window``.  ``plate``: the frame the source's
    pixels cover (`clfx.kit.warp.warp_frame`; default ``display_window`` and ``window``),
    whose imaged outline ``fit=crop`` fills the display window with.  Raises ParamError on
    a fold."""
    fx, fy, cx, cy = intrinsics(p, camera, display_window, pixel_aspect)
    k = coefficients(p, camera, display_window, pixel_aspect)
    frame = display_window.union(window)
    r_corner = corner_radius(frame, fx, fy, cx, cy)
    r_fold = monotonic_range(k, r_corner)
    check_fold(name, f"k1={k[0]:.6g}, k2={k[1]:.6g}, k3={k[2]:.6g}", r_fold, r_corner,
               "normalised by the focal length in pixels")
    # The source frame's outline as the lens images it, for the fit scale (crop: the
    # plate's, overscan included, so a margin the plate has is used before it scales).
    bx, by = rect_boundary(frame if plate is None else plate) if p.fit == "crop" \
        else rect_boundary(display_window)
    dxn, dyn = project((bx - cx) / fx, (by - cy) / fy, k)
    s_fit = fit_scale(p.fit, display_window, cx, cy, dxn * fx + cx, dyn * fy + cy)
    r_hi = r_fold if math.isfinite(r_fold) else _reach(k, r_corner * s_fit)
    return dict(fx=fx, fy=fy, cx=cx, cy=cy, k=k, fit_scale=s_fit, r_fold=r_fold, r_hi=r_hi)


def _jacobian(x, y, g):
    """d(source point) / d(output point) in pixels (..., 2, 2) at normalised source points
    (x, y): the inverse of the model's Jacobian, scaled by the intrinsics and fit."""
    k1, k2, k3, p1, p2 = g["k"]
    r2 = x * x + y * y
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    dradial = k1 + r2 * (2 * k2 + r2 * 3 * k3)
    j11 = radial + 2 * x * x * dradial + 2 * p1 * y + 6 * p2 * x
    j12 = 2 * x * y * dradial + 2 * p1 * x + 2 * p2 * y
    j22 = radial + 2 * y * y * dradial + 6 * p1 * y + 2 * p2 * x
    with np.errstate(invalid="ignore", divide="ignore"):
        inv_det = g["fit_scale"] / (j11 * j22 - j12 * j12)
    fx, fy = g["fx"], g["fy"]
    jac = np.empty(np.shape(x) + (2, 2))
    jac[..., 0, 0] = j22 * inv_det
    jac[..., 0, 1] = -j12 * inv_det * fx / fy
    jac[..., 1, 0] = -j12 * inv_det * fy / fx
    jac[..., 1, 1] = j11 * inv_det
    return jac


def map_points(p, camera, display_window, window, pixel_aspect, ox, oy, *,
               name="distortion", jacobian=False, plate=None):
    """Source points (frame coordinates, float64; NaN = no source) of output points
    ``(ox, oy)`` (frame coordinates, anywhere inside ``display_window`` or ``window``), and
    with ``jacobian`` their Jacobians d(source) / d(output) (..., 2, 2)."""
    return _points(_geometry(p, camera, display_window, window, pixel_aspect, name, plate),
                   ox, oy, jacobian)


def _points(g, ox, oy, jacobian):
    fx, fy, cx, cy, s_fit = g["fx"], g["fy"], g["cx"], g["cy"], g["fit_scale"]
    xu, yu = undistort((ox - cx) / fx * s_fit, (oy - cy) / fy * s_fit, g["k"], g["r_hi"], fx)
    if jacobian:
        return xu * fx + cx, yu * fy + cy, _jacobian(xu, yu, g)
    return xu * fx + cx, yu * fy + cy


def forward_points(g, sx, sy):
    """Where the output shows the source points ``(sx, sy)`` (frame coordinates): the
    model's projection, scaled by the fit about the principal point (the map's inverse)."""
    fx, fy, cx, cy, s_fit = g["fx"], g["fy"], g["cx"], g["cy"], g["fit_scale"]
    xd, yd = project((sx - cx) / fx, (sy - cy) / fy, g["k"])
    return cx + xd * fx / s_fit, cy + yd * fy / s_fit


def build_map(p, camera, display_window, window, pixel_aspect, *, name="distortion",
              jacobian=False, plate=None):
    """Source points (frame coordinates, float64) for the pixel centres of ``window``.

    Returns ``(sx, sy, info)``; ``info`` holds the intrinsics, coefficients, fit scale, the
    count of output pixels without a source and, with ``jacobian``, the map's Jacobian
    d(source) / d(output) per pixel (``info["jacobian"]``, (h, w, 2, 2), analytic: the
    inverse of the model's Jacobian at the source point).  Raises ParamError if the radial
    map folds over inside the frame.  ``plate``: as in `_geometry`.
    """
    g = _geometry(p, camera, display_window, window, pixel_aspect, name, plate)
    out = _points(g, *pixel_centres(window), jacobian)
    sx, sy = out[:2]
    info = dict(fx=g["fx"], fy=g["fy"], cx=g["cx"], cy=g["cy"], k=g["k"],
                fit_scale=g["fit_scale"], no_source=int(np.count_nonzero(~np.isfinite(sx))),
                r_fold=g["r_fold"])
    if jacobian:
        info["jacobian"] = out[2]
    return sx, sy, info


def _reach(k, r_needed: float) -> float:
    """A radius whose image exceeds r_needed on a map that never folds."""
    fwd = radial_forward(k)
    r = max(r_needed, 1e-6)
    while fwd(r) < r_needed and r < 1e6:
        r *= 2.0
    return max(r, r_needed) * 1.01


@register
class Distortion(FootprintWarp, Plugin):
    no_source_note = "beyond the lens's reach"
    descriptor = Descriptor(
        name="distortion", label="Lens distortion", group="Lens", kernel="distortion.cl",
        summary="Brown-Conrady barrel/pincushion/tangential distortion with OpenCV's "
                "conventions, through a robustly inverted map.",
        params=(
            FloatParam("amount", 0.0, min=-0.9, max=2.0,
                       hint="Simple barrel (< 0) or pincushion (> 0): the frame corner moves by "
                            "this fraction of its radius (adds to k1)."),
            FloatParam("k1", 0.0, min=-10.0, max=10.0,
                       hint="OpenCV radial coefficient of r^2 (r normalised by the focal length)."),
            FloatParam("k2", 0.0, min=-100.0, max=100.0, hint="OpenCV radial coefficient of r^4."),
            FloatParam("k3", 0.0, min=-1000.0, max=1000.0, hint="OpenCV radial coefficient of r^6."),
            FloatParam("p1", 0.0, min=-1.0, max=1.0, hint="OpenCV tangential (decentering) coefficient p1."),
            FloatParam("p2", 0.0, min=-1.0, max=1.0, hint="OpenCV tangential (decentering) coefficient p2."),
            FloatParam("fx", 0.0, min=0.0, max=1e7,
                       hint="Focal length in pixels along x; 0 = from the camera block and frame width."),
            FloatParam("fy", 0.0, min=0.0, max=1e7,
                       hint="Focal length in pixels along y; 0 = fx times the pixel aspect."),
            FloatParam("cx", 0.0, min=-1e6, max=1e6,
                       hint="Principal point x in OpenCV pixels (pixel centres at integers, from "
                            "the display window's left); 0 = display window centre."),
            FloatParam("cy", 0.0, min=-1e6, max=1e6,
                       hint="Principal point y in OpenCV pixels from the display window's top; "
                            "0 = display window centre."),
            ChoiceParam("fit", "crop", choices=FITS,
                        hint="crop = scale up just enough that no pixel of the display window "
                             "reads past the plate (its overscan used first; 1 for a "
                             "pincushion); none = keep the scale (a barrel reads past the "
                             "plate: border); fit-all = the whole source stays visible; "
                             "fill = the imaged source touches the frame."),
            ChoiceParam("border", "edge", choices=BORDERS,
                        hint="What points and filter taps outside the frame (display window, "
                             "or the overscan where larger) read: edge (the edge texel "
                             "repeated), mirror, black (transparent: darkens the frame's "
                             "edge); inside the frame, outside the data window is transparent "
                             "black."),
        ),
        quality=FOOTPRINT_LEVELS,
    )

    def is_identity(self, p, ctx):
        if p.amount == 0.0 and p.k1 == p.k2 == p.k3 == p.p1 == p.p2 == 0.0:
            return "amount and all coefficients (k1, k2, k3, p1, p2) are 0"
        return None

    # -- the model (clfx.kit.warp.FootprintWarp renders it) ----------------------------------
    def warp_geometry(self, p, ctx, plate):
        return _geometry(p, ctx.camera, ctx.display_window, ctx.source.window,
                         ctx.pixel_aspect, "distortion", plate)

    def warp_points(self, g, ox, oy, jacobian):
        return _points(g, ox, oy, jacobian)

    def warp_forward(self, g, sx, sy):
        return forward_points(g, sx, sy)

    def warp_info(self, g):
        return dict(fx=g["fx"], fy=g["fy"], cx=g["cx"], cy=g["cy"], k=g["k"],
                    fit_scale=g["fit_scale"], r_fold=g["r_fold"])

    def reads_anywhere(self, g, rect):
        # near the fold (|J| = 50 near a strong barrel's): points anywhere
        return corner_radius(rect, g["fx"], g["fy"], g["cx"], g["cy"]) >= g["r_fold"]
