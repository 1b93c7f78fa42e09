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
pixels (``clfx.fx.resample.on_canvas``).

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
from clfx.fx.resample import (BORDERS, FITS, CanvasRows, FootprintMap, ResampleLevel,
                              band_window, canvas_context, check_fold, elliptical_map,
                              fit_scale, fold_radius, footprint_defines, frame_key,
                              launch_footprint, map_bands, on_plate_canvas, pixel_centres,
                              plate_frame, rect_boundary, WARP_REACH_TEXELS, warp_frame,
                              warp_interest, warp_region)
from clfx.host import Plugin, register

NEWTON_STEPS = 8
RESIDUAL_TOL_PX = 1e-6

LEVELS = {
    "draft": ResampleLevel("footprint quadratic (3x3): 3-point interpolation plus a variance term "
                           "that follows the map's Jacobian (area-averages where the lens "
                           "compresses the source), packed map, float32 sums",
                           filter="quadratic", footprint=True),
    "preview": ResampleLevel("footprint bicubic (4x4): Keys blended with the cubic B-spline as "
                             "the map's Jacobian asks, anti-ringing clamp, packed map, float32 "
                             "sums", filter="bicubic", footprint=True),
    "final": ResampleLevel("footprint Lanczos-3 (up to 8x8): the mean of two Lanczos-3 samples "
                           "spread by the map's Jacobian, anti-ringing clamp, packed map "
                           "(positions to ~1e-7 px), float32 sums",
                           filter="lanczos3", footprint=True),
    "reference": ResampleLevel("elliptical footprint: n x n Lanczos-3 samples spread along the "
                               "Jacobian's principal axes (covariance of the output pixel's "
                               "preimage), float64 map and sums", fp64=True, filter="lanczos3",
                               footprint=True),
}


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
    pixels cover (`clfx.fx.resample.warp_frame`; default ``display_window`` and ``window``),
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


def _widest(g, rect, n: int = 33) -> float:
    """The largest |J| (2-norm, texels per output pixel) of the map over ``rect``: its
    outline and an n x n grid (compression grows with the radius up to a fold, so the
    outline holds the maximum of the models accepted here; the grid covers the others)."""
    if rect.empty:
        return 1.0
    bx, by = rect_boundary(rect, 256)
    gx, gy = np.meshgrid(np.linspace(rect.x0, rect.x1, n), np.linspace(rect.y0, rect.y1, n))
    _, _, jac = _points(g, np.concatenate([bx, gx.ravel()]), np.concatenate([by, gy.ravel()]),
                        True)
    norms = np.linalg.norm(np.nan_to_num(jac), ord=2, axis=(-2, -1))
    return max(float(norms.max(initial=0.0)), 1.0)


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
class Distortion(Plugin):
    whole_frame = None   # a tile computes its band's rows of the whole canvas (`on_canvas`)
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
        quality=LEVELS,
    )

    def is_identity(self, p, ctx):
        if p.amount == 0.0 and p.k1 == p.k2 == p.k3 == p.p1 == p.p2 == 0.0:
            return "amount and all coefficients (k1, k2, k3, p1, p2) are 0"
        return None

    def geometry(self, p, ctx):
        return _geometry(p, ctx.camera, ctx.display_window, ctx.source.window,
                         ctx.pixel_aspect, "distortion", plate_frame(ctx))

    def region_of_definition(self, p, ctx):
        # Output pixels read up to ~0.75 |J| + 4 texels from their source points (footprints
        # widen where the lens compresses: |J| = 50 near a strong barrel's fold), so the data
        # window grown by that, mapped forward, bounds where its content lands.  Kept in
        # ``rt.cache`` with the maps: the Jacobian survey costs tens of milliseconds of host
        # time, asked several times a frame and the same for every frame of a shot.
        def build():
            g = self.geometry(p, ctx)
            widest = _widest(g, ctx.source.window.union(ctx.output_limit))
            reach = math.ceil(0.75 * widest) + WARP_REACH_TEXELS - 4
            if corner_radius(ctx.source.window.grown(reach + 4), g["fx"], g["fy"], g["cx"],
                             g["cy"]) >= g["r_fold"]:
                return ctx.source.window.union(warp_frame(ctx))   # near the fold: anywhere
            return warp_region(lambda xs, ys: [forward_points(g, xs, ys)], ctx, p.border,
                               reach=reach)

        return ctx.runtime.cache.get(("distortion.rod",) + frame_key(p, ctx)
                                     + (ctx.output_limit,), build)

    def region_of_interest(self, p, ctx, window):
        def build():
            g = self.geometry(p, ctx)
            return warp_interest(lambda x, y: [_points(g, x, y, False)], window,
                                 4 + math.ceil(0.75 * _widest(g, window)))

        return ctx.runtime.cache.get(("distortion.roi",) + frame_key(p, ctx) + (window,),
                                     build)

    def host_map(self, rt, p, ctx, plate):
        """The float64 source points of ``ctx.source``'s pixels (source-window coordinates,
        NaN = no source), their Jacobians and the map's info, kept in ``rt.cache`` (shared by
        every level's device map).  ``plate``: the frame the plate covers (`plate_frame` of
        the step's context: ``ctx`` is the canvas's)."""
        src = ctx.source

        def build():
            sx, sy, info = build_map(p, ctx.camera, ctx.display_window, src.window,
                                     ctx.pixel_aspect, jacobian=True, plate=plate)
            return sx - src.window.x0, sy - src.window.y0, info.pop("jacobian"), info

        return rt.cache.get(("distortion.host_map",) + frame_key(p, ctx) + (plate,), build)

    def device_map(self, rt, p, ctx, filter_name, double, plate, rows=None):
        """The device map of one level, kept in ``rt.cache``: ``(map, info)``; float levels a
        :class:`clfx.fx.resample.DeviceFootprintMap` of their footprint filter; ``double``
        (reference) the float64 elliptical map (:func:`clfx.fx.resample.elliptical_map`).
        ``rows``: the `CanvasRows` of ``ctx.source``'s window (the canvas) to map (default
        all: a tile maps its band's); ``plate`` as in `host_map`."""
        src = ctx.source
        rows = rows or CanvasRows.whole(src.window)

        def build():
            if rows.tiled or (not double and len(map_bands(src.height, src.pitch)) > 1):
                return self.banded_map(rt, p, ctx, None if double else filter_name, rows,
                                       plate)
            sx, sy, jac, info = self.host_map(rt, p, ctx, plate)
            if double:
                return elliptical_map(rt, sx, sy, jac, src.pitch), info
            return FootprintMap(sx, sy, jac, filter_name, src.width, src.height, src.pitch,
                                p.border).upload(rt), info

        key = "elliptical" if double else filter_name
        return rt.cache.get(("distortion.map",) + frame_key(p, ctx) + (plate, key) + rows.key,
                            build)

    def prepare(self, rt, p, ctx):
        if not self.is_identity(p, ctx):
            lvl = self.level(ctx)
            self.device_map(rt, p, canvas_context(self, p, ctx, p.border), lvl.filter,
                            rt.use_fp64(lvl.fp64), plate_frame(ctx))

    def banded_map(self, rt, p, ctx, filter_name, rows, plate):
        """A frame larger than one band (``clfx.fx.resample.map_bands``), or a tile's band
        of rows (``rows``): the footprint map built band by band from the same geometry (no
        float64 map of the whole frame is kept), or with ``filter_name`` None the reference's
        elliptical map of ``rows``: ``(map, info)``."""
        src = ctx.source
        g = _geometry(p, ctx.camera, ctx.display_window, src.window, ctx.pixel_aspect,
                      "distortion", plate)
        no_source = 0

        def points_of(y0, y1):
            nonlocal no_source
            sx, sy, jac = _points(g, *pixel_centres(band_window(src.window, y0, y1)), True)
            no_source += int(np.count_nonzero(~np.isfinite(sx)))
            return sx - src.window.x0, sy - src.window.y0, jac

        if filter_name is None:
            dmap = elliptical_map(rt, *points_of(*rows.span), src.pitch, rows.first)
        else:
            dmap = FootprintMap.device(rt, points_of, filter_name, src.width, src.height,
                                       src.pitch, p.border, rows.span)
        info = dict(fx=g["fx"], fy=g["fy"], cx=g["cx"], cy=g["cy"], k=g["k"],
                    fit_scale=g["fit_scale"], no_source=no_source, r_fold=g["r_fold"])
        return dmap, info

    def render(self, rt, p, ctx):
        return on_plate_canvas(self, rt, p, ctx, p.border)

    def render_canvas(self, rt, p, ctx, sanitise, plate, rows=None):
        """The warp over ``ctx.source``'s window (the canvas: `on_canvas`, or the part of it
        a tile holds: ``rows``, the `CanvasRows` to compute, default all); ``plate``: the
        frame the plate covers (`on_plate_canvas`)."""
        src = ctx.source
        rows = rows or CanvasRows.whole(src.window)
        canvas = rows.canvas
        lvl = self.level(ctx)
        double = rt.use_fp64(lvl.fp64)
        dmap, info = self.device_map(rt, p, rows.context(ctx), lvl.filter, double, plate, rows)
        if info["no_source"]:
            ctx.notes.append(f"distortion: {info['no_source']} px beyond the lens's reach "
                             f"left transparent")
        defines = footprint_defines(lvl.filter, p.border, sanitise)
        dst = src.like()
        if not double:
            defines["CLFX_STREAM_STORES"] = int(rt.streams_stores(dst.nbytes))
        tail = (src.pitch, canvas.width, canvas.height, dst.pitch, rows.count, rows.first,
                rows.shift)
        if double:
            knl = rt.kernel("distortion.cl", "distortion_ewa_f64", fp64=lvl.fp64, **defines)
            rt.launch(knl, (src.pitch // 4, max(rows.count, 1)), src, dst, dmap, *tail)
            return dst
        launch_footprint(rt, rt.kernel("distortion.cl", "distortion_footprint", **defines),
                         dmap, src.pitch // 4, rows.count, (src, dst), tail)
        return dst
