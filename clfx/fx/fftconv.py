"""HDR-safe large-kernel convolution on the device (pyvkfft's OpenCL backend).

The stable entry point is :func:`convolve`; ``glare``, ``bleed``, ``soft_focus`` and
``corona`` call it through :func:`spread`, which maps a quality level (a :class:`SpreadLevel`,
declared once in :data:`LEVELS`) to an algorithm.

Model
-----
Linear (not circular) convolution with zero outside the input::

    out(o) = sum_i in(i) * psf(o - i + c),     c = (kh // 2, kw // 2)

``o`` and ``i`` are pixel coordinates of the frame (``Rect`` convention: +x right, +y down),
so the input window may be larger than the display window (EXR overscan: all of it
contributes) and the output window may be larger than the input (light spreads past the
frame; the region of definition grows).  The PSF is applied as given (not normalised here).

Algorithms
----------
``"fft"``
    In-place real-to-complex FFTs (``VkFFTApp(..., r2c=True)``), batched over the colour
    channels.  Each axis is padded to the smallest size with prime factors 2, 3, 5, 7 that
    keeps wrap-around out of the pixels kept (see :func:`fft_grid`); the PSF spectrum is
    computed once per (PSF, grid, precision) and kept in the runtime's cache (``rt.cache``,
    owner ``fftconv.spectrum``; plans: ``fftconv.plan``), unless larger than
    :data:`SPECTRUM_CACHE_BYTES`.
``precision="float64"``
    Double-precision transforms.  On PoCL they cost 1.0-1.3x float32 and remove the float32
    error floor (~1e-7 x total energy spread over every pixel: 1-7 % relative error in 1e-2
    shadows next to a 1e5 light, notes/hard-cases.md case 1).  Where the device is the
    host's CPU they run in NumPy (pocketfft), the image's rows read from its mapped buffer
    (no packed copy; rows of zeros skipped) and transformed in complex planes the runtime's
    cache keeps (every channel's at once where they fit: :func:`host_planes_in_flight`), in
    row and column chunks on every core: a row task reads its rows once for every channel,
    a column task transforms and multiplies a contiguous copy of its columns (the PSF
    spectrum is kept transposed for it), an inverse row task writes every channel of its
    kept output rows into the mapped output (no unpacking kernel, no fill: the tasks zero
    what they do not write) (:data:`HOST_FFT`, :func:`host_fft`): 0.35-0.5x VkFFT's CPU time,
    the same pixels to float64 rounding.
``threshold_split`` (float32 only)
    Pixels whose largest channel exceeds the split level are left out of the FFT and added
    exactly by a gather over their list (deterministic, no atomics), so the float32 error
    floor scales with the remaining, moderate energy only.  If more than ``split_max_points``
    pixels exceed the level, the call falls back to float64 (reported in ``info``).
``"direct"``
    A direct gather (small kernels; float64 accumulation is the reference).
``"half"``
    One pyramid level: 2x2 box-summed input, PSF resampled with a tent filter (energy and
    centroid kept), float32 FFT at half resolution, bilinear upsampling.  Error: light moves by
    up to half a pixel and the PSF core is blurred by ~1 px; energy is kept.

Non-finite input values are treated as 0 (the caller counts them; ``SceneAnalysis`` does).

Blocks (:func:`convolve_blocks`, what :func:`spread` runs)
-------------------------------------------------------------
A convolution whose one FFT grid would exceed :data:`MAX_BLOCK_CELLS` cells (8K glare
with highlights all over the frame: 6960 x 10320, 548 MiB per float64 plane, the grid and the
PSF spectrum each) is cut into
output blocks (overlap-save): each block's grid is the block plus the PSF (smooth sizes,
:func:`block_shape` picks the fewest transformed cells under the cap), its input the pixels
that reach it (:func:`reach`), its result the exact linear convolution there; one grid, plan
and PSF spectrum serve every block of the call.  The input may be a loader and the output a
consumer (``emit``), so the glare family (``clfx.kit.scatter.ScatterPlugin.spread_mixed``)
computes each block's highlights from the source and mixes each output block into the frame
at once: beside the step's source and output, only one block's buffers are on the device.
Every level keeps its semantics in blocks: "direct" blocks give the same bits as one gather,
FFT blocks (float64, float32 + split) differ from one grid by FFT rounding, the split's bright
pixels are counted over the whole support first (the float64 fallback is one decision per
frame), and "half" blocks start at even offsets from the support, so their half-resolution
pixels are the one grid's.  Below the cap (every 960x540, 1080p and 4K frame) the one-grid
path runs unchanged, with the same bits as before blocks, and still no frame-sized highlight
image: only the support's highlights are loaded, and the output is made after the transform.

Why blocks inside the effect rather than the look's band tiler (``whole_frame`` stays set):
a band renders from its region of interest, the band plus the PSF radius above and below
(8K glare: a 101-row band reads 2741 rows, a 337 MB copy of the source, and its output as
large), and each band re-transforms the blocks it crosses; internal blocks read each input
pixel only for the blocks it reaches, keep no band-sized copies, and the untiled render is
the only render, so "tiled" and "whole" are the same bits by construction.

Notes
-----
Memory (one block, or the one grid): the work buffer holds ``B x N1 x (N2 + 2)`` reals (B = channels per batch); channels
are processed one at a time when a batch would exceed :data:`MAX_BATCH_BYTES`.  At 3840x2160
with a PSF radius of a quarter diagonal the float64 grid is ~3300 x 4950: ~130 MB per plane.
The PSF is placed on the grid on the device (its wrapped quadrants copied into the zeroed
buffer), so the host never holds a grid-sized plane (392 MiB, twice, at 8K).

References: Spencer et al. 1995 (glare PSF, see ``clfx.fx.psf``); VkFFT (Tolmachev 2023).
"""
from __future__ import annotations

import functools
import hashlib
import math
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, fields

import numpy as np

from clfx.core.limits import available_cores
from clfx.core.plugin import Level
from clfx.core.rect import Rect
from clfx.device import runtime

PRECISIONS = ("float64", "float32")
METHODS = ("fft", "direct", "half")
SPECTRUM_CACHE_BYTES = 384 * 2 ** 20
"""A PSF spectrum larger than this is not cached (a 4K float64 RGB spectrum alone is ~400 MB:
such a spectrum is recomputed per frame rather than held, keeping 4K within 2 GB)."""
PLAN_NOMINAL_BYTES = 2 ** 20
"""What a cached FFT plan counts for in the cache beyond its VkFFT temporary buffer (its
compiled kernels and tables), so that the cache's LRU can evict plans of sizes not seen
again."""
MAX_BATCH_BYTES = 160 * 2 ** 20
"""Above this work-buffer size, colour channels are transformed one at a time (1080p
glare batches its three channels; 4K transforms them one by one to bound memory)."""
KERNEL_FILE = "lib/fftconv.cl"
CACHE_OWNERS = ("fftconv.plan", "fftconv.spectrum")
"""Owners of fftconv's entries in the runtime's cache (``rt.cache.clear(owner)``)."""
HOST_FFT = True
"""float64 transforms on a device that is the host's CPU (PoCL) run in NumPy's pocketfft, on
the device's own buffers (mapped: PoCL's buffers are host memory), in chunks on every core;
elsewhere VkFFT.  Measured on 2 cores (:func:`convolve` float64 of a whole 1080p frame with
a 661 x 661 PSF, CPU ms, median of 5): VkFFT with its packed copy 495-670, NumPy 305-316
(its transforms alone: 250-330 against VkFFT's 510-670 for 3 planes of 1372 x 2250, the
cinema look's glare; issue 37's passes over every channel at once: 220-260).  The result
differs by float64 rounding only (`host_fft`)."""


def host_fft(rt, precision: str) -> bool:
    """Whether ``precision`` transforms run on the host (:data:`HOST_FFT`): float64 on a
    device that shares the host's cores."""
    return HOST_FFT and precision == "float64" and bool(getattr(rt, "shares_host_cores", False))


@dataclass
class ConvolveInfo:
    """What :func:`convolve` did (for ``ctx.notes`` and tests)."""

    method: str = "fft"
    precision: str = "float64"
    grid: tuple[int, int] | None = None
    bright_pixels: int = 0
    fallback: str = ""
    blocks: int = 1
    notes: list[str] = field(default_factory=list)


# -- sizes ---------------------------------------------------------------------------------
def is_smooth(n: int, primes=(2, 3, 5, 7)) -> bool:
    """True if ``n`` has no prime factor outside ``primes`` (fast FFT sizes)."""
    for p in primes:
        while n % p == 0 and n > 1:
            n //= p
    return n == 1


def fft_size(n: int, *, even: bool = False) -> int:
    """The smallest size >= ``n`` with prime factors 2, 3, 5, 7 (even if asked)."""
    m = max(int(n), 2 if even else 1)
    while not (is_smooth(m) and (not even or m % 2 == 0)):
        m += 1
    return m


def _axis_size(support_len: int, kernel_len: int, centre: int, out_lo: int, out_hi: int) -> int:
    """Circular length that makes the circular result exact on output range [out_lo, out_hi)
    (coordinates relative to the support origin).

    Output o reads inputs o - k for k in [-centre, kernel_len - 1 - centre], i.e. the range
    A = [out_lo - (kernel_len - 1 - centre), out_hi - 1 + centre].  Positions of A outside
    the support [0, L) must not alias into it: negatives map to a + N >= L, positions >= L map
    to a - N < 0.
    """
    a_min = out_lo - (kernel_len - 1 - centre)
    a_max = out_hi - 1 + centre
    need = support_len
    if a_min < 0:
        need = max(need, support_len - a_min)
    if a_max >= support_len:
        need = max(need, a_max + 1)
    return need


def full_region(support: Rect, kh: int, kw: int) -> Rect:
    """Where the linear convolution of ``support`` with a (kh, kw) PSF can be non-zero."""
    cx, cy = kw // 2, kh // 2
    # input i reaches outputs o = i + (j - c) for taps j in [0, k)
    return Rect(support.x0 - cx, support.y0 - cy,
                support.x1 + kw - 1 - cx, support.y1 + kh - 1 - cy)


REACH_MARGIN = 2
"""Taps kept past the farthest that can carry light from the support to the output
(:func:`reachable`): the half-resolution method's tent filters reach one tap further."""


def psf_reach(support: Rect, out_window: Rect) -> tuple[int, int]:
    """(dy, dx): the farthest PSF offsets, rows and columns, that carry light from
    ``support`` to ``out_window`` (:data:`REACH_MARGIN` included): the part of a PSF worth
    building (``clfx.fx.psf.window``) and convolving (:func:`reachable`)."""
    dy = max(out_window.y1 - 1 - support.y0, support.y1 - 1 - out_window.y0, 0) + REACH_MARGIN
    dx = max(out_window.x1 - 1 - support.x0, support.x1 - 1 - out_window.x0, 0) + REACH_MARGIN
    return dy, dx


def reachable(k: np.ndarray, support: Rect, out_window: Rect) -> np.ndarray:
    """``k`` (centred, (kh, kw[, planes])) without the rows and columns that carry no light
    from ``support`` to ``out_window``: a PSF sized from a thin frame's diagonal (65535x1:
    19661 taps a side) only reaches the frame through its central rows, so the FFT grid
    becomes (h + 2 r_eff) x (w + 2 r) with r_eff bounded by the frame's extent.  The same
    ``k`` (no copy, the same bits) when everything can reach."""
    kh, kw = k.shape[:2]
    cy, cx = kh // 2, kw // 2
    dy, dx = psf_reach(support, out_window)
    if dy >= kh - 1 - cy and dx >= kw - 1 - cx:
        return k
    if dy < kh - 1 - cy:
        k = k[cy - dy:cy + dy + 1]
    if dx < kw - 1 - cx:
        k = k[:, cx - dx:cx + dx + 1]
    return np.ascontiguousarray(k)


def fft_grid(support: Rect, effective: Rect, kh: int, kw: int) -> tuple[int, int]:
    """(N1, N2) FFT grid for an input ``support`` and the output rectangle kept."""
    n1 = _axis_size(support.height, kh, kh // 2, effective.y0 - support.y0,
                    effective.y1 - support.y0)
    n2 = _axis_size(support.width, kw, kw // 2, effective.x0 - support.x0,
                    effective.x1 - support.x0)
    return fft_size(n1), fft_size(n2, even=True)


# -- PSF handling --------------------------------------------------------------------------
def _as_psf(psf) -> np.ndarray:
    k = np.asarray(psf, np.float64)
    if k.ndim == 2:
        k = k[..., None]
    if k.ndim != 3 or k.shape[2] not in (1, 3) or k.shape[0] < 1 or k.shape[1] < 1:
        raise ValueError(f"psf must have shape (kh, kw) or (kh, kw, 3), got {np.shape(psf)}")
    if not np.isfinite(k).all():
        raise ValueError("psf contains non-finite values")
    return np.ascontiguousarray(k)


def psf_digest(psf: np.ndarray) -> str:
    """Content hash of a PSF (cache key; 3 ms for 1080p glare's 661 x 661 taps)."""
    k = np.ascontiguousarray(psf, np.float64)
    h = hashlib.sha1(k.reshape(-1).view(np.uint8))   # its bytes, without a copy of them
    h.update(repr(k.shape).encode())
    return h.hexdigest()


def _real(precision: str):
    return np.float64 if precision == "float64" else np.float32


def _kernel(rt, name: str, precision: str = "float32"):
    """A kernel of ``lib/fftconv.cl`` whose REAL is ``precision`` (lib/precision.h)."""
    return rt.kernel(KERNEL_FILE, name, fp64=precision == "float64")


@dataclass(frozen=True, eq=False)
class _Plan:
    """A VkFFT plan and what it holds (for the cache's byte count)."""

    app: object
    nbytes: int


def _plan(rt, shape: tuple[int, int, int], precision: str):
    """The cached in-place r2c plan for ``shape`` = (batch, N1, N2 + 2)."""
    def build():
        from pyvkfft.opencl import VkFFTApp  # lazy: pyvkfft is ~0.3 s; `clfx looks` loads this module

        started = time.perf_counter()
        app = VkFFTApp(shape, _real(precision), rt.queue, ndim=2, inplace=True, r2c=True)
        if runtime.BUILD_LOG:    # VkFFT builds its own program per plan: a compile when cold
            runtime.log_build("vkfft", (("shape", "x".join(map(str, shape))),
                                        ("precision", precision)), time.perf_counter() - started)
        return _Plan(app, int(getattr(app, "tmp_buffer_nbytes", 0)) + PLAN_NOMINAL_BYTES)

    return rt.cache.get(("fftconv.plan", shape, precision), build).app


def _array(rt, holder, shape, dtype):
    import pyopencl.array as cla  # lazy: pyopencl is ~0.2 s; `clfx looks` loads this module

    return cla.Array(rt.queue, shape, dtype, data=holder.buffer)


DIGEST_NBYTES = 256
"""What a remembered PSF hash (:func:`psf_id`) counts for in the runtime's cache."""


def psf_id(rt, k: np.ndarray, key=None) -> str:
    """The hash of the PSF ``k`` (kh, kw, planes) that its spectra are cached under
    (:func:`psf_digest`).  With a ``key``, a name of its values that the caller keeps
    (``clfx.kit.scatter.ScatterPlugin.psf_key``: the key its PSF is cached under; equal keys
    must mean equal PSFs), hashed once per key and shape and remembered in ``rt.cache`` (a
    PSF cut to its reach, :func:`reachable`, is its centre: the shape tells the cuts apart):
    1080p glare hashed its 661 x 661 taps every frame (3 ms).  The spectra stay keyed by
    content: a new key with the same PSF (a keyframed strength) finds them."""
    if key is None:
        return psf_digest(k)
    return rt.cache.get(("fftconv.spectrum", "psf digest", key, k.shape),
                        lambda: psf_digest(k), nbytes=DIGEST_NBYTES)


def psf_spectrum(rt, psf: np.ndarray, n1: int, n2: int, precision: str, key=None):
    """``(buffer, planes)``: a device buffer with the r2c spectrum of ``psf`` placed with its
    centre at (0, 0) (planes: 1 or 3), cached by (PSF, grid, precision) in ``rt.cache``
    unless larger than :data:`SPECTRUM_CACHE_BYTES` (``key``: a name of the PSF's values,
    :func:`psf_id`)."""
    k = _as_psf(psf)
    nbytes = k.shape[2] * n1 * (n2 + 2) * np.dtype(_real(precision)).itemsize
    build = _host_spectrum if host_fft(rt, precision) else _spectrum
    if nbytes > SPECTRUM_CACHE_BYTES:
        return build(rt, k, n1, n2, precision)   # too big to keep: this frame only
    return rt.cache.get(("fftconv.spectrum", psf_id(rt, k, key), n1, n2, precision,
                         build.__name__),
                        lambda: build(rt, k, n1, n2, precision))


def _host_spectrum(rt, k: np.ndarray, n1: int, n2: int, precision: str):
    """`_spectrum` on the host (:func:`host_fft`): ``(planes x (n2 / 2 + 1) x n1 complex128
    array, planes)``, each plane the r2c transform of the taps wrapped onto the grid
    (coinciding taps add up), transposed (a column's values side by side, as
    `_host_passes`' column tasks multiply them), made in the host transforms' own work
    planes (`_host_planes`: no grid-sized plane beside them)."""
    kh, kw, planes = k.shape
    ys = (np.arange(kh) - kh // 2) % n1
    xs = (np.arange(kw) - kw // 2) % n2
    out = np.empty((planes, n2 // 2 + 1, n1), np.complex128)
    # the RGB convolutions' own planes (the shelf is kept by their count: 3 channels), not a
    # second set of grid-sized planes for a 1-plane PSF
    shelf, work, shelved = _host_planes(rt, n1, n2, host_planes_in_flight(n1, n2, 3))
    try:
        for p0 in range(0, planes, len(work)):
            group = work[:min(len(work), planes - p0)]
            for p, plane in enumerate(group, p0):
                real = plane.view(np.float64)     # (n1, n2 + 2): the r2c layout
                real.fill(0.0)
                np.add.at(real, (ys[:, None], xs[None, :]), k[..., p])
            _run_lanes([_host_passes(group, n1, spectra=out[p0:p0 + len(group)])])
    finally:
        shelf.extend(shelved)
    return out, planes


def _spectrum(rt, k: np.ndarray, n1: int, n2: int, precision: str):
    kh, kw, planes = k.shape
    cy, cx = kh // 2, kw // 2
    ys = (np.arange(kh) - cy) % n1
    xs = (np.arange(kw) - cx) % n2
    real = _real(precision)
    plane_bytes = n1 * (n2 + 2) * np.dtype(real).itemsize
    # A one-plane PSF goes through the colour image's own plan (batch 3, zero planes beside
    # it) where the image batches its channels: one VkFFT program per grid, not two (a cold
    # kernel cache compiles each, ~1 s on PoCL); its plane is the same either way.
    batch = 3 if planes == 1 and 3 * plane_bytes <= MAX_BATCH_BYTES else planes
    holder = rt.buffer(batch * plane_bytes)
    quadrants = kh <= n1 and kw <= n2
    if quadrants or batch > planes:   # the planes the copies below leave zero
        rt.cl.enqueue_fill_buffer(rt.queue, holder.buffer, real(0), 0, batch * plane_bytes)
    if quadrants:
        # no two taps coincide modulo the grid: the taps' four wrapped quadrants are copied
        # into the zeroed buffer (the host holds the PSF, never a grid-sized plane)
        taps = np.ascontiguousarray(np.moveaxis(k, 2, 0), real)     # (planes, kh, kw)
        item, row = np.dtype(real).itemsize, (n2 + 2) * np.dtype(real).itemsize
        for p in range(planes):
            for (ky, ny, y), (kx, nx, x) in _quadrants(kh, cy, n1, kw, cx, n2):
                rt.cl.enqueue_copy(rt.queue, holder.buffer, taps[p],
                                   buffer_origin=(x * item, p * n1 + y, 0),
                                   host_origin=(kx * item, ky, 0),
                                   region=(nx * item, ny, 1),
                                   buffer_pitches=(row, 0), host_pitches=(kw * item, 0))
    else:
        for p in range(planes):  # one plane on the host at a time
            # taps that coincide modulo the grid add up: the grid can be smaller than the PSF
            # when only a small output is kept (fft_grid proves the result exact there)
            plane = np.zeros((n1, n2 + 2), np.float64)
            np.add.at(plane, (ys[:, None], xs[None, :]), k[..., p])
            rt.cl.enqueue_copy(rt.queue, holder.buffer, plane.astype(real),
                               dst_offset=p * plane_bytes)
    shape = (batch, n1, n2 + 2)
    app = _plan(rt, shape, precision)
    app.fft(_array(rt, holder, shape, real))
    if batch > planes:
        spectrum = rt.buffer(planes * plane_bytes)
        rt.cl.enqueue_copy(rt.queue, spectrum.buffer, holder.buffer, byte_count=plane_bytes)
        return spectrum, planes
    return holder, planes


def _quadrants(kh: int, cy: int, n1: int, kw: int, cx: int, n2: int):
    """The blocks of a (kh, kw) PSF centred at (cy, cx) wrapped onto an (n1, n2) grid (kh <=
    n1, kw <= n2): ((first PSF row, rows, grid row), (first PSF column, columns, grid
    column)) pairs.  PSF row j lands on grid row (j - cy) mod n1: rows >= cy at the top,
    rows < cy at the bottom (the same for columns)."""
    def spans(k, c, n):
        return [s for s in ((c, k - c, 0), (0, c, n - c)) if s[1] > 0]
    return [(a, b) for a in spans(kh, cy, n1) for b in spans(kw, cx, n2)]


def clear_caches(rt) -> None:
    """Drop the cached plans and PSF spectra from ``rt.cache`` (frees device memory)."""
    for owner in CACHE_OWNERS:
        rt.cache.clear(owner)


# -- public API ----------------------------------------------------------------------------
def _checked(rt, psf, method: str, precision: str, info: ConvolveInfo | None):
    """The PSF as (kh, kw, planes) float64, the precision granted, and the info to fill;
    raises ValueError on a bad PSF, method or precision."""
    k = _as_psf(psf)
    if precision not in PRECISIONS:
        raise ValueError(f"precision {precision!r} is not one of {PRECISIONS}")
    if method not in METHODS:
        raise ValueError(f"method {method!r} is not one of {METHODS}")
    if precision == "float64" and not rt.use_fp64(True):   # says so once on stderr
        precision = "float32"
    info = info if info is not None else ConvolveInfo()
    info.method, info.precision = method, precision
    return k, precision, info


def convolve(rt, img, psf, *, out_window: Rect | None = None, support: Rect | None = None,
             precision: str = "float64", threshold_split: float | None = None,
             split_max_points: int = 256, method: str = "fft", info: ConvolveInfo | None = None):
    """Convolve the colour channels of a device image with a PSF.

    Parameters
    ----------
    rt : Runtime
    img : DeviceImage
        1 or 4 channels (RGBA: R, G, B are convolved; alpha of the result is 0).  Its window may
        be larger than the display window (overscan): all of it contributes.
    psf : ndarray, shape (kh, kw) or (kh, kw, 3)
        Kernel weights, centre at ``(kh // 2, kw // 2)``; one plane for all channels or one per
        R, G, B.  Used as given (normalise it for energy conservation).
    out_window : Rect, optional
        Output window in frame coordinates (default: everything the light reaches,
        :func:`full_region`).  Pixels it shares with nothing get 0.
    support : Rect, optional
        The part of ``img.window`` that may be non-zero (e.g. tiles with highlights); the rest
        is treated as 0, which shrinks the FFT grid.  Default: ``img.window``.
    precision : {"float64", "float32"}
        FFT precision (``method="fft"``) or accumulation precision (``"direct"``).
    threshold_split : float, optional
        float32 only: pixels whose largest channel exceeds this level are convolved exactly
        by a gather and the rest by the FFT (HDR-safe float32, see the module notes).
    split_max_points : int
        Above this many bright pixels the split falls back to float64 (``info.fallback``).
    method : {"fft", "direct", "half"}
        FFT, direct gather, or one pyramid level at half resolution (approximate).
    info : ConvolveInfo, optional
        Filled with what was done.

    Returns
    -------
    DeviceImage
        ``img.channels`` channels covering ``out_window``.

    Raises
    ------
    ValueError
        Bad PSF shape or non-finite PSF, unknown precision/method.

    Examples
    --------
    >>> out = convolve(rt, highlights, psf, out_window=rod, precision="float64")  # doctest: +SKIP
    """
    k, precision, info = _checked(rt, psf, method, precision, info)
    kh, kw = k.shape[:2]
    support = img.window if support is None else support.intersect(img.window)
    out_window = out_window or full_region(support, kh, kw)
    k = reachable(k, support, out_window)
    return _convolve(rt, img, k, support, out_window, method, precision, threshold_split,
                     split_max_points, info)


def _convolve(rt, img, k, support, out_window, method, precision, split, max_points, info,
              grid=None, spectrum=None, half=None, psf_key=None):
    """:func:`convolve` once its arguments are checked; ``grid``, ``spectrum`` (the PSF's,
    on that grid) and ``half`` (the half-resolution block) are a block's
    (:func:`convolve_blocks`): the same for every block of a frame; ``psf_key`` names ``k``'s
    values (:func:`psf_id`)."""
    kh, kw = k.shape[:2]
    dst = rt.image(out_window, img.channels)
    effective = out_window.intersect(full_region(support, kh, kw))
    if support.empty or effective.empty:
        return rt.fill(dst, 0.0)
    if method == "direct":
        _direct(rt, img, k, support, effective, dst, precision)
    elif method == "half":
        _half(rt, img, k, support, effective, dst, info, grid, spectrum, half, psf_key)
    else:
        _fft(rt, img, k, support, effective, dst, precision, split, max_points, info, grid,
             spectrum, psf_key)
    return dst


def _too_many_bright(rt, info, split, max_points):
    """preview's exact gather has more than ``max_points`` bright pixels to do: the float64
    FFT instead (said in ``info``); returns the (precision, split) to go on with."""
    info.fallback = (f"more than {max_points} pixels above the split level "
                     f"{split:g}: float64 FFT instead")
    info.notes.append(info.fallback)
    return ("float64" if rt.use_fp64(True) else "float32"), None


def _fft(rt, img, k, support, effective, dst, precision, split, max_points, info, grid=None,
         spectrum=None, psf_key=None):
    kh, kw, planes = k.shape
    if split is not None and precision == "float32":
        bright = _bright_pixels(rt, img, support, float(split), max_points)
        if bright is None:
            precision, split = _too_many_bright(rt, info, split, max_points)
        else:
            info.bright_pixels = bright[2]
    else:
        split, bright = None, None
    info.precision = precision
    need = fft_grid(support, effective, kh, kw)
    n1, n2 = grid or need
    if n1 < need[0] or n2 < need[1]:
        raise ValueError(f"FFT grid {grid} is smaller than the {need} this block needs")
    info.grid = (n1, n2)
    nch = 1 if img.channels == 1 else 3
    spec, spec_planes = spectrum or psf_spectrum(rt, k, n1, n2, precision, psf_key)
    sx, sy = support.offset_in(img.window)
    dx, dy = dst.window.x0 - support.x0, dst.window.y0 - support.y0
    ex0, ey0 = effective.offset_in(dst.window)
    if host_fft(rt, precision):   # the rows are read from the image, the result written
        _host_convolve(rt, img, (sx, sy, support.width, support.height), spec, (n1, n2),
                       dst, (dx, dy), (ex0, ey0, ex0 + effective.width, ey0 + effective.height))
        return
    real = _real(precision)
    itemsize = np.dtype(real).itemsize
    batch = nch if nch * n1 * (n2 + 2) * itemsize <= MAX_BATCH_BYTES else 1
    work = rt.buffer(batch * n1 * (n2 + 2) * itemsize)
    shape = (batch, n1, n2 + 2)
    app = _plan(rt, shape, precision)
    arr = _array(rt, work, shape, real)
    pack = _kernel(rt, "fftconv_pack", precision)
    mul = _kernel(rt, "fftconv_multiply", precision)
    unpack = _kernel(rt, "fftconv_unpack", precision)
    count = n1 * (n2 // 2 + 1)
    for c0 in range(0, nch, batch):
        rt.launch(pack, (n2 + 2, n1), img, img.pitch, img.channels, sx, sy, support.width,
                  support.height, work, n1, n2 + 2, c0, batch,
                  np.inf if split is None else split, local=None)
        app.fft(arr)
        rt.launch(mul, (count,), work, spec, count, batch, spec_planes,
                  c0 if spec_planes > 1 else 0)
        app.ifft(arr)
        rt.launch(unpack, (dst.pitch, dst.height), work, n1, n2 + 2, n2, dst, dst.pitch,
                  dst.channels, dst.width, dst.height, dx, dy, ex0, ey0, ex0 + effective.width,
                  ey0 + effective.height, c0, batch)
    if bright is not None and bright[2]:
        _gather(rt, dst, support, k, bright, precision="float32")


def _host_convolve(rt, img, support: tuple[int, int, int, int], spec: np.ndarray,
                   grid: tuple[int, int], dst, offset: tuple[int, int],
                   kept: tuple[int, int, int, int]) -> None:
    """The colour channels of the device image ``img`` over ``support`` = (x, y, width,
    height) (pixels of its buffer; non-finite values read as 0) convolved with the spectra
    ``spec`` (:func:`_host_spectrum`, 1 or 3 planes) on the host (:func:`host_fft`), on the
    ``grid`` = (N1, N2), into ``dst`` (mapped): its pixel (x, y) is the grid's ((x + dx) mod
    N2, (y + dy) mod N1) (``offset`` = (dx, dy)) inside ``kept`` = (x0, y0, x1, y1), 0
    elsewhere and in alpha.

    The channels are transformed in grid-sized complex planes kept in the runtime's cache
    (`_host_planes`), :func:`host_planes_in_flight` of them at once, each pass over all of
    them (`_host_passes`: a row task reads its rows of the image once for every channel and
    the inverse row task writes every channel of its output rows, alpha included, while
    they are in cache); the inverse row transforms run for the rows kept alone, and the
    tasks zero what they do not write (no fill of ``dst`` before, no serial pass): no
    padded planes for VkFFT, no unpacking kernel."""
    cl = rt.cl
    n1, n2 = grid
    sx, sy, sw, sh = support
    x0, y0, x1, y1 = kept
    nch = 1 if img.channels == 1 else 3
    # the kept pixels' grid rows and columns: one run each, or two where they wrap
    gy, gx = ((np.arange(lo, hi) + d) % n for lo, hi, d, n in ((y0, y1, offset[1], n1),
                                                                 (x0, x1, offset[0], n2)))
    runs = np.split(np.arange(y0, y1), np.flatnonzero(np.diff(gy) != 1) + 1)
    cols = slice(gx[0], gx[0] + len(gx)) if len(gx) and gx[-1] - gx[0] == len(gx) - 1 \
        else gx
    spans = [(int(gy[r[0] - y0]), int(gy[r[-1] - y0]) + 1) for r in runs if len(r)]
    group = host_planes_in_flight(n1, n2, nch)
    shelf, planes, shelved = _host_planes(rt, n1, n2, group)
    try:
        out, _ = cl.enqueue_map_buffer(rt.queue, dst.buffer, cl.map_flags.WRITE, 0,
                                       (max(dst.height, 1), dst.pitch, dst.channels),
                                       np.float32)
        try:
            pixels, _ = cl.enqueue_map_buffer(rt.queue, img.buffer, cl.map_flags.READ, 0,
                                              (max(img.height, 1), img.pitch, img.channels),
                                              np.float32)
            try:
                def rows(c):
                    def load(r0, r1, x):    # support rows r0..r1 of channel c into x[:, :sw]
                        x = x[:, :sw]
                        np.copyto(x, pixels[sy + r0:sy + r1, sx:sx + sw, c])
                        if not np.isfinite(x.sum()):    # float32 values: no float64 overflow
                            x[~np.isfinite(x)] = 0.0
                    return load

                def kept_rows(c):
                    def put(r0, r1, values):   # grid rows r0.. of one run
                        ys = r0 - gy[0] + y0 if r0 >= gy[0] else r0 + n1 - gy[0] + y0
                        block = out[ys:ys + r1 - r0]
                        block[:, x0:x1, c] = values[:, cols]
                        if c == 0:    # alpha (the channels past the colour ones) is 0
                            block[:, x0:x1, nch:] = 0.0
                    return put

                passes = []
                for c0 in range(0, nch, group):   # each group of channels in turn
                    chans = range(c0, min(c0 + group, nch))
                    passes += _host_passes(planes[:len(chans)], sh,
                                           [spec[c] if len(spec) > 1 else spec[0]
                                            for c in chans],
                                           [rows(c) for c in chans],
                                           (spans, [kept_rows(c) for c in chans]))
                _run_lanes([passes, [_zero_outside(out, kept)]])
            finally:
                pixels.base.release()
        finally:
            out.base.release()
    finally:
        shelf.extend(shelved)   # back for the next call


def _zero_outside(out: np.ndarray, kept: tuple[int, int, int, int]) -> list:
    """Tasks that zero the mapped image ``out`` (height x pitch x channels) outside ``kept`` =
    (x0, y0, x1, y1): whole rows above and below, the columns left and right of it (the row
    padding included)."""
    x0, y0, x1, y1 = kept
    height, pitch, channels = out.shape
    step = max(1, HOST_CHUNK_BYTES // (pitch * channels * 4))

    def zero(r0, r1):
        inside = out[max(r0, y0):min(r1, y1)]
        inside[:, :x0] = 0.0
        inside[:, x1:] = 0.0
        out[r0:min(r1, y0)] = 0.0
        out[max(r0, y1):r1] = 0.0

    if x0 <= 0 and x1 >= pitch:   # only whole rows
        spans = [(0, y0), (y1, height)]
    else:
        spans = [(0, height)]
    return [functools.partial(zero, r, min(r + step, hi)) for lo, hi in spans
            for r in range(lo, hi, step)]


HOST_PLANE_BYTES = 2 ** 27
"""Most bytes of the complex planes one host convolution transforms channels in at once
(:func:`host_planes_in_flight`): 1080p glare's 1372 x 1126 complex128 planes are 24.7 MiB
(all three at once), 4K's (~3300 x 2476) 130 MiB: one, its channels one after another."""


def host_planes_in_flight(n1: int, n2: int, channels: int) -> int:
    """How many channels a host convolution on an (N1, N2) grid transforms at once (each
    pass over all of them, its tasks on every core): at most ``channels``, within
    :data:`HOST_PLANE_BYTES` (at least one)."""
    plane = n1 * (n2 // 2 + 1) * 16
    return max(1, min(channels, HOST_PLANE_BYTES // plane))


def _host_planes(rt, n1: int, n2: int, count: int) -> tuple[list, list[np.ndarray], list]:
    """(shelf, planes, shelved): ``count`` N1 x (N2 / 2 + 1) complex128 planes, the host
    transforms' work (`_host_convolve`), taken off the shelf the runtime's cache keeps for
    this grid (their pages touched when they are made: the cache counts that cost, so the
    pool's idle buffers go before them; ``shelved``: those taken), or new ones while another
    call holds them.  Put ``shelved`` back on the shelf when done."""
    def build():
        planes = [np.empty((n1, n2 // 2 + 1), np.complex128) for _ in range(count)]
        for plane in planes:
            plane.fill(0.0)
        return planes

    shelf = rt.cache.get(("fftconv.host_plane", n1, n2, count), build)
    shelved = []
    while len(shelved) < count:
        try:
            shelved.append(shelf.pop())
        except IndexError:
            break
    fresh = [np.empty((n1, n2 // 2 + 1), np.complex128) for _ in range(count - len(shelved))]
    return shelf, shelved + fresh, shelved


HOST_CHUNK_BYTES = 2 ** 21
"""The rows one host transform task takes at a time (their copies stay in cache; the
grid-sized temporaries of a whole-plane transform, several per plane, are never made: 215
MiB each at 8K)."""

HOST_COLUMN_BYTES = 2 ** 19
"""The columns one host transform task takes at a time, copied side by side into the task's
buffer, which stays in the 2nd level cache through the forward transform, the product and
the inverse (1080p glare, 1372-point columns, CPU of a plane's: 36-38 ms in 16-32 strided
columns, 41 in 95 (2 MiB), 59 whole; contiguous copies of 23: 30-33, the same with 8-64,
2^18-2^20 bytes within the noise)."""


def _host_passes(planes: list[np.ndarray], rows: int, specs: list | None = None,
                 sources: list | None = None, sink=None, spectra=None) -> list[list]:
    """The passes over N1 x (N2 / 2 + 1) complex128 ``planes`` (one per channel), in order,
    each a list of tasks (callables; a pass's tasks may run at once, after the previous
    pass's): the forward transform of the first ``rows`` rows' N2 reals of every plane
    (``sources[p](r0, r1, x)`` writes plane p's rows r0..r1 into x[:, :width], at most N2
    values each, and leaves the rest of x, 0, alone; default the plane's own reals, the r2c
    layout; the rows after ``rows`` read as 0), then with ``specs`` (one per plane, each
    (N2 / 2 + 1) x N1: :func:`_host_spectrum`) and ``sink`` = (runs, puts) the product and
    the inverse transform (N2 reals per row, the 1 / (N1 N2) on the inverse) of only the
    grid row runs [r0, r1) of ``runs``, handed to ``puts[p](r0, r1, values)`` (values (r1 -
    r0) x N2 float64, valid during the call); without them the spectra alone, written into
    ``spectra`` (planes x (N2 / 2 + 1) x N1, transposed).

    A row task takes :data:`HOST_CHUNK_BYTES` of rows of every plane (the image's rows read
    and the output's written once, while in cache); a column task :data:`HOST_COLUMN_BYTES`
    of columns of one plane, copied side by side into a buffer of the task's thread, where
    their transforms and the product run on contiguous values, and only the rows the
    inverse row pass reads go back (NumPy's transforms release the GIL).  Every row and
    column is transformed alone, so the chunks change no bit of the result."""
    n1, half = planes[0].shape
    n2 = 2 * (half - 1)
    row_step = max(1, HOST_CHUNK_BYTES // (half * 16 * len(planes)))
    col_step = max(1, HOST_COLUMN_BYTES // (n1 * 16))
    local = threading.local()   # each thread's buffers, made once a call

    def scratch(name: str, shape, dtype) -> np.ndarray:
        if not hasattr(local, name):   # zeros: the forward rows' padding stays 0
            setattr(local, name, np.zeros(shape, dtype))
        return getattr(local, name)

    def forward_rows(r0, r1):
        for p, cplx in enumerate(planes):
            if sources is None:   # the plane's own reals: transformed before a row is written
                x = cplx.view(np.float64)[r0:r1, :n2]
                lit = x.any(axis=1)
                f = np.fft.rfft(x if lit.all() else x[lit], n=n2, axis=1)
                cplx[r0:r1][~lit] = 0.0
                cplx[r0 + np.flatnonzero(lit)] = f
                continue
            x = scratch("rows", (row_step, n2), np.float64)[:r1 - r0]
            sources[p](r0, r1, x)
            # a row of zeros transforms to zeros: glare's highlights leave a third of the
            # rows of their support dark at 1080p; each run of lit rows is transformed into
            # the plane (whole padded rows: 40 % less than NumPy's own padding of each row)
            lit = x.any(axis=1)
            cplx[r0:r1][~lit] = 0.0
            edges = np.flatnonzero(np.diff(lit, prepend=False, append=False))
            for a, b in zip(edges[::2], edges[1::2]):
                np.fft.rfft(x[a:b], axis=1, out=cplx[r0 + a:r0 + b])

    def columns(p, c0, c1):
        f = planes[p][:, c0:c1]
        t = scratch("columns", (col_step, n1), np.complex128)[:c1 - c0]
        np.copyto(t[:, :rows], f[:rows].T)
        t[:, rows:] = 0.0
        np.fft.fft(t, axis=1, out=t)
        if specs is None:
            spectra[p][c0:c1] = t
            return
        t *= specs[p][c0:c1]
        np.fft.ifft(t, axis=1, out=t)
        for r0, r1 in sink[0]:
            np.copyto(f[r0:r1], t[:, r0:r1].T)

    def put_rows(r0, r1):
        values = scratch("values", (row_step, n2), np.float64)[:r1 - r0]
        for p, cplx in enumerate(planes):
            np.fft.irfft(cplx[r0:r1], n=n2, axis=1, out=values)
            sink[1][p](r0, r1, values)

    def tasks(fn, spans, step):
        return [functools.partial(fn, i, min(i + step, hi)) for lo, hi in spans
                for i in range(lo, hi, step)]

    # the planes' tasks of a column chunk side by side: one spectrum's chunk stays in cache
    passes = [tasks(forward_rows, [(0, rows)], row_step),
              [functools.partial(columns, p, c, min(c + col_step, half))
               for c in range(0, half, col_step) for p in range(len(planes))]]
    if specs is not None:
        passes.append(tasks(put_rows, sink[0], row_step))
    return passes


def _run_lanes(lanes: list[list[list]]) -> None:
    """Run ``lanes`` (each a list of passes, a pass a list of tasks: callables) on every
    core: a lane's passes one after another, each pass's tasks at once, the lanes side by
    side, so a core that finishes its part of one lane's pass takes another lane's tasks
    rather than wait.  The first error stops every lane (no new task starts) and is raised
    once the running tasks are done.  The threads live as long as the call: none is left
    behind in the caller's process (a refused frame starts none, tests/test_frame_limits.py)."""
    lanes = [[p for p in lane if p] for lane in lanes]
    lanes = [lane for lane in lanes if lane]
    workers = max(1, available_cores())
    if workers == 1 or sum(len(p) for lane in lanes for p in lane) <= 1:
        for lane in lanes:
            for task in (t for p in lane for t in p):
                task()
        return
    lock = threading.Lock()
    errors: list[BaseException] = []
    finished = threading.Event()
    active = [len(lanes)]

    with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="clfx-fft") as pool:
        def start(lane, i):
            if i == len(lane) or errors:
                with lock:
                    active[0] -= 1
                    if not active[0]:
                        finished.set()
                return
            left = [len(lane[i])]

            def run(task):
                try:
                    if not errors:
                        task()
                except BaseException as exc:   # raised in the caller, below
                    with lock:
                        errors.append(exc)
                with lock:
                    left[0] -= 1
                    last = not left[0]
                if last:
                    start(lane, i + 1)

            for task in lane[i]:
                pool.submit(run, task)

        if lanes:
            for lane in lanes:
                start(lane, 0)
            finished.wait()
    if errors:
        raise errors[0]


def _bright_pixels(rt, img, support, split, max_points):
    """Positions and values of the support's pixels above ``split`` (row order), or None if
    there are more than ``max_points``."""
    n, args = _bright_rows(rt, img, support, split)
    sh = support.height
    total = int(n.sum())
    if total > max_points:
        return None
    if total == 0:
        return (None, None, 0)
    offsets = rt.to_device(np.concatenate([[0], np.cumsum(n)[:-1]]).astype(np.int32))
    pos = rt.buffer(8 * total)
    val = rt.buffer(16 * total)
    rt.launch(_kernel(rt, "fftconv_compact_bright"), (sh,), *args, offsets, pos, val)
    return (pos, val, total)


def _bright_rows(rt, img, support, split):
    """Per support row, how many pixels have a largest channel above ``split`` (and the
    kernel arguments that found them)."""
    sx, sy = support.offset_in(img.window)
    counts = rt.buffer(4 * support.height)
    args = (img, img.pitch, img.channels, sx, sy, support.width, support.height, split)
    rt.launch(_kernel(rt, "fftconv_count_bright"), (support.height,), *args, counts)
    return rt.from_device(counts, np.int32, support.height), args


def _psf_planes_padded(k: np.ndarray, pad: int) -> np.ndarray:
    """float32 PSF planes (planes, kh, kw + 2 pad), zero columns on both sides."""
    kh, kw, planes = k.shape
    out = np.zeros((planes, kh, kw + 2 * pad), np.float32)
    out[:, :, pad:pad + kw] = np.moveaxis(k, 2, 0)
    return out


def _gather(rt, dst, support, k, bright, precision):
    pos, val, total = bright
    kh, kw, planes = k.shape
    table = rt.to_device(_psf_planes_padded(k, 4))
    knl = _kernel(rt, "fftconv_gather", precision)
    rt.launch(knl, (dst.pitch // 4, dst.height), dst, dst.pitch, dst.channels, dst.height,
              dst.window.x0 - support.x0, dst.window.y0 - support.y0, pos, val, total, table, kw,
              kh, kw // 2, kh // 2, planes)


def _direct(rt, img, k, support, effective, dst, precision):
    kh, kw, planes = k.shape
    ppitch = dst.pitch + kw - 1 + 4
    pheight = dst.height + kh - 1
    pad = rt.buffer(ppitch * pheight * 16)
    # padded buffer origin = output origin - (kw - 1 - cx, kh - 1 - cy), in frame coords
    ox = dst.window.x0 - (kw - 1 - kw // 2)
    oy = dst.window.y0 - (kh - 1 - kh // 2)
    sx, sy = support.offset_in(img.window)
    rt.launch(_kernel(rt, "fftconv_pad"), (ppitch, pheight), img, img.pitch, img.channels, sx, sy,
              support.width, support.height, pad, ppitch, pheight, support.x0 - ox,
              support.y0 - oy)
    wtype = np.float64 if precision == "float64" else np.float32
    weights = rt.to_device(np.ascontiguousarray(np.moveaxis(k, 2, 0), wtype))
    ex0, ey0 = effective.offset_in(dst.window)
    knl = _kernel(rt, "fftconv_direct", precision)
    rt.launch(knl, (dst.pitch // 4, dst.height), pad, ppitch, dst, dst.pitch, dst.channels,
              dst.width, dst.height, ex0, ey0, ex0 + effective.width, ey0 + effective.height,
              weights, kw, kh, planes)


def tent_downsample(k: np.ndarray) -> np.ndarray:
    """A PSF for half resolution: each tap at offset d moves to offset d / 2, split between
    the two nearest half-res taps (weights 1/2) when d is odd.  Sum and centroid are kept."""
    k = _as_psf(k)

    def matrix(n):
        c = n // 2
        half = -(-max(c, n - 1 - c) // 2)      # symmetric half-res radius: centre at half
        a = np.zeros((2 * half + 1, n))
        for j, d in enumerate(range(-c, n - c)):
            if d % 2 == 0:
                a[d // 2 + half, j] = 1.0
            else:
                a[(d - 1) // 2 + half, j] = 0.5
                a[(d + 1) // 2 + half, j] = 0.5
        return a

    ay, ax = matrix(k.shape[0]), matrix(k.shape[1])
    return np.stack([ay @ k[..., p] @ ax.T for p in range(k.shape[2])], axis=2)


def half_window(support: Rect, effective: Rect) -> Rect:
    """The half-resolution pixels (coordinates: support origin halved) that the bilinear
    upsampling of ``effective`` reads."""
    # output pixel x (support coords) samples half-res u = (x - 0.5) / 2 and u + 1
    ax0, ay0 = effective.x0 - support.x0, effective.y0 - support.y0
    ax1, ay1 = effective.x1 - support.x0, effective.y1 - support.y0
    return Rect(math.floor((ax0 - 0.5) / 2), math.floor((ay0 - 0.5) / 2),
                math.floor((ax1 - 1.5) / 2) + 2, math.floor((ay1 - 1.5) / 2) + 2)


def half_psf(rt, k: np.ndarray, key=None) -> np.ndarray:
    """The half-resolution PSF, once per PSF (host matrix products: 40 ms for a 397 px PSF;
    ``key``: :func:`psf_id`)."""
    return rt.cache.get(("fftconv.spectrum", "half psf", psf_id(rt, k, key)),
                        lambda: tent_downsample(k))


def _half_key(key, k: np.ndarray):
    """The name of the half-resolution PSF of ``k``, the PSF named ``key`` (None: none)."""
    return None if key is None else ("half psf", key, k.shape)


def _half(rt, img, k, support, effective, dst, info, grid=None, spectrum=None, hi=None,
          psf_key=None):
    """One pyramid level; ``hi``: the half-resolution pixels to build (a block's; default
    all of the support's), from the full-resolution pixels of ``img`` they sum."""
    hw, hh = -(-support.width // 2), -(-support.height // 2)
    hi = hi or Rect(0, 0, hw, hh)
    half_in = rt.image(hi, 4)
    sx, sy = support.offset_in(img.window)
    sx, sy = sx + 2 * hi.x0, sy + 2 * hi.y0
    rt.launch(_kernel(rt, "fftconv_down2"), (half_in.pitch, hi.height), img, img.pitch,
              img.channels, sx, sy, min(support.width - 2 * hi.x0, 2 * hi.width),
              min(support.height - 2 * hi.y0, 2 * hi.height), half_in, half_in.pitch, hi.width,
              hi.height)
    hout = half_window(support, effective)
    kh2 = half_psf(rt, k, psf_key)
    sub = ConvolveInfo()
    half_out = _convolve(rt, half_in, _as_psf(kh2), hi, hout, "fft", "float32", None, 0, sub,
                         grid, spectrum, psf_key=_half_key(psf_key, k))
    info.grid = sub.grid
    ex0, ey0 = effective.offset_in(dst.window)
    rt.launch(_kernel(rt, "fftconv_up2"), (dst.pitch, dst.height), half_out, half_out.pitch,
              half_out.width, half_out.height, hout.x0, hout.y0, dst, dst.pitch, dst.channels,
              dst.width, dst.height, dst.window.x0 - support.x0, dst.window.y0 - support.y0, ex0,
              ey0, ex0 + effective.width, ey0 + effective.height)


# -- blocks: overlap-save over output blocks --------------------------------------------------
MAX_BLOCK_CELLS = 2 ** 25
"""Most cells (N1 x N2) of one block's FFT grid: 256 MiB per float64 plane, 512 MiB for the
block's RGBA input.  A convolution whose one-grid FFT fits runs as one block (every 960x540,
1080p and 4K effect, and glare on the 8K synthetic plate, whose highlights span 3904 x 1344
px: 4000 x 6720 cells); a larger one is cut into output blocks (:func:`convolve_blocks`).
The cap trades memory for transform work: measured with the cap at 2^24 instead, blocks of
a 2645 px PSF were 11 % output, so the 8K plate's glare took 15 blocks, 8.9x the one grid's
cells, for 1366 MiB of device peak; at this cap it is one grid, about 1520 MiB."""
MAX_FFT_AXIS = 2 ** 16
"""Longest FFT axis: VkFFT's float64 r2c plan of a 3 x 71442 grid (soft_focus on a 65535x1
frame) ended the process (SIGSEGV) on PoCL, float32 past 2^17; a longer axis is cut into
blocks (:func:`block_shape`)."""
MIN_BLOCK = 256
"""Smallest block side kept by a PSF so large that :data:`MAX_BLOCK_CELLS` leaves less (the
grid then grows past the cap rather than spending the transform on overlap)."""


def reach(rect: Rect, kh: int, kw: int) -> Rect:
    """The input pixels whose light reaches ``rect`` through a (kh, kw) PSF."""
    cx, cy = kw // 2, kh // 2
    return Rect(rect.x0 - (kw - 1 - cx), rect.y0 - (kh - 1 - cy), rect.x1 + cx, rect.y1 + cy)


@functools.lru_cache(maxsize=64)
def _smooth_sizes(lo: int, hi: int, even: bool = False) -> list[int]:
    out, n = [], fft_size(lo, even=even)
    while n <= hi:
        out.append(n)
        n = fft_size(n + 1, even=even)
    return out or [fft_size(lo, even=even)]


def block_shape(height: int, width: int, kh: int, kw: int,
                cells: int | None = None) -> tuple[int, int]:
    """(rows, columns) of the output blocks covering ``height`` x ``width`` with a (kh, kw)
    PSF: the FFT grid (block + PSF - 1, smooth sizes) of at most ``cells`` (default
    :data:`MAX_BLOCK_CELLS`, each axis at most :data:`MAX_FFT_AXIS`) that transforms the
    fewest cells in all (grid cells x log x blocks); each block side at least
    :data:`MIN_BLOCK` (or the whole side)."""
    cells = cells or MAX_BLOCK_CELLS
    lo1, lo2 = kh - 1 + min(MIN_BLOCK, height), kw - 1 + min(MIN_BLOCK, width)
    hi1 = min(fft_size(height + kh - 1), max(MAX_FFT_AXIS, fft_size(lo1)))
    hi2 = min(fft_size(width + kw - 1, even=True), max(MAX_FFT_AXIS, fft_size(lo2, even=True)))
    best = None
    for n1 in _smooth_sizes(lo1, hi1):
        for n2 in _smooth_sizes(lo2, hi2, even=True):
            if n1 * n2 > cells and best is not None:
                break
            b1, b2 = min(n1 - kh + 1, height), min(n2 - kw + 1, width)
            cost = (-(-height // b1) * -(-width // b2) * n1 * n2 * math.log2(n1 * n2),
                    n1 * n2)
            if best is None or cost < best[0] or (best[2] > cells and n1 * n2 <= cells):
                best = (cost, (b1, b2), n1 * n2)
    return best[1]


def _one_grid_fits(rt, method, k, support, effective, out_window, psf_key=None) -> bool:
    """Whether a single-block convolution's one work grid fits :data:`MAX_BLOCK_CELLS` (and
    its FFT axes :data:`MAX_FFT_AXIS`)."""
    kh, kw = k.shape[:2]
    if method == "direct":
        return (out_window.width + kw + 3) * (out_window.height + kh - 1) <= MAX_BLOCK_CELLS
    if method == "half":
        hs = Rect(0, 0, -(-support.width // 2), -(-support.height // 2))
        k2 = _as_psf(half_psf(rt, k, psf_key)).shape[:2]
        hout = half_window(support, effective)
        n1, n2 = fft_grid(hs, hout.intersect(full_region(hs, *k2)), *k2)
    else:
        n1, n2 = fft_grid(support, effective, kh, kw)
    return n1 * n2 <= MAX_BLOCK_CELLS and max(n1, n2) <= MAX_FFT_AXIS


def _block_rects(out_window: Rect, anchor: tuple[int, int], b1: int, b2: int) -> list[Rect]:
    """``out_window`` cut into blocks of b1 rows x b2 columns on a grid through ``anchor``."""
    ax, ay = anchor
    x_first = ax + math.floor((out_window.x0 - ax) / b2) * b2
    y_first = ay + math.floor((out_window.y0 - ay) / b1) * b1
    return [Rect(x, y, x + b2, y + b1).intersect(out_window)
            for y in range(y_first, out_window.y1, b1)
            for x in range(x_first, out_window.x1, b2)]


def convolve_blocks(rt, img, psf, *, out_window: Rect, support: Rect | None = None,
                    method: str = "fft", precision: str = "float64",
                    threshold_split: float | None = None, split_max_points: int = 256,
                    info: ConvolveInfo | None = None, emit=None, psf_key=None):
    """:func:`convolve` in output blocks, so its device memory is bounded by the block
    (:data:`MAX_BLOCK_CELLS`), not by the frame.

    Each output block gets the exact linear convolution of the input pixels that reach it
    (:func:`reach`; overlap-save): one FFT grid, plan and PSF spectrum serve every block of
    the call.  A convolution whose one-grid work fits the cap is one block, exactly
    :func:`convolve`.  ``"direct"`` blocks give :func:`convolve`'s bits (each output pixel
    sums the same taps in the same order); FFT blocks differ from one large FFT by FFT
    rounding only.  ``"half"`` blocks are cut at even offsets from the support, so their
    half-resolution pixels are the whole grid's.  The split's bright pixels are counted over
    the whole support first, so the float64 fallback is decided once for all blocks.

    Parameters
    ----------
    img : DeviceImage or callable
        The input, or ``load(rect) -> DeviceImage`` giving it (RGBA) over at least ``rect``
        (then ``support`` is required): only a block's input is ever on the device.
    emit : callable, optional
        ``emit(rect, g)`` receives each block's result (``rect``: blocks cover
        ``out_window`` once, in row order; a block no light reaches gets zeros); default:
        assembled into one image, returned.
    psf_key : hashable, optional
        A name of ``psf``'s values kept by the caller (equal keys, equal PSFs: the key its
        PSF is cached under): its bytes are hashed for its spectra's cache key once per key
        (:func:`psf_id`), not on each call (3 ms a frame for 1080p glare's PSF).
    Others : as :func:`convolve`.

    Returns
    -------
    DeviceImage or None
        The result over ``out_window`` (None when ``emit`` took the blocks).
    """
    k, precision, info = _checked(rt, psf, method, precision, info)
    if callable(img):
        if support is None:
            raise ValueError("convolve_blocks: a loaded input needs its support")
        load, channels = img, 4
    else:
        support = img.window if support is None else support.intersect(img.window)
        load, channels = (lambda rect: img), img.channels
    kept = _Assembled(rt, out_window, channels) if emit is None else None
    emit = emit or kept
    kh, kw = k.shape[:2]
    effective = out_window.intersect(full_region(support, kh, kw))
    if support.empty or effective.empty:
        emit(out_window, rt.fill(rt.image(out_window, channels), 0.0))
        return kept and kept.image
    if _one_grid_fits(rt, method, k, support, effective, out_window, psf_key):
        info.blocks = 1
        emit(out_window, _convolve(rt, load(support), k, support, out_window, method,
                                   precision, threshold_split, split_max_points, info,
                                   psf_key=psf_key))
        return kept and kept.image
    _blocked(rt, load, k, support, effective, out_window, method, precision, threshold_split,
             split_max_points, info, emit, channels, psf_key)
    return kept and kept.image


class _Assembled:
    """The default ``emit`` of :func:`convolve_blocks`: blocks pasted into one image (a single
    block is the image)."""

    def __init__(self, rt, window: Rect, channels: int):
        self.rt, self.window, self.channels, self.image = rt, window, channels, None

    def __call__(self, rect: Rect, g) -> None:
        if rect == self.window:
            self.image = g
            return
        if self.image is None:
            self.image = self.rt.image(self.window, self.channels)
        self.rt.paste(g, self.image, rect)


def _blocked(rt, load, k, support, effective, out_window, method, precision, split,
             max_points, info, emit, channels, psf_key=None):
    """The blocks of :func:`convolve_blocks` (the one-grid work is over the cap)."""
    kh, kw = k.shape[:2]
    anchor = (effective.x0, effective.y0)
    if method == "half":
        k2 = _as_psf(half_psf(rt, k, psf_key))
        hh, hw = k2.shape[:2]
        half_all = Rect(0, 0, -(-support.width // 2), -(-support.height // 2))
        b1, b2 = block_shape(-(-effective.height // 2) + 2, -(-effective.width // 2) + 2,
                             hh + 2, hw + 2)
        b1, b2 = 2 * b1, 2 * b2
        # blocks start at even offsets from the support: a block's half-resolution pixels
        # are the whole grid's
        anchor = (effective.x0 - (effective.x0 - support.x0) % 2,
                  effective.y0 - (effective.y0 - support.y0) % 2)
    else:
        b1, b2 = block_shape(effective.height, effective.width, kh, kw)
    blocks = []
    for rect in _block_rects(out_window, anchor, b1, b2):
        eff = rect.intersect(effective)
        if eff.empty:
            blocks.append((rect, None, None, None))
        elif method == "half":
            hout = half_window(support, eff)
            hi = reach(hout, hh, hw).intersect(half_all)
            need = fft_grid(hi, hout.intersect(full_region(hi, hh, hw)), hh, hw)
            full = Rect(support.x0 + 2 * hi.x0, support.y0 + 2 * hi.y0,
                        support.x0 + 2 * hi.x1, support.y0 + 2 * hi.y1).intersect(support)
            blocks.append((rect, full, hi, need))
        else:
            src = reach(rect, kh, kw).intersect(support)
            blocks.append((rect, src, None, fft_grid(src, eff, kh, kw)))
    live = [b for b in blocks if b[1] is not None]
    info.blocks = len(live)
    grid = (max(b[3][0] for b in live), max(b[3][1] for b in live))
    spectrum = None
    if method == "fft" and split is not None and precision == "float32":
        bright = sum(_count_bright(rt, load(t), t, split)
                     for t in _block_rects(support, (support.x0, support.y0), b1, b2))
        if bright > max_points:
            precision, split = _too_many_bright(rt, info, split, max_points)
        info.bright_pixels, max_points = bright, bright
    info.precision = precision
    if method == "fft":
        spectrum = psf_spectrum(rt, k, *grid, precision, psf_key)   # held for every block
    elif method == "half":
        spectrum = psf_spectrum(rt, k2, *grid, "float32", _half_key(psf_key, k))
    sub = ConvolveInfo()
    for rect, src, hi, _ in blocks:
        if src is None:   # no light reaches this block
            emit(rect, rt.fill(rt.image(rect, channels), 0.0))
            continue
        part_support = support if method == "half" else src
        emit(rect, _convolve(rt, load(src), k, part_support, rect, method, precision, split,
                             max_points, sub, grid if method != "direct" else None, spectrum,
                             hi, psf_key))
    info.grid = grid
    info.notes.append(f"{info.blocks} blocks of {b2}x{b1} px (FFT grid {grid[1]}x{grid[0]})"
                      if method != "direct" else f"{info.blocks} blocks of {b2}x{b1} px")


def _count_bright(rt, img, rect: Rect, split: float) -> int:
    return int(_bright_rows(rt, img, rect, split)[0].sum()) if not rect.empty else 0


# -- quality levels ------------------------------------------------------------------------
PREVIEW_SPLIT_MAX_POINTS = 64
"""preview: most bright pixels gathered exactly before falling back to float64."""
DIRECT_MAX_TAPS = 441
"""PSFs with at most this many taps (21 x 21) are convolved directly at every level."""


@dataclass(frozen=True)
class SpreadLevel(Level):
    """How :func:`spread` convolves at one quality level.

    ``method`` (PSFs above :data:`DIRECT_MAX_TAPS` taps): ``"half"`` one pyramid level
    (float32, approximate), ``"split"`` float32 FFT with the bright pixels gathered exactly
    (float64 past :data:`PREVIEW_SPLIT_MAX_POINTS` of them), ``"fft"`` an FFT in float64 when
    ``fp64`` else float32.  ``direct_max_work``: a direct gather (float64 with ``fp64``)
    replaces the FFT when output pixels x PSF taps is at most this.  ``small_fp64``: float64
    sums for the PSFs of at most 21 x 21 taps, which are always gathered directly.
    """

    method: str = "fft"
    direct_max_work: float = 0.0
    small_fp64: bool = False


LEVELS = {
    "draft": SpreadLevel(
        "one pyramid level: 2x2-summed highlights, tent-resampled PSF, float32 FFT at half "
        "resolution, bilinear upsampling (light moves <= 0.5 px, core blurred ~1 px; "
        "PSFs <= 21x21 taps: direct float32)", method="half"),
    "preview": SpreadLevel(
        "float32 r2c FFT with the HDR split: pixels above max(4 x threshold, 1e-3 x peak) "
        "(at most 64) are gathered exactly, the rest transformed; more than 64 falls "
        "back to float64 (PSFs <= 21x21 taps: direct float32)", method="split"),
    "final": SpreadLevel(
        "float64 r2c FFT (1.0-1.3x the cost of float32 on PoCL, no float32 error floor; "
        "PSFs <= 21x21 taps: direct float32)", fp64=True),
    "reference": SpreadLevel(
        "float64: direct gather with float64 accumulation when output px x taps <= 4e7, "
        "else float64 r2c FFT", fp64=True, direct_max_work=4e7, small_fp64=True),
}
"""What each quality level of :func:`spread` does (glare's and soft focus's levels)."""


def spread_level(cls: type, quality: str, summary: str, **settings) -> SpreadLevel:
    """A ``cls`` level (a :class:`SpreadLevel` subclass) with :data:`LEVELS`' convolution
    settings for ``quality``, its own ``summary`` and extra ``settings``."""
    base = {f.name: getattr(LEVELS[quality], f.name) for f in fields(SpreadLevel)}
    return cls(**{**base, "summary": summary, **settings})


def _fp(wanted: bool) -> str:
    return "float64" if wanted else "float32"


def spread(rt, img, psf, level: SpreadLevel, *, out_window: Rect, support: Rect | None = None,
           split_level: float | None = None, info: ConvolveInfo | None = None, emit=None,
           psf_key=None):
    """Convolve with the algorithm a quality ``level`` (:data:`LEVELS`) calls for.

    PSFs of at most 21 x 21 taps: direct gather (float32; float64 with ``small_fp64``).
    Larger: ``method`` "half" (half-resolution float32 FFT; approximate), "split" (float32
    FFT with bright pixels, largest channel > ``split_level``, gathered exactly; falls back to
    float64 when there are more than 64), "fft" (float64 with ``fp64``), or a direct gather
    when output px x taps <= ``direct_max_work``.  In output blocks past
    :data:`MAX_BLOCK_CELLS` (:func:`convolve_blocks`: ``img`` may be a loader, ``emit`` take
    the blocks, ``psf_key`` name the PSF's values: :func:`psf_id`).
    """
    k = _as_psf(psf)
    window = support if support is not None else getattr(img, "window", None)
    if window is not None:
        k = reachable(k, window, out_window)
    taps = k.shape[0] * k.shape[1]
    common = dict(out_window=out_window, support=support, info=info, emit=emit,
                  psf_key=psf_key)
    if taps <= DIRECT_MAX_TAPS:
        # small kernels: a direct gather beats any transform
        return convolve_blocks(rt, img, k, method="direct", precision=_fp(level.small_fp64),
                               **common)
    if level.method == "half":
        return convolve_blocks(rt, img, k, method="half", precision="float32", **common)
    if level.method == "split":
        # the exact gather costs (output px x bright px): beyond 64 bright pixels the
        # float64 FFT (1.0-1.3x float32 on PoCL) is cheaper
        return convolve_blocks(rt, img, k, precision="float32", threshold_split=split_level,
                               split_max_points=PREVIEW_SPLIT_MAX_POINTS, **common)
    if out_window.width * out_window.height * taps <= level.direct_max_work:
        return convolve_blocks(rt, img, k, method="direct", precision=_fp(level.fp64),
                               **common)
    return convolve_blocks(rt, img, k, precision=_fp(level.fp64), **common)
