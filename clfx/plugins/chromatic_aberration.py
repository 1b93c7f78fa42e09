"""Chromatic aberration: lateral (transverse) CA, as three offset channels or spectrally.

Model
-----
The lens images a point at undistorted radius r (normalised: r = 1 at the display window's
half diagonal, pixel aspect applied, measured from the optical centre ``center``) at

    r_d = r (1 + delta(lambda) ((1 - cubic) + cubic r^2)),

a magnification that depends on wavelength: ``cubic`` = 0 is pure scaling (the classic
lateral CA), 1 a distortion-like r^3 growth.  Dispersion follows Cauchy's law
n(lambda) = A + B / lambda^2, so

    delta(lambda) = amount (1/lambda^2 - <1/lambda^2>_G) / (1/450^2 - 1/650^2),

normalised so the green channel (its response-weighted mean, ~538 nm) is unmoved and the
450 nm image is ``amount`` (a fraction of its radius) larger than the 650 nm image at the
corner.  In the three-channel mode green is therefore read in place, not resampled.  Positive ``amount`` puts blue
fringes on the outside of bright edges, red on the inside; negative the reverse.

Rendering (adding the defect): for each wavelength the output pixel at r_d reads the source
at the r_u solving the model (bisection, float64, tabulated per parameter set against
(r_d / r_max)^2 and looked up in the kernel).

Spectral integration: the CIE 1931 2-degree colour matching functions (analytic multi-lobe
Gaussian fit of Wyman, Sloan & Shirley 2013, JCGT 2(2), ``clfx.fx.spectral``) are converted
to linear Rec.709 responses (XYZ -> Rec.709, D65), negative lobes clipped to 0 (no negative
light).
The band 380-720 nm is split into N equal bins; bin i reads the source at its centre
wavelength's position and adds ``w_i[c] * src_c`` to channel c, where w_i[c] is the bin's
share of channel c's (clipped) response: sum_i w_i[c] = 1, so a white or uniform image stays
exactly so, and a white point spreads into a smooth rainbow (at each wavelength the colour of
the spectral light) instead of three offset copies.  Alpha uses the luminance (y-bar)
shares.  The three-channel mode uses, per channel, the response-weighted mean delta.

References: C. Wyman, P.-P. Sloan, P. Shirley, "Simple analytic approximations to the CIE
XYZ color matching functions", JCGT 2013; IEC 61966-2-1 (sRGB/Rec.709 primaries).

Working space: the model is defined in one reference basis, linear Rec.709; pixels of another
working space are carried into it and back around the render
(``clfx.kit.spectral.in_reference_basis``), so the fringes are the same light in any space.
The functions below take ``rgb_to_xyz`` (None = Rec.709), which the render always leaves at
Rec.709.  Every step is signed: the bicubic anti-ringing clamp keeps each channel within its
neighbours' range, negative values (colours outside Rec.709) included.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from clfx.core.plugin import BoolParam, ChoiceParam, Descriptor, FloatParam, Vec2Param
from clfx.fx import spectral
from clfx.fx.resample import (BORDERS, FILTER_CODE, FILTER_TAPS, PackedMap, ResampleLevel,
                              band_window, check_fold, fold_radius, kernel_defines,
                              launch_packed, lut_lookup, pixel_centres, radial_lut)
from clfx.host import Plugin, register
from clfx.kit.spectral import in_reference_basis
from clfx.kit.warp import CanvasRows, canvas_context, frame_key, on_canvas, warp_region

LAMBDA_MIN, LAMBDA_MAX = 380.0, 720.0
LAMBDA_B, LAMBDA_R = 450.0, 650.0
LUT_SIZE = 1024

@dataclass(frozen=True)
class SpectralLevel(ResampleLevel):
    """A quality level of chromatic aberration: ``wavelengths`` spectral bins (3 = the
    three-channel mode, which ``spectral=False`` uses at every level) read with ``filter``."""

    wavelengths: int = 16


LEVELS = {
    "draft": SpectralLevel("three channels (per-channel CMF-weighted scale), bilinear from a "
                           "packed map of the red and blue source points (green in place), "
                           "float32", wavelengths=3, filter="bilinear"),
    "preview": SpectralLevel("8 wavelengths (380-720 nm bins), bicubic with anti-ringing "
                             "clamp, float32", wavelengths=8, filter="bicubic"),
    "final": SpectralLevel("16 wavelengths, bicubic with anti-ringing clamp, float32",
                           wavelengths=16, filter="bicubic"),
    "reference": SpectralLevel("32 wavelengths, bicubic with anti-ringing clamp, float64 "
                               "tables, coordinates and sums", fp64=True, wavelengths=32,
                               filter="bicubic"),
}


def rgba_response(lam, rgb_to_xyz=None):
    """Non-negative linear response of the working space's R, G, B per wavelength (None:
    Rec.709), plus y-bar for alpha."""
    xyz = spectral.cie1931_cmf(lam)
    rgb = np.clip(spectral.xyz_to_rgb(xyz, rgb_to_xyz), 0.0, None)
    return np.concatenate([rgb, xyz[..., 1:2]], -1)


def _fine_grid():
    return np.arange(LAMBDA_MIN + 0.125, LAMBDA_MAX, 0.25)


def green_inverse_square(rgb_to_xyz=None):
    """The green channel's response-weighted mean of 1/lambda^2 (nm^-2)."""
    lam = _fine_grid()
    g = rgba_response(lam, rgb_to_xyz)[:, 1]
    return float((g / lam ** 2).sum() / g.sum())


def dispersion(lam, amount, rgb_to_xyz=None):
    """Relative magnification delta(lambda) (Cauchy): 0 for the green channel's mean."""
    norm = 1.0 / LAMBDA_B ** 2 - 1.0 / LAMBDA_R ** 2
    return amount * (1.0 / np.asarray(lam, np.float64) ** 2
                     - green_inverse_square(rgb_to_xyz)) / norm


def spectral_bins(n: int, amount: float, rgb_to_xyz=None):
    """(deltas[n], weights[n, 4]): bin-centre dispersion and each bin's share of R, G, B, A.

    Weights integrate the response over each bin on a 0.25 nm grid (midpoint rule), so few
    bins still carry the right energy; every column sums to 1.
    """
    fine = _fine_grid()
    resp = rgba_response(fine, rgb_to_xyz)
    edges = np.linspace(LAMBDA_MIN, LAMBDA_MAX, n + 1)
    which = np.clip(np.searchsorted(edges, fine, side="right") - 1, 0, n - 1)
    weights = np.zeros((n, 4))
    np.add.at(weights, which, resp)
    weights /= weights.sum(0, keepdims=True)
    centres = 0.5 * (edges[:-1] + edges[1:])
    return dispersion(centres, amount, rgb_to_xyz), weights


def channel_bins(amount: float, rgb_to_xyz=None):
    """Three-channel mode: per channel the response-weighted mean delta, unit weights."""
    fine = _fine_grid()
    resp = rgba_response(fine, rgb_to_xyz)[:, :3]
    deltas = (resp * dispersion(fine, amount, rgb_to_xyz)[:, None]).sum(0) / resp.sum(0)
    deltas[1] = 0.0        # zero by construction (rounding aside): green stays in place
    weights = np.zeros((3, 4))
    weights[[0, 1, 2], [0, 1, 2]] = 1.0
    weights[1, 3] = 1.0            # alpha travels with green
    return deltas, weights


def geometry(p, display_window, window, pixel_aspect):
    """Optical centre (frame px), radius unit (y-pixels) and the largest output radius."""
    w, h = display_window.width, display_window.height
    dcx, dcy = display_window.center
    cx, cy = dcx + p.center[0] * w * 0.5, dcy + p.center[1] * h * 0.5
    unit = max(0.5 * math.hypot(w * pixel_aspect, h), 1e-9)
    r_max = max(math.hypot((x - cx) * pixel_aspect, y - cy)
                for x in (window.x0, window.x1) for y in (window.y0, window.y1)) / unit
    return cx, cy, unit, max(r_max, 1e-9)


def forward_points(p, display_window, pixel_aspect, sx, sy, rgb_to_xyz=None):
    """Where the output shows the source points ``(sx, sy)`` (frame coordinates) at the
    band's two ends, 380 and 720 nm: ``[(x, y), (x, y)]``.  The image of a point moves
    along its ray monotonically with the wavelength's delta, so every wavelength lands
    between these two."""
    cx, cy, unit, _ = geometry(p, display_window, display_window, pixel_aspect)
    dx, dy = sx - cx, sy - cy
    r2 = ((dx * pixel_aspect) ** 2 + dy * dy) / (unit * unit)
    out = []
    for lam in (LAMBDA_MIN, LAMBDA_MAX):
        m = 1.0 + float(dispersion(np.float64(lam), p.amount, rgb_to_xyz)) * (
            (1.0 - p.cubic) + p.cubic * r2)
        out.append((cx + dx * m, cy + dy * m))
    return out


def radial_model(delta, cubic):
    fwd = lambda r: r * (1 + delta * ((1 - cubic) + cubic * r * r))
    der = lambda r: 1 + delta * (1 - cubic) + 3 * delta * cubic * r * r
    return fwd, der


def build_luts(deltas, cubic, r_max):
    """Per-wavelength inverse radial scale tables; ParamError if a model folds."""
    r_hi = 2.0 * r_max + 0.1
    luts = []
    for d in deltas:
        fwd, der = radial_model(float(d), cubic)
        r_fold = fold_radius(der, r_hi)
        check_fold("chromatic_aberration", f"amount/cubic (delta={d:.4g}, cubic={cubic:g})",
                   r_fold, r_max, "1 = half the frame diagonal")
        luts.append(radial_lut(fwd, min(r_hi, r_fold), r_max, LUT_SIZE))
    return np.stack(luts)


def channel_points(p, display_window, window, pixel_aspect, rows=None, rgb_to_xyz=None):
    """Three-channel mode: the red and blue source points of ``window``'s pixels
    (source-window coordinates, texel centres at +0.5, float64), looked up in float64 in the
    same tables the kernel would interpolate (green and alpha stay in place).  ``rows``
    ``(y0, y1)``: only those rows of the window (the tables are still the whole window's)."""
    cx, cy, unit, r_max = geometry(p, display_window, window, pixel_aspect)
    deltas, _ = channel_bins(p.amount, rgb_to_xyz)
    luts = build_luts(deltas, p.cubic, r_max)
    scale = 1.0 / (unit * r_max)
    ox, oy = pixel_centres(window if rows is None else band_window(window, *rows))
    dx, dy = ox - cx, oy - cy
    rho = np.clip((dx * pixel_aspect * scale) ** 2 + (dy * scale) ** 2, 0.0, 1.0)
    return [(cx + dx * s - window.x0, cy + dy * s - window.y0)
            for s in (lut_lookup(luts[i], rho) for i in (0, 2))]


@register
class ChromaticAberration(Plugin):
    whole_frame = None   # a tile computes its band's rows of the whole canvas (`on_canvas`)
    blended_bins = True
    """Three-bin bicubic levels: both bins in one pass (chromatic_aberration_packed_rb, the
    same bits); False renders each bin whole (the tests' reference)."""
    descriptor = Descriptor(
        name="chromatic_aberration", label="Chromatic aberration", group="Lens",
        kernel="chromatic_aberration.cl",
        summary="Lateral CA: wavelength-dependent magnification, rendered as three channels or "
                "spectrally (N wavelengths integrated with the CIE 1931 CMFs).",
        params=(
            FloatParam("amount", 0.002, min=-0.05, max=0.05,
                       hint="How much larger the 450 nm image is than the 650 nm one at the "
                            "frame corner, as a fraction of its radius (0.002 = ~2 px at a "
                            "1080p corner)."),
            FloatParam("cubic", 0.0, min=0.0, max=1.0,
                       hint="Radial profile: 0 = pure scaling, 1 = shift growing as r^3 "
                            "(distortion-like)."),
            Vec2Param("center", (0.0, 0.0), min=-2.0, max=2.0,
                      hint="Optical centre offset as a fraction of half the frame (x right, y down)."),
            BoolParam("spectral", True,
                      hint="Integrate N wavelengths (smooth rainbow fringes); false = three "
                           "offset channels at every quality."),
            ChoiceParam("border", "edge", choices=BORDERS,
                        hint="What reads outside the frame (display window) return: black, edge "
                             "(clamp), mirror; inside the frame, outside the data window is "
                             "transparent black."),
        ),
        quality=LEVELS,
    )

    def region_of_definition(self, p, ctx):
        # every wavelength's image of the data window (the bins' centres lie in 380-720 nm);
        # kept in ``rt.cache`` (host time asked several times a frame, the same all shot long)
        return ctx.runtime.cache.get(
            ("chromatic_aberration.rod",) + frame_key(p, ctx) + ctx.colour_key,
            lambda: warp_region(lambda xs, ys: forward_points(p, ctx.display_window,
                                                              ctx.pixel_aspect, xs, ys,
                                                              ctx.rgb_to_xyz), ctx, p.border))

    def region_of_interest(self, p, ctx, window):
        # a pixel reads c + v S with |S - 1| <= |m - 1| / (1 - |m - 1|) of the band's ends
        # (m at the window's corners: the scale grows with the radius)
        cx, cy = geometry(p, ctx.display_window, window, ctx.pixel_aspect)[:2]
        xs = np.array([window.x0, window.x1, window.x0, window.x1], np.float64)
        ys = np.array([window.y0, window.y0, window.y1, window.y1], np.float64)
        far = np.hypot(xs - cx, ys - cy)
        dev = max(float((np.hypot(x - xs, y - ys) / np.maximum(far, 1.0)).max())
                  for x, y in forward_points(p, ctx.display_window, ctx.pixel_aspect, xs, ys,
                                             ctx.rgb_to_xyz))
        return window.grown(math.ceil(far.max() * dev / max(1.0 - dev, 1e-3)) + 4)

    def packed_maps(self, rt, p, ctx, rows=None):
        """Three-bin float levels: the red and blue bins' source points as a packed map on
        the device, and the bins' weights, kept in ``rt.cache``; ``rows``: the
        `CanvasRows` of ``ctx.source``'s window (the canvas) to map (default all)."""
        src = ctx.source
        rows = rows or CanvasRows.whole(src.window)

        def build():
            _, weights = channel_bins(p.amount, ctx.rgb_to_xyz)
            points_of = lambda y0, y1: channel_points(p, ctx.display_window, src.window,
                                                      ctx.pixel_aspect, rows=(y0, y1),
                                                      rgb_to_xyz=ctx.rgb_to_xyz)
            return (PackedMap.device(rt, points_of, src.width, src.height, src.pitch,
                                     rows.span),
                    rt.to_device(weights.astype(np.float32)))

        return rt.cache.get(("chromatic_aberration.packed",) + frame_key(p, ctx)
                            + ctx.colour_key + rows.key, build)

    def is_identity(self, p, ctx):
        if p.amount == 0.0:
            return "amount is 0"
        return None

    def tables(self, rt, p, ctx, n, double):
        """The ``n`` bins' interleaved radial tables and weights on the device (float64 if
        ``double``), the kernel's constants (cx, cy, ax, ay) and the largest shift, kept in
        ``rt.cache``."""
        src = ctx.source

        def build():
            cx, cy, unit, r_max = geometry(p, ctx.display_window, src.window, ctx.pixel_aspect)
            m = ctx.rgb_to_xyz
            deltas, weights = (channel_bins(p.amount, m) if n == 3
                               else spectral_bins(n, p.amount, m))
            luts = build_luts(deltas, p.cubic, r_max)
            dt = np.float64 if double else np.float32
            scale = 1.0 / (unit * r_max)
            consts = (cx, cy, ctx.pixel_aspect * scale, scale)
            return (rt.to_device(interleave(luts).astype(dt)), rt.to_device(weights.astype(dt)),
                    consts, max_shift(luts, cx, cy, src.window))

        return rt.cache.get(("chromatic_aberration.tables",) + frame_key(p, ctx) + (n, double)
                            + ctx.colour_key, build)

    def prepare(self, rt, p, ctx):
        if self.is_identity(p, ctx):
            return
        ctx = canvas_context(self, p, ctx, p.border)
        lvl = self.level(ctx)
        n = lvl.wavelengths if p.spectral else 3
        double = rt.use_fp64(lvl.fp64)
        if n == 3 and not double:
            self.packed_maps(rt, p, ctx)
        else:
            self.tables(rt, p, ctx, n, double)

    def render(self, rt, p, ctx):
        # over the window the data window's content lands in (`on_canvas`); the spectral
        # model is defined in linear Rec.709; other working spaces are carried into it and
        # back (clfx.kit.spectral.in_reference_basis)
        return on_canvas(self, rt, p, ctx, p.border, lambda c, sanitise, rows: (
            in_reference_basis(
                rt, c, lambda cc: self.render_reference(rt, p, cc, sanitise, rows))))

    def render_reference(self, rt, p, ctx, sanitise=True, rows=None):
        """The effect on pixels in the reference basis (linear Rec.709), over
        ``ctx.source``'s window (the canvas, or the part of it a tile holds: ``rows``, the
        `CanvasRows` to compute, default all); ``sanitise``: the frame has non-finite
        pixels."""
        src = ctx.source
        rows = rows or CanvasRows.whole(src.window)
        geo, canvas = rows.context(ctx), rows.canvas
        lvl = self.level(ctx)
        n = lvl.wavelengths if p.spectral else 3
        double = rt.use_fp64(lvl.fp64)
        defines = kernel_defines(lvl.filter, p.border, sanitise)
        defines.update(NWAVE=n, NWP=padded_count(n), LUTN=LUT_SIZE, GREEN_IN_PLACE=int(n == 3))
        dst = src.like()
        at = (canvas.width, canvas.height, rows.first, rows.count, rows.shift)
        if n == 3 and not double:
            dmap, wbuf = self.packed_maps(rt, p, geo, rows)
            knl = lambda name: rt.kernel("chromatic_aberration.cl", name, fp64=lvl.fp64,
                                         CA_FAST=1, **defines)
            fast, quads = knl("chromatic_aberration_packed"), src.pitch // 4
            if (self.blended_bins and lvl.filter == "bicubic"
                    and dmap.fast_possible[FILTER_CODE["bicubic"]]):
                # both bins in one pass, then its flagged quads exactly (kernels/
                # chromatic_aberration.cl); the border quads follow in launch_packed's fix
                flags = rt.buffer(max(rows.count, 1) * quads)
                args = (src, dst, dmap.entries, flags, wbuf, src.pitch) + at
                rt.launch(knl("chromatic_aberration_packed_rb"), (quads, max(rows.count, 1)),
                          *args)
                rt.launch(knl("chromatic_aberration_packed_exact"),
                          (-(-max(rows.count, 1) * quads // 64),), *args)
                fast = None
            launch_packed(rt, fast, knl("chromatic_aberration_packed_fix"), dmap, lvl.filter,
                          quads, rows.count, (src, dst), (wbuf, src.pitch) + at)
            return dst
        luts, weights, (cx, cy, ax, ay), shift = self.tables(rt, p, geo, n, double)
        args = (src, dst, luts, weights, src.pitch, canvas.width, canvas.height, canvas.x0,
                canvas.y0, cx, cy, ax, ay)
        quads = src.pitch // 4
        inner = None if double else interior_quads(shift, FILTER_TAPS[lvl.filter],
                                                   canvas.width, canvas.height)
        # the whole canvas's ring and interior (each pixel takes one path whatever the
        # tile), cut to the rows computed
        parts = [(0, r) for r in ring(quads, max(canvas.height, 1), inner)]
        parts += [(1, inner)] if inner is not None else []
        for fast, (qx0, y0, nq, nr) in parts:
            y1, y0 = min(y0 + nr, rows.first + rows.count), max(y0, rows.first)
            if y1 <= y0 and rows.tiled:
                continue
            knl = rt.kernel("chromatic_aberration.cl", "chromatic_aberration_apply",
                            fp64=lvl.fp64, CA_FAST=fast, **defines)
            rt.launch(knl, (nq, max(y1 - y0, 1)), *args, qx0, y0, nq, y1 - y0, rows.shift)
        return dst


def padded_count(n: int) -> int:
    """Wavelengths per table entry: n padded to an OpenCL vector width (4, 8, 16) if any."""
    return next((v for v in (4, 8, 16) if n <= v), n)


def interleave(luts):
    """(n, LUTN + 1) tables -> (LUTN + 1, padded n): entry j holds every wavelength's scale,
    so the kernel reads them with one vector load per pixel; padding repeats the last."""
    n, m = luts.shape
    out = np.empty((m, padded_count(n)), luts.dtype)
    out[:, :n] = luts.T
    out[:, n:] = luts[-1:].T
    return out


def max_shift(luts, cx, cy, window):
    """Bound (x, y) in px on how far any wavelength moves any pixel of ``window``.

    A pixel at (dx, dy) from the optical centre reads c + (dx, dy) S(rho), so it moves by
    |(dx, dy)| |S - 1|; the linear interpolation of the tables stays within their values.
    inf when some radius has no preimage (NaN in a table).
    """
    dev = np.abs(np.asarray(luts, np.float64) - 1.0)
    if not np.isfinite(dev).all():
        return math.inf, math.inf
    d = float(dev.max())
    return (d * max(abs(window.x0 - cx), abs(window.x1 - cx)),
            d * max(abs(window.y0 - cy), abs(window.y1 - cy)))


def interior_quads(shift, taps: int, width: int, height: int):
    """The rectangle of quads (qx0, y0, quads, rows) whose footprints stay inside the source
    for every wavelength (so the kernel may skip the checks), or None."""
    sx, sy = shift
    if not (math.isfinite(sx) and math.isfinite(sy)):
        return None
    off = taps // 2 - 1
    # pixel x reads texels floor(x + 0.5 +- shift - 0.5) - off ... + taps - 1 (+1 for rounding)
    x_lo, x_hi = math.ceil(sx) + off + 1, width - taps + off - math.ceil(sx) - 1
    y_lo, y_hi = math.ceil(sy) + off + 1, height - taps + off - math.ceil(sy) - 1
    q_lo, q_hi = -(-x_lo // 4), (x_hi - 3) // 4
    if q_hi < q_lo or y_hi < y_lo:
        return None
    return q_lo, y_lo, q_hi - q_lo + 1, y_hi - y_lo + 1


def ring(quads: int, rows: int, inner):
    """Rectangles (qx0, y0, quads, rows) covering the quads outside ``inner`` (all if None)."""
    if inner is None:
        return [(0, 0, quads, rows)]
    q0, y0, nq, nr = inner
    parts = [(0, 0, quads, y0), (0, y0 + nr, quads, rows - y0 - nr),
             (0, y0, q0, nr), (q0 + nq, y0, quads - q0 - nq, nr)]
    return [r for r in parts if r[2] > 0 and r[3] > 0]
