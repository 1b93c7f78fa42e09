"""Lens breathing: focusing changes the field of view, so a rack focus scales the frame.

Model
-----
A lens focuses by moving its optics: a unit-focusing thin lens of focal length ``f`` focused
at ``S`` forms its image at ``v(S) = f S / (S - f)`` behind it
(``clfx.core.camera.image_distance``), and everything it images scales with ``v``.  Relative
to a reference focus ``S0`` the frame is magnified by ``v(S) / v(S0)``: focusing closer
(larger v) narrows the field of view.  Real lenses breathe less (floating elements) or the
other way (internal focusing), so

    m = 1 + amount * (v(S) / v(S0) - 1)

with ``amount`` = 0 no breathing, 1 the unit-focusing thin lens, < 0 the frame widens when
focusing close.  ``amount`` comes from the camera block (``camera.breathing``, default 0)
unless this effect's ``amount`` is not 0.  ``S`` is the camera's focus distance on this frame
(keyframes resolved); ``S0`` is ``reference_focus``, or with 0 the focus distance the shot
starts with: the camera at its first keys (``RenderContext.reference_camera``), so a static
focus never scales and a keyframed one scales away from its first key.  The focal length is
the frame's (a zoom changes the field of view on its own; the plate already shows that).

Focus distances closer than 1:1 macro (``S < 2 f``: no ordinary lens focuses there, and at
``S <= f`` there is no real image) are computed at ``2 f``, with a warning; a scale below
``SCALE_MIN`` is raised to it, with a warning.

Rendering
---------
``out(u) = src(c + (u - c) / m)`` about the optical centre ``c`` (the display window's
centre, moved by ``center``).  Scaling up (m > 1) crops; scaling down (m < 1) needs pixels
outside the frame: the data window's overscan beyond the display window is used where the
input has it; beyond the rendered pixels the edge is repeated, and one warning line says by
how much the frame widened past them.  Inside the display window, pixels outside the data
window (an element's bounding box) are transparent black.  The output window is the data
window's image (``region_of_definition``, grown by the filter's reach) with the data window:
an element scaled up grows past its box, one scaled down towards a centre outside its box
moves past the box's edge facing the centre.  The map is affine, so its Jacobian is ``(1 / m) I``
everywhere: the shared footprint filters (``clfx.fx.resample``, ``kernels/lib/resample.h``)
widen by the variance a minified pixel's preimage adds, the same for every pixel, and the
kernel computes each source point itself (nothing is built per frame while the focus moves).

Only the beauty is scaled: depth and velocity passes stay as they are.  In a look, breathing
belongs after the effects that read those passes (dof, motion blur) and beside distortion
(the lens's geometry): an effect after it would read passes that no longer line up.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from clfx.core.camera import image_distance
from clfx.core.plugin import Descriptor, FloatParam, Vec2Param
from clfx.core.rect import Rect
from clfx.fx.resample import ResampleLevel, elliptical_spread, footprint_defines, footprint_spread
from clfx.host import Plugin, StepPlan, register
from clfx.kit.warp import CanvasRows, band_rows, needs_sanitising, whole_context

MACRO = 2.0
"""Closest focus, in focal lengths: 1:1 macro (the image as large as the object)."""

SCALE_MIN = 0.25
"""The smallest scale rendered (the frame widened 4x): beyond it nothing is left to show."""

IDENTITY_TOL = 1e-6
"""A scale within this of 1 moves no point of a 1e5-pixel-wide frame by 0.1 px."""

LEVELS = {
    "draft": ResampleLevel("footprint quadratic (3x3): 3-point interpolation plus the variance "
                           "a minified pixel's preimage adds (the same for every pixel of a "
                           "uniform scale), float32 sums", filter="quadratic", footprint=True),
    "preview": ResampleLevel("footprint bicubic (4x4): Keys blended with the cubic B-spline as "
                             "the scale minifies, anti-ringing clamp, float32 sums",
                             filter="bicubic", footprint=True),
    "final": ResampleLevel("footprint Lanczos-3 (up to 8x8): the mean of two Lanczos-3 samples "
                           "spread by the minification, anti-ringing clamp, float32 sums",
                           filter="lanczos3", footprint=True),
    "reference": ResampleLevel("elliptical footprint: n x n Lanczos-3 samples over the output "
                               "pixel's preimage, float64 positions and sums", fp64=True,
                               filter="lanczos3", footprint=True),
}


def thin_lens_scale(focus: float, reference: float, focal_length_mm: float,
                    amount: float) -> tuple[float, list[str]]:
    """The breathing scale ``m = 1 + amount (v(S) / v(S0) - 1)`` and the warnings its clamps
    raise (closer than 1:1 macro; a scale below ``SCALE_MIN``).

    Parameters
    ----------
    focus, reference : float
        Focus distances ``S`` and ``S0`` in scene units (metres).
    focal_length_mm : float
        The lens's focal length in mm.
    amount : float
        0 no breathing, 1 a unit-focusing thin lens, < 0 widening when focusing close.
    """
    if amount == 0.0:
        return 1.0, []
    warnings = []
    closest = MACRO * focal_length_mm / 1000.0
    if min(focus, reference) < closest:
        warnings.append(f"focus distance {min(focus, reference):g} is closer than 1:1 macro for "
                        f"a {focal_length_mm:g} mm lens: breathing computed at {closest:g} "
                        f"(2 focal lengths)")
    ratio = (image_distance(focal_length_mm, max(focus, closest))
             / image_distance(focal_length_mm, max(reference, closest)))
    m = 1.0 + amount * (ratio - 1.0)
    if m < SCALE_MIN:
        warnings.append(f"breathing scale {m:.4g} raised to {SCALE_MIN:g} (amount {amount:g})")
        m = SCALE_MIN
    return m, warnings


def centre(p, display_window: Rect) -> tuple[float, float]:
    """The optical centre in frame coordinates (pixel centres at +0.5)."""
    cx, cy = display_window.center
    return (cx + p.center[0] * display_window.width / 2.0,
            cy + p.center[1] * display_window.height / 2.0)


@dataclass(frozen=True)
class BreathingPlan(StepPlan):
    """breathing's plan for one step of a frame: the scale m and its clamps' warnings."""

    m: float = 1.0
    warnings: tuple = ()


@register
class Breathing(Plugin):
    whole_frame = None   # a tile computes its band's rows with the whole render's geometry
    descriptor = Descriptor(
        name="breathing", label="Lens breathing", group="Lens", kernel="breathing.cl",
        summary="Focusing changes the field of view: with an animated focus distance the frame "
                "scales about the optical centre (thin-lens image distance).",
        params=(
            FloatParam("amount", 0.0, min=-2.0, max=2.0, display_min=-1.0, display_max=1.0,
                       hint="How much the lens breathes: 1 = unit-focusing thin lens, < 0 = "
                            "the frame widens when focusing close; 0 = the camera block's "
                            "breathing."),
            FloatParam("reference_focus", 0.0, min=0.0, max=1e9, units="m",
                       hint="Focus distance at which the frame keeps its scale, in scene units; "
                            "0 = the camera's focus distance at its first keyframe (a static "
                            "focus then never scales)."),
            Vec2Param("center", (0.0, 0.0), min=-2.0, max=2.0,
                      hint="Optical centre from the display window's centre, in half widths "
                           "and half heights (1, 1 = the bottom-right corner)."),
        ),
        quality=LEVELS,
    )

    def amount(self, p, ctx) -> float:
        """This step's ``amount``, or the camera block's ``breathing`` where it is 0."""
        return p.amount if p.amount != 0.0 else ctx.camera.breathing

    def reference_focus(self, p, ctx) -> float:
        return p.reference_focus if p.reference_focus > 0.0 else ctx.reference_camera.focus_distance

    def plan(self, p, ctx) -> BreathingPlan:
        if self.amount(p, ctx) == 0.0:
            return BreathingPlan("breathing amount is 0 (the step's amount and camera.breathing)")
        m, warnings = thin_lens_scale(ctx.camera.focus_distance, self.reference_focus(p, ctx),
                                      ctx.camera.focal_length, self.amount(p, ctx))
        identity = None
        if abs(m - 1.0) <= IDENTITY_TOL:
            identity = (f"focus distance {ctx.camera.focus_distance:g} is the reference "
                        f"{self.reference_focus(p, ctx):g}: the field of view does not change "
                        f"(scale {m:.7f})")
        return BreathingPlan(identity, m, tuple(warnings))

    def scale(self, p, ctx) -> tuple[float, list[str]]:
        """The frame's scale m (> 1 narrows the view) and the warnings of its clamps: the
        step's plan's."""
        plan = self.planned(p, ctx)
        return plan.m, list(plan.warnings)

    def is_identity(self, p, ctx):
        return self.planned(p, ctx).identity

    def _mapped(self, p, ctx, rect: Rect, m: float, reach: int) -> Rect:
        """The pixels covering ``c + (rect - c) * m``, grown by ``reach``."""
        cx, cy = centre(p, ctx.display_window)
        x0, x1 = (cx + (v - cx) * m for v in (rect.x0, rect.x1))
        y0, y1 = (cy + (v - cy) * m for v in (rect.y0, rect.y1))
        eps = 1e-9 * (1.0 + abs(x0) + abs(x1) + abs(y0) + abs(y1))   # exact edges stay put
        return Rect(math.floor(x0 + eps) - reach, math.floor(y0 + eps) - reach,
                    math.ceil(x1 - eps) + reach, math.ceil(y1 - eps) + reach)

    def region_of_definition(self, p, ctx):
        # Scaling carries the data window's content along rays from the optical centre:
        # outward when m > 1 (a data window inside the display window grows), inward when
        # m < 1, where a box beside the centre moves past its own edge that faces it.  The
        # filter's reach is ~4 texels, m px each on the output (at least a pixel's).
        m, _ = self.scale(p, ctx)
        src = ctx.source.window
        return src.union(self._mapped(p, ctx, src, m, math.ceil(4 * max(m, 1.0)) + 1))

    def region_of_interest(self, p, ctx, window):
        m, _ = self.scale(p, ctx)
        reach = 5 + math.ceil(0.5 / m)     # the widest window (8 taps) plus sub-footprints
        return self._mapped(p, ctx, window, 1.0 / m, reach).union(window)

    def _overhang_warning(self, p, ctx, m: float, src: Rect, out: Rect) -> str | None:
        """The line saying how far the kept output reads past the pixels there are, if it
        does (``src``: the source window with the display window's empty parts added)."""
        keep = out.intersect(ctx.display_window)
        if keep.empty:
            return None
        cx, cy = centre(p, ctx.display_window)
        x0, x1 = (cx + (v - cx) / m for v in (keep.x0, keep.x1))
        y0, y1 = (cy + (v - cy) / m for v in (keep.y0, keep.y1))
        sides = (max(src.x0 - x0, 0.0), max(x1 - src.x1, 0.0), max(src.y0 - y0, 0.0),
                 max(y1 - src.y1, 0.0))
        over_x, over_y = sides[0] + sides[1], sides[2] + sides[3]
        if max(sides) <= 1e-3:
            return None
        past = 100.0 * max(over_x / keep.width, over_y / keep.height)
        change = (f"widens the frame by {100.0 * (1.0 / m - 1.0):.2f}%" if m < 1.0
                  else f"scales the frame by {m:.5f}")
        return (f"focus {ctx.camera.focus_distance:g} (reference {self.reference_focus(p, ctx):g}) "
                f"{change}; {past:.2f}% of it lies past the rendered pixels "
                f"(up to {max(sides):.1f} px a side, no overscan there): edge pixels repeated "
                f"(render with overscan to fill it)")

    def render(self, rt, p, ctx):
        lvl = self.level(ctx)
        # a tile (ctx.tiling) renders its band's rows of the whole render, from the whole
        # render's geometry (`clfx.kit.warp.CanvasRows`)
        whole = whole_context(ctx)
        m, warnings = self.scale(p, whole)
        out_win = self.output_window(p, whole)
        # Inside the display window, pixels outside the data window are transparent black (an
        # element's bounding box): read as 0.  Past the display window's edge, where the data
        # window ends there, nothing was rendered: the edge repeats (and a warning says so).
        need = self.region_of_interest(p, whole, out_win)
        read = whole.source.window.union(need.intersect(ctx.display_window))
        rows = CanvasRows.whole(out_win)
        part = read
        if ctx.tiling is not None:
            band = ctx.tiling.band
            part, rows = band_rows(read, self.region_of_interest(p, whole, band), band, out_win)
            out_win = band
        src = rt.reframe(ctx.source, part, "zero")
        line = self._overhang_warning(p, ctx, m, read, rows.canvas)
        ctx.warnings.extend(warnings + ([line] if line else []))
        ctx.notes.append(f"breathing: scale {m:.6f}")
        double = rt.use_fp64(lvl.fp64)
        cx, cy = centre(p, ctx.display_window)
        inv = 1.0 / m
        # output pixel x of out_win reads x * inv + a (source-window coordinates)
        ax = cx + (rows.canvas.x0 + 0.5 - cx) * inv - read.x0
        ay = cy + (rows.canvas.y0 + 0.5 - cy) * inv - read.y0
        jac = np.array([[[inv, 0.0], [0.0, inv]]])
        defines = footprint_defines(lvl.filter, "edge", needs_sanitising(ctx, "breathing"))
        dst = rt.image(out_win, 4)
        head = (src, dst, src.pitch, read.width, read.height, dst.pitch, dst.height)
        at = (rows.first, rows.shift)
        size = (dst.pitch // 4, max(dst.height, 1))
        if double:
            jc, n = elliptical_spread(jac)
            knl = rt.kernel("breathing.cl", "breathing_ewa_f64", fp64=lvl.fp64, **defines)
            rt.launch(knl, size, *head, ax, ay, inv, jc[0, 0, 0], int(n[0]), *at)
            return dst
        hx, hy, n = footprint_spread(jac, lvl.filter)
        knl = rt.kernel("breathing.cl", "breathing_footprint",
                        CLFX_STREAM_STORES=int(rt.streams_stores(dst.nbytes)), **defines)
        rt.launch(knl, size, *head, ax, ay, inv, hx[0], hy[0], n[0], *at)
        return dst
