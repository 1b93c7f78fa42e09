"""The warp family's canvas and band protocol: what distortion, lens, chromatic_aberration,
breathing and keystone share between their maps (`clfx.fx.resample`) and the host.

A warp renders ``out(u) = src(map(u))`` over a *canvas* (`warp_canvas`): its output window,
grown to the frame where the border rule (``edge``, ``mirror``) applies at the frame's edge.
Its arithmetic is in the canvas's coordinates whatever part of it renders: a tile of a tiled
render computes its rows of the whole render's canvas (`CanvasRows`, `on_canvas`), so every
pixel gets the whole render's bits.  An effect supplies its maps and a
``render(canvas_ctx, sanitise, rows)``; `on_canvas` (or `on_plate_canvas` where the maps
depend on the plate, ``fit=crop``) does the rest.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from types import SimpleNamespace
from typing import ClassVar

import numpy as np

from clfx.device.runtime import ALIGN_PX
from clfx.fx.resample import (FootprintMap, ResampleLevel, band_window, bounding_rect,
                              elliptical_map, footprint_defines, launch_footprint, map_bands,
                              pixel_centres, rect_boundary, warp_interest)


def frame_key(p, ctx) -> tuple:
    """What a warp's maps depend on besides the effect and level (part of its ``rt.cache``
    keys): the parameters, the source's window and row pitch, the display window, pixel
    aspect and camera."""
    src = ctx.source
    return (p.hash_hex(), src.window, src.pitch, ctx.display_window, ctx.pixel_aspect,
            ctx.camera)


def needs_sanitising(ctx, effect: str) -> bool:
    """True if the frame has non-finite pixels (from the shared per-frame analysis).

    Such pixels read as 0 in the resampler; the count goes to ``ctx.notes``.  Without any,
    the kernels are built without the per-texel test.
    """
    try:
        count = ctx.analysis.nonfinite_count
        count = count() if callable(count) else int(count)
    except Exception:      # no analysis available: stay safe
        return True
    if count:
        ctx.notes.append(f"{effect}: {count} non-finite pixel(s) read as 0")
    return count > 0


WARP_REACH_TEXELS = 4
"""How far past a texel a warp's filters read it (Lanczos-3's 3 taps, rounded up): a source
window grown by this many texels before it is mapped bounds where its pixels can land."""


def warp_frame(ctx):
    """The frame a warp's ``border`` rule applies at: the display window, or the data window
    where it is larger (overscan).  Inside it, pixels outside the data window are
    transparent black (an element's bounding box), not an edge to repeat."""
    return ctx.source.window.union(ctx.display_window)


def plate_frame(ctx):
    """The frame a warp's plate covers (`warp_frame`) as the whole render sees it (a tile's
    context gives the whole render's): the outline ``fit=crop`` fills the display window
    with.  Asked of the step's context, never of a canvas's (`on_canvas`)."""
    return warp_frame(whole_context(ctx))


def warp_region(forward, ctx, border: str, margin: int = 2, reach: int = 0):
    """Region of definition of a warp whose source points land at ``forward(xs, ys)`` (frame
    coordinates; a list of ``(xs, ys)``, one per channel that moves differently).

    The data window, grown by the filters' reach (``WARP_REACH_TEXELS``, plus ``reach``
    texels where footprints widen), has its outline mapped: the maps here are radial and
    monotonic, so the outline's image bounds the whole window's; the data window itself
    stays (an image that shrinks keeps its window).  ``margin`` output pixels cover the sampling of the outline and the
    footprints' sub-samples.  ``border``: with ``edge`` where the data window reaches the
    frame's edge (``warp_frame``), or ``mirror``, points read past the frame bring its edge
    in anywhere: the frame is added."""
    src = ctx.source.window
    if src.empty:
        return src
    xs, ys = rect_boundary(src.grown(WARP_REACH_TEXELS + max(int(reach), 0)), 512)
    rod = src           # the data window stays (a shrinking image keeps its window)
    for fx, fy in forward(xs, ys):
        rod = rod.union(bounding_rect(fx, fy, margin, src))
    frame = warp_frame(ctx)
    if border == "mirror" or (border == "edge" and not _inside(src, frame)):
        rod = rod.union(frame)
    return rod


def _inside(rect, frame) -> bool:
    """``rect`` lies strictly inside ``frame`` (touches none of its edges)."""
    return (rect.x0 > frame.x0 and rect.y0 > frame.y0 and rect.x1 < frame.x1
            and rect.y1 < frame.y1)


def warp_canvas(plugin, p, ctx, border: str):
    """``(canvas, out)``: the window a warp renders over and the one it returns.

    ``out`` is ``plugin.output_window`` (the data window grown to where its content lands,
    within the output limit).  The canvas is ``out`` with a black border; with ``edge`` or
    ``mirror`` it also covers the frame (``warp_frame``), so the rule applies at the frame's
    edge and never at a data window smaller than the frame.  ``edge`` with a data window
    strictly inside the frame needs only a transparent pixel around it: the frame's edge is
    transparent there, and so is the canvas's."""
    out = plugin.output_window(p, ctx)
    src, frame = ctx.source.window, warp_frame(ctx)
    if border == "black":
        return out, out
    if border == "edge" and _inside(src, frame):
        return out.union(src.grown(1)), out
    return out.union(frame), out


def warp_source(rt, ctx, canvas, border: str):
    """The source on ``canvas``: transparent black inside the frame where the data window
    does not reach; past the frame the edge repeated (``edge``) or black."""
    src, frame = ctx.source, warp_frame(ctx)
    if border == "black" or canvas == frame or _inside(src.window, frame):
        return rt.reframe(src, canvas, "zero")
    return rt.reframe(rt.reframe(src, frame, "zero"), canvas,
                      "clamp" if border == "edge" else "zero")


def canvas_stand_in(window):
    """A source with ``window``'s geometry and no pixels (a look's `prepare`), for building
    the maps of a warp's canvas ahead of the frame."""
    return SimpleNamespace(window=window, channels=4, width=window.width,
                           height=window.height,
                           pitch=max(ALIGN_PX, -(-window.width // ALIGN_PX) * ALIGN_PX))


@dataclass(frozen=True)
class CanvasRows:
    """The rows of a warp's canvas one render computes, and how its kernels address them.

    A warp's arithmetic (the maps' source points, the texel indices and fractions, the
    border rule) is in the coordinates of its ``canvas`` (`warp_canvas`) whatever part of
    it renders: a tile of a tiled render (`on_canvas`) computes output rows ``first <=
    y < first + count`` (relative to the canvas's top) from a source buffer holding canvas
    rows from ``shift`` on, and writes an output of the same rows as its source; kernels
    address both buffers in canvas rows (``buffer - shift`` rows), so each pixel of the
    band gets the whole render's bits.  A whole render: every row, ``shift`` 0."""

    canvas: object
    first: int
    count: int
    shift: int = 0

    @classmethod
    def whole(cls, canvas) -> "CanvasRows":
        return cls(canvas, 0, canvas.height)

    @property
    def tiled(self) -> bool:
        return (self.first, self.count, self.shift) != (0, self.canvas.height, 0)

    @property
    def key(self) -> tuple:
        """What a map of these rows adds to its cache key (nothing for a whole render's)."""
        return (self.first, self.count) if self.tiled else ()

    @property
    def span(self) -> tuple[int, int]:
        return self.first, self.first + self.count

    def context(self, ctx):
        """``ctx`` as the maps see it: over (a stand-in of) the whole canvas."""
        return ctx if ctx.source.window == self.canvas else ctx.over(
            source=canvas_stand_in(self.canvas))


TILE_MARGIN_ROWS = 8
"""Rows a tile's source holds beyond its band's region of interest (see `on_canvas`)."""


def on_canvas(plugin, rt, p, ctx, border: str, render):
    """Render a warp over its canvas (`warp_canvas`): ``render(canvas_ctx, sanitise, rows)``
    sees a context whose source is the frame on the canvas (its maps are built for the
    canvas's pixels and cached under its window) and the `CanvasRows` to compute; the result
    is cut to the output window.  ``sanitise``: the frame has non-finite pixels (asked of
    the frame's own analysis).

    In a tile of a tiled render (``ctx.tiling``) the canvas is the whole render's, the
    source the canvas rows the band's region of interest covers (with
    ``TILE_MARGIN_ROWS``), filled as the whole render fills them (`warp_source`), and only
    the band's rows are computed; the result covers the band."""
    name = plugin.descriptor.name
    sanitise = needs_sanitising(ctx, name)
    if ctx.tiling is not None:
        return _tile_on_canvas(plugin, rt, p, ctx, border, render, sanitise)
    canvas, out = warp_canvas(plugin, p, ctx, border)
    rows = CanvasRows.whole(canvas)
    if canvas == ctx.source.window:
        img = render(ctx, sanitise, rows)
    else:
        img = render(ctx.with_source(warp_source(rt, ctx, canvas, border)), sanitise, rows)
    return rt.reframe(img, out, "zero")


def on_plate_canvas(plugin, rt, p, ctx, border: str):
    """`on_canvas` for a warp whose maps depend on the plate it reads (``fit=crop``:
    distortion, lens): ``plugin.render_canvas(rt, p, canvas_ctx, sanitise, plate, rows)``
    with ``plate`` the step's `plate_frame` (a canvas's context no longer knows it)."""
    plate = plate_frame(ctx)
    return on_canvas(plugin, rt, p, ctx, border, lambda c, sanitise, rows:
                     plugin.render_canvas(rt, p, c, sanitise, plate, rows))


def whole_context(ctx):
    """``ctx`` as the whole render sees it: in a tile of a tiled render (``ctx.tiling``) over
    a stand-in of the whole source window (the geometry, maps and canvas of the whole
    render), else ``ctx`` itself."""
    return ctx if ctx.tiling is None else ctx.over(
        source=canvas_stand_in(ctx.tiling.whole), tiling=None)


def band_rows(read, roi, band, canvas) -> tuple:
    """What a tile computing the rows ``band`` of the output ``canvas`` reads and renders.

    Parameters
    ----------
    read : Rect
        The whole render's source window (the frame on the warp's canvas, or what a scale
        reads).
    roi : Rect
        The band's region of interest.
    band, canvas : Rect
        The band and the whole render's output canvas.

    Returns
    -------
    (Rect, CanvasRows)
        The rows of ``read`` the tile's source holds (the region of interest and the band,
        ``TILE_MARGIN_ROWS`` more each side, within ``read``) and the band's `CanvasRows`.
    """
    y0 = max(read.y0, min(roi.y0, band.y0) - TILE_MARGIN_ROWS)
    y1 = min(read.y1, max(roi.y1, band.y1) + TILE_MARGIN_ROWS)
    return (type(read)(read.x0, y0, read.x1, y1),
            CanvasRows(canvas, band.y0 - canvas.y0, band.height, y0 - read.y0))


def _tile_on_canvas(plugin, rt, p, ctx, border, render, sanitise):
    """`on_canvas` of a tile (``ctx.tiling``): the band's rows of the whole render."""
    band = ctx.tiling.band
    whole = whole_context(ctx)
    canvas, _ = warp_canvas(plugin, p, whole, border)
    part, rows = band_rows(canvas, plugin.region_of_interest(p, whole, band), band, canvas)
    y0, y1 = part.y0, part.y1
    frame = warp_frame(whole)
    if border == "edge" and not (canvas == frame or _inside(whole.source.window, frame)):
        # the rows past the frame repeat its edge rows: bring the ones they repeat
        top = min(max(y0, frame.y0), frame.y1 - 1)
        bottom = max(min(y1, frame.y1), top + 1)
        rows_of = type(canvas)(frame.x0, top, frame.x1, bottom)
        source = rt.reframe(rt.reframe(ctx.source, rows_of, "zero"), part, "clamp")
    else:
        source = rt.reframe(ctx.source, part, "zero")
    return render(ctx.over(source=source), sanitise, rows)


def canvas_context(plugin, p, ctx, border: str):
    """``ctx`` over a stand-in of the warp's canvas (for `Plugin.prepare`)."""
    canvas, _ = warp_canvas(plugin, p, ctx, border)
    if canvas == ctx.source.window:
        return ctx
    return ctx.with_source(canvas_stand_in(canvas))



# -- a warp through an analytic map, on the shared footprint kernels ---------------------------
def widest(points, rect, n: int = 33) -> float:
    """The largest |J| (2-norm, texels per output pixel) of a map over ``rect``: its outline
    and an n x n grid (``points(xs, ys, True)`` gives ``(sx, sy, jac)``; compression grows
    towards a fold or a horizon, so the outline holds the maximum of the maps accepted here;
    the grid covers the others)."""
    if rect.empty:
        return 1.0
    bx, by = rect_boundary(rect, 256)
    gx, gy = np.meshgrid(np.linspace(rect.x0, rect.x1, n), np.linspace(rect.y0, rect.y1, n))
    _, _, jac = points(np.concatenate([bx, gx.ravel()]), np.concatenate([by, gy.ravel()]),
                       True)
    norms = np.linalg.norm(np.nan_to_num(jac), ord=2, axis=(-2, -1))
    return max(float(norms.max(initial=0.0)), 1.0)


FOOTPRINT_LEVELS = {
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
"""The quality levels of a `FootprintWarp` (distortion, keystone): the footprint filters of
kernels/lib/resample.h, the reference's elliptical footprint in float64."""


class PlateCanvasWarp:
    """A warp rendered on the plate's canvas (`on_plate_canvas`), whose maps a look's
    ``prepare`` builds ahead on the canvas's stand-in (a Plugin mixin): the effect writes
    :meth:`prepare_maps` (build, through ``rt.cache``, what ``render_canvas`` will ask for,
    on ``cctx``, the canvas's context, at level ``lvl`` for ``plate``) and ``render_canvas``."""

    def prepare_maps(self, rt, p, cctx, lvl, plate) -> None:
        raise NotImplementedError

    def prepare(self, rt, p, ctx):
        if not self.is_identity(p, ctx):
            self.prepare_maps(rt, p, canvas_context(self, p, ctx, p.border), self.level(ctx),
                              plate_frame(ctx))

    def render(self, rt, p, ctx):
        return on_plate_canvas(self, rt, p, ctx, p.border)


class FootprintWarp(PlateCanvasWarp):
    """A warp whose inverse map and its Jacobian are analytic, rendered by the shared
    footprint kernels (a Plugin mixin: ``class Keystone(FootprintWarp, Plugin)``).

    The effect writes its model and nothing of bands, tiles, canvases or caches:

    - :meth:`warp_geometry`: what the map needs of a frame (intrinsics, coefficients, the
      ``fit`` scale), from the context's camera, display window, source window and pixel
      aspect, and ``plate`` (`plate_frame`: the outline ``fit=crop`` fills the display
      window with); raise `ParamError` for a model the frame cannot take.
    - :meth:`warp_points`: the source points (frame coordinates, float64, NaN = no source)
      of output points, with their Jacobians d(source) / d(output) (..., 2, 2) when asked.
    - :meth:`warp_forward`: where the output shows source points (the map's inverse, for
      the region of definition; NaN where none).
    - :meth:`warp_info` (optional): what the map's info holds beside ``no_source``;
      :meth:`reads_anywhere` (optional): True where the outline of a window comes near a
      fold or horizon, so the region of definition is the frame.

    The descriptor's ``kernel`` instantiates ``FOOTPRINT_WARP_KERNELS`` and
    ``EWA_WARP_KERNELS`` (kernels/lib/footprint_warp.h) under its name, its levels are
    ``clfx.fx.resample.ResampleLevel`` with ``footprint=True`` and its params include
    ``fit`` (`clfx.fx.resample.FITS`) and ``border`` (`clfx.fx.resample.BORDERS`).
    Regions, the canvas (`on_plate_canvas`), a tile's rows (`CanvasRows`), maps built in
    bands (`clfx.fx.resample.map_bands`), their cache keys and the look's ``prepare`` come
    from here, so a tile's pixels are the whole render's.
    """

    whole_frame: ClassVar[str | None] = None   # a tile computes its band's rows (`on_canvas`)
    no_source_note: ClassVar[str] = "beyond the map's reach"
    """How a render's note names the output pixels without a source."""

    # -- what the effect supplies ------------------------------------------------------------
    def warp_geometry(self, p, ctx, plate):
        raise NotImplementedError

    def warp_points(self, g, ox, oy, jacobian: bool):
        raise NotImplementedError

    def warp_forward(self, g, sx, sy):
        raise NotImplementedError

    def warp_info(self, g) -> dict:
        return {}

    def reads_anywhere(self, g, rect) -> bool:
        return False

    # -- regions ----------------------------------------------------------------------------
    def geometry(self, p, ctx):
        """The map's geometry for the step's context (its plate: `plate_frame`)."""
        return self.warp_geometry(p, ctx, plate_frame(ctx))

    def widest(self, g, rect) -> float:
        """The map's largest compression over ``rect`` (`widest`)."""
        return widest(lambda x, y, jac: self.warp_points(g, x, y, jac), rect)

    def region_of_definition(self, p, ctx):
        # Output pixels read up to ~0.75 |J| + 4 texels from their source points (footprints
        # widen where the map compresses), so the data window grown by that, mapped forward,
        # bounds where its content lands.  Kept in ``rt.cache`` with the maps: the Jacobian
        # survey costs tens of milliseconds of host time, asked several times a frame and
        # the same for every frame of a shot.
        def build():
            g = self.geometry(p, ctx)
            reach = (math.ceil(0.75 * self.widest(g, ctx.source.window.union(ctx.output_limit)))
                     + WARP_REACH_TEXELS - 4)
            if self.reads_anywhere(g, ctx.source.window.grown(reach + 4)):
                return ctx.source.window.union(warp_frame(ctx))
            return warp_region(lambda xs, ys: [self.warp_forward(g, xs, ys)], ctx, p.border,
                               reach=reach)

        return ctx.runtime.cache.get((f"{self.descriptor.name}.rod",) + frame_key(p, ctx)
                                     + (ctx.output_limit,), build)

    def region_of_interest(self, p, ctx, window):
        def build():
            g = self.geometry(p, ctx)
            return warp_interest(lambda x, y: [self.warp_points(g, x, y, False)], window,
                                 4 + math.ceil(0.75 * self.widest(g, window)))

        return ctx.runtime.cache.get((f"{self.descriptor.name}.roi",) + frame_key(p, ctx)
                                     + (window,), build)

    # -- maps -------------------------------------------------------------------------------
    def host_map(self, rt, p, ctx, plate):
        """The float64 source points of ``ctx.source``'s pixels (source-window coordinates,
        NaN = no source), their Jacobians and the map's info, kept in ``rt.cache`` (shared by
        every level's device map).  ``plate``: the frame the plate covers (`plate_frame` of
        the step's context: ``ctx`` is the canvas's)."""
        src = ctx.source

        def build():
            g = self.warp_geometry(p, ctx, plate)
            sx, sy, jac = self.warp_points(g, *pixel_centres(src.window), True)
            info = dict(self.warp_info(g), no_source=int(np.count_nonzero(~np.isfinite(sx))))
            return sx - src.window.x0, sy - src.window.y0, jac, info

        return rt.cache.get((f"{self.descriptor.name}.host_map",) + frame_key(p, ctx)
                            + (plate,), build)

    def banded_map(self, rt, p, ctx, filter_name, rows, plate):
        """A frame larger than one band (`clfx.fx.resample.map_bands`), or a tile's band of
        rows (``rows``): the footprint map built band by band from the same geometry (no
        float64 map of the whole frame is kept), or with ``filter_name`` None the reference's
        elliptical map of ``rows``: ``(map, info)``."""
        src = ctx.source
        g = self.warp_geometry(p, ctx, plate)
        no_source = 0

        def points_of(y0, y1):
            nonlocal no_source
            sx, sy, jac = self.warp_points(g, *pixel_centres(band_window(src.window, y0, y1)),
                                           True)
            no_source += int(np.count_nonzero(~np.isfinite(sx)))
            return sx - src.window.x0, sy - src.window.y0, jac

        if filter_name is None:
            dmap = elliptical_map(rt, *points_of(*rows.span), src.pitch, rows.first)
        else:
            dmap = FootprintMap.device(rt, points_of, filter_name, src.width, src.height,
                                       src.pitch, p.border, rows.span)
        return dmap, dict(self.warp_info(g), no_source=no_source)

    def device_map(self, rt, p, ctx, filter_name, double, plate, rows=None):
        """The device map of one level, kept in ``rt.cache``: ``(map, info)``; float levels a
        `clfx.fx.resample.DeviceFootprintMap` of their footprint filter; ``double``
        (reference) the float64 elliptical map (`clfx.fx.resample.elliptical_map`).
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
        return rt.cache.get((f"{self.descriptor.name}.map",) + frame_key(p, ctx)
                            + (plate, key) + rows.key, build)

    def prepare_maps(self, rt, p, cctx, lvl, plate):
        self.device_map(rt, p, cctx, lvl.filter, rt.use_fp64(lvl.fp64), plate)

    # -- render -----------------------------------------------------------------------------
    def render_canvas(self, rt, p, ctx, sanitise, plate, rows=None):
        """The warp over ``ctx.source``'s window (the canvas: `on_canvas`, or the part of it
        a tile holds: ``rows``, the `CanvasRows` to compute, default all); ``plate``: the
        frame the plate covers (`on_plate_canvas`)."""
        name, kfile = self.descriptor.name, self.descriptor.kernel
        src = ctx.source
        rows = rows or CanvasRows.whole(src.window)
        canvas = rows.canvas
        lvl = self.level(ctx)
        double = rt.use_fp64(lvl.fp64)
        dmap, info = self.device_map(rt, p, rows.context(ctx), lvl.filter, double, plate, rows)
        if info["no_source"]:
            ctx.notes.append(f"{name}: {info['no_source']} px {self.no_source_note} left "
                             f"transparent")
        defines = footprint_defines(lvl.filter, p.border, sanitise)
        dst = src.like()
        if not double:
            defines["CLFX_STREAM_STORES"] = int(rt.streams_stores(dst.nbytes))
        tail = (src.pitch, canvas.width, canvas.height, dst.pitch, rows.count, rows.first,
                rows.shift)
        if double:
            knl = rt.kernel(kfile, f"{name}_ewa_f64", fp64=lvl.fp64, **defines)
            rt.launch(knl, (src.pitch // 4, max(rows.count, 1)), src, dst, dmap, *tail)
            return dst
        launch_footprint(rt, rt.kernel(kfile, f"{name}_footprint", **defines), dmap,
                         src.pitch // 4, rows.count, (src, dst), tail)
        return dst
