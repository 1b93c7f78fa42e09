"""Host side of clfx's warping effects: inverse maps, fold checks, fit scales, filters.

Shared by ``distortion``, ``chromatic_aberration`` and ``lens`` (device side:
``kernels/lib/resample.h``).  Everything here runs once per parameter set and frame geometry, in
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
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

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
    ``fp64`` reads a float64 map and accumulates in float64 (``kernels/lib/precision.h``)."""

    filter: str = "lanczos3"


def kernel_defines(filter_name: str, border: str, sanitise: bool = True) -> dict:
    """``-D`` defines selecting the filter, border rule and NaN/Inf handling (the precision
    comes from the level: ``rt.kernel(..., fp64=level.fp64, **defines)``)."""
    return {"RS_FILTER": FILTER_CODE[filter_name], "RS_BORDER": BORDER_CODE[border],
            "RS_SANITISE": int(bool(sanitise))}


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


def fit_scale(mode: str, rect, cx: float, cy: float, boundary_x, boundary_y) -> float:
    """Scale s of output coordinates about (cx, cy) for ``fit`` = none / fit-all / fill.

    ``boundary_x, boundary_y`` are where the lens images the source frame's outline (frame
    coordinates, distorted).  The output pixel u then shows the distorted point
    c + s (u - c): ``fit-all`` picks the largest ratio of imaged outline to frame outline
    along each direction (the whole source stays visible, touching the frame), ``fill`` the
    smallest (no output pixel reads outside the source).  Assumes the imaged outline is
    star-shaped about c, which holds for the monotonic radial maps accepted here.
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

    def __init__(self, points, width: int, height: int, pitch: int):
        rows, quads = max(points[0][0].shape[0], 1), pitch // 4
        entries, coords = [], []
        bad = {code: np.zeros((rows, quads), bool) for code in self.TAPS}
        for sx, sy in points:
            px, py = _padded(sx, pitch, 0.5), _padded(sy, pitch, 0.5)
            finite = np.isfinite(px) & np.isfinite(py) & (np.abs(px) < 1e7) & (np.abs(py) < 1e7)
            ix, tx = _split(np.where(finite, px, 0.5))
            iy, ty = _split(np.where(finite, py, 0.5))
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
        fix = {code: (rt.to_device(r) if len(r) else None, len(r))
               for code, r in self.fixups.items()}
        return DevicePackedMap(rt.to_device(self.entries), fix, self.fast_possible,
                               self.entries.shape[2] // 12)


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
    """Enqueue a packed-map warp: ``fast`` over every quad, then ``fix`` over the border
    quads of ``filter_name``.  Kernel arguments: ``fast(*head, entries, *tail)`` and
    ``fix(*head, records, count, *tail)``."""
    code = FILTER_CODE[filter_name]
    if dmap.fast_possible[code]:
        rt.launch(fast, (quads_x, max(rows, 1)), *head, dmap.entries, *tail)
    buf, count = dmap.fixups[code]
    if count:
        rt.launch(fix, (count,), *head, buf, np.int32(count), *tail)


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


def check_fold(name: str, coeffs: str, r_fold: float, r_corner: float, unit: str) -> None:
    """ParamError if a radial map folds over before the frame corner."""
    if r_fold <= r_corner:
        raise ParamError(
            f"{name}: {coeffs} fold over inside the frame: the radial map stops increasing "
            f"at r={r_fold:.3f} before the corner at r={r_corner:.3f} ({unit}); reduce the "
            f"coefficients (a real lens images each point once)")
