"""What a scene calls for: one cheap analysis pass per frame, shared by all effects.

Two small kernels read the frame once (vectorised, 4 pixels per step) and record per
32 x 32 tile: maximum and mean
luminance, non-finite pixel count, maximum velocity, depth range.  Effects use it to skip a
frame (an identity with a reason) or the tiles that need nothing: no highlight above a
threshold, a circle of confusion below half a pixel, velocity below half a pixel, no light
source in view.  The per-tile arrays are small (a 1080p frame has 60 x 34 tiles).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from clfx.core.camera import Camera
from clfx.core.rect import Rect

TILE = 32
"""Tile size in pixels of the analysis grid."""
STATS = 9
"""Values per tile (``kernels/lib/analysis.cl``)."""


MID_GREY = 0.18
"""Middle grey of a scene-referred plate normalised to 18 % grey: the scale the noise models
state their amounts at, and the exposure reference when a frame has no positive light."""

METER_TRIM = 0.25
"""The meter clamps the log of each tile's mean luminance to the quartiles of its frame's
(``METER_TRIM`` of the tiles at either end): lights and black borders do not move it."""

MIDDLE_GREY_AUTO = ("meter the frame: the mean of the log of its 32 x 32 tile mean "
                    "luminances, each clamped to their quartiles (lights, empty background "
                    "and black borders excluded)")
"""What ``middle_grey: auto`` means (`FloatParam.auto` of the noise effects)."""


def meter(mean_lum) -> float:
    """Metered middle grey of a frame from its tile mean luminances: a winsorised
    log-average.

    Tiles without light (mean <= 0: the empty background of a CG element, a black border)
    are left out; the log of every other tile's mean is clamped to the 25th-75th
    percentiles of theirs (the lights and the darkest quarter are counted at the quartile),
    and the mean of those logs is exponentiated.  So the meter is robust (a candle flame in
    a few tiles, or a letterbox, moves it by nothing; a pixel's noise by ~1e-4 of itself),
    continuous in the content (no jump as the ball of a moving shot crosses a tile), and
    scale-equivariant (k times the plate gives k times the grey).  ``MID_GREY`` when no
    tile holds light.  The analysis that supplies the tiles is the whole frame's, also when
    the effect renders in bands (`RenderContext.tile`).

    Parameters
    ----------
    mean_lum : array_like
        Per-tile mean luminance (`SceneAnalysis.mean_lum`); non-finite entries are ignored.

    Returns
    -------
    float
        The scene-linear luminance taken as middle grey.
    """
    m = np.asarray(mean_lum, np.float64).ravel()
    m = m[np.isfinite(m) & (m > 0.0)]
    if not m.size:
        return MID_GREY
    logs = np.log(m)
    lo, hi = np.percentile(logs, [100 * METER_TRIM, 100 * (1 - METER_TRIM)])
    return float(np.exp(np.mean(np.clip(logs, lo, hi))))


EXPOSURE_MIN = 1e-30
"""The least exposure reference: below it (a plate of denormals metered, a stated 1e-40) the
effects' per-unit gains (``1 / E``) would overflow float32; no plate with an image is near it."""


@dataclass
class LightSource:
    """A bright connected region of tiles, in the frame's full pixel coordinates."""

    x: float                 # luminance-weighted centre (tile resolution), px
    y: float
    bbox: Rect
    peak: float              # max luminance in the region
    energy: float            # sum over tiles of mean luminance x tile area (approximate)
    in_view: bool            # intersects the display window


@dataclass
class SceneAnalysis:
    window: Rect
    display_window: Rect
    tile: int
    max_lum: np.ndarray
    mean_lum: np.ndarray
    nonfinite: np.ndarray
    max_speed: np.ndarray | None
    min_depth: np.ndarray | None
    max_depth: np.ndarray | None
    bad_depth: np.ndarray | None
    camera: Camera = field(default_factory=Camera)
    seconds: float = 0.0
    stray_light: np.ndarray | None = None
    """Per tile, finite pixels with light but no alpha (alpha <= 0, some RGB != 0)."""

    # -- highlights ---------------------------------------------------------------------
    @property
    def peak_luminance(self) -> float:
        return float(self.max_lum.max()) if self.max_lum.size else 0.0

    @property
    def nonfinite_count(self) -> int:
        return int(self.nonfinite.sum())

    def any_above(self, threshold: float) -> bool:
        """True if any finite pixel's luminance exceeds ``threshold``."""
        return self.peak_luminance > threshold

    def tiles_above(self, threshold: float) -> np.ndarray:
        """Boolean (tiles_y, tiles_x) mask of tiles with a pixel above ``threshold``."""
        return self.max_lum > threshold

    def highlight_bounds(self, threshold: float) -> Rect:
        """Bounding box (frame coordinates) of the tiles with a pixel above ``threshold``;
        an empty rectangle when there is none.  Large-kernel effects transform only this."""
        ys, xs = np.nonzero(self.tiles_above(threshold))
        win, t = self.window, self.tile
        if ys.size == 0:
            return Rect(win.x0, win.y0, win.x0, win.y0)
        return Rect(win.x0 + int(xs.min()) * t, win.y0 + int(ys.min()) * t,
                    win.x0 + (int(xs.max()) + 1) * t, win.y0 + (int(ys.max()) + 1) * t).intersect(win)

    def light_sources(self, threshold: float, *, margin_px: int = 0) -> list[LightSource]:
        """Connected regions of tiles brighter than ``threshold`` (8-connectivity).

        Sources up to ``margin_px`` outside the display window (EXR overscan) are kept and
        flagged ``in_view=False``.
        """
        mask = self.tiles_above(threshold)
        if not mask.any():
            return []
        labels = _label(mask)
        near = self.display_window.grown(margin_px)
        sources = []
        for lab in range(1, labels.max() + 1):
            ys, xs = np.nonzero(labels == lab)
            w = self.mean_lum[ys, xs].astype(np.float64) * self.tile ** 2
            energy = float(w.sum())
            if not math.isfinite(energy):   # tiles near 3e38 overflowed their float32 mean:
                w = np.isinf(w).astype(np.float64)     # they dominate, equally
            cx = self.window.x0 + (xs + 0.5) * self.tile
            cy = self.window.y0 + (ys + 0.5) * self.tile
            wsum = float(w.sum()) or 1.0
            bbox = Rect(int(self.window.x0 + xs.min() * self.tile),
                        int(self.window.y0 + ys.min() * self.tile),
                        int(min(self.window.x1, self.window.x0 + (xs.max() + 1) * self.tile)),
                        int(min(self.window.y1, self.window.y0 + (ys.max() + 1) * self.tile)))
            if bbox.intersect(near).empty:
                continue
            sources.append(LightSource(float((w * cx).sum() / wsum), float((w * cy).sum() / wsum),
                                       bbox, float(self.max_lum[ys, xs].max()), energy,
                                       not bbox.intersect(self.display_window).empty))
        return sorted(sources, key=lambda s: -s.energy)

    def region_peaks(self, threshold: float) -> np.ndarray:
        """Per tile, the peak luminance of the connected region of tiles brighter than
        ``threshold`` it belongs to (the light of :meth:`light_sources`; 8-connectivity),
        0 for tiles in none: what "the brightest part of this light" is."""
        mask = self.tiles_above(threshold)
        out = np.zeros(mask.shape)
        if mask.any():
            labels = _label(mask)
            peaks = np.zeros(labels.max() + 1)
            np.maximum.at(peaks, labels[mask], self.max_lum[mask])
            out[mask] = peaks[labels[mask]]
        return out

    # -- alpha --------------------------------------------------------------------------
    def alpha_is_coverage(self) -> bool:
        """True if no pixel with alpha <= 0 holds light: the frame is premultiplied and its
        transparent areas are empty (a CG element on nothing, as OpenEXR's Beachball; an
        opaque plate trivially).  A photograph with a matte in its alpha (ScanLines'
        CandleGlass: light where alpha is 0) or an additive element (light, alpha 0) is not."""
        return self.stray_light is not None and int(self.stray_light.sum()) == 0

    # -- motion -------------------------------------------------------------------------
    def moving_tiles(self, min_px: float = 0.5) -> np.ndarray | None:
        """Mask of tiles where some pixel moves at least ``min_px`` (None: no velocity)."""
        return None if self.max_speed is None else self.max_speed >= min_px

    @property
    def peak_speed(self) -> float:
        return 0.0 if self.max_speed is None or not self.max_speed.size else float(self.max_speed.max())

    # -- depth of field -----------------------------------------------------------------
    def coc_tiles(self, camera: Camera | None = None, width_px: float | None = None):
        """(min, max) circle-of-confusion diameter per tile, in pixels, or None.

        The thin-lens CoC is monotonic on each side of the focus distance, so a tile's
        extremes come from its depth range (0 if the range straddles the focus plane).
        """
        if self.min_depth is None:
            return None
        cam = camera or self.camera
        width_px = width_px or self.display_window.width
        coc = np.vectorize(lambda z: cam.coc_px(float(z), width_px), otypes=[np.float64])
        valid = np.isfinite(self.min_depth) | (self.max_depth > 0)
        zmin = np.where(valid, self.min_depth, cam.focus_distance)
        zmax = np.where(valid, self.max_depth, cam.focus_distance)
        c0, c1 = coc(zmin), coc(zmax)
        straddle = (zmin <= cam.focus_distance) & (zmax >= cam.focus_distance)
        return np.where(straddle, 0.0, np.minimum(c0, c1)), np.maximum(c0, c1)

    def summary(self) -> dict:
        d = {"peak_luminance": self.peak_luminance, "nonfinite_pixels": self.nonfinite_count,
             "tiles": [int(self.max_lum.shape[1]), int(self.max_lum.shape[0])], "tile": self.tile,
             "ms": round(self.seconds * 1e3, 2)}
        if self.max_speed is not None:
            d["peak_speed_px"] = self.peak_speed
            d["moving_tiles"] = int(self.moving_tiles().sum())
        if self.min_depth is not None:
            finite = self.min_depth[np.isfinite(self.min_depth)]
            d["depth_range"] = [float(finite.min()) if finite.size else None,
                                float(self.max_depth.max()) if self.max_depth.size else None]
        return d


def _label(mask: np.ndarray) -> np.ndarray:
    """8-connected component labels of a small boolean grid (iterative flood fill)."""
    labels = np.zeros(mask.shape, np.int32)
    current = 0
    h, w = mask.shape
    for y0, x0 in zip(*np.nonzero(mask)):
        if labels[y0, x0]:
            continue
        current += 1
        stack = [(y0, x0)]
        labels[y0, x0] = current
        while stack:
            y, x = stack.pop()
            for dy in (-1, 0, 1):
                for dx in (-1, 0, 1):
                    yy, xx = y + dy, x + dx
                    if 0 <= yy < h and 0 <= xx < w and mask[yy, xx] and not labels[yy, xx]:
                        labels[yy, xx] = current
                        stack.append((yy, xx))
    return labels


def analyse(rt, source, *, depth=None, velocity=None, camera: Camera | None = None,
            display_window: Rect | None = None,
            luminance_defines: dict | None = None) -> SceneAnalysis:
    """Run the tile-statistics kernel over ``source`` (and passes sharing its window);
    luminance weighs RGB as ``luminance_defines`` say (``ctx.luminance_defines``: the working
    space's Y row; default Rec.709)."""
    t0 = time.perf_counter()
    w, h = source.width, source.height
    tx, ty = max(1, math.ceil(w / TILE)), max(1, math.ceil(h / TILE))
    if depth is not None and depth.window != source.window:
        depth = None  # passes no longer aligned with the beauty (an effect changed the window)
    if velocity is not None and velocity.window != source.window:
        velocity = None
    stats = rt.buffer(tx * ty * STATS * 4)
    rows = rt.buffer(max(h, 1) * tx * STATS * 4)
    dummy = rt.buffer(64)
    f = np.int32
    rt.launch(rt.kernel("lib/analysis.cl", "analysis_rows", TILE=TILE,
                        **(luminance_defines or {})), (tx, max(h, 1)), source,
              f(source.pitch), f(w), f(h),
              depth.buffer if depth is not None else dummy.buffer,
              velocity.buffer if velocity is not None else dummy.buffer,
              f(depth is not None), f(velocity is not None), rows, f(tx))
    rt.launch(rt.kernel("lib/analysis.cl", "analysis_tiles", TILE=TILE), (tx, ty), rows, f(w), f(h),
              stats, f(tx), f(ty))
    s = rt.from_device(stats, np.float32, tx * ty * STATS).reshape(ty, tx, STATS)
    if w == 0 or h == 0:
        s[:] = 0
    return SceneAnalysis(
        window=source.window, display_window=display_window or source.window, tile=TILE,
        max_lum=s[..., 0].copy(), mean_lum=s[..., 1].copy(), nonfinite=s[..., 2].astype(np.int64),
        max_speed=s[..., 3].copy() if velocity is not None else None,
        min_depth=s[..., 4].copy() if depth is not None else None,
        max_depth=s[..., 5].copy() if depth is not None else None,
        bad_depth=s[..., 6].astype(np.int64) if depth is not None else None,
        camera=camera or Camera(), seconds=time.perf_counter() - t0,
        stray_light=s[..., 8].astype(np.int64))
