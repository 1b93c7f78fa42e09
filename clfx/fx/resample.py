"""Host side of clfx's warping effects: inverse maps, fold checks, fit scales, filters.

Shared by the warps (``distortion``, ``keystone``, ``chromatic_aberration``, ``lens``,
``breathing``; device side: ``kernels/lib/resample.h``); their canvas and band protocol is
``clfx.kit.warp``.  Everything here runs once per parameter set and frame geometry, in
float64 NumPy, and the result (a displacement map or a radial look-up table) is kept in the
runtime's cache (``rt.cache``) and reused across frames.

Conventions
-----------
Continuous pixel coordinates: the centre of pixel (i, j) of a window is (i + 0.5, j + 0.5)
relative to the window's origin; frame coordinates add the window origin.  OpenCV puts pixel
centres at integers, so an OpenCV point u_cv is u_cv + 0.5 here.

A warp renders ``out(u) = src(map(u))``: for each output pixel the map gives the point of the
source image to read.  To *add* a lens defect (distortion, lateral CA) the map is the inverse
of the lens model: the model sends an undistorted point to where the lens images it, so the
output pixel u_d reads the undistorted point u_u with model(u_u) = u_d.  The inverse is found
by bracketed bisection / Newton, never by fixed-point iteration (hard-cases.md case 10).

Footprints (``FOOTPRINTS``, ``FootprintMap``, ``elliptical_map``): where a map compresses the
source, a filter read at one point aliases; the footprint filters widen per output pixel by
the variance the pixel's preimage (from the map's Jacobian) adds beyond a texel, packed once
per parameter set like the point maps.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from clfx.core import cancel
from clfx.core.errors import ParamError
from clfx.core.plugin import Level

FILTERS = ("bilinear", "bicubic", "lanczos3")
FILTER_CODE = {"bilinear": 0, "bicubic": 1, "lanczos3": 2}
FILTER_TAPS = {"bilinear": 2, "bicubic": 4, "lanczos3": 6}
BORDERS = ("black", "edge", "mirror")
BORDER_CODE = {"black": 0, "edge": 1, "mirror": 2}


@dataclass(frozen=True)
class ResampleLevel(Level):
    """A warping effect's quality level: its resampling ``filter`` (one of ``FILTERS``);
    ``fp64`` reads a float64 map and accumulates in float64 (``kernels/lib/precision.h``).
    ``footprint``: the filter's footprint follows the map's local Jacobian (one of
    ``FOOTPRINTS``; the reference level's elliptical footprint when ``fp64``), so regions the
    map compresses are area-averaged instead of aliased."""

    filter: str = "lanczos3"
    footprint: bool = False


@dataclass(frozen=True)
class Footprint:
    """A footprint filter of ``kernels/lib/resample.h`` (see :func:`footprint_spread`).

    ``code`` (FP_FILTER), ``taps`` per axis of the fast kernel's window, ``kappa`` (scale of
    the extra variance: the filter's own shape attenuates high frequencies less than the box
    it stands for, so the draft's 3 taps need more), ``cap`` (the largest extra variance one
    window holds; beyond it the footprint is split into n x n sub-footprints), ``half_f``
    (the packed map stores the fractions as float16, 12 ints a quad, not float32, 16 ints:
    ``FP_Q_INTS`` in kernels/lib/resample.h).
    """

    code: int
    taps: int
    kappa: float
    cap: float
    half_f: bool = False

    @property
    def entry_ints(self) -> int:
        """Ints per quad of the packed map."""
        return 12 if self.half_f else 16


FOOTPRINTS = {
    "quadratic": Footprint(0, 3, 1.3, 0.75, half_f=True),
    "bicubic": Footprint(1, 4, 1.0, 1.0 / 3.0),
    "lanczos3": Footprint(2, 8, 1.0, 0.25),
}
"""Footprint filters (draft, preview, final): 3-tap quadratic with a variance term, Keys
bicubic blended with the cubic B-spline, the mean of two Lanczos-3 samples at +-h.  The
Lanczos pair's cap, 0.25 (h <= 1/2: one window takes a pixel up to W = 2 texels wide): with
the texel's own box its response cos(2 pi f h) L(f) sinc(f) follows the box's sinc(W f) only
while h is small (at h = 1/2 both are 0 at the source's Nyquist); at h = 0.86 (W = 3.1, the
top rows of keystone's ``steep`` bench case) it passes -0.29 of Nyquist where the box passes
-0.20, which aliases once minified (that case's rel. error at 320x180: 0.0691 at cap 0.98,
0.0672 at 0.25, the reference level 0.0648).  Wider pixels split into n x n parts."""


def kernel_defines(filter_name: str, border: str, sanitise: bool = True) -> dict:
    """``-D`` defines selecting the filter, border rule and NaN/Inf handling (the precision
    comes from the level: ``rt.kernel(..., fp64=level.fp64, **defines)``)."""
    return {"RS_FILTER": FILTER_CODE[filter_name], "RS_BORDER": BORDER_CODE[border],
            "RS_SANITISE": int(bool(sanitise))}


BAND_PIXELS = 1 << 18
"""Maps are built on the host in bands of at most this many pixels (whole rows of the source's
pitch) and uploaded band by band: the float64 temporaries (~150 bytes per pixel) are a band's,
not the frame's (an 8K frame's would be ~5 GB).  A 1920x1080 frame is one band."""


def map_bands(height: int, pitch: int) -> list[tuple[int, int]]:
    """Row ranges ``(y0, y1)`` of the bands a map of ``height`` rows of ``pitch`` pixels is
    built in (one band, ``(0, height)``, when it fits in :data:`BAND_PIXELS`)."""
    step = max(1, BAND_PIXELS // max(int(pitch), 1))
    return [(y, min(height, y + step)) for y in range(0, max(height, 1), step)]


def band_window(window, y0: int, y1: int):
    """Rows ``y0 <= y < y1`` of ``window`` (relative to its top), as a window."""
    return type(window)(window.x0, window.y0 + y0, window.x1, window.y0 + y1)


def row_spans(rows: tuple[int, int], pitch: int) -> list[tuple[int, int]]:
    """:func:`map_bands` of the output rows ``rows = (y0, y1)`` of a map (all of a whole
    render's, a band of them in a tile: `CanvasRows`)."""
    y0, y1 = rows
    return [(y0 + a, y0 + b) for a, b in map_bands(y1 - y0, pitch)]


def _upload_bands(rt, spans, make, records: dict):
    """A pooled buffer filled band by band with a map's entries: ``make(y0, y1)`` returns
    the band's entries (an array of the same bytes per row for every band), its records by
    key (flat quad indices of the band in column 0, offset here by the band's first quad,
    so they count from the canvas's first row) and the quads per row; ``records`` collects
    the records.  The buffer holds the rows of ``spans`` from the first one's."""
    holder = per_row = None
    first = spans[0][0]
    for y0, y1 in spans:
        cancel.check()      # a map prepared ahead of need stops here once cancelled
        entries, recs, quads_per_row = make(y0, y1)
        if holder is None:
            per_row = entries.nbytes // max(y1 - y0, 1)
            holder = rt.buffer(max(spans[-1][1] - first, 1) * per_row)
        rt.cl.enqueue_copy(rt.queue, holder.buffer, np.ascontiguousarray(entries),
                           dst_offset=(y0 - first) * per_row)   # blocking: the band may go now
        for key, rec in recs.items():
            rec[:, 0] += y0 * quads_per_row
            records.setdefault(key, []).append(rec)
    return holder


def pixel_centres(window, frame_origin=True):
    """(x, y) float64 grids of the pixel centres of ``window`` in frame coordinates."""
    xs = np.arange(window.width, dtype=np.float64) + 0.5 + (window.x0 if frame_origin else 0)
    ys = np.arange(window.height, dtype=np.float64) + 0.5 + (window.y0 if frame_origin else 0)
    return np.meshgrid(xs, ys)


# -- 1D radial models ----------------------------------------------------------------------
def fold_radius(derivative, r_max: float, samples: int = 20001) -> float:
    """The first radius in (0, r_max] where a radial map stops increasing, or inf.

    ``derivative(r)`` is d r_d / d r_u.  Sampled densely, then refined by bisection, so a
    fold between samples narrower than r_max / samples could be missed; real lens models
    are low-order polynomials whose folds are wide.
    """
    r = np.linspace(0.0, r_max, samples)
    d = derivative(r)
    bad = np.nonzero(d <= 0.0)[0]
    if bad.size == 0:
        return math.inf
    i = int(bad[0])
    if i == 0:
        return 0.0
    lo, hi = r[i - 1], r[i]
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if derivative(np.array(mid)) > 0.0:
            lo = mid
        else:
            hi = mid
    return float(0.5 * (lo + hi))


def radial_inverse(forward, r_d, r_hi: float, iterations: int = 64):
    """Solve ``forward(r_u) = r_d`` for r_u in [0, r_hi] by bisection (float64).

    ``forward`` must increase on [0, r_hi] (check with :func:`fold_radius`).  Targets beyond
    ``forward(r_hi)`` have no preimage and give NaN.  64 halvings reach the float64 floor.
    """
    r_d = np.asarray(r_d, np.float64)
    lo = np.zeros_like(r_d)
    hi = np.full_like(r_d, r_hi)
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        below = forward(mid) < r_d
        lo = np.where(below, mid, lo)
        hi = np.where(below, hi, mid)
    r_u = 0.5 * (lo + hi)
    top = forward(np.float64(r_hi))
    return np.where(r_d <= top * (1 + 1e-12), r_u, np.nan)


def radial_inverse_fast(forward, derivative, r_d, r_hi: float, table: int = 65537):
    """Same answer as :func:`radial_inverse`, ~20x faster for whole-frame maps.

    A bracketed start from a monotonic table of ``forward`` on [0, r_hi] (np.interp: the
    start lies on the right branch), then two Newton steps using ``derivative`` (the table's
    interpolation error, ~1e-10 of the radius, squares away), clamped to [0, r_hi].  Targets
    beyond ``forward(r_hi)`` give NaN.
    """
    r_d = np.asarray(r_d, np.float64)
    r_tab = np.linspace(0.0, r_hi, table)
    r_u = np.interp(r_d, forward(r_tab), r_tab, right=np.nan)
    for _ in range(2):
        with np.errstate(invalid="ignore", divide="ignore"):
            r_u = np.clip(r_u - (forward(r_u) - r_d) / derivative(r_u), 0.0, r_hi)
    return r_u


def radial_lut(forward, r_hi_u: float, r_max_d: float, size: int = 1024):
    """Inverse radial scale r_u / r_d tabulated against rho = (r_d / r_max_d)^2 in [0, 1].

    The kernel looks it up with linear interpolation in rho (no square root).  NaN marks
    radii with no preimage.  The scale of a smooth lens model varies slowly, so 1024 entries
    interpolate to ~1e-7 relative (checked by the tests against direct bisection).
    """
    rho = np.linspace(0.0, 1.0, size + 1)
    r_d = np.sqrt(rho) * r_max_d
    r_u = radial_inverse(forward, r_d, r_hi_u)
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.where(r_d > 0, r_u / np.where(r_d > 0, r_d, 1.0), 0.0)
    # r_d -> 0: the scale tends to 1 / forward'(0)
    eps = 1e-9 * max(r_hi_u, 1e-300)
    scale[0] = eps / forward(np.float64(eps))
    return scale


def lut_lookup(lut, rho):
    """NumPy twin of the kernel's LUT read (for tests and host-side checks)."""
    n = lut.size - 1
    t = np.clip(rho, 0.0, 1.0) * n
    i = np.minimum(np.floor(t).astype(np.int64), n - 1)
    f = t - i
    return lut[i] * (1 - f) + lut[i + 1] * f


# -- fitting the output frame -------------------------------------------------------------
def rect_boundary(rect, n_per_side: int = 1024):
    """Points along the outer edges of ``rect`` (frame coordinates, continuous)."""
    t = np.linspace(0.0, 1.0, n_per_side, endpoint=False)
    x0, y0, x1, y1 = float(rect.x0), float(rect.y0), float(rect.x1), float(rect.y1)
    xs = np.concatenate([x0 + t * (x1 - x0), np.full_like(t, x1), x1 - t * (x1 - x0), np.full_like(t, x0)])
    ys = np.concatenate([np.full_like(t, y0), y0 + t * (y1 - y0), np.full_like(t, y1), y1 - t * (y1 - y0)])
    return xs, ys


def rect_radius(rect, cx: float, cy: float, dx, dy):
    """Distance from (cx, cy) to the edge of ``rect`` along direction (dx, dy)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = np.where(dx > 0, (rect.x1 - cx) / dx, np.where(dx < 0, (rect.x0 - cx) / dx, np.inf))
        ty = np.where(dy > 0, (rect.y1 - cy) / dy, np.where(dy < 0, (rect.y0 - cy) / dy, np.inf))
    return np.minimum(tx, ty)


FITS = ("crop", "none", "fit-all", "fill")
"""A warp's ``fit`` choices (distortion, lens): ``crop`` (the default) scales up just enough
that no output pixel of the display window reads past the plate, ``none`` keeps the scale,
``fit-all`` keeps the whole source visible, ``fill`` makes the imaged source touch the frame."""


def fit_scale(mode: str, rect, cx: float, cy: float, boundary_x, boundary_y) -> float:
    """Scale s of output coordinates about (cx, cy) for ``fit`` = none / fit-all / fill /
    crop (`FITS`).

    ``boundary_x, boundary_y`` are where the lens images the source frame's outline (frame
    coordinates, distorted).  The output pixel u then shows the distorted point
    c + s (u - c): ``fit-all`` picks the largest ratio of imaged outline to frame outline
    along each direction (the whole source stays visible, touching the frame), ``fill`` the
    smallest (no output pixel reads outside the source), ``crop`` the smallest but never
    above 1 (scales up only where the lens would read past the source: with the plate's
    overscan as the outline, a margin the plate has is used before anything is cropped).
    Assumes the imaged outline is star-shaped about c, which holds for the monotonic radial
    maps accepted here.
    """
    if mode == "none":
        return 1.0
    dx, dy = boundary_x - cx, boundary_y - cy
    dist = np.hypot(dx, dy)
    ok = np.isfinite(dist) & (dist > 0)
    if not ok.any():
        return 1.0
    ratio = dist[ok] / rect_radius(rect, cx, cy, dx[ok] / dist[ok], dy[ok] / dist[ok])
    ratio = ratio[np.isfinite(ratio) & (ratio > 0)]
    if ratio.size == 0:
        return 1.0
    if mode == "crop":
        return min(1.0, float(ratio.min()))
    return float(ratio.max() if mode == "fit-all" else ratio.min())


# -- device upload ---------------------------------------------------------------------------
def upload_map(rt, dx, dy, pitch: int, double: bool):
    """Interleaved (dx, dy) displacement map with the output image's row pitch.

    Displacements (source point minus output pixel centre) rather than absolute coordinates:
    float32 stores them to ~1e-6 px (the kernels' float levels then add them to the pixel
    position in float32, ~1e-4 px at 4K; the reference level keeps float64 throughout).
    """
    h, w = dx.shape
    dtype = np.float64 if double else np.float32
    host = np.zeros((max(h, 1), pitch, 2), dtype)
    host[:h, :w, 0] = dx
    host[:h, :w, 1] = dy
    return rt.to_device(host)


def _split(p):
    """floor(p - 0.5) as an integer and the float32 fraction in [0, 1) (carried, not 1.0)."""
    f = p - 0.5
    i = np.floor(f)
    t = (f - i).astype(np.float32)
    carry = t >= 1.0                      # float32 rounding of 1 - 1e-9
    return i + carry, np.where(carry, np.float32(0.0), t)


def _padded(a, pitch: int, fill: float):
    """(rows, pitch) copy of ``a`` whose padding columns repeat each row's last pixel."""
    h, w = a.shape
    out = np.full((max(h, 1), pitch), fill)
    if h and w:
        out[:h, :w] = a
        out[:h, w:] = a[:, -1:]
    return out


class PackedMap:
    """One or more maps of source points in the load-efficient form of kernels/lib/resample.h.

    ``points`` is a list of ``(sx, sy)`` pairs (float64, shape (h, w)): continuous
    source-window coordinates (texel centres at +0.5) for the output pixels, NaN = no
    source.  Output rows share ``pitch`` (a multiple of 4) with the source.

    ``entries`` (int32, (h, pitch // 4, 12 * maps)): per quad of 4 output pixels (a
    work-item) and map, the float indices ``(iy * pitch + ix) * 4`` of the 4 texels
    (ix, iy) = floor(point - 0.5), clipped into the image, then the 4 x fractions and the 4 y
    fractions as float32 bits (exact to ~6e-8 px).  The fast kernel reads them for every
    quad: no floor, no conversion, no border rule, nothing but vector loads.

    ``fixups[filter code]``: the quads where some footprint of that filter (2x2, 4x4, 6x6)
    leaves the source or some point is undefined, as int32 records of ``4 + 8 * maps``:
    the quad's index, 3 unused, then per map the 4 points' x and y as float32 bits.  A
    second, small kernel re-renders just those quads through the checked path (border
    rule, NaN -> 0) over the fast kernel's output (which clamps their texel indices so it
    never reads outside the buffer).  Padding pixels repeat the row's last pixel.
    """

    TAPS = {FILTER_CODE[f]: taps for f, taps in FILTER_TAPS.items()}

    def __init__(self, points, width: int, height: int, pitch: int, first_row: int = 0):
        rows, quads = max(points[0][0].shape[0], 1), pitch // 4
        entries, coords = [], []
        bad = {code: np.zeros((rows, quads), bool) for code in self.TAPS}
        # where the fast kernel reads for an undefined point (its quad is re-rendered): the
        # output pixel itself, rows first_row.. of the image, inside a tile's buffer too
        own_x, own_y = np.meshgrid(np.arange(pitch) + 0.5, np.arange(rows) + 0.5 + first_row)
        for sx, sy in points:
            px, py = _padded(sx, pitch, 0.5), _padded(sy, pitch, 0.5)
            finite = np.isfinite(px) & np.isfinite(py) & (np.abs(px) < 1e7) & (np.abs(py) < 1e7)
            ix, tx = _split(np.where(finite, px, own_x))
            iy, ty = _split(np.where(finite, py, own_y))
            for code, taps in self.TAPS.items():
                off = taps // 2 - 1
                inside = finite & (ix - off >= 0) & (ix - off + taps <= width) \
                    & (iy - off >= 0) & (iy - off + taps <= height)
                bad[code] |= ~inside.reshape(rows, quads, 4).all(axis=2)
            base = (np.clip(iy, 0, max(height - 1, 0)) * pitch
                    + np.clip(ix, 0, max(width - 1, 0))) * 4
            e = np.empty((rows, quads, 3, 4), np.int32)
            e[:, :, 0] = base.astype(np.int32).reshape(rows, quads, 4)
            e[:, :, 1] = np.where(finite, tx, 0).astype(np.float32).view(np.int32).reshape(rows, quads, 4)
            e[:, :, 2] = np.where(finite, ty, 0).astype(np.float32).view(np.int32).reshape(rows, quads, 4)
            entries.append(e.reshape(rows, quads, 12))
            c = np.empty((rows, quads, 2, 4), np.int32)
            c[:, :, 0] = px.astype(np.float32).view(np.int32).reshape(rows, quads, 4)
            c[:, :, 1] = py.astype(np.float32).view(np.int32).reshape(rows, quads, 4)
            coords.append(c.reshape(rows * quads, 8))
        self.entries = np.concatenate(entries, axis=2)
        self.fixups = {}
        for code, mask in bad.items():
            idx = np.flatnonzero(mask)
            rec = np.zeros((idx.size, 4 + 8 * len(points)), np.int32)
            rec[:, 0] = idx
            for m, c in enumerate(coords):
                rec[:, 4 + 8 * m: 12 + 8 * m] = c[idx]
            self.fixups[code] = rec
        self.interior_fraction = {code: 1.0 - m.mean() for code, m in bad.items()}
        # the fast kernel needs one footprint that fits in the source to clamp into
        self.fast_possible = {code: width >= taps and height >= taps
                              for code, taps in self.TAPS.items()}

    def upload(self, rt) -> "DevicePackedMap":
        """The map's device buffers (a value for ``rt.cache``)."""
        return self._device(rt, rt.to_device(self.entries), self.fixups, self.fast_possible,
                            self.entries.shape[2] // 12)

    @staticmethod
    def _device(rt, entries, fixups, fast_possible, maps) -> "DevicePackedMap":
        fix = {code: (rt.to_device(r) if len(r) else None, len(r)) for code, r in fixups.items()}
        return DevicePackedMap(entries, fix, fast_possible, maps)

    @classmethod
    def device(cls, rt, points_of, width: int, height: int, pitch: int,
               rows: tuple[int, int] | None = None) -> "DevicePackedMap":
        """The map built and uploaded in bands of rows (:func:`map_bands`), the same as
        ``PackedMap(points_of(0, height), ...).upload(rt)``: ``points_of(y0, y1)`` gives
        the points of output rows ``y0 <= y < y1``.  Host memory is one band's.  ``rows``:
        only those output rows (a tile's band, `CanvasRows`; its fix-up records count quads
        from the canvas's first row)."""
        spans = row_spans(rows or (0, height), pitch)
        if len(spans) == 1 and spans[0][0] == 0:
            return cls(points_of(*spans[0]), width, height, pitch).upload(rt)
        quads, found = pitch // 4, {}

        def make(y0, y1):
            m = cls(points_of(y0, y1), width, height, pitch, y0)
            found["maps"], found["fast"] = m.entries.shape[2] // 12, m.fast_possible
            return m.entries, m.fixups, quads

        records: dict = {}
        entries = _upload_bands(rt, spans, make, records)
        fixups = {code: np.concatenate(r) for code, r in records.items()}
        return cls._device(rt, entries, fixups, found["fast"], found["maps"])


@dataclass(frozen=True)
class DevicePackedMap:
    """A :class:`PackedMap` on the device: ``entries`` (pooled buffer), ``fixups`` (filter
    code -> (records buffer or None, count)), ``fast_possible`` (filter code -> bool) and
    the number of ``maps`` per quad.  ``nbytes`` counts its buffers for the cache's cap."""

    entries: object
    fixups: dict
    fast_possible: dict
    maps: int

    @property
    def nbytes(self) -> int:
        return int(self.entries.nbytes) + sum(int(b.nbytes) for b, _ in self.fixups.values()
                                              if b is not None)


def launch_packed(rt, fast, fix, dmap: DevicePackedMap, filter_name: str, quads_x: int,
                  rows: int, head: tuple, tail: tuple):
    """Enqueue a packed-map warp: ``fast`` over every quad (None: the caller did), then
    ``fix`` over the border quads of ``filter_name``.  Kernel arguments:
    ``fast(*head, entries, *tail)`` and ``fix(*head, records, count, *tail)``."""
    code = FILTER_CODE[filter_name]
    if fast is not None and dmap.fast_possible[code]:
        rt.launch(fast, (quads_x, max(rows, 1)), *head, dmap.entries, *tail)
    buf, count = dmap.fixups[code]
    if count:
        rt.launch(fix, (count,), *head, buf, count, *tail)


def check_fold(name: str, coeffs: str, r_fold: float, r_corner: float, unit: str) -> None:
    """ParamError if a radial map folds over before the frame corner."""
    if r_fold <= r_corner:
        raise ParamError(
            f"{name}: {coeffs} fold over inside the frame: the radial map stops increasing "
            f"at r={r_fold:.3f} before the corner at r={r_corner:.3f} ({unit}); reduce the "
            f"coefficients (a real lens images each point once)")


# -- footprint filters: resampling that follows the map's Jacobian --------------------------
def footprint_defines(filter_name: str, border: str, sanitise: bool = True) -> dict:
    """``-D`` defines of the footprint kernels: FP_FILTER (``FOOTPRINTS``), the layout of a
    :class:`FootprintMap`'s quads (FP_Q_INTS), the border rule, NaN/Inf handling, and
    Lanczos-3 for the reference's elliptical samples."""
    fp = FOOTPRINTS[filter_name]
    return {"FP_FILTER": fp.code, "FP_Q_INTS": fp.entry_ints,
            "RS_FILTER": FILTER_CODE["lanczos3"], "RS_BORDER": BORDER_CODE[border],
            "RS_SANITISE": int(bool(sanitise))}


def footprint_spread(jac, filter_name: str):
    """Per-pixel spreads ``(hx, hy)`` and sub-footprint counts ``n`` of a footprint filter.

    ``jac`` (..., 2, 2) is d(source) / d(output) in pixels.  The output pixel's preimage has
    the marginal widths W_x^2 = J11^2 + J12^2, W_y^2 = J21^2 + J22^2 (texels); a box of width
    W adds the variance (W^2 - 1) / 12 to the texel's own box, so the filter gets the extra
    variance v = kappa max(W^2 - 1, 0) / 12 per axis (0 where the map magnifies: the plain
    filter).  Where v exceeds the filter's ``cap`` the footprint is split into n x n
    sub-footprints of J / n (the smallest n that fits).  h = sqrt(v), rounded to float16 as
    the kernels store it (returned as float64).
    """
    fp = FOOTPRINTS[filter_name]
    jac = np.nan_to_num(np.asarray(jac, np.float64))
    w2x = jac[..., 0, 0] ** 2 + jac[..., 0, 1] ** 2
    w2y = jac[..., 1, 0] ** 2 + jac[..., 1, 1] ** 2
    n = np.ones(w2x.shape, np.int64)

    def var(w2):
        return fp.kappa * np.maximum(w2 / n ** 2 - 1.0, 0.0) / 12.0

    while True:
        over = (var(w2x) > fp.cap) | (var(w2y) > fp.cap)
        if not over.any():
            break
        n = np.where(over, n + 1, n)
    hx = np.sqrt(var(w2x)).astype(np.float16)
    hy = np.sqrt(var(w2y)).astype(np.float16)
    return hx.astype(np.float64), hy.astype(np.float64), n


def footprint_window(p, h, filter_name: str):
    """The fast window's first texel (float64 integers) and the stored fraction along one
    axis (kernels/lib/resample.h ``fp_window``): quadratic: round(u) - 1 and d in
    [-0.5, 0.5); bicubic: floor(u) - 1 and frac(u); lanczos3: floor(u - h) - 2 and
    frac(u - h), with u = p - 0.5.  Fractions in [0, 1) rounding to 1.0 in float32 carry."""
    if filter_name == "quadratic":
        m = np.floor(p)
        return m - 1, (p - m - 0.5).astype(np.float32)
    m = p - 0.5 - (h if filter_name == "lanczos3" else 0.0)
    i, f = _split(m + 0.5)
    return i - (2 if filter_name == "lanczos3" else 1), f


class FootprintMap:
    """Source points and Jacobians packed for the footprint kernels of one filter.

    ``sx, sy`` (float64, (h, w)): source-window coordinates of the output pixels (NaN = no
    source); ``jac`` (h, w, 2, 2) their Jacobians.  Output rows share ``pitch`` (a multiple
    of 4) with the source; padding pixels repeat each row's last pixel.

    ``entries`` (int32, (h, pitch // 4, E), E = the filter's ``Footprint.entry_ints``): per
    quad of 4 output pixels the float indices ``(iy0 * pitch + ix0) * 4`` of their windows'
    top-left texels, the fractions f_x, f_y (4 each: float32 bits, or 8 float16 in 4 ints)
    and (h_x, h_y) as two float16 (see ``footprint_spread`` and ``footprint_window``), when
    every window lies inside the source and needs no sub-footprints.  Otherwise the quad's
    indices are -2 when all four outputs are 0 (black border: no source, or every window
    outside the source, a split pixel's parts' windows too) and -1 when the kernel renders it from its record (the record's index
    in the quad's second int) in ``records`` (int32, (k, 56)): the quad index, 3 unused, the
    quad's E packed ints padded to 16 (a window that fits stands in for the others), a mode
    per pixel (0: the fast
    path, 1: the checked path, 2: 0), then for the checked path the 4 points' x and y
    (float32), their (h_x, h_y) (float16 pairs), sub-footprint counts n and the Jacobians'
    J11, J12, J21, J22 (float32, 4 each).  ``fast_pixels`` (bool, (h, pitch)): the pixels
    the fast path renders from the packed fractions (float16 ones where the filter's
    ``half_f``), the rest from their points.
    """

    def __init__(self, sx, sy, jac, filter_name: str, width: int, height: int, pitch: int,
                 border: str = "black", first_row: int = 0):
        fp = FOOTPRINTS[filter_name]
        taps, ints = fp.taps, fp.entry_ints
        rows, quads = max(sx.shape[0], 1), pitch // 4
        px, py = _padded(sx, pitch, 0.5), _padded(sy, pitch, 0.5)
        jp = np.empty((rows, pitch, 2, 2))
        for a in (0, 1):
            for b in (0, 1):
                jp[..., a, b] = _padded(jac[..., a, b], pitch, float(a == b))
        finite = np.isfinite(px) & np.isfinite(py) & (np.abs(px) < 1e7) & (np.abs(py) < 1e7)
        finite &= np.isfinite(jp).all(axis=(-2, -1))
        px, py = np.where(finite, px, 0.5), np.where(finite, py, 0.5)
        jp = np.where(finite[..., None, None], jp, np.eye(2))
        hx, hy, n = footprint_spread(jp, filter_name)
        ix, fx = footprint_window(px, hx, filter_name)
        iy, fy = footprint_window(py, hy, filter_name)
        inside = (ix >= 0) & (ix + taps <= width) & (iy >= 0) & (iy + taps <= height)
        if filter_name == "quadratic":    # its rows are read as 4 texels: stay in the buffer
            inside &= (ix + 4 <= pitch) | (iy + taps < height)
        fast = finite & (n == 1) & inside
        # the window's taps all outside the source: 0 with a black border
        outside = (ix + taps <= 0) | (ix >= width) | (iy + taps <= 0) | (iy >= height)
        # split pixels (n > 1): their parts' centres lie within s +- (|J11| + |J12|,
        # |J21| + |J22|) / 2, each part's window within taps + 1 texels of its centre
        rx = 0.5 * (np.abs(jp[..., 0, 0]) + np.abs(jp[..., 0, 1])) + taps + 1
        ry = 0.5 * (np.abs(jp[..., 1, 0]) + np.abs(jp[..., 1, 1])) + taps + 1
        far = (px + rx <= 0) | (px - rx >= width) | (py + ry <= 0) | (py - ry >= height)
        zero = ~finite | ((((n == 1) & outside) | far) & (border == "black"))
        q_fast = fast.reshape(rows, quads, 4).all(axis=2)
        q_zero = zero.reshape(rows, quads, 4).all(axis=2) & ~q_fast
        base = (np.clip(iy, 0, None) * pitch + np.clip(ix, 0, None)) * 4
        h2 = np.stack([hx, hy], -1).astype(np.float16).view(np.int32)[..., 0]
        e = np.empty((rows, quads, ints // 4, 4), np.int32)
        # a window that fits, for pixels not on the fast path (read, then not used): at the
        # map's first row (``first_row``, of the image), inside a tile's buffer too
        fits = (min(max(first_row, 0), max(height - taps, 0)) * pitch) * 4
        e[:, :, 0] = np.where(fast, base, fits).reshape(rows, quads, 4)
        if fp.half_f:       # (f_x of the 4 pixels, f_y of the 4) as 8 float16
            f16 = np.concatenate([fx.reshape(rows, quads, 4), fy.reshape(rows, quads, 4)], 2)
            e[:, :, 1] = f16.astype(np.float16).view(np.int32)
        else:
            e[:, :, 1] = fx.reshape(rows, quads, 4).view(np.int32)
            e[:, :, 2] = fy.reshape(rows, quads, 4).view(np.int32)
        e[:, :, -1] = h2.reshape(rows, quads, 4)
        e = e.reshape(rows, quads, ints)
        fix = np.flatnonzero(~(q_fast | q_zero))
        qv = lambda a: a.reshape(rows * quads, 4)[fix]
        rec = np.zeros((fix.size, 14, 4), np.int32)
        rec[:, 0, 0] = fix
        rec[:, 1:1 + ints // 4] = e.reshape(rows * quads, ints // 4, 4)[fix]
        rec[:, 5] = qv(np.where(fast, 0, np.where(zero, 2, 1)))        # per pixel: mode
        f32 = lambda a: qv(np.where(finite, a, np.nan).astype(np.float32)).view(np.int32)
        rec[:, 6], rec[:, 7] = f32(px), f32(py)
        rec[:, 8], rec[:, 9] = qv(h2), qv(n.astype(np.int32))
        for k, (a, b) in enumerate(((0, 0), (0, 1), (1, 0), (1, 1))):
            rec[:, 10 + k] = qv(jp[..., a, b].astype(np.float32)).view(np.int32)
        e[..., 0:4] = np.where(q_fast[..., None], e[..., 0:4], np.where(q_zero, -2, -1)[..., None])
        e.reshape(rows * quads, ints)[fix, 1] = np.arange(fix.size, dtype=np.int32)
        self.entries = e
        self.records = rec.reshape(fix.size, 56)
        self.fast_pixels = fast
        total = max(rows * quads, 1)
        self.fractions = {"fast": float(q_fast.sum()) / total, "zero": float(q_zero.sum()) / total,
                          "checked": fix.size / total}

    def upload(self, rt) -> "DeviceFootprintMap":
        """The map's device buffers (a value for ``rt.cache``)."""
        count = len(self.records)
        return DeviceFootprintMap(rt.to_device(self.entries),
                                  rt.to_device(self.records) if count else None, count,
                                  dict(self.fractions))

    @classmethod
    def device(cls, rt, points_of, filter_name: str, width: int, height: int, pitch: int,
               border: str = "black", rows: tuple[int, int] | None = None
               ) -> "DeviceFootprintMap":
        """The map built and uploaded in bands of rows (:func:`map_bands`), the same as
        ``FootprintMap(*points_of(0, height), ...).upload(rt)``: ``points_of(y0, y1)``
        gives ``(sx, sy, jac)`` of output rows ``y0 <= y < y1``.  Host memory is one band's.
        ``rows``: only those output rows (a tile's band, `CanvasRows`)."""
        spans = row_spans(rows or (0, height), pitch)
        if len(spans) == 1 and spans[0][0] == 0:
            return cls(*points_of(*spans[0]), filter_name, width, height, pitch,
                       border).upload(rt)
        quads, counts = pitch // 4, {"fast": 0.0, "zero": 0.0}

        def make(y0, y1):
            m = cls(*points_of(y0, y1), filter_name, width, height, pitch, border, y0)
            before = sum(len(r) for r in records.get("records", ()))
            checked = m.entries[..., 0] == -1          # record indices count from the band's
            m.entries[..., 1][checked] += before        # first: make them the whole map's
            n = (y1 - y0) * quads
            for k in counts:
                counts[k] += m.fractions[k] * n
            return m.entries, {"records": m.records}, quads

        records: dict = {}
        entries = _upload_bands(rt, spans, make, records)
        rec = np.concatenate(records["records"])
        total = max(max(spans[-1][1] - spans[0][0], 1) * quads, 1)
        fractions = {"fast": counts["fast"] / total, "zero": counts["zero"] / total,
                     "checked": len(rec) / total}
        return DeviceFootprintMap(entries, rt.to_device(rec) if len(rec) else None, len(rec),
                                  fractions)


@dataclass(frozen=True)
class DeviceFootprintMap:
    """A :class:`FootprintMap` on the device: ``entries``, ``records`` (or None), their
    ``count`` and the ``fractions`` of fast, zero and checked quads."""

    entries: object
    records: object
    count: int
    fractions: dict

    @property
    def nbytes(self) -> int:
        return int(self.entries.nbytes) + (int(self.records.nbytes) if self.records is not None else 0)


def launch_footprint(rt, knl, dmap: DeviceFootprintMap, quads_x: int, rows: int,
                     head: tuple, tail: tuple):
    """Enqueue a footprint warp ``knl(*head, entries, records, *tail)`` over every quad: one
    launch, the checked quads rendered from their records inside it (PoCL 3.1 held a second
    kernel queued behind the first for up to ~4 ms at random: kernels/distortion.cl)."""
    records = dmap.records if dmap.records is not None else dmap.entries   # never read then
    rt.launch(knl, (quads_x, max(rows, 1)), *head, dmap.entries, records, *tail)


def elliptical_spread(jac):
    """``(jc, n)`` of the reference's elliptical footprint.

    ``jc`` = U sqrt(max(S^2 - 1, 0)) V^T from the SVD J = U S V^T: the part of the output
    pixel's preimage (the parallelogram J [-1/2, 1/2]^2) wider than a texel, along its
    principal axes (0 where the map magnifies).  ``n``: samples per axis, 1 where ``jc`` is 0,
    else max(2, ceil(sqrt(1 + c^2))) for the longer column c of ``jc`` (neighbouring samples
    at most one texel apart).
    """
    jac = np.nan_to_num(np.asarray(jac, np.float64))
    u, s, vt = np.linalg.svd(jac)
    e = np.sqrt(np.maximum(s * s - 1.0, 0.0))
    jc = (u * e[..., None, :]) @ vt
    c2 = np.maximum(jc[..., 0, 0] ** 2 + jc[..., 1, 0] ** 2, jc[..., 0, 1] ** 2 + jc[..., 1, 1] ** 2)
    n = np.where(e.max(axis=-1) > 0.0, np.maximum(2.0, np.ceil(np.sqrt(1.0 + c2))), 1.0)
    return jc, n


def elliptical_map(rt, sx, sy, jac, pitch: int, row0: int = 0):
    """The reference level's float64 map (kernels/distortion.cl ``distortion_ewa_f64``): per
    pixel the displacement (dx, dy) from its centre, the columns of ``jc`` and ``n``
    (:func:`elliptical_spread`), 8 doubles, rows of ``pitch`` pixels; ``row0``: the first
    row's index in the canvas (a tile's band, `CanvasRows`)."""
    h, w = sx.shape
    ox, oy = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5 + row0)
    jc, n = elliptical_spread(jac)
    host = np.zeros((max(h, 1), pitch, 8))
    host[:h, :w, 0] = sx - ox
    host[:h, :w, 1] = sy - oy
    host[:h, :w, 2] = jc[..., 0, 0]
    host[:h, :w, 3] = jc[..., 1, 0]
    host[:h, :w, 4] = jc[..., 0, 1]
    host[:h, :w, 5] = jc[..., 1, 1]
    host[:h, :w, 6] = n
    host[h:, :, 6] = 1.0
    host[:, w:, 6] = 1.0
    return rt.to_device(host)


# -- a warp's regions: where an outline's points land -----------------------------------------
def bounding_rect(xs, ys, margin: int, fallback):
    """The pixels covering the finite points ``(xs, ys)`` (frame coordinates), grown by
    ``margin``; ``fallback`` when none is finite."""
    xs, ys = np.asarray(xs, np.float64), np.asarray(ys, np.float64)
    ok = np.isfinite(xs) & np.isfinite(ys)
    if not ok.any():
        return fallback
    rect = type(fallback)
    return rect(math.floor(xs[ok].min()) - margin, math.floor(ys[ok].min()) - margin,
                math.ceil(xs[ok].max()) + margin, math.ceil(ys[ok].max()) + margin)


def warp_interest(inverse, window, reach: int):
    """Region of interest of a warp: the source points ``inverse(xs, ys)`` (a list of
    ``(xs, ys)`` per channel) of ``window``'s outline, bounded and grown by ``reach``
    texels, with ``window`` itself."""
    if window.empty:
        return window
    xs, ys = rect_boundary(window, 512)
    roi = window
    for sx, sy in inverse(xs, ys):
        roi = roi.union(bounding_rect(sx, sy, reach, window))
    return roi
