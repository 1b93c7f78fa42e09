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
every layer uses.  Radii are clamped to ``max_coc / 2 * diagonal``; the default (a quarter of
the diagonal) lets any physical lens through, and a clamp that bites adds one line naming
the effect, the frame and the CoC asked for to ``ctx.warnings`` (the pipeline prints them on
stderr) and to the notes.  Invalid depths (NaN, 0, negative) count as in focus; non-finite
colours become 0 (counted in the notes).
Pixel aspect stretches the aperture vertically (radii are in x pixels).  The bokeh is the
aperture: a disk, or a polygon of ``blades`` blades inscribed in the CoC circle, first vertex
up, turned by the rotation, blended toward the disk by ``roundness``; behind the focus plane
it is upright, in front turned by 180 degrees (the geometry of :mod:`clfx.bench.groundtruth`).

Algorithm (after Jimenez 2014, "Next generation post processing in Call of Duty: Advanced
Warfare", simplified for offline use)
1. ``dof_prepare``: sanitised colour and signed CoC radius into a padded buffer.
2. ``dof_edges``: edge-aware radii.  Renderers write an antialiased beauty but a depth taken
   at the pixel centre, so a light beside a blurred foreground bar has pixels that mix the
   light with the bar and carry the bar's depth; spread with the bar's CoC they make a
   bright half-disk.  A pixel on a depth edge (its 3 x 3 radii span a pixel or more) whose
   log luminance is far (> 0.5) from the median of its own layer's neighbours takes the
   radius of the other layer's neighbour that looks most like it, when that layer is the
   sharper one: the light stays a sharp light, partly covered by the bar's blur.
3. Tiles (32 px, the shared scene analysis): the largest CoC radius a tile's depth range can
   produce, dilated on the host over as many tiles as the largest radius reaches (3 x 3 for
   radii up to a tile); tiles whose neighbourhood maximum is below half a pixel are copied
   (and the whole frame is an identity when every tile is).  Per tile also the largest
   radius of a pixel in front of the focus plane within reach: pixels in focus (or nearly)
   gather over only that and their own radius.
4. ``dof_gather``: taps over the neighbourhood radius ``R``: every pixel of the disk up to
   the level's ``dense_radius`` (a single bright pixel spreads into an evenly lit disk with
   an antialiased rim), beyond that rings (ring spacing and count by quality); two fields
   per pixel:
   - near field (taps in front of the focus plane): each tap spreads its light over its own
     CoC area (weight ``coverage / (pi r^2)``), so a blurred foreground spreads over the
     in-focus background; its coverage (tap area x weight, summed) is the foreground alpha;
   - far field (the rest): normalised, and a tap behind the pixel spreads at most the
     pixel's own radius, so an in-focus edge does not bleed into a blurred background and a
     blurred background does not wash over a sharp object; for a near pixel the far field
     is the background hidden behind it, estimated from the visible background around:
     where a tap's own CoC would not reach, its colour is capped at ``CAP_FACTOR`` times the
     geometric mean luminance of the tiles around (``dof_tile_cap``), so a sharp light does
     not shine through a blurred bar beside it.
   ``out = far (1 - alpha) + near alpha``.  Every tap rejected falls back to the centre pixel.
5. Tiles whose every pixel is far out of focus (CoC radius above the level's
   ``half_res_radius``) are also gathered at half resolution (``dof_down2``: 2 x 2 box of
   colour, mean radius halved; the same gather with half the radius) and upsampled
   bilinearly, except where the half-resolution pixels span more than the level's
   ``refine`` in log luminance (the rim of a bokeh disk: a highlight's rim stays as crisp
   as the full-resolution gather's, no light leaks outside it) or a pixel is sharper (an
   edge-aware radius): there the full-resolution gather runs.

Each work-item gathers 4 adjacent pixels with shared tap offsets (float16 vectors).  Finite
colours give finite results: a gather whose float sums overflow (values near 3e38) is taken
again with every colour scaled by 2^-64, and the box and the bilinear weights are applied
before summing.

Light leaves the data window: the region of definition grows by the largest CoC radius the
frame's depth range can produce (the tiles of the shared scene analysis; the ``max_coc``
clamp without them).  When the output window is larger than the source window (a data window
tighter than the display window), the beauty is extended with transparent black and the
depth by its edge values, and the tiles are taken over the grown window.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from clfx.core.camera import aperture_radius, coc_signed, first_blade_angle
from clfx.core.plugin import ChoiceParam, Clip, Descriptor, FloatParam, IntParam, Level
from clfx.core.rect import Rect
from clfx.fx.analysis import TILE  # dof's tiles are the shared analysis's
from clfx.host import Plugin, register

LOCAL = (8, 4)      # work-group: 32 x 4 pixels, one tile wide


class Lens(NamedTuple):
    """A frame's lens in pixels."""

    k_half: float        # CoC radius at infinity (K / 2), px
    focus: float         # focus distance, scene units
    clamp_r: float       # largest CoC radius (max_coc / 2 x diagonal), px
    blades: int          # aperture blades (< 3: round)
    first: float         # direction of the first blade's vertex, radians


@dataclass(frozen=True)
class DofLevel(Level):
    """What one quality level of the gather does."""

    spacing: float = 1.0              # ring spacing of sparse tap tables, px
    max_rings: int = 12               # rings at most (3 K (K + 1) + 1 taps)
    dense_radius: float = 16.0        # radii up to this: every pixel of the disk is a tap
    half_res_radius: float = 6.0      # tiles whose every CoC radius is >= this: half resolution
    refine: float = math.inf          # log-luminance span that a half-res pixel gathers again


LEVELS = {
    "draft": DofLevel("every pixel of the disk a tap up to 16 px radius, then at most 8 rings; "
                      "half resolution where every CoC radius >= 3 px, only strong bokeh rims "
                      "gathered again at full resolution; float32 sums",
                      spacing=1.0, max_rings=8, dense_radius=16.0, half_res_radius=3.0,
                      refine=1.0),
    "preview": DofLevel("every pixel of the disk a tap up to 16 px radius, then at most 12 "
                        "rings; half resolution where every CoC radius >= 3 px, bokeh rims "
                        "gathered again at full resolution; float32 sums",
                        spacing=1.0, max_rings=12, dense_radius=16.0, half_res_radius=3.0,
                        refine=0.5),
    "final": DofLevel("every pixel of the disk a tap up to 32 px radius, then at most 32 rings; "
                      "half resolution where every CoC radius >= 6 px, bokeh rims and other "
                      "contrasts over 0.15 in log luminance gathered again at full resolution; "
                      "float32 sums",
                      spacing=1.0, max_rings=32, dense_radius=32.0, half_res_radius=6.0,
                      refine=0.15),
    "reference": DofLevel("every pixel of the disk a tap up to 32 px radius, then at most 32 "
                          "rings, all at full resolution, float64 sums",
                          fp64=True, spacing=1.0, max_rings=32, dense_radius=32.0,
                          half_res_radius=math.inf),
}

CAP_FACTOR = 4.0
"""Background hidden behind a blurred foreground pixel is filled in from the visible
background around, its colours capped at this many times the geometric mean luminance of
the tiles around (so a light beside a blurred bar does not shine through it)."""


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
              first: float = -0.5 * math.pi, roundness: float = 0.0,
              dense: float = 0.0) -> np.ndarray:
    """The gather's taps for a neighbourhood radius ``radius`` (px): (n, 8) float32 rows of
    (offset x, offset y, near distance, far distance, area, 0, 0, 0).

    Up to ``dense`` px: every pixel offset within ``radius + 0.5`` (x px; y stretched by the
    pixel aspect) is a tap standing for its own area, so a single bright pixel spreads into
    an evenly lit disk.  Beyond: ``K = clamp(ceil(radius / spacing), 1, kmax)`` rings at radii
    ``k radius / K`` with ``6k`` taps each (odd rings turned by half a step) plus the centre:
    uniform density over the disk, each tap standing for ``pi/3 (radius/K)^2`` px^2 (the
    centre ``pi/4 (...)^2``), offsets rounded to whole pixels.  Distances are measured on the
    integer offsets in x pixels, divided by the aperture's boundary radius in the direction
    of ``o`` (near taps: bokeh turned 180 degrees) or ``-o`` (far taps).
    """
    if radius <= dense:
        e = int(math.floor(radius + 0.5))
        ey = int(math.floor((radius + 0.5) * aspect))
        oy, ox = np.mgrid[-ey:ey + 1, -e:e + 1].astype(np.float64)
        keep = np.hypot(ox, oy / aspect) <= radius + 0.5
        ox, oy = ox[keep], oy[keep]
        order = np.lexsort((ox, oy, np.hypot(ox, oy / aspect)))   # centre first
        ox, oy = ox[order], oy[order]
        area = np.full(ox.shape, 1.0 / aspect)
    else:
        K = int(min(max(math.ceil(radius / spacing), 1), kmax))
        step = radius / K
        ox, oy, area = [0.0], [0.0], [0.25 * math.pi * step * step]
        for k in range(1, K + 1):
            n = 6 * k
            th = (np.arange(n) + (0.5 if k & 1 else 0.0)) * (2.0 * math.pi / n)
            ox.extend(np.rint(k * step * np.cos(th)))
            oy.extend(np.rint(k * step * np.sin(th) * aspect))
            area.extend([math.pi / 3.0 * step * step] * n)
        ox, oy, area = np.asarray(ox), np.asarray(oy), np.asarray(area)
    dy = oy / aspect
    d = np.hypot(ox, dy)
    phi = np.arctan2(dy, ox)
    table = np.zeros((len(ox), 8), np.float32)
    table[:, 0], table[:, 1] = ox, oy
    table[:, 2] = d / aperture_radius(phi, blades, first, roundness)
    table[:, 3] = d / aperture_radius(phi + math.pi, blades, first, roundness)
    table[:, 4] = area
    return table


def quantised_radius(r):
    """Tile radii rounded up to half pixels (a handful of tap tables per frame, none much
    larger than needed); 0 below half a pixel (the tile is copied)."""
    r = np.asarray(r, np.float64)
    return np.where(r < 0.5, 0.0, np.maximum(np.ceil(2.0 * r) / 2.0, 1.0))


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
            FloatParam("max_coc", 0.25, min=0.0, max=1.0,
                       hint="Largest CoC diameter as a fraction of the frame diagonal: a "
                            "safety clamp that any physical lens passes by default; when it "
                            "bites, a warning names the CoC asked for."),
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
    def lens(self, p, ctx) -> Lens:
        """The frame's lens in pixels (CoC at infinity, focus, clamp, aperture shape)."""
        k_half = 0.5 * lens_scale_px(p, ctx.camera, ctx.diagonal_px, ctx.width_px)
        clamp_r = 0.5 * p.max_coc * ctx.diagonal_px
        blades = ctx.camera.blades if p.blades < 0 else p.blades
        rot = ctx.camera.blade_rotation + p.blade_rotation
        return Lens(k_half, focus_distance(p, ctx.camera), clamp_r, blades,
                    first_blade_angle(rot))

    def tile_radii(self, p, ctx, *, with_near: bool = False):
        """Per 32 px tile: the largest CoC radius any pixel within reach can have (px); with
        ``with_near`` also the smallest radius of the tile's own pixels and the largest
        radius of a pixel in front of the focus plane within reach (0 if none)."""
        k_half, focus, clamp_r, _, _ = self.lens(p, ctx)
        src = ctx.source
        ty, tx = max(1, -(-src.height // TILE)), max(1, -(-src.width // TILE))
        an = ctx.analysis
        if an.min_depth is None:
            full = np.full((ty, tx), clamp_r, np.float32)  # no tile statistics: no skipping
            return (full, np.zeros_like(full), full) if with_near else full
        # the CoC is monotonic in 1/z, so a tile's extremes come from its depth range
        r0 = coc_radius(an.min_depth, k_half, focus, clamp_r)
        r1 = coc_radius(an.max_depth, k_half, focus, clamp_r)
        r = np.maximum(np.abs(r0), np.abs(r1))
        reach = max(int(math.ceil(r.max() / TILE)) if r.size else 0, 1)
        r_max = dilate_tiles(r, reach).astype(np.float32)
        if not with_near:
            return r_max
        # straddling the focus plane, or holding invalid depths (in focus): some pixel is sharp
        r_min = np.where((r0 * r1 <= 0) | (an.bad_depth > 0), 0.0,
                         np.minimum(np.abs(r0), np.abs(r1)))
        near = dilate_tiles(np.maximum(-r0, 0.0), reach)
        return r_max, r_min.astype(np.float32), near.astype(np.float32)

    def spread_px(self, p, ctx) -> tuple[int, int]:
        """How far (x, y px) light can land from its pixel: the largest CoC radius of the
        frame (rounded up as the gather's), stretched by the pixel aspect in y, plus the
        coverage ramp's pixel."""
        radii = self.tile_radii(p, ctx)
        r = float(quantised_radius(radii.max())) if radii.size else 0.0
        if r == 0.0:
            return 0, 0
        return int(math.ceil(r)) + 1, int(math.ceil(r * ctx.pixel_aspect)) + 1

    def tap_tables(self, rt, levels, lvl, aspect, blades, first, roundness):
        """One concatenated tap table for the radii in ``levels`` and, per entry of
        ``levels``, (first, count, 0, 0); each radius's table is kept in the runtime's
        cache."""
        parts, offsets, n = [], {}, 0
        for r in sorted(set(levels.ravel().tolist()) - {0.0}):
            key = ("dof.taps", r, lvl.spacing, lvl.max_rings, lvl.dense_radius, aspect, blades,
                   first, roundness)
            taps = rt.cache.get(key, lambda r=r: tap_table(
                r, lvl.spacing, lvl.max_rings, aspect, blades, first, roundness,
                dense=lvl.dense_radius))
            offsets[r] = (n, len(taps))
            parts.append(taps)
            n += len(taps)
        table = np.concatenate(parts) if parts else np.zeros((1, 8), np.float32)
        info = np.zeros(levels.shape + (4,), np.int32)
        for r, (first_tap, count) in offsets.items():
            info[levels == r, :2] = (first_tap, count)
        return np.ascontiguousarray(table), np.ascontiguousarray(info)

    def clamp_warning(self, p, ctx) -> str | None:
        """The warning when ``max_coc`` cuts a CoC this frame asks for, else None."""
        lens = self.lens(p, ctx)
        an = ctx.analysis
        if an.min_depth is None or not an.min_depth.size:
            return None
        asked = 2.0 * float(np.abs(np.concatenate([
            coc_signed(an.min_depth, lens.k_half, lens.focus).ravel(),
            coc_signed(an.max_depth, lens.k_half, lens.focus).ravel()])).max())
        if asked <= 2.0 * lens.clamp_r * (1.0 + 1e-6):
            return None
        return (f"a CoC of {asked:.1f} px is asked for and clamped to "
                f"{2.0 * lens.clamp_r:.1f} px (max_coc = {p.max_coc:g} of the diagonal); "
                f"raise dof.max_coc to keep the lens")

    def is_identity(self, p, ctx):
        k_half, _, clamp_r, _, _ = self.lens(p, ctx)
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
        warning = self.clamp_warning(p, ctx)
        if warning and warning not in ctx.warnings:  # stderr: "frame N: dof: <warning>"
            ctx.warnings.append(warning)
            ctx.notes.append(warning)
        window = self.output_window(p, ctx)
        if window != ctx.source.window:
            # Light leaves the data window: render over the grown window, outside it nothing
            # (transparent black) at the edge's depth.  A copy of the context, so the scene
            # analysis (the tiles) is taken over the grown window; notes stay shared.
            ctx = ctx.grown_to(window)
            ctx.notes.append(f"dof: grown to {window}")
        src, depth = ctx.source, ctx.depth
        lvl = self.level(ctx)
        k_half, focus, clamp_r, blades, first = self.lens(p, ctx)
        aspect = ctx.pixel_aspect
        radii, r_min, near = self.tile_radii(p, ctx, with_near=True)
        levels = quantised_radius(radii)
        # Tiles whose every pixel is far out of focus are gathered at half resolution.
        half = (r_min >= lvl.half_res_radius) & (levels > 0)
        r_max = float(levels.max())
        # pad by the largest reach (+2 for rounding), quantised so buffers get reused
        pad = int(math.ceil((r_max * max(1.0, aspect) + 2) / 8.0) * 8)
        w, h = src.width, src.height
        padded = Rect.from_size(-(-(w + 2 * pad + 4) // 4) * 4, h + 2 * pad)
        col, coc0, coc = rt.image(padded, 4), rt.image(padded, 1), rt.image(padded, 1)
        f32, i32 = np.float32, np.int32
        luma = ctx.luminance_defines     # log luminance of the working space
        prep = rt.kernel("dof.cl", "dof_prepare", fp64=lvl.fp64, **luma)
        rt.launch(prep, (col.pitch // 4, col.height), src, depth, i32(src.pitch), i32(w),
                  i32(h), col, coc0, i32(col.pitch), i32(col.height), i32(pad), f32(k_half),
                  f32(focus), f32(clamp_r))
        rt.launch(rt.kernel("dof.cl", "dof_edges", fp64=lvl.fp64, **luma), (-(-w // 4), h),
                  col, coc0, coc, i32(col.pitch), i32(col.height), i32(pad), i32(w), i32(h),
                  local=(8, 4))
        del coc0
        # mean log luminance per tile: the caps of the hidden background
        ty, tx = radii.shape
        log_mean = rt.buffer(tx * ty * 4)
        rt.launch(rt.kernel("dof.cl", "dof_tile_cap", fp64=lvl.fp64, **luma), (tx, ty), col,
                  i32(col.pitch), i32(pad), i32(w), i32(h), i32(TILE), i32(tx), i32(ty),
                  log_mean)
        gather = rt.kernel("dof.cl", "dof_gather", fp64=lvl.fp64, **luma)
        common = (lvl, aspect, blades, first, p.roundness, log_mean)
        hdst = None
        if half.any():
            hw, hh, hpad = -(-w // 2), -(-h // 2), pad // 2
            hpadded = Rect.from_size(-(-(hw + 2 * hpad + 4) // 4) * 4, hh + 2 * hpad)
            colh, coch = rt.image(hpadded, 4), rt.image(hpadded, 1)
            rt.launch(rt.kernel("dof.cl", "dof_down2", fp64=lvl.fp64, **luma),
                      (colh.pitch, colh.height), col, coc, i32(col.pitch), i32(col.height), colh,
                      coch, i32(colh.pitch),
                      i32(colh.height))
            hdst = rt.image((hh, hw), 4)
            hlevels = quantised_radius(np.where(half, 0.5 * radii, 0.0))
            self._gather(rt, gather, colh, coch, hpad, hdst, hlevels, hlevels, None, *common,
                         tile=TILE // 2)
        # full resolution: sharp pixels gather over their own reach and the near field's,
        # out-of-focus ones take the half-resolution result where it is smooth
        sharp = np.where(levels > 0, quantised_radius(np.maximum(near, lvl.half_res_radius)
                                                      if math.isfinite(lvl.half_res_radius)
                                                      else radii), 0.0)
        sharp = np.minimum(sharp, levels)
        mode = np.where(half, 1, 0) + np.where(levels <= lvl.dense_radius, 2, 0)
        dst = src.like()
        self._gather(rt, gather, col, coc, pad, dst, levels, sharp, mode, *common, hres=hdst)
        an = ctx.analysis
        notes = []
        if an.nonfinite_count:
            notes.append(f"{an.nonfinite_count} non-finite pixels set to 0")
        if an.bad_depth is not None and int(an.bad_depth.sum()):
            notes.append(f"{int(an.bad_depth.sum())} invalid depths treated as in focus")
        skipped = int((levels == 0).sum())
        notes.append(f"{skipped}/{radii.size} tiles in focus (copied), "
                     f"{int(half.sum())} at half resolution")
        ctx.notes.append("dof: " + "; ".join(notes))
        return dst

    def _gather(self, rt, knl, col, coc, pad, dst, levels, sharp, mode, lvl, aspect, blades,
                first, roundness, log_mean, *, tile=TILE, hres=None):
        """Launch ``dof_gather`` over ``dst``: per tile the table of radius ``levels``, that
        of radius ``sharp`` for pixels in focus, ``mode`` (bit 0: take ``hres`` where it is
        smooth, bit 1: gather again where it is not)."""
        table, info = self.tap_tables(rt, np.stack([levels, sharp]), lvl, aspect, blades, first,
                                      roundness)
        tiles = np.zeros(levels.shape + (8,), np.int32)
        tiles[..., :2], tiles[..., 2:4] = info[0, ..., :2], info[1, ..., :2]
        tiles[..., 4] = 0 if mode is None else mode
        taps, tile_info = rt.to_device(table), rt.to_device(tiles)
        i32, f32 = np.int32, np.float32
        hres_args = ((hres, i32(hres.pitch), i32(hres.width), i32(hres.height)) if hres is not None
                     else (dst, i32(dst.pitch), i32(1), i32(1)))
        rt.launch(knl, (-(-dst.width // 4), dst.height), col, coc, i32(col.pitch), i32(pad),
                  dst, i32(dst.pitch), i32(dst.width), i32(dst.height), taps, tile_info,
                  log_mean, i32(levels.shape[1]), i32(levels.shape[0]), i32(tile),
                  f32(CAP_FACTOR), *hres_args, f32(lvl.refine), f32(lvl.half_res_radius),
                  local=LOCAL)
        # (the pooled tables may be dropped now: the in-order queue uses them before any
        # later command could overwrite a reused buffer)
