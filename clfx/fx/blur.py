"""Device Gaussian blur and pyramid steps: a reusable, cost-flat separable blur.

Public API (``defocus`` blurs with it)
--------------------------------------
``gaussian_blur(rt, img, sigma_x, sigma_y=None, *, quality="final", border="clamp", out=None)``
    Blur a :class:`~clfx.device.runtime.DeviceImage` (1, 2 or 4 channels) by a Gaussian with standard
    deviations ``sigma_x``, ``sigma_y`` in pixels.  Returns a new DeviceImage, or ``out``.
``LEVELS``
    The blur's quality levels as :class:`BlurLevel` data (an effect that is this blur
    declares them as its own).
``sanitize_nonfinite(rt, img)``
    A copy with NaN/Inf set to 0, and the number of pixels that had one.
``downsample(rt, img, factor, ...)``, ``upsample(rt, coarse, factor, out)``,
``downsample2x``, ``upsample2x``
    Gaussian-prefiltered decimation and B-spline reconstruction (the blur's own pyramid
    steps, for effects that work at low resolution).
``blur_plan(sigma, quality)``
    Which method and pyramid factor a sigma gets (for reports and tests).

Model
-----
The blur is the discrete, normalised Gaussian ``g[k] ~ exp(-k^2 / (2 sigma^2))`` applied
separably, with the image extended past its window by the border mode:

- ``"clamp"`` (default): edge pixels repeat (no dark rim on a full frame);
- ``"mirror"``: reflect-101 (``2 1 0 1 2``), periodic, so a kernel wider than the image
  still reads inside it (hard-cases.md #11);
- ``"zero"``: black outside the window (a premultiplied element; light spreads out).

The output may cover a different window than the input (``out``): a blur that spreads light
past the frame renders into a window grown by ~3 sigma.  Each axis is handled independently:

``copy``    sigma < 0.3 px: the Gaussian's tails are below 4e-3 of the centre tap.
``direct``  separable passes of radius ``ceil(truncate * sigma)``, weights precomputed on the
            host, 4 pixels per work-item (one float16 for RGBA), short tap loops unrolled to
            a rung of :data:`TAP_RUNGS` (a few programs for every radius), and no index
            arithmetic inside the loop except near the borders.
``pyramid`` cost independent of sigma: decimate by ``F = 2^k`` with a Gaussian prefilter of
            ``sigma_p = c * F`` fine pixels, blur at low resolution, and reconstruct with the
            cubic B-spline (variance ``F^2 / 3``).  Variances add:
            ``sigma^2 = sigma_p^2 + F^2 * V_c + F^2 / 3``, so the coarse kernel has variance
            ``V_c = sigma^2 / F^2 - c^2 - 1/3`` (coarse pixels).  The B-spline is flatter than a
            Gaussian (4th cumulant ``-1/30`` coarse px^4); the coarse kernel cancels it: an equal
            mixture of two Gaussians of variances ``V_c -/+ sqrt(1/90)`` (4th cumulant
            ``+1/30``), still positive everywhere, so no ringing and no negatives.  ``F`` is the
            largest power of two keeping ``sqrt(V_c) >= s_min``; the low-resolution grid spans
            the output window plus a margin, and the decimation reads the input through the
            border mode, so borders are as exact as in the direct method.

Quality levels (``LEVELS``; measured errors in ``notes`` of the report and tests/test_blur.py)

=========  ========  ====  ======  =======================================================
level      truncate  c     s_min   accumulation
=========  ========  ====  ======  =======================================================
draft      3.0       0.6   1.0     float32; error on an impulse ~1e-3 of its peak
preview    3.5       0.7   1.5     float32
final      4.0       0.8   2.0     float32; ~1e-4
reference  6.0       --    inf     float64 direct (never a pyramid), error ~1e-7 (float32 I/O)
=========  ========  ====  ======  =======================================================

The kernels do not sanitise: NaN/Inf spread over the footprint (no further: no tap past
the kernel is read).  Call
:func:`sanitize_nonfinite` first where inputs may hold them.

References
----------
P. J. Burt, E. H. Adelson, "The Laplacian pyramid as a compact image code", 1983.
M. Unser, A. Aldroubi, M. Eden, "B-spline signal processing", IEEE TSP 41(2), 1993.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from clfx.core.plugin import Level
from clfx.core.rect import Rect

MIN_SIGMA = 0.3
"""Below this many pixels an axis is copied: the neighbour tap would be < 4e-3 of the centre."""

BORDERS = {"zero": 0, "clamp": 1, "mirror": 2}
"""Border modes and their kernel codes."""

KERNEL_FILE = "lib/blur.cl"

_BSPLINE_KAPPA4 = -1.0 / 30.0      # 4th cumulant of the cubic B-spline (4 unit boxes)
_MIXTURE_HALF_SPREAD = math.sqrt(-_BSPLINE_KAPPA4 / 3.0)   # d with 3 d^2 = 1/30


@dataclass(frozen=True)
class BlurLevel(Level):
    """Concrete choices of one quality level (``fp64``: accumulate and hold weights in float64).

    Attributes
    ----------
    truncate : float
        Kernel radius in standard deviations (direct passes and the pyramid's Gaussians).
    pyramid_truncate : float
        Radius in sigmas of the pyramid's prefilter and coarse kernel (a truncated prefilter
        aliases about as much as its lost tail).
    prefilter : float
        Decimation prefilter sigma in coarse pixels (``c``); aliasing ~ ``exp(-2 pi^2 c^2)``.
    min_coarse_sigma : float
        Smallest coarse-level sigma ``s_min`` (coarse pixels); inf = never use the pyramid.
    """

    truncate: float = 4.0
    pyramid_truncate: float = 5.5
    prefilter: float = 0.8
    min_coarse_sigma: float = 2.0


LEVELS = {
    "draft": BlurLevel("direct Gaussian truncated at 3 sigma below ~2 px; above, pyramid with "
                       "prefilter 0.6 coarse px, coarse sigma >= 1, B-spline upsampling; float32 "
                       "(impulse error <= 7e-3 of peak)",
                       truncate=3.0, pyramid_truncate=3.5, prefilter=0.6, min_coarse_sigma=1.0),
    "preview": BlurLevel("direct at 3.5 sigma below ~3.5 px; pyramid with prefilter 0.7, coarse "
                         "sigma >= 1.5; float32 (<= 1e-3)",
                         truncate=3.5, pyramid_truncate=4.5, prefilter=0.7, min_coarse_sigma=1.5),
    "final": BlurLevel("direct at 4 sigma below ~4.5 px; pyramid with prefilter 0.8, coarse "
                       "sigma >= 2; float32 (<= 1.5e-4)",
                       truncate=4.0, pyramid_truncate=5.5, prefilter=0.8, min_coarse_sigma=2.0),
    "reference": BlurLevel("direct separable Gaussian truncated at 6 sigma, float64 accumulation "
                           "and weights, at any size (slow for large sizes; <= 1e-7)",
                           fp64=True, truncate=6.0, pyramid_truncate=6.0, prefilter=0.0,
                           min_coarse_sigma=math.inf),
}
"""The blur's quality levels, declared once (defocus's levels are these)."""


@dataclass(frozen=True)
class AxisPlan:
    """How one axis is blurred: ``method`` is "copy", "direct" or "pyramid"."""

    method: str
    sigma: float
    truncate: float
    factor: int = 1
    prefilter_sigma: float = 0.0   # fine pixels
    coarse_variance: float = 0.0   # coarse pixels^2

    @property
    def radius(self) -> int:
        """Direct-kernel radius in pixels."""
        return max(1, math.ceil(self.truncate * self.sigma))


def blur_plan(sigma: float, quality: "str | BlurLevel" = "final") -> AxisPlan:
    """The method for blurring one axis by ``sigma`` pixels at ``quality``.

    The pyramid is used from the first factor ``F = 2`` that keeps the coarse sigma at or
    above the level's ``s_min``; its cost is then flat in sigma.
    """
    q = _quality(quality)
    sigma = float(sigma)
    if not math.isfinite(sigma) or sigma < 0:
        raise ValueError(f"gaussian_blur: sigma must be a finite number >= 0, got {sigma!r}")
    if sigma < MIN_SIGMA:
        return AxisPlan("copy", sigma, q.truncate)
    best = None
    f = 2
    while math.isfinite(q.min_coarse_sigma):
        v = (sigma / f) ** 2 - q.prefilter ** 2 - 1.0 / 3.0
        if v < q.min_coarse_sigma ** 2:
            break
        best = AxisPlan("pyramid", sigma, q.pyramid_truncate, f, q.prefilter * f, v)
        f *= 2
    return best or AxisPlan("direct", sigma, q.truncate)


def _quality(quality: "str | BlurLevel") -> BlurLevel:
    if isinstance(quality, BlurLevel):
        return quality
    try:
        return LEVELS[quality]
    except KeyError:
        raise ValueError(f"gaussian_blur: quality {quality!r} is not one of "
                         f"{', '.join(LEVELS)}") from None


# -- host-side weight and index tables ------------------------------------------------------
TAP_RUNGS = (8, 16)
"""The tap-count ladder: a pass of ``n`` taps runs the program built for the smallest rung
``>= n`` (its loops unrolled to the rung, the taps past ``n`` skipped at run time), or above
the top rung the one with a plain loop (no ``TAPS`` define).  A few programs per channel count
and precision cover every sigma, where each tap count had one (an animated blur size compiled
a program per new count).  Unrolling is what costs to compile, and buys little beyond short
kernels: tests/fx/test_blur.py on a cold kernel cache took 91 s of CPU with a program per
count (64 programs), 82 s with rungs up to 64 (22), 23 s with these (13) and 14 s with none
(6); warm, 960x540 passes of every rung choice timed within the noise (+-15%) of the exact
counts, the plain loop included."""


def _tap_rung(taps: int) -> int:
    """The ``TAPS`` define of the program that runs ``taps`` taps (0: a plain loop)."""
    return next((r for r in TAP_RUNGS if taps <= r), 0)


def gaussian_weights(sigma: float, radius: int) -> np.ndarray:
    """Normalised sampled Gaussian of ``2 * radius + 1`` taps (float64)."""
    k = np.arange(-radius, radius + 1, dtype=np.float64)
    w = np.exp(-0.5 * (k / sigma) ** 2)
    return w / w.sum()


def _mixture_weights(variance: float, truncate: float) -> np.ndarray:
    """Coarse kernel: equal mix of Gaussians of variance ``V -/+ d`` (4th cumulant +1/30)."""
    d = _MIXTURE_HALF_SPREAD
    hi = math.sqrt(variance + d)
    radius = max(1, math.ceil(truncate * hi))
    k = np.arange(-radius, radius + 1, dtype=np.float64)
    parts = []
    for v in (variance - d, variance + d):
        g = np.exp(-0.5 * k * k / v)
        parts.append(g / g.sum())
    return 0.5 * (parts[0] + parts[1])


def _bspline3(t: np.ndarray) -> np.ndarray:
    """Centred cubic B-spline (support [-2, 2], partition of unity)."""
    a = np.abs(t)
    return np.where(a < 1, 2.0 / 3.0 - a * a + 0.5 * a ** 3,
                    np.where(a < 2, (2 - a) ** 3 / 6.0, 0.0))


def _map_indices(i: np.ndarray, n: int, border: str):
    """(index, weight factor) of line positions ``i`` under the border mode."""
    if border == "mirror":
        if n <= 1:
            return np.zeros_like(i), np.ones(i.shape)
        period = 2 * (n - 1)
        m = np.mod(i, period)
        return np.where(m < n, m, period - m), np.ones(i.shape)
    inside = (i >= 0) & (i < n)
    idx = np.clip(i, 0, n - 1)
    return idx, (inside.astype(np.float64) if border == "zero" else np.ones(i.shape))


def _pad_rows(a: np.ndarray, rows: int) -> np.ndarray:
    """Repeat the last row so a table covers ``rows`` outputs (padding pixels stay finite)."""
    if a.shape[0] >= rows:
        return a
    return np.concatenate([a, np.repeat(a[-1:], rows - a.shape[0], axis=0)])


def _pitch(n: int) -> int:
    return max(4, -(-n // 4) * 4)


@dataclass(frozen=True)
class _Table:
    idx: np.ndarray      # (outputs, taps) int32
    w: np.ndarray        # (outputs, taps) float64, each row normalised
    n_out: int
    inside: np.ndarray | None = None   # (outputs, taps) 0/1: zero border masks taps


def _decimation_table(plan: AxisPlan, n_in: int, offset: int, n_out: int, border: str):
    """Coarse samples over the output line plus a margin, read through the border mode.

    Coarse sample j sits at output coordinate ``-margin + (F - 1) / 2 + F j`` (pixel centres
    at integers), i.e. it averages the F x F block it covers, weighted by the prefilter.
    Returns the table, the number of coarse samples and the margin.
    """
    f = plan.factor
    coarse = _mixture_weights(plan.coarse_variance, plan.truncate)
    rc = coarse.size // 2
    margin = (rc + 3) * f
    n_c = -(-(n_out + 2 * margin) // f) + 1
    centres = -margin + (f - 1) / 2.0 + f * np.arange(n_c) + offset
    rp = max(1, math.ceil(plan.truncate * plan.prefilter_sigma))
    start = np.floor(centres).astype(np.int64) - rp
    pos = start[:, None] + np.arange(2 * rp + 2)[None, :]
    w = np.exp(-0.5 * ((pos - centres[:, None]) / plan.prefilter_sigma) ** 2)
    w /= w.sum(axis=1, keepdims=True)
    idx, inside = _map_indices(pos, n_in, border)
    return _Table(idx.astype(np.int32), w, n_c, inside), n_c, margin


def _coarse_blur_table(plan: AxisPlan, n_c: int) -> _Table:
    coarse = _mixture_weights(plan.coarse_variance, plan.truncate)
    rc = coarse.size // 2
    pos = np.arange(n_c)[:, None] + np.arange(-rc, rc + 1)[None, :]
    idx = np.clip(pos, 0, n_c - 1)  # never reached for output pixels (margin), kept in bounds
    return _Table(idx.astype(np.int32), np.broadcast_to(coarse, pos.shape).copy(), n_c)


def _upsample_table(f: int, n_c: int, margin: int, n_out: int) -> _Table:
    """Cubic B-spline reconstruction of output pixels from coarse samples."""
    x = np.arange(n_out, dtype=np.float64)
    u = (x + margin - (f - 1) / 2.0) / f
    j0 = np.floor(u).astype(np.int64) - 1
    pos = j0[:, None] + np.arange(4)[None, :]
    w = _bspline3(u[:, None] - pos)
    return _Table(np.clip(pos, 0, n_c - 1).astype(np.int32), w, n_out)


def _copy_table(n_in: int, offset: int, n_out: int, border: str) -> _Table:
    pos = (np.arange(n_out) + offset)[:, None]
    idx, inside = _map_indices(pos, n_in, border)
    return _Table(idx.astype(np.int32), np.ones(pos.shape), n_out, inside)


# -- device-side tables ----------------------------------------------------------------------
def _cached(rt, key, make):
    """Weight and index tables on the device, kept in the runtime's cache (owner "blur")."""
    return rt.cache.get(("blur",) + key, make)


def _wdtype(double: bool):
    return np.float64 if double else np.float32


def _rounded_weights(w: np.ndarray, dtype) -> np.ndarray:
    """``w`` (rows normalised in float64) in ``dtype``, each row's rounding residual added to
    its largest tap, so a flat field stays flat to the accumulation's rounding even with
    thousands of taps."""
    out = w.astype(dtype)
    if dtype == np.float32 and out.size:
        residual = w.sum(axis=-1) - out.astype(np.float64).sum(axis=-1)
        rows = np.arange(out.shape[0]) if out.ndim == 2 else ()
        top = np.argmax(out, axis=-1)
        out[rows, top] = (out[rows, top].astype(np.float64) + residual).astype(dtype)
    return out


def _device_table(rt, table: _Table, rows: int, double: bool):
    """(taps, idx buffer, weight buffer) with rows padded to ``rows``."""
    dtype = _wdtype(double)
    idx = np.ascontiguousarray(_pad_rows(table.idx, rows)[:rows], np.int32)
    w = _rounded_weights(_pad_rows(table.w, rows), dtype)
    if table.inside is not None:
        w = w * _pad_rows(table.inside, rows).astype(dtype)
    return idx.shape[1], rt.to_device(idx), rt.to_device(np.ascontiguousarray(w[:rows]))


# -- passes ---------------------------------------------------------------------------------
@dataclass
class _Pass:
    """One kernel launch: ``run(src, dst)`` with ``dst`` of ``rows`` x ``cols`` pixels."""

    rows: int
    cols: int
    run: object


def _kernel(rt, name, channels, taps, double):
    rung = _tap_rung(taps)   # the plain-loop program is blur_sanitize's (no TAPS define)
    taps_define = {"TAPS": rung} if rung else {}
    return rt.kernel(KERNEL_FILE, name, fp64=double, CH=channels, **taps_define)


def _direct_weights(rt, plan, double):
    def make():
        w = gaussian_weights(plan.sigma, plan.radius)[None, :]
        return rt.to_device(_rounded_weights(w, _wdtype(double))[0])
    return _cached(rt, ("wdirect", plan.sigma, plan.truncate, double), make)


def _direct(rt, axis, plan, ch, double, border, n_in, offset, rows, cols):
    """A direct Gaussian pass along x (``axis`` "h": ``n_in`` input columns) or y ("v":
    ``n_in`` input rows) into ``rows`` x ``cols`` pixels, output index j reading input
    j + ``offset``."""
    taps = 2 * plan.radius + 1
    wbuf = _direct_weights(rt, plan, double)
    knl = _kernel(rt, f"blur_direct_{axis}", ch, taps, double)

    def run(src, dst):
        head = ((src, src.pitch, n_in, dst, dst.pitch, rows) if axis == "h"
                else (src, n_in, dst, rows, dst.pitch))
        rt.launch(knl, (dst.pitch // 4, rows), *head, offset, wbuf, taps, BORDERS[border])
    return _Pass(rows, cols, run)


LONG_SUM_TAPS = 64
"""Gathers with more taps accumulate in float64: a float32 running sum of ~800 taps drifts by
~1e-6 (a flat field must stay flat to 1e-6)."""


def _table_buffers(rt, t: _Table, rows: int, double: bool):
    dbl = double or rt.use_fp64(t.idx.shape[1] > LONG_SUM_TAPS)
    return (t.n_out, dbl) + _device_table(rt, t, rows, dbl)


def _gather_h(rt, key, make_table, ch, double, rows):
    """Gather along rows from a cached table; output columns = the table's outputs."""
    def make():
        t = make_table()
        return _table_buffers(rt, t, _pitch(t.n_out), double)
    cols, dbl, taps, ibuf, wbuf = _cached(rt, ("h",) + key + (double,), make)
    knl = _kernel(rt, "blur_gather_h", ch, taps, dbl)

    def run(src, dst):
        rt.launch(knl, (dst.pitch // 4, rows), src, src.pitch, dst, dst.pitch, rows, ibuf, wbuf,
                  taps)
    return _Pass(rows, cols, run)


def _gather_v(rt, key, make_table, ch, double, cols):
    def make():
        t = make_table()
        return _table_buffers(rt, t, t.n_out, double)
    rows, dbl, taps, ibuf, wbuf = _cached(rt, ("v",) + key + (double,), make)
    knl = _kernel(rt, "blur_gather_v", ch, taps, dbl)

    def run(src, dst):
        rt.launch(knl, (dst.pitch // 4, rows), src, dst, dst.pitch, rows, ibuf, wbuf, taps)
    return _Pass(rows, cols, run)


def _build_passes(rt, img, window, px: AxisPlan, py: AxisPlan, border, double):
    ch = img.channels
    wi, wo = img.window, window
    ox, oy = wo.x0 - wi.x0, wo.y0 - wi.y0
    passes: list[_Pass] = []
    cols, rows = wi.width, wi.height

    # x, first half: to the output columns (direct / copy) or to the coarse columns
    if px.method == "direct":
        passes.append(_direct(rt, "h", px, ch, double, border, wi.width, ox, rows, wo.width))
        cols = wo.width
    elif px.method == "pyramid":
        gx = ("dec", px, wi.width, ox, wo.width, border)
        dec_x, ncx, mx = _decimation_table(px, wi.width, ox, wo.width, border)
        passes.append(_gather_h(rt, gx, lambda: dec_x, ch, double, rows))
        cols = ncx
    elif wo.x0 != wi.x0 or wo.x1 != wi.x1:
        key = ("copy", wi.width, ox, wo.width, border)
        passes.append(_gather_h(rt, key, lambda: _copy_table(wi.width, ox, wo.width, border),
                                ch, double, rows))
        cols = wo.width

    def coarse_x(r):
        return _gather_h(rt, ("blur", px, ncx), lambda: _coarse_blur_table(px, ncx),
                         ch, double, r)

    # y, completely (blurring x at the coarse level while y is coarse too)
    x_blurred = px.method != "pyramid"
    if py.method == "direct":
        passes.append(_direct(rt, "v", py, ch, double, border, wi.height, oy, wo.height, cols))
        rows = wo.height
    elif py.method == "pyramid":
        dec_y, ncy, my = _decimation_table(py, wi.height, oy, wo.height, border)
        passes.append(_gather_v(rt, ("dec", py, wi.height, oy, wo.height, border),
                                lambda: dec_y, ch, double, cols))
        if not x_blurred:
            passes.append(coarse_x(ncy))
            x_blurred = True
        passes.append(_gather_v(rt, ("blur", py, ncy), lambda: _coarse_blur_table(py, ncy),
                                ch, double, cols))
        passes.append(_gather_v(rt, ("up", py.factor, ncy, my, wo.height),
                                lambda: _upsample_table(py.factor, ncy, my, wo.height),
                                ch, double, cols))
        rows = wo.height
    elif wo.y0 != wi.y0 or wo.y1 != wi.y1:
        passes.append(_gather_v(rt, ("copy", wi.height, oy, wo.height, border),
                                lambda: _copy_table(wi.height, oy, wo.height, border),
                                ch, double, cols))
        rows = wo.height

    # x, second half: coarse blur (if not done) and B-spline reconstruction
    if px.method == "pyramid":
        if not x_blurred:
            passes.append(coarse_x(rows))
        passes.append(_gather_h(rt, ("up", px.factor, ncx, mx, wo.width),
                                lambda: _upsample_table(px.factor, ncx, mx, wo.width),
                                ch, double, rows))
    return passes


def gaussian_blur(rt, img, sigma_x: float, sigma_y: float | None = None, *,
                  quality: str = "final", border: str = "clamp", out=None):
    """Blur a device image by a Gaussian (separable, cost flat in sigma).

    Parameters
    ----------
    rt : Runtime
    img : DeviceImage
        Input, 1, 2 or 4 channels (any meaning: RGBA, depth, velocity...).  Not modified.
        Must hold finite values (see :func:`sanitize_nonfinite`).
    sigma_x, sigma_y : float
        Standard deviations in pixels along x and y; ``sigma_y`` defaults to ``sigma_x``.
        An axis with sigma < 0.3 px is copied.
    quality : {"draft", "preview", "final", "reference"} or BlurLevel
        See the module docstring (``LEVELS``): pyramid settings, or the direct float64
        Gaussian truncated at 6 sigma for ``reference``.
    border : {"clamp", "mirror", "zero"}
        How the image continues past its window.
    out : DeviceImage, optional
        Destination with the same channels.  Its window (frame coordinates) may differ from
        ``img``'s, e.g. grown by 3 sigma so light spreads past the frame: the blur is
        evaluated at every pixel of ``out.window``.  Default: a new image over ``img.window``.

    Returns
    -------
    DeviceImage
        ``out`` or a new image; enqueued, not waited for.

    Notes
    -----
    Accuracy against the exact discrete Gaussian (max error over an impulse, relative to the
    output's peak; tests/test_blur.py states the tolerances): reference ~1e-7, final <~2e-4,
    preview <~1e-3, draft <~5e-3.  Energy of an interior impulse is conserved to 1e-6
    (direct) and ~1e-5 (pyramid).  All weights are positive: no negatives, no ringing.
    """
    if border not in BORDERS:
        raise ValueError(f"gaussian_blur: border {border!r} is not one of {', '.join(BORDERS)}")
    if img.channels not in (1, 2, 4):
        raise ValueError(f"gaussian_blur: {img.channels} channels; expected 1, 2 or 4")
    sigma_y = sigma_x if sigma_y is None else sigma_y
    q = _quality(quality)
    px, py = blur_plan(sigma_x, q), blur_plan(sigma_y, q)
    double = rt.use_fp64(q.fp64)
    if out is None:
        out = rt.image(img.window, img.channels)
    elif out.channels != img.channels:
        raise ValueError(f"gaussian_blur: out has {out.channels} channels, img {img.channels}")
    if img.window.empty or out.window.empty:
        return out
    passes = _build_passes(rt, img, out.window, px, py, border, double)
    if not passes:
        rt.cl.enqueue_copy(rt.queue, out.buffer, img.buffer, byte_count=img.nbytes)
        return out
    cur = img
    for i, ps in enumerate(passes):
        dst = out if i == len(passes) - 1 else rt.image(Rect.from_size(ps.cols, ps.rows), img.channels)
        ps.run(cur, dst)
        cur = dst
    return out


# -- sanitising -----------------------------------------------------------------------------
def sanitize_nonfinite(rt, img):
    """A copy of ``img`` with every NaN/Inf value set to 0, and how many pixels had one.

    Returns
    -------
    (DeviceImage, int)
        The count is read back (one int per row): this waits for the queue.
    """
    dst = img.like()
    counts = rt.buffer(max(img.height, 1) * 4)
    knl = rt.kernel(KERNEL_FILE, "blur_sanitize", CH=img.channels)
    rt.launch(knl, (max(img.height, 1),), img, dst, img.pitch, img.width, img.height, counts)
    n = int(rt.from_device(counts, np.int32, max(img.height, 1))[:img.height].sum())
    return dst, n


# -- pyramid helpers ------------------------------------------------------------------------
def downsample(rt, img, factor: int, *, prefilter: float = 0.8, border: str = "clamp",
               truncate: float = 5.5):
    """Decimate by an integer ``factor`` with a Gaussian prefilter.

    Coarse pixel ``(i, j)`` is the prefiltered image at the centre of the ``factor`` x
    ``factor`` block of fine pixels it covers (block origin = ``img.window``'s origin), with
    sigma ``prefilter * factor`` fine pixels (0.8: aliasing ~3e-6).  The result covers
    ``ceil(w / factor) x ceil(h / factor)`` pixels; its window is that size at origin 0 (a
    coarse grid, not placed in the frame).  The prefilter adds variance
    ``(prefilter * factor)^2`` (fine px^2).
    """
    if factor == 1:
        return rt.copy(img)
    sigma = prefilter * factor
    plan = AxisPlan("pyramid", sigma, truncate, factor, sigma, 0.0)
    ch = img.channels
    ncx, ncy = -(-img.width // factor), -(-img.height // factor)

    def table(n_in, n_c):
        centres = (factor - 1) / 2.0 + factor * np.arange(n_c)
        rp = max(1, math.ceil(truncate * sigma))
        pos = np.floor(centres).astype(np.int64)[:, None] - rp + np.arange(2 * rp + 2)[None, :]
        w = np.exp(-0.5 * ((pos - centres[:, None]) / sigma) ** 2)
        w /= w.sum(axis=1, keepdims=True)
        idx, inside = _map_indices(pos, n_in, border)
        return _Table(idx.astype(np.int32), w, n_c, inside)

    ph = _gather_h(rt, ("down", plan, img.width, border), lambda: table(img.width, ncx),
                   ch, False, img.height)
    pv = _gather_v(rt, ("down", plan, img.height, border), lambda: table(img.height, ncy),
                   ch, False, ncx)
    mid = rt.image(Rect.from_size(ncx, img.height), ch)
    ph.run(img, mid)
    out = rt.image(Rect.from_size(ncx, ncy), ch)
    pv.run(mid, out)
    return out


def upsample(rt, coarse, factor: int, out):
    """Cubic B-spline reconstruction of ``coarse`` (from :func:`downsample`) into ``out``.

    Fine pixel ``x`` of ``out`` reads coarse position ``(x - (factor - 1) / 2) / factor``
    (the inverse of :func:`downsample`'s grid).  The B-spline is positive and a partition of
    unity (flat stays flat, energy is kept); it adds variance ``factor^2 / 3`` fine px^2 and
    is clamped at the coarse grid's edges.
    """
    ch = coarse.channels
    ncx, ncy = coarse.width, coarse.height
    mid = rt.image(Rect.from_size(ncx, out.height), ch)
    pv = _gather_v(rt, ("up", factor, ncy, 0, out.height),
                   lambda: _upsample_table(factor, ncy, 0, out.height), ch, False, ncx)
    pv.run(coarse, mid)
    ph = _gather_h(rt, ("up", factor, ncx, 0, out.width),
                   lambda: _upsample_table(factor, ncx, 0, out.width), ch, False, out.height)
    ph.run(mid, out)
    return out


def downsample2x(rt, img, *, border: str = "clamp"):
    """:func:`downsample` by 2 (prefilter sigma 1.6 fine pixels)."""
    return downsample(rt, img, 2, border=border)


def upsample2x(rt, coarse, out=None):
    """:func:`upsample` by 2; ``out`` defaults to twice the coarse size."""
    if out is None:
        out = rt.image(Rect.from_size(coarse.width * 2, coarse.height * 2), coarse.channels)
    return upsample(rt, coarse, 2, out)
