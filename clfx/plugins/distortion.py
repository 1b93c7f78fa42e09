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

Defaults: fx = the camera block's focal length in pixels (``camera.focal_length_px``), fy =
fx * pixel_aspect (pixels taller than wide need fewer of them per mm vertically), principal
point at the display window's centre.  ``amount`` adds a resolution-independent barrel (< 0)
or pincushion (> 0): k1 += amount / r_c^2, where r_c is the normalised radius of the frame
corner, so the corner moves by ``amount`` of its radius.

Parameters whose radial map folds over (d r_d / d r_u <= 0) inside the frame are refused
with a ParamError: a real lens images each point once, and a folded map has two answers.
Output points beyond the largest radius the lens reaches have no source and are transparent;
points whose source lies outside the source image are filled by ``border``.

``fit``: ``none`` keeps the scale; ``fit-all`` scales the output so the whole source frame
stays visible (its imaged outline touches the frame); ``fill`` so that no output pixel reads
outside the source frame (no undefined border).

References: D. C. Brown, "Decentering distortion of lenses", 1966; OpenCV camera
calibration documentation (calib3d).
"""
from __future__ import annotations

import math

import numpy as np

from clfx.core.plugin import ChoiceParam, Descriptor, FloatParam
from clfx.fx.resample import (BORDERS, PackedMap, ResampleLevel, check_fold, fit_scale,
                              fold_radius, frame_key, kernel_defines, launch_packed,
                              needs_sanitising, pixel_centres, rect_boundary, upload_map)
from clfx.host import Plugin, register

NEWTON_STEPS = 8
RESIDUAL_TOL_PX = 1e-6

LEVELS = {
    "draft": ResampleLevel("bilinear (2x2) from a packed map (texel indices + float32 "
                           "fractions), float32 sums", filter="bilinear"),
    "preview": ResampleLevel("bicubic (Keys a=-0.5, 4x4) with the 2x2 anti-ringing clamp, "
                             "packed map, float32 sums", filter="bicubic"),
    "final": ResampleLevel("Lanczos-3 (6x6) with the 2x2 anti-ringing clamp, packed map "
                           "(positions to ~1e-7 px; border tiles ~1e-4 px at 4K), float32 sums",
                           filter="lanczos3"),
    "reference": ResampleLevel("Lanczos-3 with the anti-ringing clamp, float64 map and float64 "
                               "sums", fp64=True, filter="lanczos3"),
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
        x = x - step_x
        y = y - step_y
        # quadratic convergence: stop once every step is far below the tolerance
        if not (np.nanmax(np.abs(step_x), initial=0.0) * fx > 1e-9
                or np.nanmax(np.abs(step_y), initial=0.0) * fx > 1e-9):
            break
    ex, ey = project(x, y, k)
    residual = np.hypot(ex - xd, ey - yd) * fx
    bad = ~(residual <= RESIDUAL_TOL_PX) | ~(np.hypot(x, y) <= r_hi)
    x = np.where(bad, np.nan, x)
    y = np.where(bad, np.nan, y)
    return x, y


def build_map(p, camera, display_window, window, pixel_aspect, *, name="distortion"):
    """Source points (frame coordinates, float64) for the pixel centres of ``window``.

    Returns ``(sx, sy, info)``; ``info`` holds the intrinsics, coefficients, fit scale and
    the count of output pixels without a source.  Raises ParamError if the radial map folds
    over inside the frame.
    """
    fx, fy, cx, cy = intrinsics(p, camera, display_window, pixel_aspect)
    k = coefficients(p, camera, display_window, pixel_aspect)
    frame = display_window.union(window)
    r_corner = corner_radius(frame, fx, fy, cx, cy)
    r_fold = monotonic_range(k, r_corner)
    check_fold(name, f"k1={k[0]:.6g}, k2={k[1]:.6g}, k3={k[2]:.6g}", r_fold, r_corner,
               "normalised by the focal length in pixels")
    # The source frame's outline as the lens images it, for the fit scale.
    bx, by = rect_boundary(display_window)
    dxn, dyn = project((bx - cx) / fx, (by - cy) / fy, k)
    s_fit = fit_scale(p.fit, display_window, cx, cy, dxn * fx + cx, dyn * fy + cy)
    ox, oy = pixel_centres(window)
    xd = (ox - cx) / fx * s_fit
    yd = (oy - cy) / fy * s_fit
    r_needed = float(np.nanmax(np.hypot(xd, yd))) if xd.size else 0.0
    r_hi = r_fold if math.isfinite(r_fold) else _reach(k, r_needed)
    xu, yu = undistort(xd, yd, k, r_hi, fx)
    sx, sy = xu * fx + cx, yu * fy + cy
    info = dict(fx=fx, fy=fy, cx=cx, cy=cy, k=k, fit_scale=s_fit,
                no_source=int(np.count_nonzero(~np.isfinite(sx))), r_fold=r_fold)
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
            ChoiceParam("fit", "none", choices=("none", "fit-all", "fill"),
                        hint="none; fit-all = the whole source stays visible; fill = no "
                             "undefined border."),
            ChoiceParam("border", "black", choices=BORDERS,
                        hint="What points outside the source read: black (transparent), edge "
                             "(clamp), mirror."),
        ),
        quality=LEVELS,
    )

    def is_identity(self, p, ctx):
        if p.amount == 0.0 and p.k1 == p.k2 == p.k3 == p.p1 == p.p2 == 0.0:
            return "amount and all coefficients (k1, k2, k3, p1, p2) are 0"
        return None

    def host_map(self, rt, p, ctx):
        """The float64 source points of ``ctx.source``'s pixels (source-window coordinates,
        NaN = no source) and the map's info, kept in ``rt.cache`` (shared by the packed and
        the float64 device maps)."""
        src = ctx.source

        def build():
            sx, sy, info = build_map(p, ctx.camera, ctx.display_window, src.window,
                                     ctx.pixel_aspect)
            return sx - src.window.x0, sy - src.window.y0, info

        return rt.cache.get(("distortion.host_map",) + frame_key(p, ctx), build)

    def device_map(self, rt, p, ctx, double):
        """The device map for this parameter set and frame geometry, kept in ``rt.cache``:
        ``(map, info)``; float levels: a :class:`clfx.fx.resample.DevicePackedMap` (one serves
        bilinear, bicubic and Lanczos-3); ``double`` (reference): a float64 displacement map.
        """
        src = ctx.source

        def build():
            sx, sy, info = self.host_map(rt, p, ctx)
            if double:
                ox, oy = pixel_centres(src.window, frame_origin=False)
                return upload_map(rt, sx - ox, sy - oy, src.pitch, True), info
            return PackedMap([(sx, sy)], src.width, src.height, src.pitch).upload(rt), info

        return rt.cache.get(("distortion.map",) + frame_key(p, ctx) + (double,), build)

    def render(self, rt, p, ctx):
        src = ctx.source
        lvl = self.level(ctx)
        double = rt.use_fp64(lvl.fp64)
        dmap, info = self.device_map(rt, p, ctx, double)
        if info["no_source"]:
            ctx.notes.append(f"distortion: {info['no_source']} px beyond the lens's reach "
                             f"left transparent")
        defines = kernel_defines(lvl.filter, p.border, needs_sanitising(ctx, "distortion"))
        dst = src.like()
        i32 = np.int32
        tail = (i32(src.pitch), i32(src.width), i32(src.height), i32(dst.pitch), i32(dst.height))
        if double:
            knl = rt.kernel("distortion.cl", "distortion_warp_f64", fp64=lvl.fp64, **defines)
            rt.launch(knl, (src.pitch // 4, max(src.height, 1)), src, dst, dmap, *tail)
            return dst
        launch_packed(rt, rt.kernel("distortion.cl", "distortion_warp", fp64=lvl.fp64, **defines),
                      rt.kernel("distortion.cl", "distortion_fix", fp64=lvl.fp64, **defines),
                      dmap, lvl.filter, src.pitch // 4, src.height, (src, dst), tail)
        return dst
