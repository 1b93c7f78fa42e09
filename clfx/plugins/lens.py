"""Lens: the distortion, transverse chromatic aberration and vignetting of a real lens, from
the lensfun database, applied in the simulating direction (adding the defects).

Model (lensfun's, with lensfun's coordinates: see ``clfx.fx.lensdb``)
------------------------------------------------------------------
Radii are normalised (r = 1 at half the short side of the calibration frame).  Each model
maps an undistorted radius r_u to the radius r_d at which the lens images it:

    poly3   r_d = r_u (1 - k1 + k1 r_u^2)
    poly5   r_d = r_u (1 + k1 r_u^2 + k2 r_u^4)
    ptlens  r_d = r_u (a r_u^3 + b r_u^2 + c r_u + 1 - a - b - c)
    TCA linear  r_c = k_c r_g;   TCA poly3  r_c = r_g (b_c r_g^2 + c_c r_g + v_c)  (c = red, blue)
    vignetting pa   I_d = I (1 + k1 r^2 + k2 r^4 + k3 r^6),  r = 1 at the calibration corner

Simulating (lensfun's ``reverse=True``): the output pixel u reads green (and alpha) at the
undistorted point u_g = D^-1(u) and red/blue at T_c^-1(u_g) (the TCA model inverted about the
same centre), then RGB is multiplied by the vignetting polynomial at u.  Inverses are found
by float64 bisection on the increasing branch (maps that fold inside the frame are refused),
once per parameter set: the green map point by point, the TCA inverses as radial tables.
The float levels then look the tables up on the host (float64) and pack every channel's
source points (green, red, blue) into a :class:`clfx.fx.resample.PackedMap` (a pure gather on
the device, border quads through a second, checked kernel); the reference level reads a
float64 displacement map and float64 tables in the kernel.  Vignetting is evaluated in the
kernels (a short polynomial per pixel).

The frame's edge: ``fit`` defaults to ``crop`` (as distortion's): a barrel lens reads past
the plate towards the frame's edge, so the output is scaled up just enough that the display
window reads inside the plate (overscan included; never below 1, so a pincushion keeps
lensfun's scale 1), and ``border=edge`` gives filter taps past the edge the edge texel: no
dark and no repeated rows at the border.  ``fit=none`` is lensfun's scale 1.

The calibration is interpolated by lensfun itself (``lensfunpy.Lens.interpolate_*``) at the
focal length, aperture and distance (0 = from the camera block); the crop factor comes from
the camera block's sensor size.  The tests check the coordinates against lensfunpy's
``Modifier`` (reverse mode) and the vignetting against its colour modification.
"""
from __future__ import annotations

import math

import numpy as np

from clfx.core.errors import ParamError
from clfx.core.plugin import BoolParam, ChoiceParam, Descriptor, FloatParam, StringParam
from clfx.fx import lensdb
from clfx.fx.resample import (BORDERS, FITS, DevicePackedMap, PackedMap, ResampleLevel, band_window,
                              check_fold, fit_scale, fold_radius, kernel_defines, launch_packed,
                              lut_lookup, map_bands, pixel_centres, radial_inverse,
                              radial_inverse_fast, radial_lut, rect_boundary, upload_map,
                              warp_interest)
from clfx.host import Plugin, register
from clfx.kit.warp import (CanvasRows, PlateCanvasWarp, frame_key, plate_frame,
                           warp_region)

LUT_SIZE = 1024

LEVELS = {
    "draft": ResampleLevel("bilinear (2x2) from a packed map of the green, red and blue source "
                           "points (texel indices + float32 fractions, from float64 geometry), "
                           "float32 sums", filter="bilinear"),
    "preview": ResampleLevel("bicubic (Keys a=-0.5, 4x4) with the 2x2 anti-ringing clamp, "
                             "packed map, float32 sums", filter="bicubic"),
    "final": ResampleLevel("Lanczos-3 (6x6) with the 2x2 anti-ringing clamp, packed map, "
                           "float32 sums", filter="lanczos3"),
    "reference": ResampleLevel("Lanczos-3 with the anti-ringing clamp, float64 map, tables and "
                               "sums", fp64=True, filter="lanczos3"),
}


def distortion_model(name, terms):
    """(forward, derivative) of a lensfun distortion model in normalised radius."""
    if name == "poly3":
        k1 = terms[0]
        return (lambda r: r * (1 - k1 + k1 * r * r), lambda r: 1 - k1 + 3 * k1 * r * r)
    if name == "poly5":
        k1, k2 = terms[:2]
        return (lambda r: r * (1 + k1 * r * r + k2 * r ** 4),
                lambda r: 1 + 3 * k1 * r * r + 5 * k2 * r ** 4)
    a, b, c = terms[:3]
    d = 1 - a - b - c
    return (lambda r: r * (a * r ** 3 + b * r * r + c * r + d),
            lambda r: 4 * a * r ** 3 + 3 * b * r * r + 2 * c * r + d)


def tca_models(name, terms):
    """[(forward, derivative)] for red and blue."""
    if name == "linear":
        return [(lambda r, k=k: k * r, lambda r, k=k: k + 0 * r) for k in terms[:2]]
    vr, vb, cr, cb, br, bb = terms[:6]
    return [(lambda r, v=v, c=c, b=b: r * (b * r * r + c * r + v),
             lambda r, v=v, c=c, b=b: 3 * b * r * r + 2 * c * r + v)
            for v, c, b in ((vr, cr, br), (vb, cb, bb))]


def settings(p, camera):
    """(focal mm, f-number, distance m) with 0 taken from the camera block."""
    focal = p.focal_length or camera.focal_length
    aperture = p.aperture or camera.f_number
    distance = p.distance or camera.focus_distance
    return focal, aperture, distance


def simulation_geometry(cal, norm, display_window, window, fit="none", distortion=True,
                        points=None, plate=None):
    """Green source points (frame coordinates) for ``window``'s pixel centres (or for the
    output ``points`` (xs, ys), frame coordinates), and info.  ``plate``: the frame the
    source's pixels cover (`clfx.kit.warp.plate_frame`; default the display window),
    whose imaged outline ``fit=crop`` fills the display window with.

    lensfun works in pixel-index coordinates of the display window (centres at integers):
    p = u - 0.5 - origin.  Returns ``(sx, sy, info)`` with sx = NaN where no source exists;
    ``info`` has the fold radius, fit scale and the largest normalised radius read.
    """
    ox0, oy0 = display_window.x0 + 0.5, display_window.y0 + 0.5
    ccx, ccy = norm.center_x + ox0, norm.center_y + oy0          # centre, frame coordinates
    ux, uy = pixel_centres(window) if points is None else points
    corners = [(x, y) for x in (display_window.x0, display_window.x1)
               for y in (display_window.y0, display_window.y1)]
    r_corner = max(math.hypot(x - ccx, y - ccy) for x, y in corners) * norm.scale
    info = dict(fit_scale=1.0, r_fold=math.inf, center=(ccx, ccy))
    if not (distortion and cal.distortion):
        return ux, uy, info
    fwd, der = distortion_model(*cal.distortion)
    r_fold = fold_radius(der, 4.0 * r_corner + 1e-6)
    name, terms = cal.distortion
    check_fold("lens", f"{name} distortion {tuple(round(t, 6) for t in terms)}", r_fold,
               r_corner, "lensfun: 1 = half the short side")
    # the imaged outline the fit scale fills the frame with (crop: the plate's, overscan
    # included, so a margin the plate has is used before it scales)
    bx, by = rect_boundary(plate if fit == "crop" and plate is not None else display_window)
    br = np.hypot(bx - ccx, by - ccy) * norm.scale
    with np.errstate(invalid="ignore", divide="ignore"):
        bs = np.where(br > 0, fwd(br) / np.where(br > 0, br, 1), 1.0)
    s_fit = fit_scale(fit, display_window, ccx, ccy, ccx + (bx - ccx) * bs, ccy + (by - ccy) * bs)
    dx, dy = (ux - ccx) * s_fit, (uy - ccy) * s_fit
    r_d = np.hypot(dx, dy) * norm.scale
    r_hi = r_fold if math.isfinite(r_fold) else 4.0 * r_corner + 1.0
    r_u = radial_inverse_fast(fwd, der, r_d, r_hi)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(r_d > 0, r_u / np.where(r_d > 0, r_d, 1.0), 1.0 / der(np.float64(0)))
    info.update(fit_scale=s_fit, r_fold=r_fold)
    return ccx + dx * s, ccy + dy * s, info


def forward_points(cal, norm, display_window, sx, sy, fit="none", distortion=True, tca=True,
                   plate=None):
    """Where the output shows the source points ``(sx, sy)`` (frame coordinates) in each
    channel that moves differently: green (and alpha) through the distortion model, red and
    blue through their TCA model, then the distortion (the kernels' maps inverted)."""
    _, _, info = simulation_geometry(cal, norm, display_window, display_window, fit,
                                     distortion, points=(np.zeros(1), np.zeros(1)),
                                     plate=plate)
    ccx, ccy = info["center"]
    dist = distortion_model(*cal.distortion) if distortion and cal.distortion else None

    def radial(fwd, x, y):
        r = np.hypot(x - ccx, y - ccy) * norm.scale
        with np.errstate(invalid="ignore", divide="ignore"):
            m = np.where(r > 0, fwd(r) / np.where(r > 0, r, 1.0), 1.0)
        return ccx + (x - ccx) * m, ccy + (y - ccy) * m

    def out(x, y):
        if dist is not None:
            x, y = radial(dist[0], x, y)
        s = 1.0 / info["fit_scale"]
        return ccx + (x - ccx) * s, ccy + (y - ccy) * s

    channels = [out(sx, sy)]
    for fwd, _ in (tca_models(*cal.tca) if tca and cal.tca else []):
        channels.append(out(*radial(fwd, sx, sy)))
    return channels


def tca_luts(cal, r_max):
    """Inverse radial scale tables for red and blue (normalised radius of the green point)."""
    luts = []
    for fwd, der in tca_models(*cal.tca):
        r_hi = 2.0 * r_max + 0.1
        r_fold = fold_radius(der, r_hi)
        check_fold("lens", f"{cal.tca[0]} TCA {tuple(round(t, 7) for t in cal.tca[1])}",
                   r_fold, r_max, "lensfun: 1 = half the short side")
        luts.append(radial_lut(fwd, min(r_hi, r_fold), r_max, LUT_SIZE))
    return np.stack(luts)


def channel_points(cal, norm, display_window, window, fit="none", distortion=True, tca=True,
                   points=None, plate=None):
    """Host twin of the kernel's coordinates: {'red','green','blue'} -> (sx, sy) in frame
    coordinates, by direct bisection (no table), of ``window``'s pixel centres or of the
    output ``points``.  Used by the tests against lensfunpy and for regions of interest."""
    gx, gy, info = simulation_geometry(cal, norm, display_window, window, fit, distortion,
                                       points, plate)
    out = {"green": (gx, gy)}
    ccx, ccy = info["center"]
    for name, model in zip(("red", "blue"), tca_models(*cal.tca) if (tca and cal.tca) else []):
        fwd, der = model
        r_g = np.hypot(gx - ccx, gy - ccy) * norm.scale
        r_c = radial_inverse(fwd, r_g, 2.0 * float(np.nanmax(r_g)) + 0.1)
        with np.errstate(invalid="ignore", divide="ignore"):
            s = np.where(r_g > 0, r_c / np.where(r_g > 0, r_g, 1.0), 1.0 / der(np.float64(0)))
        out[name] = (ccx + (gx - ccx) * s, ccy + (gy - ccy) * s)
    for name in ("red", "blue"):
        out.setdefault(name, (gx, gy))
    return out, info


@register
class Lens(PlateCanvasWarp, Plugin):
    whole_frame = None   # a tile computes its band's rows of the whole canvas (`on_canvas`)
    descriptor = Descriptor(
        name="lens", label="Real lens (lensfun)", group="Lens", kernel="lens.cl",
        summary="Distortion, transverse CA and vignetting of a real lens from the lensfun "
                "database, added as the lens would (simulating direction).",
        params=(
            StringParam("maker", "", hint="Lens maker as in lensfun (optional; disambiguates)."),
            StringParam("model", "", hint="Lens model as in lensfun; search with `clfx lenses WORDS`."),
            FloatParam("focal_length", 0.0, min=0.0, max=5000.0,
                       hint="Focal length in mm for the calibration; 0 = the camera block's."),
            FloatParam("aperture", 0.0, min=0.0, max=128.0,
                       hint="f-number for the vignetting calibration; 0 = the camera block's."),
            FloatParam("distance", 0.0, min=0.0, max=1e9,
                       hint="Focus distance in metres for the vignetting calibration; 0 = the "
                            "camera block's."),
            BoolParam("distortion", True, hint="Apply the lens's geometric distortion."),
            BoolParam("tca", True, hint="Apply its transverse chromatic aberration."),
            BoolParam("vignetting", True, hint="Apply its vignetting."),
            ChoiceParam("fit", "crop", choices=FITS,
                        hint="crop = scale up just enough that no pixel of the display window "
                             "reads past the plate (its overscan used first; 1 for a "
                             "pincushion); none = lensfun scale 1 (a barrel reads past the "
                             "plate: border); fit-all = whole source visible; fill = the "
                             "imaged source touches the frame."),
            ChoiceParam("border", "edge", choices=BORDERS,
                        hint="What reads outside the frame (display window) return: black, edge "
                             "(clamp), mirror; inside the frame, outside the data window is "
                             "transparent black."),
        ),
        quality=LEVELS,
    )

    def lens_refs(self, p):
        return (("model", "lensfun", (p.maker, p.model)),) if p.model.strip() else ()

    def is_identity(self, p, ctx):
        if not p.model.strip():
            raise ParamError("lens: no lens chosen; set model (search with `clfx lenses WORDS`)")
        if not (p.distortion or p.tca or p.vignetting):
            return "distortion, tca and vignetting are all off"
        return None

    def host_geometry(self, rt, p, ctx, plate):
        """The geometry of this parameter set and frame (kept in ``rt.cache``): the kernel
        constants, the TCA tables and how to make every channel's source points for any
        band of rows; no whole-frame point array is kept (at 8K one is 265 MB a channel).

        Returns a dict with ``points(y0, y1)`` (a list of (sx, sy): green and, with TCA,
        red and blue source points of output rows ``y0 <= y < y1``, source-window
        coordinates, texel centres at +0.5, NaN = no source), ``luts``, ``consts`` (ccx,
        ccy, lut_scale, vig_scale, vk1, vk2, vk3; centre in source-window coordinates),
        ``flags`` (use_map, use_tca, use_vig) and ``notes``.  ``plate``: the frame the
        plate covers (`plate_frame` of the step's context: ``ctx`` is the canvas's).
        """
        return rt.cache.get(("lens.geometry",) + frame_key(p, ctx) + (plate,),
                            lambda: self._geometry(p, ctx, plate))

    def calibration(self, p, ctx):
        """``(lens, cal, norm, focal)``: the lens, its calibration at this frame's settings
        and lensfun's normalisation of the display window."""
        dw = ctx.display_window
        crop = lensdb.crop_factor(ctx.camera, dw.width, dw.height, ctx.pixel_aspect)
        lens = lensdb.get_lens(p.maker, p.model, crop)
        focal, aperture, distance = settings(p, ctx.camera)
        cal = lensdb.calibration(lens, focal, aperture, distance)
        return lens, cal, lensdb.Normalisation.for_image(cal, crop, dw.width, dw.height), focal

    def region_of_definition(self, p, ctx):
        _, cal, norm, _ = self.calibration(p, ctx)
        use_map, use_tca = bool(p.distortion and cal.distortion), bool(p.tca and cal.tca)
        if not (use_map or use_tca):
            return ctx.source.window        # vignetting only: nothing moves
        # lensfun's models compress the source by well under 2x inside the frame: the
        # filters' reach covers their windows
        plate = plate_frame(ctx)
        return warp_region(lambda xs, ys: forward_points(cal, norm, ctx.display_window, xs, ys,
                                                         p.fit, use_map, use_tca, plate),
                           ctx, p.border)

    def region_of_interest(self, p, ctx, window):
        _, cal, norm, _ = self.calibration(p, ctx)
        use_map, use_tca = bool(p.distortion and cal.distortion), bool(p.tca and cal.tca)
        if not (use_map or use_tca):
            return window

        plate = plate_frame(ctx)

        def inverse(xs, ys):
            chans, _ = channel_points(cal, norm, ctx.display_window, window, p.fit, use_map,
                                      use_tca, points=(xs, ys), plate=plate)
            return list(chans.values())

        return warp_interest(inverse, window, 5)

    def _geometry(self, p, ctx, plate):
        src = ctx.source
        dw = ctx.display_window
        lens, cal, norm, focal = self.calibration(p, ctx)
        notes = []
        use_map = bool(p.distortion and cal.distortion)
        use_tca = bool(p.tca and cal.tca)
        use_vig = bool(p.vignetting and cal.vignetting)
        for want, have, what in ((p.distortion, cal.distortion, "distortion"),
                                 (p.tca, cal.tca, "TCA"), (p.vignetting, cal.vignetting, "vignetting")):
            if want and not have:
                notes.append(f"lens: {lens.model} has no {what} calibration at {focal:g} mm")
        if not (lens.min_focal <= focal <= (lens.max_focal or lens.min_focal)):
            notes.append(f"lens: {focal:g} mm is outside {lens.model}'s range "
                         f"{lens.min_focal:g}-{lens.max_focal:g} mm (lensfun extrapolates)")
        win = src.window
        x0, y0 = win.x0, win.y0

        def green(b0, b1):      # frame coordinates; the same numbers as a whole-frame call
            gx, gy, _ = simulation_geometry(cal, norm, dw, band_window(win, b0, b1), p.fit,
                                            use_map, plate=plate)
            return gx, gy

        _, _, info = simulation_geometry(cal, norm, dw, band_window(win, 0, min(1, win.height)),
                                         p.fit, use_map, plate=plate)   # fold, centre, fit
        ccx, ccy = info["center"]
        geo = dict(luts=None, lut_scale=0.0)
        if use_tca:
            # the largest green radius read, band by band (a whole-frame nanmax, exactly)
            r_max = -math.inf
            for b0, b1 in map_bands(win.height, src.pitch):
                gx, gy = green(b0, b1)
                r_g = np.hypot(gx - ccx, gy - ccy) * norm.scale
                if np.any(np.isfinite(r_g)):
                    r_max = max(r_max, float(np.nanmax(r_g)))
            r_max = max(r_max if r_max > -math.inf else (math.nan if win.width * win.height else 0.0),
                        1e-9) * 1.0001
            luts = tca_luts(cal, r_max)
            geo.update(luts=luts, lut_scale=(norm.scale / r_max) ** 2)
        lut_scale = geo["lut_scale"]

        def points(b0, b1):
            gx, gy = green(b0, b1)
            out = [(gx - x0, gy - y0)]
            if use_tca:
                # the kernel's table read, in float64: rho = |u_g - C|^2 scaled to [0, 1]
                dx, dy = gx - ccx, gy - ccy
                rho = (dx * dx + dy * dy) * lut_scale
                defined = np.isfinite(rho)
                for lut in geo["luts"]:
                    sc = np.where(defined, lut_lookup(lut, np.where(defined, rho, 0.0)), np.nan)
                    out.append((ccx + dx * sc - x0, ccy + dy * sc - y0))
            return out

        vk = cal.vignetting[1][:3] if use_vig else (0.0, 0.0, 0.0)
        geo.update(points=points,
                   consts=(ccx - x0, ccy - y0, lut_scale,
                           norm.scale / norm.vignetting_unit) + tuple(vk),
                   flags=(use_map, use_tca, use_vig), notes=notes)
        return geo

    def device_buffers(self, rt, p, ctx, double, plate, rows=None):
        """Device data, kept in ``rt.cache``: reference (``double``) ``(map, luts)``, float64
        buffers; float levels a :class:`clfx.fx.resample.DevicePackedMap` of green (and red,
        blue with TCA), built band by band (`PackedMap.device`), with ``maps`` = 0 when
        nothing moves (vignetting only).  ``rows``: the `CanvasRows` of ``ctx.source``'s
        window (the canvas) to map (default all); ``plate`` as in `host_geometry`."""
        src = ctx.source
        rows = rows or CanvasRows.whole(src.window)

        def build():
            geo = self.host_geometry(rt, p, ctx, plate)
            use_map, use_tca, _ = geo["flags"]
            if double:
                if not use_map:
                    return rt.to_device(np.zeros(2)), rt.to_device(
                        geo["luts"] if use_tca else np.zeros(2))
                ux, uy = pixel_centres(band_window(src.window, *rows.span), frame_origin=False)
                gx, gy = geo["points"](*rows.span)[0]
                return (upload_map(rt, gx - ux, gy - (uy + rows.first), src.pitch, True),
                        rt.to_device(geo["luts"] if use_tca else np.zeros(2)))
            if not (use_map or use_tca):      # vignetting only: the source is read in place
                return DevicePackedMap(rt.to_device(np.zeros(4, np.int32)), {}, {}, 0)
            return PackedMap.device(rt, geo["points"], src.width, src.height, src.pitch,
                                    rows.span)

        return rt.cache.get(("lens.device",) + frame_key(p, ctx) + (plate, double) + rows.key,
                            build)

    def prepare_maps(self, rt, p, cctx, lvl, plate):
        self.device_buffers(rt, p, cctx, rt.use_fp64(lvl.fp64), plate)

    def render_canvas(self, rt, p, ctx, sanitise, plate, rows=None):
        """The lens over ``ctx.source``'s window (the canvas: `on_canvas`, or the part of it
        a tile holds: ``rows``, the `CanvasRows` to compute, default all); ``plate``: the
        frame the plate covers (`on_plate_canvas`)."""
        src = ctx.source
        rows = rows or CanvasRows.whole(src.window)
        canvas = rows.canvas
        lvl = self.level(ctx)
        double = rt.use_fp64(lvl.fp64)
        cctx = rows.context(ctx)
        bufs = self.device_buffers(rt, p, cctx, double, plate, rows)
        geo = self.host_geometry(rt, p, cctx, plate)
        use_map, use_tca, use_vig = geo["flags"]
        ctx.notes.extend(geo["notes"])
        defines = kernel_defines(lvl.filter, p.border, sanitise)
        defines.update(HAS_MAP=int(use_map), HAS_TCA=int(use_tca), HAS_VIG=int(use_vig),
                       LUTN=LUT_SIZE)
        dst = src.like()
        at = (src.pitch, canvas.width, canvas.height, rows.first, rows.count, rows.shift)
        if double:
            map_buf, lut_buf = bufs
            knl = rt.kernel("lens.cl", "lens_apply", fp64=lvl.fp64, **defines)
            rt.launch(knl, (src.pitch // 4, max(rows.count, 1)), src, dst, map_buf, lut_buf, *at,
                      *geo["consts"])
            return dst
        defines.update(LENS_MAPS=bufs.maps)
        ccx, ccy, _, vig_scale, vk1, vk2, vk3 = geo["consts"]
        tail = at + (ccx, ccy, vig_scale, vk1, vk2, vk3)
        fast = rt.kernel("lens.cl", "lens_packed", fp64=lvl.fp64, **defines)
        if bufs.maps == 0:
            rt.launch(fast, (src.pitch // 4, max(rows.count, 1)), src, dst, bufs.entries, *tail)
            return dst
        launch_packed(rt, fast, rt.kernel("lens.cl", "lens_packed_fix", fp64=lvl.fp64, **defines),
                      bufs, lvl.filter, src.pitch // 4, rows.count, (src, dst), tail)
        return dst
