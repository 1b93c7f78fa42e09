"""Depth of field: a gather ("scatter-as-gather") lens blur from a depth pass.

Model
-----
Thin lens (Potmesil & Chakravarty 1981).  A point at planar depth ``z`` seen through a lens of
focal length ``f`` and f-number ``N`` focused at ``S`` blurs into a circle of confusion of
diameter ``c = (f/N) * f/(S - f) * |1 - S/z|`` on the sensor, ``c * width_px / sensor_width``
in pixels; clfx works with the signed radius ``r = K/2 (1 - S/z)`` (``K`` = the CoC at
infinity, in px), negative in front of the focus plane, which is finite at ``z = inf``.  With
``coc_source = max_blur`` the CoC at infinity is given directly, ``K = max_blur * diagonal``
(still linear in ``1/z``); the formula is :func:`clfx.core.camera.coc_signed`, the one copy
every layer uses.  Radii are clamped to ``max_coc / 2 * diagonal``.  Invalid depths
(NaN, 0, negative) count as in focus; non-finite colours become 0 (counted in the notes).
Pixel aspect stretches the aperture vertically (radii are in x pixels).  The bokeh is the
aperture: a disk, or a polygon of ``blades`` blades inscribed in the CoC circle, first vertex
up, turned by the rotation, blended toward the disk by ``roundness``; behind the focus plane
it is upright, in front turned by 180 degrees (the geometry of :mod:`clfx.bench.groundtruth`).

Algorithm (after Jimenez 2014, "Next generation post processing in Call of Duty: Advanced
Warfare", simplified for offline use)
1. ``dof_prepare``: sanitised colour and signed CoC radius into a padded buffer.
2. Tiles (32 px, the shared scene analysis): the largest CoC radius a tile's depth range can
   produce, dilated on the host over as many tiles as the largest radius reaches (3 x 3 for
   radii up to a tile); tiles whose neighbourhood maximum is below half a pixel are copied
   (and the whole frame is an identity when every tile is).
3. ``dof_gather``: rings of taps over the neighbourhood radius ``R`` (ring spacing and ring
   count by quality), split into two fields per pixel:
   - near field (taps in front of the focus plane): each tap spreads its light over its own
     CoC area (weight ``coverage / (pi r^2)``), so a blurred foreground spreads over the
     in-focus background; its coverage (tap area x weight, summed) is the foreground alpha;
   - far field (the rest): normalised, and a tap behind the pixel spreads at most the
     pixel's own radius, so an in-focus edge does not bleed into a blurred background and a
     blurred background does not wash over a sharp object; for a near pixel the far field
     is the background hidden behind it, estimated from the visible background around.
   ``out = far + alpha * (near - far)``.  Every tap rejected falls back to the centre pixel.
4. Tiles whose every pixel is far out of focus (CoC radius above a threshold per quality
   level) are gathered at half resolution (2 x 2 box of colour, mean radius halved: the
   shared ``blur_box_down2`` of :mod:`clfx.fx.blur`; the same gather with half the radius)
   and upsampled bilinearly into those tiles only, so in-focus edges always come from the
   full-resolution gather.

Each work-item gathers 4 adjacent pixels with shared tap offsets (float16 vectors).

Light leaves the data window: the region of definition grows by the largest CoC radius the
frame's depth range can produce (the tiles of the shared scene analysis; the ``max_coc``
clamp without them).  When the output window is larger than the source window (a data window
tighter than the display window), the beauty is extended with transparent black and the
depth by its edge values, and the tiles are taken over the grown window.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from clfx.core.camera import aperture_radius, coc_signed, first_blade_angle
from clfx.core.plugin import ChoiceParam, Clip, Descriptor, FloatParam, IntParam, Level
from clfx.core.rect import Rect
from clfx.fx.analysis import TILE  # dof's tiles are the shared analysis's
from clfx.fx.blur import box_downsample2x
from clfx.host import Plugin, register

LOCAL = (8, 4)      # work-group: 32 x 4 pixels, one tile wide


@dataclass(frozen=True)
class DofLevel(Level):
    """What one quality level of the gather does."""

    spacing: float = 1.0              # ring spacing, px
    max_rings: int = 12               # rings at most (3 K (K + 1) + 1 taps)
    half_res_radius: float = 6.0      # tiles whose every CoC radius is >= this: half resolution


LEVELS = {
    "draft": DofLevel("rings every 2 px, at most 4 rings (61 taps); tiles whose every pixel has "
                      "a CoC radius >= 2 px gathered at half resolution; float32 sums",
                      spacing=2.0, max_rings=4, half_res_radius=2.0),
    "preview": DofLevel("rings every 1 px, at most 6 rings (127 taps); half resolution where "
                        "every CoC radius >= 3 px; float32 sums",
                        spacing=1.0, max_rings=6, half_res_radius=3.0),
    "final": DofLevel("rings every 1 px, at most 12 rings (469 taps); half resolution where "
                      "every CoC radius >= 6 px; float32 sums",
                      spacing=1.0, max_rings=12, half_res_radius=6.0),
    "reference": DofLevel("rings every 1 px, at most 32 rings (3169 taps), all at full "
                          "resolution, float64 sums",
                          fp64=True, spacing=1.0, max_rings=32, half_res_radius=math.inf),
}


def lens_scale_px(p, camera, ctx_diag: float, width_px: float) -> float:
    """``K``: the CoC diameter in pixels at infinity, from the camera (with this effect's
    f-number and focus overrides) or ``max_blur``."""
    if p.coc_source == "max_blur":
        return p.max_blur * ctx_diag
    return camera.updated(f_number=p.f_number or camera.f_number,
                          focus_distance=focus_distance(p, camera)).coc_scale_px(width_px)


def focus_distance(p, camera) -> float:
    return p.focus_distance or camera.focus_distance


def coc_radius(depth, k_half: float, focus: float, clamp_r: float):
    """Signed CoC radius in px for planar depths (float64 NumPy; same rules as the kernel)."""
    return np.clip(coc_signed(depth, k_half, focus), -clamp_r, clamp_r)


def tap_table(radius: float, spacing: float, kmax: int, aspect: float = 1.0, blades: int = 0,
              first: float = -0.5 * math.pi, roundness: float = 0.0) -> np.ndarray:
    """The gather's taps for a neighbourhood radius ``radius`` (px): (n, 8) float32 rows of
    (offset x, offset y, near distance, far distance, area, 0, 0, 0).

    ``K = clamp(ceil(radius / spacing), 1, kmax)`` rings at radii ``k radius / K`` with ``6k``
    taps each (odd rings turned by half a step) plus the centre: uniform density over the
    disk, each tap standing for ``pi/3 (radius/K)^2`` px^2 (the centre ``pi/4 (...)^2``).
    Offsets are rounded to whole pixels (y stretched by the pixel aspect); distances are
    measured on the rounded offsets in x pixels, divided by the aperture's boundary radius
    in the direction of ``o`` (near taps: bokeh turned 180 degrees) or ``-o`` (far taps).
    """
    K = int(min(max(math.ceil(radius / spacing), 1), kmax))
    step = radius / K
    rows = [(0.0, 0.0, 0.0, 0.0, 0.25 * math.pi * step * step)]
    for k in range(1, K + 1):
        n = 6 * k
        th = (np.arange(n) + (0.5 if k & 1 else 0.0)) * (2.0 * math.pi / n)
        ox = np.rint(k * step * np.cos(th))
        oy = np.rint(k * step * np.sin(th) * aspect)
        dy = oy / aspect
        d = np.hypot(ox, dy)
        phi = np.arctan2(dy, ox)
        d_near = d / aperture_radius(phi, blades, first, roundness)
        d_far = d / aperture_radius(phi + math.pi, blades, first, roundness)
        area = np.full(n, math.pi / 3.0 * step * step)
        rows.extend(zip(ox, oy, d_near, d_far, area))
    table = np.zeros((len(rows), 8), np.float32)
    table[:, :5] = np.asarray(rows, np.float64)
    return table


def quantised_radius(r):
    """Tile radii rounded up to whole pixels (a handful of tap tables per frame); 0 below
    half a pixel (the tile is copied)."""
    r = np.asarray(r, np.float64)
    return np.where(r < 0.5, 0.0, np.maximum(np.ceil(r), 1.0))


def dilate_tiles(t: np.ndarray, reach: int) -> np.ndarray:
    """Maximum over a (2 reach + 1)^2 tile neighbourhood (small host arrays)."""
    out = t.copy()
    h, w = t.shape
    for dy in range(-reach, reach + 1):
        for dx in range(-reach, reach + 1):
            ys, yd = slice(max(0, dy), h + min(0, dy)), slice(max(0, -dy), h + min(0, -dy))
            xs, xd = slice(max(0, dx), w + min(0, dx)), slice(max(0, -dx), w + min(0, -dx))
            out[yd, xd] = np.maximum(out[yd, xd], t[ys, xs])
    return out


@register
class Dof(Plugin):
    descriptor = Descriptor(
        name="dof", label="Depth of field", group="Lens", kernel="dof.cl",
        summary="Thin-lens depth of field from a depth pass: gather with separate near and "
                "far fields, aperture-shaped bokeh.",
        clips=(Clip("source"), Clip("depth", channels=1,
                                    hint="Planar depth in scene units (m); +inf = background.")),
        params=(
            ChoiceParam("coc_source", "camera", choices=("camera", "max_blur"),
                        hint="camera: CoC from the camera block's lens; max_blur: the CoC at "
                             "infinity is max_blur (linear in 1/depth)."),
            FloatParam("max_blur", 0.01, min=0.0, max=0.25,
                       hint="CoC diameter at infinity as a fraction of the frame diagonal "
                            "(coc_source = max_blur)."),
            FloatParam("f_number", 0.0, min=0.0, max=128.0,
                       hint="Aperture f-number; 0 = the camera block's."),
            FloatParam("focus_distance", 0.0, min=0.0, max=1e9,
                       hint="Distance in focus in scene units (m); 0 = the camera block's."),
            FloatParam("max_coc", 0.05, min=0.0, max=0.25,
                       hint="Largest CoC diameter as a fraction of the frame diagonal (clamp)."),
            IntParam("blades", -1, min=-1, max=32,
                     hint="Aperture blades; -1 = the camera block's, 0 = round."),
            FloatParam("blade_rotation", 0.0, min=-360.0, max=360.0,
                       hint="Extra rotation of the aperture polygon in degrees (clockwise)."),
            FloatParam("roundness", 0.0, min=0.0, max=1.0,
                       hint="0 = straight blades, 1 = round bokeh."),
        ),
        quality=LEVELS,
        spreads_light=True,
    )

    # -- geometry --------------------------------------------------------------------------
    def _lens(self, p, ctx):
        """(K/2, focus, clamp radius, blades, first-blade angle in radians)."""
        k_half = 0.5 * lens_scale_px(p, ctx.camera, ctx.diagonal_px, ctx.width_px)
        clamp_r = 0.5 * p.max_coc * ctx.diagonal_px
        blades = ctx.camera.blades if p.blades < 0 else p.blades
        rot = ctx.camera.blade_rotation + p.blade_rotation
        return k_half, focus_distance(p, ctx.camera), clamp_r, blades, first_blade_angle(rot)

    def tile_radii(self, p, ctx, *, with_min: bool = False):
        """Per 32 px tile: the largest CoC radius any pixel within reach can have (px); with
        ``with_min`` also the smallest radius of the tile's own pixels."""
        k_half, focus, clamp_r, _, _ = self._lens(p, ctx)
        src = ctx.source
        ty, tx = max(1, -(-src.height // TILE)), max(1, -(-src.width // TILE))
        an = ctx.analysis
        if an.min_depth is None:
            full = np.full((ty, tx), clamp_r, np.float32)  # no tile statistics: no skipping
            return (full, np.zeros_like(full)) if with_min else full
        # the CoC is monotonic in 1/z, so a tile's extremes come from its depth range
        r0 = coc_radius(an.min_depth, k_half, focus, clamp_r)
        r1 = coc_radius(an.max_depth, k_half, focus, clamp_r)
        r = np.maximum(np.abs(r0), np.abs(r1))
        reach = int(math.ceil(r.max() / TILE)) if r.size else 0
        r_max = dilate_tiles(r, max(reach, 1)).astype(np.float32)
        if not with_min:
            return r_max
        # straddling the focus plane, or holding invalid depths (in focus): some pixel is sharp
        r_min = np.where((r0 * r1 <= 0) | (an.bad_depth > 0), 0.0,
                         np.minimum(np.abs(r0), np.abs(r1)))
        return r_max, r_min.astype(np.float32)

    def spread_px(self, p, ctx) -> tuple[int, int]:
        """How far (x, y px) light can land from its pixel: the largest CoC radius of the
        frame (whole pixels, as the gather's), stretched by the pixel aspect in y, plus the
        coverage ramp's pixel."""
        radii = self.tile_radii(p, ctx)
        r = float(quantised_radius(radii.max())) if radii.size else 0.0
        if r == 0.0:
            return 0, 0
        return int(math.ceil(r)) + 1, int(math.ceil(r * ctx.pixel_aspect)) + 1

    def tap_tables(self, rt, levels, spacing, kmax, aspect, blades, first, roundness):
        """One concatenated tap table for the frame's radius levels and per-tile (first,
        count) pairs; each radius's table is kept in the runtime's cache."""
        parts, offsets, n = [], {}, 0
        for r in sorted(set(levels.ravel().tolist()) - {0.0}):
            taps = rt.cache.get(("dof.taps", r, spacing, kmax, aspect, blades, first, roundness),
                                lambda r=r: tap_table(r, spacing, kmax, aspect, blades, first,
                                                      roundness))
            offsets[r] = (n, len(taps))
            parts.append(taps)
            n += len(taps)
        table = np.concatenate(parts) if parts else np.zeros((1, 8), np.float32)
        info = np.zeros(levels.shape + (2,), np.int32)
        for r, (first_tap, count) in offsets.items():
            info[levels == r] = (first_tap, count)
        return np.ascontiguousarray(table), np.ascontiguousarray(info)

    def _gather(self, rt, knl, col, coc, pad, dst, levels, lvl, aspect, blades, first,
                roundness, tile=TILE):
        table, info = self.tap_tables(rt, levels, lvl.spacing, lvl.max_rings, aspect, blades,
                                      first, roundness)
        taps, tiles = rt.to_device(table), rt.to_device(info)
        i32 = np.int32
        rt.launch(knl, (-(-dst.width // 4), dst.height), col, coc, i32(col.pitch), i32(pad),
                  dst, i32(dst.pitch), i32(dst.width), i32(dst.height), taps, tiles,
                  i32(levels.shape[1]), i32(tile), local=LOCAL)
        # (the pooled tables may be dropped now: the in-order queue uses them before any
        # later command could overwrite a reused buffer)

    def is_identity(self, p, ctx):
        k_half, _, clamp_r, _, _ = self._lens(p, ctx)
        if k_half == 0.0 or clamp_r < 0.25:
            return "the circle of confusion is 0 (max_blur, max_coc or aperture)"
        if ctx.depth is not None and float(self.tile_radii(p, ctx).max()) < 0.5:
            return "circle of confusion below half a pixel everywhere"
        return None

    def region_of_definition(self, p, ctx):
        return ctx.source.window.grown(*self.spread_px(p, ctx))

    def region_of_interest(self, p, ctx, window):
        return window.grown(*self.spread_px(p, ctx))

    # -- render ----------------------------------------------------------------------------
    def render(self, rt, p, ctx):
        window = self.output_window(p, ctx)
        if window != ctx.source.window:
            # Light leaves the data window: render over the grown window, outside it nothing
            # (transparent black) at the edge's depth.  A copy of the context, so the scene
            # analysis (the tiles) is taken over the grown window; notes stay shared.
            ctx = ctx.grown_to(window)
            ctx.notes.append(f"dof: grown to {window}")
        src, depth = ctx.source, ctx.depth
        lvl = self.level(ctx)
        k_half, focus, clamp_r, blades, first = self._lens(p, ctx)
        radii, r_min = self.tile_radii(p, ctx, with_min=True)
        # Tiles whose every pixel is far out of focus are gathered at half resolution.
        half = r_min >= lvl.half_res_radius
        levels = quantised_radius(np.where(half, 0.0, radii))
        r_max = float(quantised_radius(radii).max())
        # pad by the largest reach (+2 for rounding), quantised so buffers get reused
        pad = int(math.ceil((r_max * max(1.0, ctx.pixel_aspect) + 2) / 8.0) * 8)
        w, h = src.width, src.height
        padded = Rect.from_size(-(-(w + 2 * pad + 4) // 4) * 4, h + 2 * pad)
        col, coc = rt.image(padded, 4), rt.image(padded, 1)
        f32, i32 = np.float32, np.int32
        prep = rt.kernel("dof.cl", "dof_prepare", fp64=lvl.fp64)
        rt.launch(prep, (col.pitch // 4, col.height), src, depth, i32(src.pitch), i32(w),
                  i32(h), col, coc, i32(col.pitch), i32(col.height), i32(pad), f32(k_half),
                  f32(focus), f32(clamp_r))
        gather = rt.kernel("dof.cl", "dof_gather", fp64=lvl.fp64)
        dst = src.like()
        self._gather(rt, gather, col, coc, pad, dst, levels, lvl, ctx.pixel_aspect, blades,
                     first, p.roundness)
        if half.any():
            hw, hh, hpad = -(-w // 2), -(-h // 2), pad // 2
            hpadded = Rect.from_size(-(-(hw + 2 * hpad + 4) // 4) * 4, hh + 2 * hpad)
            colh = box_downsample2x(rt, col, rt.image(hpadded, 4), scale=0.25)
            coch = box_downsample2x(rt, coc, rt.image(hpadded, 1), scale=0.125)  # radii halved
            hdst = rt.image((hh, hw), 4)
            hlevels = quantised_radius(np.where(half, 0.5 * radii, 0.0))
            self._gather(rt, gather, colh, coch, hpad, hdst, hlevels, lvl, ctx.pixel_aspect,
                         blades, first, p.roundness, tile=TILE // 2)
            flags = rt.to_device(np.ascontiguousarray(half, np.int32))
            rt.launch(rt.kernel("dof.cl", "dof_upsample", fp64=lvl.fp64), (w, h), hdst,
                      i32(hdst.pitch), i32(hw), i32(hh), dst, i32(dst.pitch), i32(w), i32(h),
                      flags, i32(half.shape[1]), i32(TILE), local=(32, 4))
        an = ctx.analysis
        notes = []
        if an.nonfinite_count:
            notes.append(f"{an.nonfinite_count} non-finite pixels set to 0")
        if an.bad_depth is not None and int(an.bad_depth.sum()):
            notes.append(f"{int(an.bad_depth.sum())} invalid depths treated as in focus")
        skipped = int((quantised_radius(radii) == 0).sum())
        notes.append(f"{skipped}/{radii.size} tiles in focus (copied), "
                     f"{int(half.sum())} at half resolution")
        ctx.notes.append("dof: " + "; ".join(notes))
        return dst
