"""Motion blur reconstructed from a velocity field: the gather shared by the blurs of motion.

``motion_blur`` runs it on the velocity pass; ``camera_blur`` on the velocity field of a
trucking camera.  Both declare their quality levels from :data:`LEVELS` and read the shutter
through :func:`shutter_from` (the physics is :func:`clfx.core.camera.shutter_interval`).

Model
-----
During the open shutter ``[t0, t1]`` (frames, relative to the frame time) a surface point seen
at pixel ``y`` at the frame time sits at ``y + v_y t``, with ``v_y`` the velocity (forward
px/frame, +x right, +y down; :mod:`clfx.core.frame`).  The blurred pixel ``x`` is the time
average of whatever surface covers ``x``; a post-process only knows the surfaces visible at the
frame time, so it reconstructs that average by gathering.

Algorithm (McGuire, Hennessy, Bukowski & Osman 2012, "A reconstruction filter for plausible
motion blur"; Jimenez 2014, "Next generation post processing in Call of Duty: Advanced
Warfare"; Guertin, McGuire & Nowrouzezahrai 2014)
--------------------------------------------------------------------------------------------
1. *Prepare*: velocities sanitised (NaN/Inf -> 0) and clamped so that no pixel reaches farther
   than the maximum blur radius ``R`` (at most :data:`MAX_RADIUS_PX`); depth sanitised (NaN,
   <= 0, +inf -> "far").  With a depth pass, the rim pixels of small bright moving surfaces
   take their motion (*dilate*): renderers write velocity from the surface at the pixel
   centre, so the antialiased rim of a moving light carries the background's velocity
   though most of its light is the light's, which would stay behind as a static ring.
2. *TileMax* over ``k x k`` tiles, ``k`` = ``R`` rounded up to a multiple of 4 (at least 8),
   with ``R`` taken from the frame's actual peak speed when smaller, then *NeighborMax* over
   3 x 3 tiles: the dominant velocity ``v_n`` of every pixel that can reach into the tile.
3. *Classification*: the small NeighborMax grid is read back; tiles whose ``v_n`` smears less
   than :data:`MIN_BLUR_PX` are skipped outright (the output starts as a copy of the input),
   the others form compact lists, and the gather runs over them only.  A tile is
   *front-free* when its largest depth is at most the smallest of every tile its reads reach
   (TileMax also keeps each tile's depth range; :func:`_front_free`): no sample lies in front
   of any of its pixels, each soft depth test below would give exactly 0, and the gather skips
   the occluder set and the tests (the same bits for less work).  A tile's sample count
   follows its own blur length (``ceil(length / spacing)``, capped per quality level); the
   samples use the midpoint rule (deterministic, exact for a linear image) unless the cap
   leaves them sparser than :data:`JITTER_SPACING_PX`, where a per-pixel jitter turns ghost
   copies into grain.  Tiles shorter than :data:`CUBIC_MAX_PX` (:data:`FINE_CUBIC_MAX_PX`
   at final and reference) read colours through a clamped cubic (one launch; sub-pixel
   smears take a closed form, below), the others bilinearly (another).
4. *Gather*: each work-item shades 4 pixels sharing the tile's ``v_n``.  Pixel ``x`` takes N
   samples ``y_i = x - v_n t_i`` with ``t_i`` stratified over ``[t0, t1]`` (midpoint, or one
   per-pixel jitter: interleaved gradient noise, shifted per frame).  With
   ``d = x - y``, the sample's smear reaches ``x`` if ``d . v_y / |v_y|`` lies in
   ``|v_y| [t0, t1]`` (and ``d`` is within a pixel of y's line of motion); its weight is the
   source length per sample (``|v_n| dt``) times the smear's density there (1 / its length,
   edges softened over one pixel or one sample spacing).  A soft depth test (2% of depth)
   sorts samples into *occluders* (in front of x) and the *layer behind* (same depth: weighted
   by their own smear; farther: by x's own smear, i.e. the background revealed behind x's
   blurred edge).  Output = occluders (normalised if their coverage exceeds 1) + the remaining
   coverage times the normalised layer behind, or times the centre pixel when no sample
   belongs to it.  For one uniform velocity this reduces to the exact box line blur of the
   reconstructed image; a constant image stays constant; static pixels next to moving ones
   keep their colour where nothing passes in front of them.  Lanes whose samples share one
   offset (no jitter, one velocity) read their colours together (a 4 x 7 block for the
   cubic, 2 x 5 for bilinear).

Short blurs (issue 11, "slow motion")
-------------------------------------
A smear of a pixel or two integrates the image over about a pixel, so how the image is
reconstructed between pixel centres decides the result: bilinear reads blur every sample by
up to a quarter pixel, as much again as the motion, and per-pixel jitter with two or three
samples is noise of the texture's full contrast; both ended 8-9 dB further from a
supersampled truth than the unblurred input on fine stripes moving 2 px/frame.  Short tiles
therefore use the midpoint rule and a Catmull-Rom blended with the tent by the smear's
length (tent up to 3/8 px, where the kinks of box-filtered edges dominate; full cubic from
half a pixel on: with the full cubic only from a whole pixel, fine stripes and grain moving
1 px/frame through a 180 degree shutter ended 2-8 dB below the input, issue 24), clamped per
channel to the 2 x 2 pixels around each read so it cannot ring
around HDR lights (the clamp adds a little energy to an isolated hot pixel: up to ~8%).

Where the tent would be read (a pixel's own smear ``L`` under 3/8 px, blended out by 1/2 px,
centred shutters), the average over the pixel's own surface is the closed form of a short
box instead (kernels/lib/motion.cl ``mb_short_smear``, per pixel, no tile switches): the
pixel plus ``c`` times the second difference along its motion, ``c = L^2 / 16`` (between a
smooth image's ``L^2 / 24`` and ``pi^2 L^2 / 96`` at the Nyquist frequency) or the tent's
``L / 8`` where the samples alternate along the motion and cannot place their edges (the
blocky, pixel-periodic walls of the layered bench).  The tent flattened fine texture moving
0.4-0.75 px/frame 3-20 dB below the unblurred input (its response at the Nyquist frequency
``1 - L / 2`` against the smear's ``sinc(L / 2)``); the closed form ends 0.07-3.2 dB above
it, and a per-tile second-order path tried before cost the walls 0.4-2 dB (issue 24).

Step edges (issue 35): a renderer's pixel is the box average of the scene over it, so where a
texture is flat patches with hard edges (a checker, print, text) the value of a pixel between
two different neighbours gives where the edge lies inside it, and moving such a row of cell
averages by less than a pixel is finite-volume advection.  Every smear under a pixel (fading
out by 1.5 px, centred shutters) therefore also takes the step model (kernels/lib/motion.cl
``mb_step_smear``: each cell rebuilt as a step between its neighbours that keeps its mean,
SLIC; extrema flat), along the pixel axes (the smear's two parts, plus the cross term of a
diagonal smear with the diagonal neighbours), weighted by how much the pixels around look like
plateaus beside edges (two neighbours within 0.1% of the largest step; no ramp of three steps
the same way, which a slanted or pre-filtered edge makes).  A neighbour behind the pixel is
what its moving edge reveals and enters flat.  An edge on a pixel boundary then spreads by
the tent's ``L / 8``, one inside a pixel stays there: a checker of 3 px squares drifting 1.7
px/frame ended 6 dB behind the naive bilinear line blur through the clamped cubic (exact on
pixel-aligned edges, 34.45 vs 40.54 dB at 320x180) and scores 40.55 with it; 2.5 px squares
35.73 -> 40.80 dB (naive 34.49).  Cycles' renders (a 1.5 px Blackman-Harris pixel filter: no
plateaus at the pixel scale) keep the linear reads.

Without a depth pass all pixels count as one depth (no occlusion ordering).  Reads outside
the images clamp to their edge: a caller that wants the blur to leave its data window passes
images already extended to the grown window.

References
----------
M. McGuire, P. Hennessy, M. Bukowski, B. Osman, "A reconstruction filter for plausible motion
blur", I3D 2012.  J. Jimenez, "Next generation post processing in Call of Duty: Advanced
Warfare", SIGGRAPH 2014 course.  J.-P. Guertin, M. McGuire, D. Nowrouzezahrai, "A fast and
stable feature-aware motion blur filter", HPG 2014.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace

import numpy as np

from clfx.core.camera import SHUTTER_OFFSETS as CAMERA_SHUTTER_OFFSETS
from clfx.core.camera import shutter_interval
from clfx.core.plugin import Level
from clfx.device.runtime import kernel_dir

KERNEL = "lib/motion.cl"

MAX_RADIUS_PX = 512
"""Hard cap of the blur radius (reach of one pixel's smear) in pixels, whatever the params:
a 1000 px/frame velocity is clamped to it (the tile size equals the radius)."""

SHUTTER_OFFSETS = ("camera",) + CAMERA_SHUTTER_OFFSETS
"""Choices of an effect's ``shutter_offset`` parameter: 'camera' = the camera block's."""

LOCAL = 64
"""Work-group size of the 1D gather launch (pinned: PoCL compiles one work-group function)."""

MIN_BLUR_PX = 0.1
"""Smears shorter than this (px over the shutter) count as no motion: such tiles are copied,
such pixels occlude nothing.  A renderer blurs a 0.4 px smear visibly at a sharp edge (a
tenth of the contrast), so the threshold sits well below half a pixel."""

CUBIC_MAX_PX = 8.0
"""Tiles whose blur is shorter than this (px) fetch colours through a clamped Catmull-Rom
instead of bilinearly (or nearest): over a short smear the reconstruction filter's own blur is
as large as the motion's, and only a sharper one brings the result closer to the truth than
the unblurred input."""

JITTER_SPACING_PX = 4.0
"""Per-pixel jitter only where samples lie farther apart than this along the blur (the
level's sample cap bites hard): denser samples use the midpoint rule, which is exact for a
linear image and has no noise; jitter turns the ghost copies of very sparse samples into
grain.  On the bench cases the midpoint rule scored 0.3-2.3 dB closer to the truth than
jitter at 1-4 px spacing (draft at 1920x1080: samples up to 3.75 px apart)."""


@dataclass(frozen=True)
class MotionLevel(Level):
    """What one quality level of the motion gather does."""

    max_samples: int = 32   # samples per pixel, at most
    spacing: float = 0.5    # target distance between samples along the blur, px
    bilinear: bool = True   # bilinear colour fetches on long blurs (else nearest)
    jitter: bool = True     # per-pixel jitter where the sample cap leaves samples sparse
                            # (else the midpoint rule everywhere: exact quadrature, may band)
    cubic_max_px: float = CUBIC_MAX_PX   # tiles with shorter blurs read through the cubic
    short_spacing: float = 0.0  # sample spacing on those tiles, px (0: ``spacing``)


def _summary(lvl: MotionLevel) -> str:
    return (f"up to {lvl.max_samples} samples per pixel (one per {lvl.spacing:g} px of the "
            f"tile's blur length, {lvl.short_spacing or lvl.spacing:g} px under "
            f"{SHORT_MAX_PX:g} px), {'bilinear' if lvl.bilinear else 'nearest'} colour fetches "
            f"(clamped cubic under {lvl.cubic_max_px:g} px), "
            f"{'float64' if lvl.fp64 else 'float32'} accumulation, midpoint rule"
            f"{f' (per-pixel jitter where samples are over {JITTER_SPACING_PX:g} px apart)' if lvl.jitter else ''}; "
            f"static tiles copied")


SHORT_SPACING_PX = 1.0
"""Sample spacing (px) at every level on tiles whose blur is under :data:`SHORT_MAX_PX` (read
through the clamped cubic): each read through the cubic smooths the texture a little (most
at half-pixel offsets), and more samples at more offsets summed more of it, so finer levels
ended further from the truth on short blurs (issue 35: Cycles' slow scene at 320x180, rel.
error 0.0243 draft, 0.0244 final, 0.0270 reference at spacings 1, 1/2, 1/4 px; 0.0243 at
every level with a sample per pixel)."""

SHORT_MAX_PX = 3.0
"""Blurs (px) under which tiles take :data:`SHORT_SPACING_PX`; longer ones keep the level's
spacing: small HDR lights streaking 6.7 px (``fast_light`` at 320x180) need their samples
(final 49.22 dB with them, 47.59 at a sample per pixel), as do Cycles' truck (0.0806 final,
0.0785 reference).  It was 2 px: the layered bench's 2.5 px blurs (5 px/frame) then took
2 and 4 samples per pixel at final and reference and ended worse than preview (rel. error
0.0232 / 0.0233 / 0.0237 for preview / final / reference at 320x180; 0.0231 at both with a
sample per pixel); on a band-limited texture moving 2.5-2.8 px in 8 directions the finer
spacing won in 4 and lost in 4, summed RMSE 0.0344 final, 0.0354 reference against 0.0335
at a sample per pixel (issue 35)."""


FINE_CUBIC_MAX_PX = 12.0
"""``final`` and ``reference``: tiles whose blur is shorter than this read through the clamped
cubic (the faster levels: :data:`CUBIC_MAX_PX`).  A bilinear read at offset ``a`` blurs by
the tent (variance ``a (1 - a)``).  At a sample per pixel (draft, preview) the reads of a
pixel's neighbours land near one offset and their weights ``1 - a`` and ``a`` add up to one
per pixel, so along a pixel axis the sum is the pixels' own box (no tent); at two or four
samples per pixel they land at every offset and the sum converges to the box convolved with
the tent: the finer levels blurred the texture more and ended worse than preview on Cycles'
pan (9-10 px blurs: rel. error 0.0721 preview, 0.0736 final, 0.0733 reference at 320x180;
through the cubic 0.0686 and 0.0683, log-PSNR 51.1 -> 51.9 and 51.9 dB) and on a band-limited
texture moving 9-11 px in 5 of 9 directions (through the cubic final beats preview in all 9:
RMSE 1.07x lower along the x axis, 2.2-3.3x on diagonals).  Longer blurs stay bilinear: up to 16 px, Cycles' truck's
final went 0.0806 -> 0.0813 (the clamp's energy on streaking lights); up to 12, 0.0806.
The clamp that keeps the cubic from ringing adds energy to an isolated hot pixel (6-12% on
a single 1e5 pixel streaking 3-11 px; 0% on bilinear tiles), as it did under 8 px before.
Cost: the cubic's 4 x 7 reads against bilinear's 2 x 5 on those tiles, the pan's final 184-191
-> 226-229 ms of CPU (reference 345-350 -> 420-426; truck and spin unchanged, 320x180)."""


LEVELS = {name: replace(lvl, summary=_summary(lvl)) for name, lvl in {
    "draft": MotionLevel("", max_samples=8, spacing=1.0, bilinear=True,
                         short_spacing=SHORT_SPACING_PX),
    "preview": MotionLevel("", max_samples=16, spacing=1.0, bilinear=True,
                           short_spacing=SHORT_SPACING_PX),
    "final": MotionLevel("", max_samples=32, spacing=0.5, bilinear=True,
                         cubic_max_px=FINE_CUBIC_MAX_PX, short_spacing=SHORT_SPACING_PX),
    "reference": MotionLevel("", fp64=True, max_samples=256, spacing=0.25, bilinear=True,
                             jitter=False, cubic_max_px=FINE_CUBIC_MAX_PX,
                             short_spacing=SHORT_SPACING_PX),
}.items()}
"""The quality levels of the motion gather, declared once (summaries: motion_blur's)."""


# -- shutter and geometry ----------------------------------------------------------------------
def shutter_from(p, camera) -> tuple[float, float]:
    """The shutter interval from the params' overrides (``shutter_angle`` < 0 and
    ``shutter_offset`` = 'camera' defer to it), else from the camera block."""
    angle = camera.shutter_angle if p.shutter_angle < 0 else p.shutter_angle
    offset = camera.shutter_offset if p.shutter_offset == "camera" else p.shutter_offset
    return shutter_interval(angle, offset)


def reach_factor(t0: float, t1: float) -> float:
    """How far (in frames of motion) a pixel's smear reaches from its own position."""
    return max(abs(t0), abs(t1))


def reach_px(peak_speed: float, t0: float, t1: float, max_radius_px: float) -> float:
    """How far (px) any pixel's smear reaches: the blur radius for a peak speed (px/frame),
    clamped to ``max_radius_px`` and :data:`MAX_RADIUS_PX`."""
    return float(min(max(peak_speed, 0.0) * reach_factor(t0, t1), max_radius_px, MAX_RADIUS_PX))


def tile_size(radius_px: float) -> int:
    """TileMax tile size: the blur radius rounded up to a multiple of 4, at least 8 px."""
    return int(max(8, 4 * math.ceil(min(radius_px, MAX_RADIUS_PX) / 4.0)))


def _arc_constant(name: str) -> float:
    """``#define <name> <value>f`` of kernels/lib/arc.h: the arc's constants have one copy,
    the kernels'."""
    m = re.search(rf"^#define {name} ([0-9.eE+-]+)f\b", (kernel_dir() / "lib/arc.h").read_text(),
                  re.MULTILINE)
    if m is None:
        raise RuntimeError(f"kernels/lib/arc.h defines no {name}")
    return float(m.group(1))


MIN_TURN = _arc_constant("ARC_MIN_TURN")
"""rad/frame: a path turning slower is the quadratic through its three positions."""

MAX_TURN = _arc_constant("ARC_MAX_TURN")
"""rad/frame: a path turning faster is taken as turning this fast."""


def turn_rate(forward, backward):
    """Turn rate (rad/frame, >= 0) of the circle through a point's positions at -1, 0 and +1
    frame: with ``s = f + b`` and ``e = f - b``, a point turning at ``w`` about a centre has
    ``e`` perpendicular to ``s`` and ``|e| / |s| = tan(w / 2)``; only ``e``'s part across
    ``s`` counts (a straight path that speeds up has ``e`` along ``s``: ``w = 0``)."""
    f, b = np.asarray(forward, np.float64), np.asarray(backward, np.float64)
    s, e = f + b, f - b
    cross = np.abs(s[..., 0] * e[..., 1] - s[..., 1] * e[..., 0])
    return np.minimum(2.0 * np.arctan2(cross, (s * s).sum(-1)), MAX_TURN)


def path(forward, backward, t):
    """Displacement (px) at time ``t`` (frames) of a point whose motion to the next frame is
    ``forward`` and from the previous one ``backward`` (px/frame, last axis x, y): the arc
    through its positions at -1, 0 and +1 frame at a constant turn rate ``w``
    (:func:`turn_rate`), ``A (f + b) / 2 + C (f - b) / 2`` with ``A = sin(w t) / sin(w)``,
    ``C = sin^2(w t / 2) / sin^2(w / 2)``; on a straight path (``w = 0``) the quadratic
    ``t (f + b) / 2 + t^2 (f - b) / 2``, and with ``f = b`` the line ``f t``.  A point on a
    turning surface follows its circle exactly (kernels/lib/arc.h, ``MB_ARC``); the
    quadratic through the same three positions cuts inside the arc and ends short (72
    deg/frame through a centred 180 degree shutter: 0.56 px off a 40 px radius and its ends
    2.9 px short; the line along the forward motion strays 7.9 px)."""
    f, b = np.asarray(forward, np.float64), np.asarray(backward, np.float64)
    w = turn_rate(f, b)[..., None]
    t = np.asarray(t, np.float64)
    t = t[..., None] if 0 < t.ndim < f.ndim else t      # per point, or already (..., 1)
    curved = w > MIN_TURN
    ws = np.where(curved, w, 1.0)
    a = np.where(curved, np.sin(ws * t) / np.sin(ws), t)
    c = np.where(curved, (np.sin(0.5 * ws * t) / np.sin(0.5 * ws)) ** 2, t * t)
    return a * 0.5 * (f + b) + c * 0.5 * (f - b)


@dataclass(frozen=True)
class BlurStats:
    """What one reconstruction did (for notes and benchmarks)."""

    tile: int
    radius_px: float
    tiles: int
    moving_tiles: int
    max_samples: int


def sanitized_copy(rt, src):
    """A copy of ``src`` with non-finite components set to 0 (so they cannot spread)."""
    out = src.like()
    knl = rt.kernel(KERNEL, "motion_sanitize")
    rt.launch(knl, (src.pitch // 4, src.height), src, out, src.pitch,
              src.height)
    return out


# -- tiled renders -----------------------------------------------------------------------------
GRID_CHUNK_PIXELS = 1 << 20
"""A tiled render builds the frame's velocity tiles (:func:`tile_grid`) from rows of about
this many pixels at a time."""


def path_reach(t0: float, t1: float, curved: bool) -> float:
    """The farthest any sample of the gather lies from its pixel, in units of the clamped
    speed ``vmax`` (px/frame): ``max |t|`` over the shutter on straight paths; on arcs
    (:func:`path`, forward and backward motion each at most ``vmax``) an upper bound of
    ``|A(t)| + |C(t)|`` over the shutter, its mirror ``-t`` (x's own samples) and every turn
    rate up to :data:`MAX_TURN` (a grid, 2 % slack)."""
    reach_t = reach_factor(t0, t1)
    if not curved:
        return reach_t
    w = np.linspace(0.0, MAX_TURN, 521)[:, None]
    t = np.linspace(-reach_t, reach_t, 401)[None, :]
    ws = np.where(w > MIN_TURN, w, 1.0)
    a = np.where(w > MIN_TURN, np.sin(ws * t) / np.sin(ws), t)
    c = np.where(w > MIN_TURN, (np.sin(0.5 * ws * t) / np.sin(0.5 * ws)) ** 2, t * t)
    return float((np.abs(a) + np.abs(c)).max()) * 1.02


@dataclass(frozen=True)
class TileGrid:
    """The frame's velocity tiles (TileMax, NeighborMax on a grid of ``k`` px from the canvas's
    origin) and the host's classification of the moving ones (samples, jitter, front-free,
    blur length): what every band of a tiled render reads (built once a frame in the step's
    plan, :func:`tile_grid`), or a whole render builds from its own buffers.  ``nmax_b``:
    the backward motion of each NeighborMax record's pixel.  Immutable: the host arrays are
    read-only."""

    k: int
    tiles_x: int
    tiles_y: int
    nmax: object
    nmax_b: object
    xs: np.ndarray
    ys: np.ndarray
    n: np.ndarray
    jitter: np.ndarray
    front_free: np.ndarray
    length: np.ndarray
    stats: BlurStats

    def __post_init__(self):
        for a in (self.xs, self.ys, self.n, self.jitter, self.front_free, self.length):
            a.flags.writeable = False


def is_static(t0, t1, radius) -> bool:
    """Nothing moves far enough to blur (at most :data:`MIN_BLUR_PX` over the shutter)."""
    reach_t = reach_factor(t0, t1)
    return reach_t <= 0.0 or radius * (t1 - t0) / reach_t < MIN_BLUR_PX


def _defines(level, has_depth: bool, curved: bool) -> dict:
    return dict(BILINEAR=int(level.bilinear), JITTER=int(level.jitter),
                HAS_DEPTH=int(has_depth), MIN_BLUR=f"{MIN_BLUR_PX!r}f",
                fp64=level.fp64, **({"CURVED": 1} if curved else {}))


def _prepared(rt, col, velocity, depth, back, defines, vmax, duration):
    """The aux records (vx, vy, z, |v|) of ``velocity`` (and ``back``'s: dummy without it),
    clamped to ``vmax``, dilated with a depth pass; over the rows the images hold."""
    pitch, w, h = col.pitch, col.width, col.height
    dummy = rt.buffer(16)
    aux = rt.image(col.window, 4)
    rt.launch(rt.kernel(KERNEL, "motion_prepare", **defines), (pitch // 4, h), velocity,
              depth if depth is not None else dummy, aux, pitch, h, vmax)
    auxb = dummy
    if back is not None:    # (bx, by, z, |b|), clamped like the forward motion
        auxb = rt.image(col.window, 4)
        rt.launch(rt.kernel(KERNEL, "motion_prepare", **defines), (pitch // 4, h), back,
                  depth if depth is not None else dummy, auxb, pitch, h, vmax)
    if depth is not None:   # rims of small bright moving surfaces move with them
        dilated = rt.image(col.window, 4)
        extra = ()
        if back is not None:   # the backward records follow the same choices
            dilated_b = rt.image(col.window, 4)
            extra = (auxb, dilated_b)
        rt.launch(rt.kernel(KERNEL, "motion_dilate", **defines), (pitch // 4, h), aux, col,
                  dilated, pitch, w, h, duration, *extra)
        aux = dilated
        if back is not None:
            auxb = dilated_b
    return aux, auxb


def _geometry(t0, t1, max_radius_px, peak_speed):
    """(radius px, tile size, clamped speed px/frame) of a reconstruction."""
    radius, reach_t = reach_px(peak_speed, t0, t1, max_radius_px), reach_factor(t0, t1)
    return radius, tile_size(radius), (radius / reach_t if reach_t > 0.0 else 0.0)


def _grid_buffers(rt, w, h, k, curved):
    """The tile grid's size and buffers: TileMax records, their backward motion (CURVED) and
    the tiles' depth ranges."""
    tx, ty = -(-w // k), -(-h // k)
    bufs = (rt.buffer(tx * ty * 16), rt.buffer(tx * ty * 8) if curved else rt.buffer(16),
            rt.buffer(tx * ty * 8))
    return tx, ty, bufs


def _tilemax(rt, defines, aux, auxb, tiles, pitch, w, h, row0, tx, ty, ty0, ty1, k):
    rt.launch(rt.kernel(KERNEL, "motion_tilemax", **defines), (tx, ty1 - ty0), aux, auxb,
              *tiles, pitch, w, h, row0, tx, ty, ty0, k)


def _front_free(zrange: np.ndarray, k: int, reach: float) -> np.ndarray:
    """Per tile: no pixel the gather's samples (within ``reach`` px of their pixel) or the
    closed forms' taps (2 px) can read lies in front of any of the tile's pixels: the
    tile's largest depth is at most the smallest of the tiles around it, so every soft
    depth test of its gather gives exactly 0 (kernels/lib/motion.cl, motion_gather).
    ``zrange``: (tiles_y, tiles_x, 2) smallest and largest depth per tile.  A sample at
    ``x + 0.5 - d`` reads the pixel ``floor`` of it, within ``floor(|d| + 0.5)`` px of ``x``
    (a little slack for the float32 clamp of the speeds)."""
    px = max(math.floor(reach * (1.0 + 1e-4) + 0.5), 2)
    m = -(-px // k)                                   # tiles around a tile the reads reach
    lo = np.pad(zrange[..., 0], m, constant_values=np.inf)
    ty, tx = zrange.shape[:2]
    rows = np.min([lo[i:i + ty] for i in range(2 * m + 1)], axis=0)
    near = np.min([rows[:, j:j + tx] for j in range(2 * m + 1)], axis=0)
    return zrange[..., 1] <= near


def _classified(rt, defines, tiles, tx, ty, k, radius, t0, t1, level, curved) -> TileGrid:
    """NeighborMax of the TileMax grid ``tiles`` and the moving tiles' sample counts."""
    nmax = rt.buffer(tx * ty * 16)
    nmax_b = rt.buffer(tx * ty * 8) if curved else rt.buffer(16)
    rt.launch(rt.kernel(KERNEL, "motion_neighbormax", **defines), (tx, ty), tiles[0],
              tiles[1], nmax, nmax_b, tx, ty)
    # Classification on the host: a few thousand floats, the only read-backs.
    nm = rt.from_device(nmax, np.float32, tx * ty * 4).reshape(ty, tx, 4)
    length = nm[..., 2].astype(np.float64) * (t1 - t0)     # blur length of the tile's v_n
    ys, xs = np.nonzero(length >= MIN_BLUR_PX)
    length = length[ys, xs]
    zrange = rt.from_device(tiles[2], np.float32, tx * ty * 2).reshape(ty, tx, 2)
    reach_t = reach_factor(t0, t1)
    free = _front_free(zrange, k, path_reach(t0, t1, curved) * radius / reach_t)[ys, xs]
    spacing = np.where(length < min(level.cubic_max_px, SHORT_MAX_PX),
                       level.short_spacing or level.spacing, level.spacing)
    n = np.clip(np.ceil(length / spacing), 2, level.max_samples).astype(np.int32)
    jitter = (level.jitter & (length / n > JITTER_SPACING_PX)).astype(np.int32)
    stats = BlurStats(k, radius, tx * ty, int(xs.size), int(n.max()) if n.size else 0)
    return TileGrid(k, tx, ty, nmax, nmax_b, xs, ys, n, jitter, free, length, stats)


def tile_grid(rt, rows_of, *, width: int, height: int, t0: float, t1: float,
              max_radius_px: float, peak_speed: float, level: MotionLevel, has_depth: bool,
              curved: bool) -> TileGrid | None:
    """The frame's :class:`TileGrid` over a canvas of ``width`` x ``height`` px, built from
    rows of it at a time (about :data:`GRID_CHUNK_PIXELS`, whole tile rows): ``rows_of(r0,
    r1)`` gives ``(colour, velocity, depth, back)`` images over the canvas rows ``r0 <= y <
    r1`` as the whole render fills them (colour sanitised; depth and back None where the
    render has none), and each chunk holds a row more on each side for the dilation, so its
    records are the whole render's.  None when nothing moves (every band is a copy)."""
    radius, k, vmax = _geometry(t0, t1, max_radius_px, peak_speed)
    if width == 0 or height == 0 or is_static(t0, t1, radius):
        return None
    defines = _defines(level, has_depth, curved)
    tx, ty, tiles = _grid_buffers(rt, width, height, k, curved)
    step = max(1, GRID_CHUNK_PIXELS // max(width * k, 1))     # tile rows a chunk
    for ty0 in range(0, ty, step):
        ty1 = min(ty0 + step, ty)
        r0, r1 = max(ty0 * k - 1, 0), min(ty1 * k + 1, height)
        col, vel, depth, back = rows_of(r0, r1)
        aux, auxb = _prepared(rt, col, vel, depth if has_depth else None,
                              back if curved else None, defines, vmax, t1 - t0)
        _tilemax(rt, defines, aux, auxb, tiles, col.pitch, width, height, r0, tx, ty, ty0, ty1,
                 k)
        del col, vel, depth, back, aux, auxb
    return _classified(rt, defines, tiles, tx, ty, k, radius, t0, t1, level, curved)


def reconstruct(rt, src, velocity, depth=None, *, t0: float, t1: float, max_radius_px: float,
                peak_speed: float, level: MotionLevel, frame: int = 0, nonfinite: int = 0,
                velocity_back=None, grid: TileGrid | None = None, row0: int = 0,
                band: tuple[int, int] | None = None):
    """Motion blur of ``src`` from a velocity field (and optional depth) on the device.

    Parameters
    ----------
    rt : Runtime
    src : DeviceImage
        RGBA, scene-linear premultiplied.
    velocity : DeviceImage
        2 channels, forward px/frame, same window as ``src``.
    depth : DeviceImage or None
        Planar depth, same window; None = one depth for all pixels.
    t0, t1 : float
        Open shutter in frames relative to the frame time.
    max_radius_px : float
        Largest reach of a pixel's smear in px (velocities are clamped to it).
    peak_speed : float
        Largest speed in the pass, px/frame (sizes the tiles; need not be exact, an upper
        bound works, it is clamped to ``max_radius_px``).
    level : MotionLevel
        Samples, fetches and precision (one of :data:`LEVELS`, or an effect's copy).
    frame : int
        Shifts the jitter pattern per frame.
    nonfinite : int
        Number of non-finite source pixels (> 0 makes a sanitised copy first).
    velocity_back : DeviceImage or None
        Backward motion, px/frame (current - previous position, +y down), same window: with
        it every path is the arc through the previous, current and next positions at a
        constant turn rate (:func:`path`); without it, the straight line along ``velocity``.
    grid, row0, band
        A band of a tiled render: the images hold the canvas rows from ``row0`` on (the
        band's rows ``band = (y0, y1)`` and `clfx.kit.motion.band_margin` rows around them,
        as the whole render fills them), ``grid`` is the frame's (:func:`tile_grid`); the
        band's rows are the whole render's, the rest of the output is the (sanitised) input.
        Default: the images are the whole canvas, and its grid is built from them.

    Returns
    -------
    (DeviceImage, BlurStats)
    """
    w, h, pitch = src.width, src.height, src.pitch
    radius, k, vmax = _geometry(t0, t1, max_radius_px, peak_speed)
    col = sanitized_copy(rt, src) if nonfinite else src
    dst = rt.copy(col)
    if w == 0 or h == 0 or is_static(t0, t1, radius):
        return dst, BlurStats(0, radius, 0, 0, 0)
    curved = velocity_back is not None
    defines = _defines(level, depth is not None, curved)
    aux, auxb = _prepared(rt, col, velocity, depth, velocity_back, defines, vmax, t1 - t0)
    if grid is None:
        tx, ty, tiles = _grid_buffers(rt, w, h, k, curved)
        _tilemax(rt, defines, aux, auxb, tiles, pitch, w, h, 0, tx, ty, 0, ty, k)
        grid = _classified(rt, defines, tiles, tx, ty, k, radius, t0, t1, level, curved)
        del tiles
    k = grid.k
    y0, y1 = band if band is not None else (row0, row0 + h)
    sel = (grid.ys * k < y1) & ((grid.ys + 1) * k > y0)     # the moving tiles of the band
    if not sel.any():
        return dst, grid.stats
    short = grid.length < level.cubic_max_px
    qpt = k * k // 4
    for part, cubic in ((sel & short, 1), (sel & ~short, 0)):
        if not part.any():       # one launch per fetch filter
            continue
        flags = grid.jitter[part] | (grid.front_free[part].astype(np.int32) << 1)
        table = rt.to_device(np.stack([grid.xs[part], grid.ys[part], grid.n[part], flags],
                                      axis=1).astype(np.int32).ravel())
        count = int(part.sum())
        rt.launch(rt.kernel(KERNEL, "motion_gather", CUBIC=cubic, **defines),
                  (count * qpt,), col, aux, auxb, grid.nmax, grid.nmax_b, table, count,
                  dst, pitch, w, row0, row0 + h, y0, y1,
                  grid.tiles_x, k, t0, t1, frame, local=(LOCAL,))
    return dst, grid.stats
