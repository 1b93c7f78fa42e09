"""Streaks: star-filter streaks and the diffraction spikes of a bladed aperture.

Model
-----
A streak comes from the light above its level: ``rgb * max(lum - t, 0) / lum`` with ``t``
the larger of ``threshold`` and ``core`` times the peak luminance of the light the pixel
belongs to (the connected region of 32 px scene-analysis tiles brighter than ``threshold``).
So a candle streaks from its bright core, not from its glow or the wax it lights (``core =
0``: everything above ``threshold`` streaks). With a core rule, light in no light's tile
(light an earlier step of the look drew: the analysis is the frame's) does not streak:
star-filter's spikes fanned its star's rays out into wedges. ``source_color`` mixes the
streaking light towards its luminance (0: the streak's colour is the tint alone, as the
coatings of an anamorphic lens colour its streaks whatever the light). Each compact light's
streaking light is then gathered into one point: a pixel whose luminance is the highest
within ``SEED_RADIUS`` (1.2 % of the diagonal, ties to the earlier pixel) and whose window's
border holds no streaking light takes the streaking light of that window to its
luminance-weighted centroid (bilinear splat, sub-pixel). A star filter's or a blade's streak
is a diffraction line a pixel or two wide (the filter's grating or the edge spreads each
point of the image into a line as thin as the lens resolves); spreading every pixel of a
small light drew a band as wide as the flame, which the eye reads as a thick smeared bar.
Two peaks closer than the radius streak as one. An extended light (streaking light on its
window's border: a window pane, the sky) streaks pixel by pixel, a band as wide as it is:
gathered into points it gave a hatch of parallel lines from its noise's local maxima.
These points and pixels are spread along ``n`` directions by a one-sided exponential line
kernel per direction,

    K_d(x) = sum_{k=0}^{S - 1} a_c^k  delta(x - k d),   a_c = 0.01^(1 / L_c),

so a streak has faded to 1% of its start after ``L_c`` pixels (``length`` times the frame
diagonal; ``color_shift`` makes red travel further than blue, or the reverse, so a streak
changes colour along its length as a diffraction streak does).  The support ``S`` reaches
:data:`TAIL` (2.5) x ``L``, where the exponential is 1e-5 of its start: a streak fades
smoothly into the dark and its end is below 1e-4 of its brightest pixel (no blunt end,
whatever the light's brightness).  Each direction's kernel is normalised to sum to
``intensity * tint_c / n``, so the added light equals ``intensity`` times the highlights'
energy.  Output = sanitised source + streaks; alpha is kept.

Star filter (``mode="star"``): ``streaks`` directions at ``angle + 360 i / streaks`` degrees,
counter-clockwise from +x (screen up is -y).  A scratched filter gives a streak
perpendicular to each scratch; ``streaks`` counts the rays, not the scratches.

Anamorphic streaks (``mode="anamorphic"``): two rays, at ``angle`` and opposite (0:
horizontal). A streak is the light reflected between the coated faces of the anamorphic
cylinder: two reflections off its anti-reflection coating (``coating``, a stack of
:data:`clfx.fx.optics.MULTILAYER_DESIGNS` on crown glass 1.52, by the transfer-matrix
method) designed at ``coating_nm``; its colour is that reflectance squared over the visible
spectrum (CIE 1931, Rec.709), normalised to luminance 1 and multiplied by ``tint``. A V-coat
(MgF2 / Al2O3 quarter-quarter) tuned in the deep red, 740 nm, reflects almost nothing there
and more and more towards the blue: blue-cyan, hue 213 degrees (RGB 0.00, 1.14, 2.54). A
single MgF2 layer cannot be that colour: its residual rises in the red as well as the blue,
hue 225-258 degrees, lavender-violet over a warm scene. Each pixel's light is weighted by
``(L / peak)^core_power`` (``core_power`` -1: 3), so a light's brightest rows carry it (the
streak is a line from its point, as every mode's); and it falls off with distance: 70 % of
its light in a bright part fading to 1 % at ``0.15 length``, 30 % in a long faint part
fading to 1 % at ``length`` (a sum of two exponentials, each run as its own Kawase chain).

Diffraction spikes (``mode="aperture"``): the far field of a straight blade edge is a line
perpendicular to it (the Fourier transform of a half plane), so an N-blade polygon aperture
(vertices at ``blade_rotation + 360 i / N``) makes spikes along its edge normals,
``blade_rotation + 180 (2i + 1) / N`` and their opposites: N spikes for even N (opposite
edges are parallel), 2N for odd N (Ritschel et al. 2009).  ``blades = 0`` takes the camera
block's blades and rotation; a round aperture has no spikes: the step does nothing and says
so on stderr (``ctx.warnings``).  A spike is shaped as diffraction makes it: its brightness
falls as the inverse square of the distance (three exponentials, ``APERTURE_PARTS``: a
bright root tapering into a long faint tip, 1 % of the root at ``length``) and each channel
reaches as far as its wavelength (``SPIKE_WAVELENGTHS_NM``: the tips turn red).  Its width
is the light's: a light's core (``core``) streaks, so a small bright sun gives thin spikes.

Algorithm (Kawase 2003, "Frame buffer postprocessing effects in DOUBLE-S.T.E.A.L")
-----------------------------------------------------------------------------------
Per direction, N passes with ``T 4^(N-1) >= TAIL L' + 1`` (smallest N, then smallest T <= 4
taps in the last pass); pass n has 4 taps at offsets ``s * 4^n * d`` (s = 0..3) with weights
``a_c^(s 4^n)`` (0 for s >= T in the last pass), where the step ``d`` is one whole pixel along the
ray's major axis (|d| = 1 / max(|cos|, |sin|) px, L' = L / |d| steps), so taps fall on
pixel columns (rows) and interpolate linearly between two pixels.  Every k in [0, S) has
exactly one base-4 expansion, so the passes compose to exactly the truncated exponential
above: 4N taps per pixel instead of S.  Interpolated taps blur each pass by a sub-pixel
amount across the streak (not at all for rays at multiples of 45 degrees); the oracle
(``tests/reference/streaks.py``) computes exactly this composition in float64, and
``line_kernel_streaks`` there the exponential line kernel at the same tap positions (one
interpolated tap per step k).

Error against that exact line kernel, measured (float64, one ray, L = 60 px, 1e4 point):
identical energy; identical kernels at multiples of 45 degrees; at 30 degrees a relative L1
difference of 0.25 and an rms width across the ray of 0.47 px against 0.35 px: the Kawase
streak is a fraction of a pixel wider, never longer or brighter. At 1080p (one 30-degree
ray, L = 100 px, 12 lights), max error / peak against the exact line kernel: reference
3.7e-2, final 4.7e-2 (measured before the support reached 2.5 L). Truncation at S > 2.5 L'
drops 1e-5 of the infinite exponential's energy (the kernel is renormalised).

Quality levels: final and reference run the passes at full resolution.  Draft and preview
run each ray on a grid reduced 8 (draft) or 4 (preview) times along the ray's major axis
only, full resolution across it (`ray_grid`): a ray is a line a pixel or two wide, and
passes at 1/4 or 1/2 resolution in both axes drew it 4-8 px wide at a fraction of its
amplitude, further from the reference in log-PSNR than no ray at all (bench, 960 x 540:
draft 26.0, preview 27.2 dB, the unchanged input 29.8).  A working pixel stands for the run
of ``factor`` pixels along the ray's line through its centre, a whole pixel (each pixel of
the run taken from the nearest pixel across the line); a light's point splats bilinearly
along the line onto the two working columns around it and across in each; both are moved
half a working pixel towards the streak (`RayGrid.lead`: a working pixel then stands for the
run of the one-sided streak it is the middle of, not half of it behind the light).  A step
is one working pixel along the axis, its part across interpolated linearly at full
resolution, as final's; the rays of one line (a ray and its opposite) sum on their grid,
which is upsampled along the line (linear between the two working columns around a pixel,
linear across in each) into a full-resolution streak sum.  The passes cost 1 / factor of
final's (not 1 / factor^2), plus one full-resolution upsample per line; the streaking light
of the pixels no seed gathered is computed once a frame (``streaks_extended``), each ray's
grid gathers it.  The oracle computes these grids in float64 (``factor``).  Measured
(``clfx bench --effects streaks``, log-PSNR against the reference level): 320 x 180 draft
35.7, preview 41.7 dB, input 18.9; 960 x 540 62.5, 67.8, input 29.8; 1920 x 1080 70.3,
77.8, input 35.7 (factors 4 and 2: 41.7, 46.0; 67.8, 68.9; 77.8, 79.7, but preview's passes
then cost nearly final's time on PoCL: CPU time at 960 x 540, one PoCL thread, 128-147 ms
against final's 138-157 and 100-108 at factor 4).  Along a thin ray the width (1.1-2.4 px
FWHM) and the straightness (0.06-0.11 px) of final's.  Every tap is interpolated (taps
rounded to whole pixels in long passes made a thin ray wander by half a pixel per pass, a
staircase along it).

Memory and tiles (issue 26)
---------------------------
The frame-wide part (seeds, bright pixels, every ray's passes, their full-resolution sum) is
computed once per frame in the step's plan; the render, whole or one band of a tiled
render, adds its rows of that sum to its rows of the source (a band's region of interest is
itself).  At final and reference a frame over ``STREAM_PIXELS`` streams through the passes
in chunks of rows: a ray sweeps the frame against its taps' direction (a pass reads rows at
``y + s 4^n sy``, all on one side), each pass's input held as a ring of the chunk and the
rows the later passes still read (about the support, ``TAIL L``, in all), and the sum waits
on the host, composed in pieces.  The whole passes needed three frame-sized buffers: at 8K
UHD (cinema, 4 rays of 440 px) 1519 MiB against 352 MiB of rings and a chunk.  Every pixel
takes the same floats either way: a tap past a ring's rows has weight 0 (the last pass's
unused taps) and reads a finite non-negative value, as every held value is.  Draft and
preview do not stream: their rays' working buffers are reduced 8 or 4 times along one axis
(three of them, the largest grid's), and the frame holds the once-a-frame extended light
(source-sized) and the full-resolution sum on the device; at 8K UHD (7680 x 4320, RGBA
float32) that is 506 MiB each for the sum and the extended light plus three working
buffers of about 64 (draft) or 127 MiB (preview) and their zero margins: 1.2-1.4 GiB, against
final's 352 MiB (computed from the sizes, not measured).

Where the passes run (issue 37)
-------------------------------
At final and reference a frame that does not stream runs each ray's passes only over the
row spans within its reach of the bright pixels: the seeds kernel marks the 8 px blocks of
the source with streaking light (with a core rule it runs over a light's tiles alone), the
host draws the seeds' windows (``streaks_dilate`` only past ``SEEDS_READ`` lights) and
rasterises, row by row, the bright boxes (lit blocks no seed wholly gathered, and each
seed's 2 x 2 splat) swept against the ray over what each pass's light can reach (pass n:
4^(n+1) - 1 steps) and grown by the bilinear spread so far (`pass_spans`); the bright, pass
and clear kernels take those spans in row order (tiles one by one cost 2-3 times as much per
pixel on PoCL). What the passes read outside them is cleared first, so stale buffers from
the pool change nothing: the same bits as whole rows (the streamed path,
`tests/plugins/test_streaks.py`).  1080p demo frame, cinema's streaks alone (4 rays of 275
px from 25 lights): kernels 405-431 -> 63 ms of CPU per frame (prof2), the passes 249 -> 17
ms; in the cinema look the streaks step 352 -> 68 ms.
References: M. Kawase, GDC 2003; T. Ritschel et al., "Temporal glare", Eurographics 2009.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from types import MappingProxyType
from typing import Mapping

import numpy as np

from clfx.core.camera import BLADES_WHY, NO_POLYGON
from clfx.core.plugin import ChoiceParam, Descriptor, FloatParam, IntParam, Level, RGBParam
from clfx.core.rect import Rect
from clfx.fx import optics, spectral
from clfx.host import Plugin, StepPlan, read_only, register

TAPS = 4
"""Taps per pass; pass n steps 4^n pixels, so N passes cover 4^N - 1 pixels."""

TAIL = math.log(1e5) / math.log(100.0)
"""Support of the exponential in units of its 1 % length: there it is 1e-5 of its start."""

ANAMORPHIC_PARTS = ((0.15, 0.7), (1.0, 0.3))
"""mode anamorphic: (1 % length as a fraction of ``length``, share of the light) of the bright
near part and the long faint part."""

APERTURE_PARTS = ((0.08, 0.068), (0.3, 0.246), (1.0, 0.686))
"""mode aperture: three exponentials (1 % lengths as fractions of ``length`` L, shares of the
light) whose sum follows a diffraction spike's ``1 / (1 + 9 r / L)^2`` (the far field of a
straight blade edge falls as the inverse square of the distance) within 12 % out to 0.5 L
(a least-squares fit), then falls faster than the power law (0.3 % of its root at L where
the law has 1 %; an exponential tail, below 1e-5 at 2.5 L): a bright root that tapers into
a long faint tip instead of a bar of even brightness."""

SPIKE_WAVELENGTHS_NM = (610.0, 550.0, 465.0)
"""mode aperture: each channel's spike is as long as its wavelength (the diffraction angle
of an edge scales with lambda): red 1.11 x and blue 0.85 x green's length, so a spike's tip
turns red and its root stays white, as real starbursts do."""

ANAMORPHIC_CORE_POWER = 3.0
"""mode anamorphic, core_power -1: the exponent of (L / peak) weighting each pixel's light."""

GLASS_INDEX = 1.52
"""The anamorphic coating model: a stack of ``MULTILAYER_DESIGNS`` on crown glass."""


@dataclass(frozen=True)
class StreaksLevel(Level):
    """A streaks quality level: the passes run at 1 / ``factor`` resolution along each
    ray's major axis, full resolution across it (`ray_grid`), every tap interpolated
    (whole-pixel taps made a thin ray wander by half a pixel per long pass: a staircase);
    ``fp64``: float64 tap sums."""

    factor: int = 1


LEVELS = {
    "draft": StreaksLevel("Kawase passes at 1/8 resolution along each ray, full resolution "
                          "across it (a ray stays a pixel thin), upsampled along the rays, "
                          "float32", factor=8),
    "preview": StreaksLevel("Kawase passes at 1/4 resolution along each ray, full resolution "
                            "across it, float32", factor=4),
    "final": StreaksLevel("Kawase passes at full resolution, float32"),
    "reference": StreaksLevel("Kawase passes at full resolution, float64 tap sums (exactly "
                              "the oracle's composed kernel)", fp64=True),
}

SEED_RADIUS = 0.012
"""A compact light's peak gathers the streaking light within this fraction of the frame
diagonal (a Chebyshev radius: 9 px at 640 x 360, 26 px at 1080p; a candle flame's core fits)
into one point, the light's centroid; of two peaks closer than this only the brighter
streaks.  A light with streaking light on that window's border (``RING_SHARE``) is
extended: it streaks pixel by pixel."""

RING_SHARE = 0.1
"""Streaking light (luminance) on the window's border above this share of the peak's own
makes a light extended."""

MAX_SEEDS = 1 << 16
"""Most lights (seed points) one frame streaks from."""

BIN = 16
"""Working pixels per side of the blocks the seed points are listed by."""

BLOCK = 8
"""Side (px) of the blocks of the source the seeds mark with streaking light (issue 37):
what final's and reference's whole passes are planned from (`pass_spans`)."""

SPAN = 32
"""Most pixels of a row span one work-group takes (`row_spans`: 8 work-items of a pass).
Spans in row order cost what whole rows did per pixel; tiles taken one by one cost 2-3 times
as much on PoCL (measured, a pass at 1080p: 13 ms of CPU whole, 13-17 in spans of 16-256
px, 26-54 in tiles of 32 or 64 px)."""


def block_boxes(mask: np.ndarray, block: int = BLOCK) -> np.ndarray:
    """Inclusive pixel boxes (x0, y0, x1, y1) covering the blocks set in ``mask``: one per
    run of set blocks along a row of blocks."""
    edges = np.diff(np.pad(mask, ((0, 0), (1, 1))).astype(np.int8), axis=1)
    rows, first = np.nonzero(edges == 1)
    _, end = np.nonzero(edges == -1)
    return np.stack([first * block, rows * block, end * block - 1, rows * block + block - 1],
                    axis=1).astype(np.float64)


def raster(width: int, height: int, boxes: np.ndarray, u=(0.0, 0.0), t=(0.0, 0.0),
           job: np.ndarray | None = None) -> np.ndarray:
    """int64 (n, 3) row intervals (y, q0, q1) of the 4-pixel runs (a pass work-item's)
    q0 <= q < q1 of row y holding a pixel of some box (n x 4: x0, y0, x1, y1, inclusive real
    bounds) moved by t u for a real t in [t0, t1], within ``width`` x ``height``: row by row,
    the box's rows at the t that bring them there, so a box swept along a diagonal ray is a
    diagonal band, not its bounding box.  Unsorted; intervals may overlap (`merged`).

    ``u`` and ``t`` = (t0, t1): one pair for every box, or one per box ((n, 2) arrays);
    ``job``: an int per box, whose rows are numbered ``y + job * height`` (`job_spans`:
    many rasters in one pass of array operations)."""
    b = np.asarray(boxes, np.float64).reshape(-1, 4)
    u = np.broadcast_to(np.asarray(u, np.float64), (len(b), 2))
    t = np.broadcast_to(np.asarray(t, np.float64), (len(b), 2))
    ux, uy, t0, t1 = u[:, 0], u[:, 1], t[:, 0], t[:, 1]
    lo, hi = np.minimum(t0 * uy, t1 * uy), np.maximum(t0 * uy, t1 * uy)
    r0 = np.clip(np.ceil(b[:, 1] + lo), 0, height).astype(np.int64)
    r1 = np.clip(np.floor(b[:, 3] + hi) + 1, 0, height).astype(np.int64)
    count = np.maximum(r1 - r0, 0)
    box = np.repeat(np.arange(len(b)), count)
    y = r0[box] + np.arange(len(box)) - np.repeat(np.cumsum(count) - count, count)
    b, ux, uy, ta, tb = b[box], ux[box], uy[box], t0[box], t1[box]
    moves = uy != 0.0
    if moves.any():   # the t that bring a row of the box to row y
        with np.errstate(divide="ignore", invalid="ignore"):
            top, bottom = (y - b[:, 3]) / uy, (y - b[:, 1]) / uy
        up = uy < 0.0
        top, bottom = np.where(up, bottom, top), np.where(up, top, bottom)
        ta = np.where(moves, np.maximum(ta, top), ta)
        tb = np.where(moves, np.minimum(tb, bottom), tb)
    c0 = np.ceil(b[:, 0] + np.minimum(ta * ux, tb * ux))
    c1 = np.floor(b[:, 2] + np.maximum(ta * ux, tb * ux))
    keep = (ta <= tb) & (c0 <= c1) & (c1 >= 0) & (c0 < width)
    c0 = np.clip(c0[keep], 0, width - 1).astype(np.int64)
    c1 = np.clip(c1[keep], 0, width - 1).astype(np.int64)
    y = y[keep] if job is None else y[keep] + height * np.asarray(job, np.int64)[box][keep]
    return np.stack([y, c0 // 4, c1 // 4 + 1], axis=1)


def merged(intervals: np.ndarray) -> np.ndarray:
    """Row intervals (y, q0, q1) (`raster`), overlapping or touching ones joined, in row
    order."""
    if not len(intervals):
        return intervals.reshape(0, 3)
    row = int(intervals[:, 2].max()) + 1
    g0, g1 = (intervals[:, 0] * row + intervals[:, k] for k in (1, 2))
    order = np.argsort(g0, kind="stable")
    g0, g1 = g0[order], g1[order]
    reach = np.maximum.accumulate(g1)
    first = np.ones(len(g0), bool)
    first[1:] = g0[1:] > reach[:-1]       # not within the runs before: a new run starts
    starts = g0[first]
    ends = np.maximum.reduceat(g1, np.flatnonzero(first))
    return np.stack([starts // row, starts % row, ends - starts // row * row], axis=1)


def row_spans(intervals: np.ndarray, width: int, span: int = SPAN) -> np.ndarray:
    """int32 (n, 4) row spans (x0, y, x1, 0) of row intervals (`raster`) within ``width``,
    at most ``span`` px each, in row order: the ``spans`` of the TILED kernels."""
    iv = merged(intervals)
    x0, x1 = iv[:, 1] * 4, np.minimum(iv[:, 2] * 4, width)
    pieces = -(-(x1 - x0) // span)
    run = np.repeat(np.arange(len(x0)), pieces)
    k = np.arange(len(run)) - np.repeat(np.cumsum(pieces) - pieces, pieces)
    px0 = x0[run] + k * span
    out = np.stack([px0, iv[run, 0], np.minimum(px0 + span, x1[run]), np.zeros_like(px0)],
                   axis=1)
    return np.ascontiguousarray(out, np.int32)


def job_spans(width: int, height: int, parts: list, jobs: int) -> list[np.ndarray]:
    """The row spans (`row_spans`) of each of ``jobs`` sets of swept boxes, from ``parts`` =
    [(job, boxes, u, t), ...] (`raster`'s arguments; a job's parts are joined): every part
    rastered, merged and cut at once (one call per part took ~0.2 ms of NumPy calls on a
    handful of boxes: final's plan of the cinema look's 4 rays made 49, ~9 ms a frame
    while the device waited)."""
    counts = [len(np.reshape(b, (-1, 4))) for _, b, _, _ in parts]
    boxes = np.concatenate([np.reshape(b, (-1, 4)) for _, b, _, _ in parts])
    u, t = (np.repeat(np.array([part[k] for part in parts], np.float64).reshape(-1, 2),
                      counts, axis=0) for k in (2, 3))
    job = np.repeat([part[0] for part in parts], counts)
    spans = row_spans(raster(width, height, boxes, u, t, job), width)
    which = spans[:, 1] // height                     # row order: the jobs in turn
    spans[:, 1] -= which * height
    return np.split(spans, np.searchsorted(which, np.arange(1, jobs)))


def light_boxes(lights: np.ndarray, analysis_tile: int, width: int,
                height: int) -> np.ndarray:
    """Inclusive pixel boxes of the analysis tiles set in ``lights`` in a ``width`` x
    ``height`` source (the last tile across and down also holds the pixels past the map:
    `streaks_peak` clamps)."""
    j, i = np.nonzero(lights)
    a, (ty, tx) = analysis_tile, lights.shape
    return np.stack([i * a, j * a, np.where(i == tx - 1, width, i * a + a) - 1,
                     np.where(j == ty - 1, height, j * a + a) - 1], axis=1).astype(np.float64)


def gathered_flags(rows: np.ndarray, width: int, height: int, radius: int) -> np.ndarray:
    """uint8 (``height``, ``width``) flags of the pixels within ``radius`` px (Chebyshev) of
    a seed (rows' peak x, y): the seeds' windows, what the kernel ``streaks_dilate`` grows
    the seeds' own flags into."""
    out = np.zeros((height, width), np.uint8)
    for x, y in rows[:, :2].astype(np.int64):
        out[max(y - radius, 0):y + radius + 1, max(x - radius, 0):x + radius + 1] = 1
    return out


def ray_spread(ray: Ray) -> list[tuple[int, int]]:
    """Per pass, the pixels (x, y) a ray's passes up to it spread its light across its line:
    one per pass whose float32 taps (the kernel's ``s * step``) fall between pixels along
    that axis (each tap reads the pixel past them as well); 0 for rays along the axes and the
    diagonals."""
    out, sx, sy = [], 0, 0
    for n in range(ray.passes):
        for axis, step in enumerate((ray.sx, ray.sy)):
            taps = np.float32(step * TAPS ** n) * np.arange(1, TAPS, dtype=np.float32)
            spreads = bool(np.any(taps != np.floor(taps)))
            sx, sy = (sx + spreads, sy) if axis == 0 else (sx, sy + spreads)
        out.append((sx, sy))
    return out


def pass_spans(lit: np.ndarray, gathered: np.ndarray | None, points: np.ndarray, ox: int,
               oy: int, size: tuple[int, int], wp: int, h: int, rays) -> tuple:
    """Where final's and reference's whole passes run (`Streaks.streak_sum`), as row
    spans (`row_spans`) of the ``wp`` x ``h`` working frame (the output window; the
    source's ``size`` = (width, height) at (ox, oy) in it).

    ``bright``: where the bright pixels can be: the source's ``lit`` ``BLOCK`` px blocks
    (with streaking light) but those wholly inside the seeds' windows (``gathered``, the
    source's flags where the host drew them, else None: every lit block), and the two
    pixels each way of each seed's bilinear splat (``points``: x, y working pixels).
    ``clear``: what the rays' first passes read of the bright pixels (the union of the
    rays' ``read``).  Per ray, (``work``, ``read``): ``work`` where its streak can be, the
    bright boxes swept against the ray over its support, grown by its spread (`ray_spread`)
    and half a pixel (the float32 steps); its passes write all of it.  ``read``: all its
    passes read, each pixel of ``work`` (up to 3 px past that band across: the runs of 4)
    moved up to the last pass's farthest tap ahead (``(TAPS - 1) 4^(N - 1)`` steps, its taps
    of weight 0 too) and by a bilinear pixel: zero where it is not ``work``."""
    w, hs = size
    if gathered is not None and lit.any():   # no bright pixel in a block a seed gathered
        j, i = np.nonzero(lit)
        ys = np.minimum(j[:, None] * BLOCK + np.arange(BLOCK), hs - 1)
        xs = np.minimum(i[:, None] * BLOCK + np.arange(BLOCK), w - 1)
        lit = lit.copy()
        lit[j, i] = ~(gathered[ys[:, :, None], xs[:, None, :]] != 0).all(axis=(1, 2))
    boxes = block_boxes(lit)
    boxes[:, 2:] = np.minimum(boxes[:, 2:], [w - 1, hs - 1])
    boxes += [ox, oy, ox, oy]
    at = np.floor(np.asarray(points, np.float64)[:, :2])
    boxes = np.concatenate([boxes, np.concatenate([at, at + 1.0], axis=1)])
    # one `job_spans` per ray (its passes, then its read: arrays small enough to stay in
    # cache), and one for the bright pixels and the rays' first reads
    firsts, out = [(0, boxes, (0.0, 0.0), (0.0, 0.0))], []
    for ray in rays:
        u, spread, parts = (-ray.sx, -ray.sy), ray_spread(ray), []
        for n in range(ray.passes):    # pass n: the light moved up to 4^(n+1) - 1 steps
            support = (ray.top if n == ray.passes - 1 else TAPS) * TAPS ** n
            mx, my = (m + 0.5 for m in spread[n])
            parts.append((n, boxes + [-mx, -my, mx, my], u, (0.0, support - 1.0)))
        ahead = (TAPS - 1) * TAPS ** (ray.passes - 1)
        mx, my = spread[-1][0] + 4.5, spread[-1][1] + 1.5
        parts.append((ray.passes, boxes + [-mx, -my, mx, my], u,
                      (-float(ahead), support - 1.0)))
        mx, my = spread[0][0] + 4.5, spread[0][1] + 1.5
        firsts.append((1, boxes + [-mx, -my, mx, my], u, (-(TAPS - 1.0), TAPS - 1.0)))
        spans = job_spans(wp, h, parts, ray.passes + 1)
        out.append((spans[:-1], spans[-1]))
    bright, first = job_spans(wp, h, firsts, 2)
    return bright, first, out


def bin_points(points: np.ndarray, width: int, height: int, size: int,
               spread: tuple[int, int] = (0, 0)):
    """(starts, members) int32: for each ``size`` x ``size`` block of a ``width`` x ``height``
    grid (row-major), the indices of the points whose splat touches it,
    ``members[starts[b]:starts[b + 1]]``, in point order.  The splat: the 2 x 2 pixels around
    the point grown by ``spread`` (x, y) pixels each side (a ray-aligned grid's splat moves
    across the ray by up to the reduction factor)."""
    bx, by = -(-width // size), -(-height // size)
    pairs = []
    ex, ey = spread
    for i, (x, y) in enumerate(points[:, :2].astype(np.float64)):
        x0, y0 = math.floor(x), math.floor(y)
        u0, u1 = max(x0 - ex, 0), min(x0 + 1 + ex, width - 1)
        v0, v1 = max(y0 - ey, 0), min(y0 + 1 + ey, height - 1)
        if u0 > u1 or v0 > v1:
            continue
        pairs += [(v * bx + u, i) for v in range(v0 // size, v1 // size + 1)
                  for u in range(u0 // size, u1 // size + 1)]
    pairs.sort()
    counts = np.bincount([b for b, _ in pairs], minlength=bx * by) if pairs else \
        np.zeros(bx * by, np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)]).astype(np.int32)
    return starts, np.array([i for _, i in pairs], np.int32)


MAX_MARGIN = 512
"""Largest zero margin (working-resolution pixels) given to draft's and preview's pass
buffers (`WorkLayout`); longer rays use bounds-tested taps instead.  Final's passes always
test their bounds (`Streaks.streak_sum`)."""

LOCAL = (64, 1)
"""Work-group of the pass kernel (measured fastest on PoCL here: 16 vs 20 ms per pass)."""


@dataclass(frozen=True)
class WorkLayout:
    """Pass buffers of the rays on one working grid: interior ``wp`` (width rounded up to 4)
    x ``h`` pixels at pixel ``org`` of rows ``pitch`` apart, zero margins wide enough for
    every tap in x and in y (no bounds tests) unless the rays are so long that the margins
    would cost more than the tests (``checked``: no margins)."""

    wp: int
    h: int
    pitch: int
    org: int
    nbytes: int
    checked: bool

    @classmethod
    def of(cls, rays: list[tuple[RayGrid, int]]) -> "WorkLayout":
        """The layout of (grid, passes) rays of one grid."""
        grid = rays[0][0]
        margins = []
        for axis in ("sx", "sy"):
            reach = max(math.ceil(3 * TAPS ** (n - 1) * abs(getattr(g, axis))) + 2
                        for g, n in rays)
            margins.append(-(-reach // 4) * 4)
        checked = max(margins) > MAX_MARGIN
        mx, my = (0, 0) if checked else margins
        wp = -(-grid.w // 4) * 4
        pitch = wp + 2 * mx
        return cls(wp, grid.h, pitch, my * pitch + mx, pitch * (grid.h + 2 * my) * 16, checked)


def streak_angles(mode: str, streaks: int, angle: float, blades: int,
                  blade_rotation: float) -> list[float]:
    """Directions of the rays in degrees (counter-clockwise from +x, screen up = -y).

    ``mode="star"``: ``streaks`` rays from ``angle``.  ``mode="anamorphic"``: ``angle`` and
    its opposite.  ``mode="aperture"``: edge normals of a regular ``blades``-gon rotated by
    ``blade_rotation`` plus ``angle``, and their opposites (N for even N, 2N for odd N); empty
    for a round aperture (``blades < 3``).
    """
    if mode == "star":
        return [angle + 360.0 * i / streaks for i in range(streaks)]
    if mode == "anamorphic":
        return [angle, angle + 180.0]
    if blades < 3:
        return []
    normals = [blade_rotation + angle + 180.0 * (2 * i + 1) / blades for i in range(blades)]
    rays = normals + [a + 180.0 for a in normals]
    unique = []
    for a in rays:
        if all(abs((a - b + 180.0) % 360.0 - 180.0) > 1e-6 for b in unique):
            unique.append(a)
    return unique


def direction(angle_deg: float) -> tuple[float, float]:
    """Unit step (dx, dy) in image coordinates (+y down) for a screen angle."""
    t = math.radians(angle_deg)
    dx, dy = math.cos(t), -math.sin(t)
    # exact zeros for axis-aligned rays: no bilinear blur across them
    return (0.0 if abs(dx) < 1e-12 else dx, 0.0 if abs(dy) < 1e-12 else dy)


def grid_step(angle_deg: float) -> tuple[float, float, float]:
    """One tap step along a ray, (sx, sy, length px): a whole pixel along the ray's major
    axis, a fraction along the minor one.  Taps then fall on pixel columns (or rows), so a
    tap interpolates linearly between 2 pixels instead of 4 (half the loads, and no blur along
    the major axis)."""
    dx, dy = direction(angle_deg)
    major = max(abs(dx), abs(dy))
    return dx / major, dy / major, 1.0 / major


@dataclass(frozen=True)
class RayGrid:
    """The working grid of a ray (``kernels/streaks.cl``, "Ray-aligned working grids"):
    ``w`` x ``h`` working pixels of ``fx`` x ``fy`` output pixels, reduced along the ray's
    major axis only (fx = fy = 1 at full resolution); ``shear``: the ray's change across per
    pixel along that axis (0 at full resolution: no offsets); (``sx``, ``sy``): one step in
    working pixels, one working pixel along the reduced axis; ``step_px``: its length in
    output pixels; the output window starts (``ex``, ``ey``) pixels into the grid (one working
    pixel along the reduced axis, where `lead` moves the light of the window's first and last
    pixels)."""

    fx: int
    fy: int
    shear: float
    w: int
    h: int
    sx: float
    sy: float
    step_px: float
    ex: int = 0
    ey: int = 0

    @property
    def lead(self) -> int:
        """Pixels along the reduced axis (+x or +y) the light of a working pixel comes from
        ahead of its centre: half a working pixel in the ray's step direction, the streak
        being drawn backwards from the light (a tap at +k steps)."""
        f = max(self.fx, self.fy)
        return int(math.copysign(f // 2, self.sx if self.fx > 1 else self.sy))

    @property
    def layout(self) -> tuple[int, int]:
        return self.fx, self.fy

    @property
    def line(self) -> tuple[int, int, float]:
        """Rays of one line (a ray and its opposite) share a working sum, upsampled once."""
        return self.fx, self.fy, round(self.shear, 9)


def ray_grid(angle_deg: float, factor: int, width: int, height: int) -> RayGrid:
    """The working grid of a ray over a ``width`` x ``height`` output window: full
    resolution for ``factor`` 1, else reduced ``factor`` times along the ray's major axis
    (x when |cos| >= |sin|), full resolution across it, so the ray stays a pixel thin."""
    sx, sy, step_len = grid_step(angle_deg)
    if factor == 1:
        return RayGrid(1, 1, 0.0, width, height, sx, sy, step_len)
    if abs(sx) >= abs(sy):
        return RayGrid(factor, 1, sy / sx, -(-width // factor) + 2, height, sx, factor * sy,
                       factor * step_len, ex=factor)
    return RayGrid(1, factor, sx / sy, width, -(-height // factor) + 2, factor * sx, sy,
                   factor * step_len, ey=factor)


def grid_points(rows: np.ndarray, ox: int, oy: int, fx: int, fy: int) -> np.ndarray:
    """(x, y, r, g, b, 0, 0, 0) float32 rows of `Streaks.seed_points`' lights on a working
    grid of ``fx`` x ``fy`` output pixels: the centroid in working pixels (centres aligned),
    the light divided by fx fy (a working pixel's light is the mean of its output pixels').
    Working pixel X is centred on output pixel ``f X + f // 2`` (a whole pixel)."""
    out = np.zeros((len(rows), 8), np.float32)
    # source pixel -> output window pixel -> working pixel: (x - f // 2) / f, written for
    # f = 1 as it always was (x + 0.5) / 1 - 0.5 (final's points unchanged to the bit)
    out[:, 0] = (rows[:, 2] + ox + 0.5 * (fx % 2)) / fx - 0.5
    out[:, 1] = (rows[:, 3] + oy + 0.5 * (fy % 2)) / fy - 0.5
    out[:, 2:5] = rows[:, 4:7] / np.float32(fx * fy)
    return out


def channel_lengths(length_px: float, color_shift: float, mode: str = "star") -> np.ndarray:
    """Per-channel 1% length in pixels: red longer and blue shorter for color_shift > 0; in
    aperture mode also in proportion to the channel's wavelength (``SPIKE_WAVELENGTHS_NM``)."""
    out = length_px * (1.0 + 0.5 * color_shift * np.array([1.0, 0.0, -1.0]))
    if mode == "aperture":
        out = out * np.asarray(SPIKE_WAVELENGTHS_NM) / SPIKE_WAVELENGTHS_NM[1]
    return out


def pass_plan(max_length_px: float) -> tuple[int, int]:
    """(N passes, T taps in the last one): the smallest support ``S = T 4^(N-1)`` with
    ``S >= TAIL L + 1`` (the truncated tail is below 1e-5 of the start)."""
    need = TAIL * max(max_length_px, 1.0) + 1.0
    n = max(1, math.ceil(math.log(need, TAPS) - 1e-12))
    top = min(TAPS, max(1, math.ceil(need / TAPS ** (n - 1) - 1e-9)))
    return n, top


def support_steps(max_length_px: float) -> int:
    """The support ``T 4^(N-1)`` of :func:`pass_plan`, in steps."""
    n, top = pass_plan(max_length_px)
    return top * TAPS ** (n - 1)


def pass_weights(lengths_px: np.ndarray, passes: int, gain: np.ndarray,
                 top: int = TAPS) -> list[np.ndarray]:
    """Per-pass tap weights, shape (passes, 4 taps, 4 channels); gain folded into pass 0; the
    last pass has ``top`` taps of non-zero weight.

    ``gain`` (3,) is divided by the truncated kernel's sum so each channel sums to ``gain``.
    """
    a = 0.01 ** (1.0 / np.maximum(lengths_px, 1e-3))        # per-channel decay per pixel
    support = top * TAPS ** (passes - 1)
    total = np.where(a < 1.0, (1.0 - a ** support) / np.maximum(1.0 - a, 1e-300), support)
    out = []
    for n in range(passes):
        b = TAPS ** n
        w = np.zeros((TAPS, 4))
        for s in range(top if n == passes - 1 else TAPS):
            w[s, :3] = a ** (s * b)
        if n == 0:
            w[:, :3] *= gain / total
        out.append(w)
    return out


def coating_tint(design_nm: float, design: str = "v-coat") -> np.ndarray:
    """RGB (luminance 1) of light reflected twice off the anti-reflection stack ``design``
    (:data:`clfx.fx.optics.MULTILAYER_DESIGNS`) designed at ``design_nm`` on crown glass: the
    stack's residual reflectance squared, integrated with the CIE 1931 observer into linear
    Rec.709 (into gamut)."""
    lam = spectral.wavelengths(80)
    weights = spectral.spectral_rgb_weights(lam)
    refl = optics.thin_film_reflectance(1.0, GLASS_INDEX, optics.MULTILAYER_DESIGNS[design],
                                        design_nm, lam)
    rgb = spectral.to_gamut((refl ** 2) @ weights / weights.sum(axis=0))
    return rgb / float(rgb @ np.array([0.2126, 0.7152, 0.0722]))


def streak_parts(mode: str) -> tuple[tuple[float, float], ...]:
    """(1 % length as a fraction of ``length``, share of the light) of each exponential."""
    return {"anamorphic": ANAMORPHIC_PARTS, "aperture": APERTURE_PARTS}.get(mode, ((1.0, 1.0),))


STREAM_PIXELS = 1 << 22
"""A frame of more pixels than this (4K UHD) streams through final and reference's
passes in chunks of rows (`Streaks.streak_sum`) where that holds fewer rows on the device
than the three frame-sized buffers of the whole passes; its streak sum waits on the host."""

CHUNK_PIXELS = 1 << 20
"""Pixels (whole rows) of a streamed chunk, and of a piece of a streamed compose."""

SEEDS_READ = 1024
"""Seed points read with their count (one wait); a frame with more lights reads them all."""


@dataclass(frozen=True)
class Ray:
    """One ray's Kawase chain: step (sx, sy) per pass-0 tap, ``passes``, ``top`` taps of
    non-zero weight in the last pass, per-pass weights (`pass_weights`), its working
    grid (`ray_grid`; sx, sy are its steps)."""

    sx: float
    sy: float
    passes: int
    top: int
    weights: tuple
    grid: RayGrid | None = None


def ray_rows(ray: Ray, chunk: int, height: int) -> list[int]:
    """Rows a streamed ray keeps of the input of each of its passes (pass n's taps reach
    ``(taps - 1) 4^n |sy|`` rows, plus the bilinear row): a chunk and the rows the pass
    reads past it, at most the frame's ``height``."""
    out = []
    for n in range(ray.passes):
        taps = ray.top if n == ray.passes - 1 else TAPS
        reach = math.ceil((taps - 1) * TAPS ** n * abs(ray.sy)) + 1
        out.append(min(height, chunk + reach))
    return out


def ring_rows(rays, chunk: int, height: int) -> list[int]:
    """Rows of each held buffer of a streamed frame: the most any ray keeps at that pass."""
    per_ray = [ray_rows(r, chunk, height) for r in rays]
    return [max(r[n] for r in per_ray if n < len(r))
            for n in range(max(len(r) for r in per_ray))]


def streams(width: int, height: int, rings: list[int], chunk: int) -> bool:
    """Whether a ``width`` x ``height`` working frame streams (`Streaks.streak_sum`): it is
    over ``STREAM_PIXELS`` and its held rows (``rings``, the chunk's sum) are fewer than the
    whole passes' three frame-sized buffers less one (a fourth holds the bright pixels
    the rays share where several start from them: a frame that streaks whole is under
    ``STREAM_PIXELS``)."""
    return width * height > STREAM_PIXELS and sum(rings) + chunk < 2 * height


@dataclass(frozen=True)
class StreaksFrame:
    """The frame-wide inputs of a streaks step, taken from its whole context when the plan
    is built: the source, the output window, the level, the rays, the per-tile peak map
    (map, tiles across, tiles down; read-only), the working space's luminance defines
    (read-only)."""

    source: object
    out_win: Rect
    level: StreaksLevel
    rays: tuple
    peak: tuple
    analysis_tile: int
    radius: int
    luminance_defines: Mapping
    nonfinite: int


@dataclass(frozen=True)
class StreaksPlan(StepPlan):
    """The frame's inputs and its streak sum (`Streaks.streak_sum`), computed in the plan so
    the sum's buffers come and go before the step's output is allocated."""

    frame: StreaksFrame | None = None
    total: "StreakSum | None" = None


@dataclass(frozen=True)
class StreakSum:
    """A frame's streaks over its output window at full resolution (RGBA float32): on the
    device (``device``, interior at ``org``, rows ``pitch`` apart) or on the host (``host``,
    rows x (width rounded up to 4) x 4, read-only)."""

    device: object = None
    org: int = 0
    pitch: int = 0
    host: np.ndarray | None = None

    def __post_init__(self):
        if self.host is not None:
            read_only(self.host)


@register
class Streaks(Plugin):
    whole_frame = None   # bands compose their rows from the plan's streak sum of the frame
    # (region of interest: the band itself, the base class's; the rays come from that sum)
    descriptor = Descriptor(
        name="streaks", label="Streaks (star filter)", group="Glare", kernel="streaks.cl",
        summary="Star-filter streaks or aperture diffraction spikes from the highlights, "
                "by iterated 4-tap passes (Kawase).",
        spreads_light=True,
        params=(
            FloatParam("threshold", 1.0, min=0.0, max=1e6,
                       hint="Scene-linear luminance above which pixels streak."),
            FloatParam("intensity", 0.1, min=0.0, max=100.0,
                       hint="Light added to the streaks as a fraction of the highlights' energy."),
            ChoiceParam("mode", "star", choices=("star", "aperture", "anamorphic"),
                        hint="star: `streaks` rays at `angle`; aperture: diffraction spikes of "
                             "the blade polygon (N spikes for even N, 2N for odd N); "
                             "anamorphic: a thin streak both ways along `angle` (0: "
                             "horizontal), coloured by the coating, bright near the light and "
                             "long and faint beyond."),
            IntParam("streaks", 4, min=1, max=32, hint="Number of rays in star mode."),
            FloatParam("angle", 45.0, min=-360.0, max=360.0, units="deg",
                       hint="Angle of the first ray (star) or extra aperture rotation, degrees "
                            "counter-clockwise from +x."),
            IntParam("blades", 0, min=0, max=32, exclude=NO_POLYGON, exclude_why=BLADES_WHY,
                     hint="Aperture blades in aperture mode; 0 = the camera block's blades."),
            FloatParam("length", 0.08, min=0.0005, max=2.0,
                       hint="Distance at which a streak has faded to 1%, as a fraction of the "
                            "frame diagonal; it ends (below 1e-5) at 2.5 x that."),
            FloatParam("core", 0.5, min=0.0, max=1.0,
                       hint="Only the light above this fraction of its light's peak luminance "
                            "streaks (a light: a connected region above threshold): the bright "
                            "core of a flame, not its glow or what it lights (0: all above "
                            "threshold)."),
            FloatParam("core_power", -1.0, min=-1.0, max=8.0,
                       hint="Weight of each pixel's light by (L / its light's peak)^power: "
                            "> 0 thins a streak to its light's brightest rows; -1 = 3 in "
                            "anamorphic mode, 0 otherwise."),
            ChoiceParam("coating", "v-coat", choices=("mgf2", "v-coat", "broadband",
                                                      "broadband-hi"),
                        hint="Anamorphic mode: the anti-reflection stack whose residual "
                             "reflection (twice) colours the streak (clfx.fx.optics)."),
            FloatParam("coating_nm", 740.0, min=380.0, max=780.0, units="nm",
                       hint="Anamorphic mode: design wavelength of that coating (a V-coat "
                            "at 740: blue-cyan)."),
            RGBParam("tint", (1.0, 1.0, 1.0), max=100.0, hint="Colour multiplier of the streaks."),
            FloatParam("source_color", 1.0, min=0.0, max=1.0,
                       hint="How much of the light's own colour a streak keeps: 1 = the "
                            "light's colour times tint; 0 = its luminance times tint (the "
                            "coating colours the streak, as anamorphic streaks)."),
            FloatParam("color_shift", 0.0, min=-1.0, max=1.0,
                       hint="Colour change along the streak: > 0 red reaches further (x1.5 at 1) "
                            "and blue less far (x0.5); < 0 the reverse."),
        ),
        quality=LEVELS,
    )

    # geometry -------------------------------------------------------------------------
    def angles(self, p, ctx) -> list[float]:
        blades = p.blades or ctx.camera.blades
        rotation = ctx.camera.blade_rotation if p.mode == "aperture" else 0.0
        return streak_angles(p.mode, p.streaks, p.angle, blades, rotation)

    def length_px(self, p, ctx) -> float:
        return p.length * ctx.diagonal_px

    @staticmethod
    def core_power(p) -> float:
        if p.core_power >= 0.0:
            return p.core_power
        return ANAMORPHIC_CORE_POWER if p.mode == "anamorphic" else 0.0

    @staticmethod
    def colour(p) -> np.ndarray:
        """The streaks' colour multiplier: ``tint``, times the coating's in anamorphic mode."""
        tint = np.asarray(p.tint, np.float64)
        return tint * coating_tint(p.coating_nm, p.coating) if p.mode == "anamorphic" else tint

    def spread_px(self, p, ctx) -> int:
        """How far light travels: the truncated kernel's support plus the bilinear footprint
        (at full resolution: the reduced levels' grids reach no further)."""
        longest = float(channel_lengths(self.length_px(p, ctx), p.color_shift, p.mode).max())
        reach = 0.0
        for a in self.angles(p, ctx) or [0.0]:
            step = grid_step(a)[2]
            reach = max(reach, support_steps(longest / step) * step)
        return int(math.ceil(reach)) + 2

    # cheap questions ------------------------------------------------------------------
    def plan(self, p, ctx) -> StreaksPlan:
        """Whether the step has work and, if so, the frame's streak sum (built on the
        step's whole context, before any band: a band cannot see the frame its rays cross;
        each band composes its rows from the sum its :class:`~clfx.host.Band` carries)."""
        identity = self.identity(p, ctx)
        if identity:
            return StreaksPlan(identity=identity)
        fr = self.frame(p, ctx)
        return StreaksPlan(frame=fr, total=self.streak_sum(ctx.runtime, p, fr, ctx.notes))

    def identity(self, p, ctx) -> str | None:
        if p.intensity == 0.0:
            return "intensity is 0"
        if p.mode == "aperture" and not self.angles(p, ctx):
            ctx.warnings.append("streaks: mode=aperture with a round aperture (camera blades "
                                "0 and blades 0) makes no diffraction spikes; set "
                                "camera.blades or streaks.blades (>= 3), or mode=star")
            return "round aperture (blades 0): no diffraction spikes"
        if not ctx.analysis.any_above(p.threshold):
            return "no pixel above threshold"
        return None

    def region_of_definition(self, p, ctx):
        return ctx.source.window.grown(self.spread_px(p, ctx))

    @staticmethod
    def peak_map(p, ctx):
        """Per analysis tile, the peak luminance of the light (connected bright region) it
        belongs to, float32 (tiles_y x tiles_x) over the source window."""
        m = ctx.analysis.region_peaks(p.threshold)
        m = np.minimum(np.nan_to_num(m, nan=0.0, posinf=0.0), np.finfo(np.float32).max)
        return read_only(np.ascontiguousarray(m, np.float32).ravel()), m.shape[1], m.shape[0]

    def seed_radius(self, ctx) -> int:
        """Half-width (px) of the window a light's peak gathers its streaking light from."""
        return max(1, round(SEED_RADIUS * ctx.diagonal_px))

    def frame(self, p, ctx) -> StreaksFrame:
        """What the streak sum reads of ``ctx`` (the step's whole context)."""
        lvl = self.level(ctx)
        out_win = self.output_window(p, ctx)
        angles, colour = self.angles(p, ctx), self.colour(p)
        rays = []
        for fraction, share in streak_parts(p.mode):
            lengths = channel_lengths(fraction * self.length_px(p, ctx), p.color_shift,
                                      p.mode)
            gain = p.intensity * share * colour / len(angles)
            for a in angles:
                grid = ray_grid(a, lvl.factor, out_win.width, out_win.height)
                passes, top = pass_plan(float(lengths.max()) / grid.step_px)
                weights = pass_weights(lengths / grid.step_px, passes, gain, top)
                rays.append(Ray(grid.sx, grid.sy, passes, top,
                                tuple(read_only(w) for w in weights), grid))
        return StreaksFrame(ctx.source, out_win, lvl, tuple(rays),
                            self.peak_map(p, ctx), ctx.analysis.tile, self.seed_radius(ctx),
                            MappingProxyType(dict(ctx.luminance_defines)),
                            ctx.analysis.nonfinite_count)

    def seed_points(self, rt, p, fr: StreaksFrame, peak, notes: list):
        """One point per compact light (kernel ``streaks_seeds``), sorted by its peak's
        position (a fixed order whatever the device's): the kernel's float32 rows (peak x, y,
        centroid x, y in source pixels, r, g, b, 0; `grid_points` places them on a working
        grid); the source-sized uint8 device flags of the pixels they gathered, and the same
        on the host where the host drew them (else None); and the bool (blocks down, across)
        mask of the source's ``BLOCK`` px blocks with streaking light.  ``peak``: the per-tile
        peak map on the device; ``notes``: the step's, told when lights are left out.  With a
        core rule only a light's tiles (``fr.peak`` > 0) can hold streaking light, and the
        kernel runs over those alone.  One wait for the count, the lit blocks and the first
        ``SEEDS_READ`` points; up to that many lights the host draws the windows the seeds
        gathered (`gathered_flags`), a frame with more reads them all and grows the flags on
        the device (``streaks_dilate``)."""
        src = fr.source
        peak_map, tiles_x, tiles_y = fr.peak
        npx = src.width * src.height
        lit_shape = (-(-src.height // BLOCK), -(-src.width // BLOCK))
        lit = rt.to_device(np.zeros(lit_shape, np.int32))
        flags = rt.buffer(max(npx, 16))   # the seeds mark it
        rt.cl.enqueue_fill_buffer(rt.queue, flags.buffer, np.uint8(0), 0, max(npx, 16))
        count = rt.to_device(np.zeros(1, np.int32))
        seeds = rt.buffer(MAX_SEEDS * 32)
        spans = None
        if p.core > 0.0:   # light only in a light's tiles (streaks_level)
            lights = np.asarray(peak_map).reshape(tiles_y, tiles_x) > 0.0
            boxes = light_boxes(lights, fr.analysis_tile, src.width, src.height)
            spans = row_spans(raster(src.width, src.height, boxes), src.width)
        knl = rt.kernel("streaks.cl", "streaks_seeds", PEAK_TILE=fr.analysis_tile,
                        TILED=int(spans is not None), BLOCK=BLOCK, **fr.luminance_defines)
        args = (src, src.pitch, src.width, src.height, p.threshold, peak, tiles_x, tiles_y,
                p.core, p.source_color, self.core_power(p), fr.radius, RING_SHARE, seeds,
                count, MAX_SEEDS, flags)
        if spans is None:
            rt.launch(knl, (src.width, src.height), *args, None, lit)
        elif len(spans):
            rt.launch(knl, (SPAN, len(spans)), *args, rt.to_device(spans), lit,
                      local=(SPAN, 1))
        n_host, first = np.zeros(1, np.int32), np.empty((SEEDS_READ, 8), np.float32)
        lit_host = np.empty(lit_shape, np.int32)
        rt.cl.enqueue_copy(rt.queue, n_host, count.buffer, is_blocking=False)
        rt.cl.enqueue_copy(rt.queue, lit_host, lit.buffer, is_blocking=False)
        rt.cl.enqueue_copy(rt.queue, first, seeds.buffer, is_blocking=True)
        n = int(n_host[0])
        if n > SEEDS_READ:   # the flags of every seed, those past MAX_SEEDS too, grown
            grown = rt.buffer(max(npx, 16))
            dilate = rt.kernel("streaks.cl", "streaks_dilate")
            for a, b, sx, sy in ((flags, grown, 1, 0), (grown, flags, 0, 1)):
                rt.launch(dilate, (src.height if sx else src.width,), a, b,
                          src.width, src.height, fr.radius, sx, sy)
        if n > MAX_SEEDS:
            notes.append(f"streaks: {n} lights, only {MAX_SEEDS} (the first found) streak")
            n = MAX_SEEDS
        rows = first[:n] if n <= SEEDS_READ else \
            rt.from_device(seeds, np.float32, 8 * n).reshape(n, 8)
        drawn = None
        if 0 < n <= SEEDS_READ:
            drawn = gathered_flags(rows, src.width, src.height, fr.radius)
            flags = rt.to_device(drawn)
        return rows[np.lexsort((rows[:, 0], rows[:, 1]))], flags, drawn, lit_host > 0

    # render ---------------------------------------------------------------------------
    def streak_sum(self, rt, p, fr: StreaksFrame, notes: list) -> StreakSum:
        """The frame's full-resolution streaks, computed once per plan: the Kawase passes of
        every ray over the whole frame's light, summed.  Draft and preview: `grid_sum`.
        Final and reference: small frames run each pass over frame-sized buffers (taps
        outside the frame read 0); a frame over ``STREAM_PIXELS`` pixels streams
        through in chunks of rows when that holds fewer rows on the device (`ring_rows`), and
        its sum waits on the host.  Both compute every pixel with the same float
        operations."""
        if fr.level.factor > 1:
            return self.grid_sum(rt, p, fr, notes)
        src, lvl = fr.source, fr.level
        ox, oy = src.window.offset_in(fr.out_win)
        w, h = fr.out_win.width, fr.out_win.height
        wp = -(-w // 4) * 4
        chunk = max(1, CHUNK_PIXELS // wp)
        rings = ring_rows(fr.rays, chunk, h)
        stream = streams(wp, h, rings, chunk)
        # no zero margins: the taps test their bounds (a tap outside reads 0, as it read a
        # margin's 0, so the floats are the same).  Margins made every buffer a size of its
        # own (2312 x 1472 at 1080p) that the pool never held from one frame to the next: four
        # fresh 52 MiB buffers a frame, paged in, zero-filled and copied; unpadded, they are
        # the frame's size, which the pool keeps (`MAX_MARGIN` still sizes draft's and
        # preview's grids)
        pitch, org = wp, 0
        defines = {"fp64": lvl.fp64, "CHECKED": 1, "RING": int(stream),
                   "TILED": int(not stream), **fr.luminance_defines}

        peak_buf = rt.to_device(fr.peak[0])
        rows, gathered, drawn, lit = self.seed_points(rt, p, fr, peak_buf, notes)
        points = grid_points(rows, ox, oy, 1, 1)
        starts, members = bin_points(points, wp, h, BIN)
        points_buf, starts_buf, members_buf = (rt.to_device(a) for a in (
            points if len(points) else np.zeros((1, 8), np.float32), starts,
            members if len(members) else np.zeros(1, np.int32)))
        bright_knl = rt.kernel("streaks.cl", "streaks_bright", PEAK_TILE=fr.analysis_tile,
                               **defines)
        _, tiles_x, tiles_y = fr.peak
        bright_args = (src, src.pitch, src.width, src.height)
        bright_tail = (1, 1, 0.0, 0, ox, oy, p.threshold,
                       peak_buf, tiles_x, tiles_y, p.core, p.source_color,
                       self.core_power(p), gathered, points_buf, starts_buf, members_buf,
                       -(-wp // BIN), BIN)
        step_knl = rt.kernel("streaks.cl", "streaks_pass", ACCUM=0, **defines)
        accum_knl = rt.kernel("streaks.cl", "streaks_pass", ACCUM=1, **defines)
        # the whole passes run over row spans (TILED), a streamed frame's over rows y0..

        uploaded = {}   # each span table on the device once a frame (they stay alive here)

        def spans_buffer(spans):
            if id(spans) not in uploaded:
                uploaded[id(spans)] = rt.to_device(spans)
            return uploaded[id(spans)]

        def launch(knl, px, rows, *args, spans=None):
            if stream:
                rt.launch(knl, (wp // px, rows), *args, None, local=LOCAL if px > 1 else None)
            elif len(spans):
                rt.launch(knl, (SPAN // px, len(spans)), *args, spans_buffer(spans),
                          local=(SPAN // px, 1))

        def bright(dst, y0, rows, ring, spans=None):   # the bright pixels and points
            launch(bright_knl, 1, rows, *bright_args, dst, org, pitch, wp,
                   h, *bright_tail, y0, ring, spans=spans)

        def run_pass(ray, n, src_buf, dst_buf, y0, rows, in_rows, out_rows, spans=None):
            b = TAPS ** n
            launch(accum_knl if n == ray.passes - 1 else step_knl, 4, rows, src_buf,
                   dst_buf, org, pitch, wp, w, h, ray.sx * b, ray.sy * b, *ray.weights[n],
                   y0, in_rows, out_rows, spans=spans)

        if not stream:
            # only the row spans within each ray's reach of the bright pixels (`pass_spans`):
            # the rest of the frame streaks nothing (issue 37: the cinema look's 4 rays of
            # 275 px at 1080p streak 3.5 % of the frame's pixels)
            bright_spans, bright_read, ray_spans = pass_spans(
                lit, drawn, points, ox, oy, (src.width, src.height), wp, h, fr.rays)
            clear_knl = rt.kernel("streaks.cl", "streaks_clear", TILED=1)

            def clear(buf, spans):   # zeros where the passes read (before they write)
                if len(spans):
                    rt.launch(clear_knl, (SPAN // 4, len(spans)), buf, org, pitch, wp, h,
                              spans_buffer(spans), local=(SPAN // 4, 1))

            nbytes = pitch * h * 16
            shared = len(fr.rays) > 1
            work = [rt.buffer(nbytes) for _ in range(3 + shared)]   # ping, pong, total(, bright)
            ping, pong, total = work[:3]
            # the last pass of each ray adds into the total; outside a ray's spans its passes
            # write nothing, and what they read there is cleared first (the pool's buffers
            # hold an earlier frame's or ray's streaks)
            rt.cl.enqueue_fill_buffer(rt.queue, total.buffer, np.float32(0.0), 0, nbytes)
            if shared:   # the bright pixels once for every ray (4 rays: 3 extractions saved,
                clear(work[3], bright_read)                 # 39 ms of CPU at 960x540)
                bright(work[3], 0, h, 0, bright_spans)
            for ray, (spans, read) in zip(fr.rays, ray_spans):
                # each ray's first pass reads the bright pixels, which no pass writes
                clear(ping, read)
                clear(pong, read)
                if shared:
                    cur = work[3]
                else:
                    bright(pong, 0, h, 0, bright_spans)
                    cur = pong
                for n in range(ray.passes):
                    dst = total if n == ray.passes - 1 else (ping if cur is not ping else pong)
                    run_pass(ray, n, cur, dst, 0, h, 0, 0, spans[n])
                    cur = dst
            result = StreakSum(device=total, org=org, pitch=pitch)
        else:
            # each buffer a pass reads keeps the rows the passes after it still read (rows
            # y % its height); a ray sweeps the frame against its taps' direction, so the
            # rows a chunk reads are this chunk's or ones swept before it
            held = [rt.buffer(r * wp * 16) for r in rings]
            for buf, r in zip(held, rings):
                rt.cl.enqueue_fill_buffer(rt.queue, buf.buffer, np.float32(0.0), 0, r * wp * 16)
            part = rt.buffer(chunk * wp * 16)
            host = np.empty((h, wp, 4), np.float32)
            for i, ray in enumerate(fr.rays):
                heights = ray_rows(ray, chunk, h)
                starts_y = range(0, h, chunk)
                for y0 in (reversed(starts_y) if ray.sy > 0 else starts_y):
                    rows = min(chunk, h - y0)
                    if i == 0:
                        rt.cl.enqueue_fill_buffer(rt.queue, part.buffer, np.float32(0.0), 0,
                                                  chunk * wp * 16)
                    else:
                        rt.cl.enqueue_copy(rt.queue, part.buffer, host[y0:y0 + rows],
                                           is_blocking=False)
                    bright(held[0], y0, rows, heights[0])
                    for n in range(ray.passes):
                        last = n == ray.passes - 1
                        run_pass(ray, n, held[n], part if last else held[n + 1], y0, rows,
                                 heights[n], chunk if last else heights[n + 1])
                    rt.cl.enqueue_copy(rt.queue, host[y0:y0 + rows], part.buffer,
                                       is_blocking=False)
            rt.finish()
            result = StreakSum(host=host)
        return result

    def grid_sum(self, rt, p, fr: StreaksFrame, notes: list) -> StreakSum:
        """Draft and preview's streak sum: each ray's passes on its ray-aligned working grid
        (`ray_grid`), the rays of one line summed there and upsampled along the line into the
        full-resolution sum, which stays on the device (the grids are not streamed: they are
        reduced along one axis; see "Memory and tiles")."""
        src, lvl, out_win = fr.source, fr.level, fr.out_win
        factor = lvl.factor
        ox, oy = src.window.offset_in(out_win)
        defines = {"fp64": lvl.fp64, **fr.luminance_defines}
        # the rays of one line share a working sum, upsampled along them once
        plans = sorted(((r.grid, r.passes, r.weights) for r in fr.rays),
                       key=lambda plan: plan[0].line)
        layouts = {grid.layout: WorkLayout.of([(g, n) for g, n, _ in plans
                                               if g.layout == grid.layout])
                   for grid, _, _ in plans}
        nbytes = max(lay.nbytes for lay in layouts.values())
        work = [rt.buffer(nbytes) for _ in range(3)]      # ping, pong, total (one line's)
        for buf in work:
            rt.cl.enqueue_fill_buffer(rt.queue, buf.buffer, np.float32(0.0), 0, nbytes)
        ping, pong, total = work
        full_pitch = -(-out_win.width // 4) * 4
        full = rt.buffer(full_pitch * out_win.height * 16)
        rt.cl.enqueue_fill_buffer(rt.queue, full.buffer, np.float32(0.0), 0,
                                  full_pitch * out_win.height * 16)

        peak_buf = rt.to_device(fr.peak[0])
        _, tiles_x, tiles_y = fr.peak
        rows, gathered, _, _ = self.seed_points(rt, p, fr, peak_buf, notes)
        seeds = {}
        for g in {grid.layout: grid for grid, _, _ in plans}.values():
            points = grid_points(rows, ox + g.ex, oy + g.ey, g.fx, g.fy)
            # a point's splat moves across by up to `factor` (shear x a working pixel), and
            # `lead` moves it by half a working pixel more
            starts, members = bin_points(points, layouts[g.layout].wp, g.h, BIN,
                                         (1 + 2 * g.ey, 1 + 2 * g.ex))
            seeds[g.layout] = [rt.to_device(a) for a in (
                points if len(points) else np.zeros((1, 8), np.float32), starts,
                members if len(members) else np.zeros(1, np.int32))]
        # the streaking light of the pixels no seed gathered, once a frame
        ext = rt.buffer(max(src.width * src.height, 1) * 16)
        rt.launch(rt.kernel("streaks.cl", "streaks_extended", PEAK_TILE=fr.analysis_tile,
                            **defines), (src.width, src.height), src, src.pitch,
                  src.width, src.height, p.threshold, peak_buf,
                  tiles_x, tiles_y, p.core, p.source_color,
                  self.core_power(p), gathered, ext)
        last_layout = None
        for k, (grid, passes, weights) in enumerate(plans):
            lay = layouts[grid.layout]
            if last_layout not in (None, lay):    # other margins: clear what the last wrote
                for buf in (ping, pong):
                    rt.cl.enqueue_fill_buffer(rt.queue, buf.buffer, np.float32(0.0), 0, nbytes)
            last_layout = lay
            kdefs = {**defines, "CHECKED": int(lay.checked)}
            bright_knl = rt.kernel("streaks.cl", "streaks_bright", PEAK_TILE=fr.analysis_tile,
                                   EXTENDED=1, **kdefs)
            step_knl = rt.kernel("streaks.cl", "streaks_pass", ACCUM=0, **kdefs)
            accum_knl = rt.kernel("streaks.cl", "streaks_pass", ACCUM=1, **kdefs)
            # each ray starts from the bright pixels, extracted again into pong (cheaper than
            # a fourth working buffer; passes write inside the zero margins only)
            rt.launch(bright_knl, (lay.wp, lay.h), ext, src.width, src.width,
                      src.height, pong, lay.org, lay.pitch, lay.wp,
                      lay.h, grid.fx, grid.fy, grid.shear,
                      grid.lead, ox + grid.ex, oy + grid.ey, p.threshold,
                      peak_buf, tiles_x, tiles_y,
                      p.core, p.source_color, self.core_power(p), gathered,
                      *seeds[grid.layout], -(-lay.wp // BIN), BIN, 0, 0, None)
            cur = pong
            for n in range(passes):
                last = n == passes - 1
                dst = total if last else (ping if cur is not ping else pong)
                b = TAPS ** n
                rt.launch(accum_knl if last else step_knl, (lay.wp // 4, lay.h), cur, dst,
                          lay.org, lay.pitch, lay.wp, grid.w, lay.h,
                          grid.sx * b, grid.sy * b, *weights[n], 0, 0, 0, None,
                          local=LOCAL)
                cur = dst
            if k + 1 == len(plans) or plans[k + 1][0].line != grid.line:
                rt.launch(rt.kernel("streaks.cl", "streaks_expand", ALONG_X=int(grid.fx > 1)),
                          (out_win.width, out_win.height), total, lay.org,
                          lay.pitch, grid.w, grid.h, factor,
                          grid.ex + grid.ey, grid.shear, full, full_pitch,
                          out_win.width, out_win.height, local=LOCAL)
                if k + 1 < len(plans):
                    rt.cl.enqueue_fill_buffer(rt.queue, total.buffer, np.float32(0.0), 0,
                                              nbytes)
        return StreakSum(device=full, org=0, pitch=full_pitch)

    def render(self, rt, p, ctx):
        plan = self.planned(p, ctx)
        fr, total = plan.frame, plan.total
        if total is None:   # rendered although the plan found nothing to do
            fr = self.frame(p, ctx)
            total = self.streak_sum(rt, p, fr, ctx.notes)
        src = ctx.source
        band = ctx.tiling.band if ctx.tiling is not None else fr.out_win
        ox, oy = src.window.offset_in(band)
        dx0, dy0 = band.offset_in(fr.out_win)
        out = rt.image(band)
        knl = rt.kernel("streaks.cl", "streaks_compose", **fr.luminance_defines)

        def compose(buf, org, pitch, r0, row0, rows):
            rt.launch(knl, (out.pitch // 4, rows), src, src.pitch, src.width,
                      src.height, ox, oy, buf, org, pitch,
                      r0, out, out.pitch,
                      band.width, row0 + rows, dx0, dy0, row0)

        if total.host is None:
            compose(total.device, total.org, total.pitch, 0, 0, band.height)
        else:   # the rows of the sum a piece of the band reads, uploaded piece by piece
            rows = max(1, CHUNK_PIXELS // out.pitch)
            wp = total.host.shape[1]
            buf = rt.buffer(rows * wp * 16)
            for row0 in range(0, band.height, rows):
                n = min(rows, band.height - row0)
                r0 = dy0 + row0
                rt.cl.enqueue_copy(rt.queue, buf.buffer, total.host[r0:r0 + n],
                                   is_blocking=False)
                compose(buf, 0, wp, r0, row0, n)
        if fr.nonfinite:
            ctx.notes.append(f"streaks: {fr.nonfinite} non-finite pixels set to 0")
        return out
