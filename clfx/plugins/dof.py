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

Lens geometry in the bokeh (camera block values, each off by default and free when off; the
ground-truth renderer models the same optics):

- Optical vignetting (cat-eye bokeh), ``Camera.optical_vignetting`` (``optical_vignetting``
  overrides it; -1 = the camera's): the aperture intersected with the lens barrel, a second
  circle of the same radius shifted by ``strength * (pixel - optical centre) / half
  diagonal`` aperture radii (x pixels; the optical centre is the display window's): round
  at the centre, a cat's eye with its long axis tangential towards the edges.  The gather
  clips each tap with the destination pixel's barrel (the shape varies smoothly over a
  bokeh; the ground truth clips its lens rays per destination pixel the same way) and the
  near field's weights divide by the clipped area, so a flat field stays flat: the
  darkening belongs to the ``vignette`` effect.  A point's light drifts by about
  ``strength * r / half diagonal`` of its energy (the destination's barrel standing for the
  point's).  That circle is the rim behind the stop; ``Camera.optical_vignetting_front``
  (``optical_vignetting_front``) is the front rim, the same strength with the circle shifted
  towards the optical centre.  Both: the aperture cut by the two circles, a lemon pointed
  at both ends (the two circles' intersection lies inside the aperture, so its area is one
  lens of two unit circles ``(front + rear) * |pixel - centre| / half diagonal`` apart).
  Build variant ``DOF_CATEYE`` (1: one circle, 2: both).
- Anamorphic squeeze, ``Camera.anamorphic_squeeze`` (``anamorphic_squeeze``; 0 = the
  camera's): in the desqueezed image the bokeh is the thin-lens CoC high and CoC / squeeze
  wide (vertical ovals).  Radii stay in x pixels and the tap tables measure offsets in
  aperture space ``(ox * squeeze, oy / pixel aspect)``, so squeeze and pixel aspect compose.
- Axial (longitudinal) chromatic aberration, ``Camera.axial_ca_red`` / ``axial_ca_blue`` (um,
  the channel's focus behind green's; ``axial_ca_red`` / ``axial_ca_blue`` add to them): a
  focus shift ``delta`` changes the signed CoC diameter by ``-delta / N`` on the sensor
  (:meth:`clfx.core.camera.Camera.axial_ca_px`), an additive per-channel offset of the
  signed radius.  Each distinct offset gets its own gather (``dof_prepare`` adds it; tiles,
  reach and region of definition include it), merged by ``dof_merge_channels`` (alpha from
  green): 2 gathers for an achromat (red and blue together), 3 otherwise.

Algorithm (after Jimenez 2014, "Next generation post processing in Call of Duty: Advanced
Warfare", simplified for offline use)
1. ``dof_prepare``: sanitised colour and signed CoC radius into a padded buffer (the edge
   pixels repeated past the frame).  What lies past the frame edge is unknown: the padding's
   colours are capped in luminance like the hidden background's (``CAP_FACTOR`` times the
   geometric mean of the tiles around the edge pixel, below), so a light on the edge row
   gives the half of its bokeh that falls inside the frame instead of a streak of copies a
   CoC radius tall (at 45 px of CoC, the issue 35 case's largest error).
2. ``dof_edges``: edge-aware radii.  Renderers write an antialiased beauty but a depth taken
   at the pixel centre, so a light beside a blurred foreground bar has pixels that mix the
   light with the bar and carry the bar's depth; spread with the bar's CoC they make a
   bright half-disk.  A pixel on a depth edge (its 3 x 3 radii span a pixel or more) whose
   log luminance is far (> 0.5) from the median of its own layer's neighbours takes the
   radius of the other layer's neighbour that looks most like it, when that layer is the
   sharper one: the light stays a sharp light, partly covered by the bar's blur.
3. ``dof_mixed``: mixed edge pixels.  The same antialiased beauty over a centre-sampled depth
   puts the in-focus card's edge row (part card, part sky) under the sky's depth; gathered
   with the sky's radius, its card part makes a soft copy of the card in the sky beyond the
   edge (issue 32).  A pixel on a depth discontinuity (its 3 x 3 edge-aware radii have a gap
   of a pixel or more, twice the rest of their range: two layers, not a steep ramp) whose
   colour lies between a near neighbour's and a far neighbour's (projected on the segment
   between them: coverage ``a`` in (0.02, 0.98), off it by at most a quarter of its
   distance to either end; of such pairs the one farthest apart in colour) is split: its
   near part ``C + (1 - a)(n - f)`` with the near neighbour's radius standing for ``a`` of
   the pixel, its far part ``C - a (n - f)`` with the far one's for ``1 - a`` (they mix back
   to ``C``); each part estimates a layer's colour, so a part below ``min(0, C, n, f)``
   in a channel is set to that bound and the other takes up the difference (still ``C``
   mixed: a rim over transparent black gave a far part of negative blue, spread into the
   blurred background).  In the dense gathers each part is a tap of its own radius
   weighted by its coverage, and a mixed pixel is gathered twice, as its far part and as
   its near part (at its own centre only that part), blended by ``a``: an in-focus edge
   stays sharp, the sky behind it stays clean.  The gather reads the split data only
   within reach of a 32 px tile holding a mixed pixel; the report says how many were
   split.  (The sparse lattice and the half-resolution gather read prefiltered colours and
   do not split.)
4. Tiles (32 px, the shared scene analysis): the largest CoC radius a tile's depth range can
   produce, dilated on the host over as many tiles as the largest radius reaches (3 x 3 for
   radii up to a tile); tiles whose neighbourhood maximum is below half a pixel are copied
   (and the whole frame is an identity when every tile is).  Per tile also the largest
   radius of a pixel in front of the focus plane within reach: 4 pixels in focus (or
   nearly: every CoC radius below the level's ``sharp_radius``) gather over only that and
   their own radius, with a table whose far field is every pixel within ``sharp_radius``
   (their own blur is no wider) and whose near field is the lattice below when the near
   blur is large (:func:`tap_table`'s ``core``): an in-focus subject beside a 40 px
   foreground post stays sharp instead of taking the lattice's prefilter tent.  In a group
   of 4 that also holds out-of-focus pixels under a sparse lattice, the pixels in focus or
   nearly take that table's gather too (the group is gathered twice): the lattice's centre
   tap gave an in-focus edge against a 41 px background its own pixels through the tent.
5. ``dof_gather``: taps over the neighbourhood radius ``R``: every pixel of the disk up to
   the level's ``dense_radius`` (a single bright pixel spreads into an evenly lit disk with
   an antialiased rim), beyond that a lattice of every 2nd, 4th, ... pixel (at most the
   level's ``lattice`` taps per radius) over a copy of the image prefiltered with the tent
   of the lattice's spacing (``dof_prefilter``, a binomial a-trous pyramid: the tents of a
   lattice sum to 1, so a bright pixel still spreads into an evenly lit disk and no
   sampling pattern shows at any radius; :func:`tap_table`); two fields per pixel:
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
   A table lists its taps nearest first, and the gather stops it where no tap can add light
   any more (:func:`tap_counts`): where none of the 4 pixels lies in front of the focus
   plane, at the largest of their radii and of the near-field radii its taps can read (per
   tile, from the depth ranges of the tiles within their reach whose near radius reaches
   back to a tap that reads them, :func:`near_bounds`, with a float32 margin).  The
   taps left out add exact zeros (the same bits): on the 1080p bench frame at final the
   in-focus pixels' taps went from 4.1 to 0.5 million (groups of 4).
6. Tiles whose every pixel is far out of focus (CoC radius above the level's
   ``half_res_radius``) are also gathered at half resolution (``dof_down2``: 2 x 2 box of
   colour, mean radius halved; the same gather with half the radius) and upsampled
   bilinearly, except where the half-resolution pixels span more than the level's
   ``refine`` in log luminance (the rim of a bokeh disk: a highlight's rim stays as crisp
   as the full-resolution gather's, no light leaks outside it) or a pixel is sharper (an
   edge-aware radius): there the full-resolution gather runs.  The upsampling reads only
   half-resolution pixels of half-resolution tiles (the others hold the unblurred source;
   the weights of the rest are renormalised): a half-resolution tile's edge pixels took a
   quarter of the sharp lamps of the tile beside it (up to 10x the truth on the issue 35
   Cycles case, where a sparse table does not gather them again).

Each work-item gathers 4 adjacent pixels with shared tap offsets (float16 vectors), 4 taps
at a time (their weights for the 4 pixels as float16 lanes, each tap's sums added in table
order: the same bits as tap by tap) unless a mixed edge pixel is within reach (tap by tap:
a split pixel is two taps); the
per-pixel passes (``dof_prepare``, ``dof_edges``, ``dof_mixed``) take 16 pixels per work-item,
with vector loads where they lie inside the image and hold no depth edge (PoCL does not
vectorise those work-items itself).  Finite
colours give finite results: a gather whose float sums overflow (values near 3e38) is taken
again with every colour scaled by 2^-64, and the box and the bilinear weights are applied
before summing.

Light leaves the data window: the region of definition grows by the largest CoC radius the
frame's depth range can produce (the tiles of the shared scene analysis; the ``max_coc``
clamp without them).  When the output window is larger than the source window (a data window
tighter than the display window), the beauty is extended with transparent black and the
depth by its edge values, and the tiles are taken over the grown window.

Tiled renders (`clfx.pipeline.look.render_tiled`) give the whole render's bits: everything
frame-wide is computed once, on the whole frame, in the step's plan (:class:`DofFrame`: the
tile radii, lattice levels, half-resolution choice, tap and tile tables, the tiles' caps, on
a grid anchored at the rendered window's origin), and a band gathers only its own rows,
from band-sized buffers over the rows its pixels read (:meth:`DofFrame.rows`: the largest
reach of a tap, its prefilter tent or the two rows its mixed-pixel split reads, and of the
half-resolution pixels its upsampling reads, starting on an even row so the 2 x 2 boxes
pair the whole render's rows).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from clfx.core.camera import BLADES_WHY, NO_POLYGON, aperture_radius, coc_signed, first_blade_angle
from clfx.core.errors import ParamError
from clfx.core.limits import DEVICE_BYTES_PER_PIXEL, check_derived
from clfx.core.plugin import ChoiceParam, Clip, Descriptor, FloatParam, IntParam, Level
from clfx.core.rect import Rect
from clfx.fx.analysis import TILE, analyse  # dof's tiles are the shared analysis's
from clfx.host import Plugin, StepPlan, read_only, register

FLT_MAX = float(np.finfo(np.float32).max)
LOCAL = (8, 4)      # work-group: 32 x 4 pixels, one tile wide
BAND_PIXELS = 1 << 22
"""Pixels per band of the analysis of a frame grown past its data window (`Dof.frame`)."""


class Lens(NamedTuple):
    """A frame's lens in pixels."""

    k_half: float        # CoC radius at infinity (K / 2), px
    focus: float         # focus distance, scene units
    clamp_r: float       # largest CoC radius (max_coc / 2 x diagonal), px
    blades: int          # aperture blades (< 3: round)
    first: float         # direction of the first blade's vertex, radians
    squeeze: float = 1.0            # anamorphic squeeze: bokeh height / width
    cateye: float = 0.0             # optical vignetting: barrel offset at the corner, radii
    ca: tuple = (0.0, 0.0)          # red, blue signed CoC radius offsets (axial CA), px
    cateye_front: float = 0.0       # front rim's offset at the corner (towards the centre)

    def cateye_strengths(self) -> tuple:
        """The signed strengths of the clipping circles (rear: +cateye, its circle shifted
        away from the optical centre; front: -cateye_front, towards it), the ones in use."""
        return tuple(k for k in (self.cateye, -self.cateye_front) if k)

    def offsets(self) -> tuple:
        """The distinct per-channel radius offsets, green's (0) first: one gather each."""
        return tuple(dict.fromkeys((0.0, *self.ca)))


def _over_channels(radii: tuple, with_near: bool = False):
    """The tile radii of a plan's channels ``((offset, (r_max, r_min, near)), ...)`` taken
    together: the largest ``r_max`` and ``near``, the smallest ``r_min`` (``r_max`` alone
    without ``with_near``)."""
    parts = [r for _, r in radii]
    if len(parts) == 1:
        return parts[0] if with_near else parts[0][0]
    r_max = np.maximum.reduce([r[0] for r in parts])
    if not with_near:
        return r_max
    return (r_max, np.minimum.reduce([r[1] for r in parts]),
            np.maximum.reduce([r[2] for r in parts]))


@dataclass(frozen=True)
class DofPlan(StepPlan):
    """dof's plan for one step of a frame, complete before any band renders: the lens; per
    channel offset, over the frame's analysis window, the tile radii (`Dof.tile_radii`:
    ``(offset, (r_max, r_min, near))``) and the gather's radii with the lattice level of the
    largest (`Dof.gather_radii`: ``(offset, (levels, level))``), read-only; how far light
    spreads (`Dof.spread_px`); and, unless the step is an identity, the frame's
    :class:`DofFrame` (`Dof.frame`), built on the whole frame."""

    lens: Lens | None = None
    radii: tuple = ()
    gathers: tuple = ()
    spread: tuple = (0, 0)
    frame: DofFrame | None = None


@dataclass(frozen=True)
class DepthTiles:
    """What dof reads of a window's scene analysis (`clfx.fx.analysis`): per 32 px tile of
    ``window`` the depth range and invalid-depth count, and the frame's non-finite pixels."""

    window: Rect
    min_depth: np.ndarray | None
    max_depth: np.ndarray | None
    bad_depth: np.ndarray | None
    nonfinite_count: int = 0


@dataclass(frozen=True)
class DofGather:
    """One gather (one channel radius offset) of a frame, on the tile grid of the whole
    render's window: everything a band of a tiled render reads instead of deriving it again
    (:meth:`Dof.frame`)."""

    offset: float
    full_l: int               # lattice level of the largest: the prefilter pyramid's depth
    half: np.ndarray          # per tile: gathered at half resolution
    half_l: int               # the half-resolution pyramid's depth
    pad: int                  # the padded buffers' border (px)
    taps: object              # (device tap table, its column stride) and per-tile table
                              # of the full-res gather
    tiles: object
    htaps: object             # ... of the half-resolution gather (None without)
    htiles: object
    reach: int                # rows a full-res pixel reads around it (taps, prefilter, edges)
    hreach: int               # half-res rows a half-res pixel reads around it (0: none)
    note: str


@dataclass(frozen=True)
class DofFrame:
    """Frame-wide values of one step, computed once on the whole frame (`Dof.frame`) and read
    by the whole render and by every band of a tiled one: the window rendered (``window``,
    the tile grid's origin), its tiles' hidden-background caps (``log_mean``, on the
    device), one :class:`DofGather` per channel offset, the report's lines."""

    window: Rect
    tiles_x: int
    tiles_y: int
    log_mean: object
    gathers: tuple
    notes: tuple
    warning: str | None

    def gather(self, offset: float) -> DofGather:
        """The :class:`DofGather` of the channel radius ``offset``."""
        return next(g for g in self.gathers if g.offset == offset)

    def rows(self, y0: int, y1: int) -> tuple[int, int]:
        """The rows (frame coordinates, not cut to the window) a band's render reads to give
        rows ``y0``..``y1`` of the whole render: each gather's reach around them, and around
        the half-resolution rows their upsampling reads (a 2 x 2 box of rows each, with the
        edge-aware radii's row beyond), widened to even rows of the grid (the
        half-resolution pixels pair the whole render's rows)."""
        top, bottom = y0 - self.window.y0, y1 - self.window.y0
        lo, hi = top, bottom
        for g in self.gathers:
            lo, hi = min(lo, top - g.reach), max(hi, bottom + g.reach)
            if g.hreach:
                h0, h1 = self.half_rows(top, bottom)
                lo = min(lo, 2 * (h0 - g.hreach) - 1)
                hi = max(hi, 2 * (h1 + g.hreach) + 1)
        lo, hi = lo // 2 * 2, -(-hi // 2) * 2
        return self.window.y0 + lo, self.window.y0 + hi

    @staticmethod
    def half_rows(top: int, bottom: int) -> tuple[int, int]:
        """The half-resolution rows (grid, from 0) that the bilinear upsampling of rows
        ``top``..``bottom`` (grid) reads (``dof_upsample4``), not cut to the frame."""
        return (top - 1) // 2, (bottom + 1) // 2 + 1


@dataclass(frozen=True)
class DofLevel(Level):
    """What one quality level of the gather does."""

    lattice: int = 12                 # beyond dense_radius: at most this many taps per radius
    dense_radius: float = 16.0        # radii up to this: every pixel of the disk is a tap
    half_res_radius: float = 6.0      # tiles whose every CoC radius is >= this: half resolution
    refine: float = math.inf          # log-luminance span that a half-res pixel gathers again
    sharp_radius: float = 6.0         # 4 pixels all below this CoC radius (none in front of
    #                                   the focus plane) gather with the tile's sharp table:
    #                                   every pixel within it a far-field tap (tap_table's core)


LEVELS = {
    "draft": DofLevel("every pixel of the disk a tap up to 16 px radius, then a lattice of at "
                      "most 10 taps per radius over a prefiltered copy (pixels under 3 px of "
                      "CoC: every pixel of their own blur); half resolution where "
                      "every CoC radius >= 3 px, only strong bokeh rims gathered again at full "
                      "resolution; float32 sums",
                      lattice=10, dense_radius=16.0, half_res_radius=3.0, refine=1.0,
                      sharp_radius=3.0),
    "preview": DofLevel("every pixel of the disk a tap up to 16 px radius, then a lattice of at "
                        "most 16 taps per radius over a prefiltered copy (pixels under 3 px of "
                        "CoC: every pixel of their own blur); half resolution where "
                        "every CoC radius >= 3 px, bokeh rims gathered again at full "
                        "resolution; float32 sums",
                        lattice=16, dense_radius=16.0, half_res_radius=3.0, refine=0.5,
                        sharp_radius=3.0),
    "final": DofLevel("every pixel of the disk a tap up to 32 px radius, then a lattice of at "
                      "most 32 taps per radius over a prefiltered copy (pixels under 6 px of "
                      "CoC: every pixel of their own blur); half resolution where "
                      "every CoC radius >= 6 px, bokeh rims and other contrasts over 0.15 in "
                      "log luminance gathered again at full resolution; float32 sums",
                      lattice=32, dense_radius=32.0, half_res_radius=6.0, refine=0.15),
    "reference": DofLevel("every pixel of the disk a tap up to 32 px radius, then a lattice of "
                          "at most 32 taps per radius over a prefiltered copy (pixels under "
                          "6 px of CoC: every pixel of their own blur), all at full "
                          "resolution, float64 sums",
                          fp64=True, lattice=32, dense_radius=32.0, half_res_radius=math.inf,
                          sharp_radius=6.0),
}

CAP_FACTOR = 4.0
"""Background hidden behind a blurred foreground pixel is filled in from the visible
background around, its colours capped at this many times the geometric mean luminance of
the tiles around (so a light beside a blurred bar does not shine through it); the edge
pixels repeated past the frame edge are capped the same way."""
MIXED_NOTE = " mixed edge pixels split"
"""The end of the report's line of the mixed edge pixels split (``dof_mixed``)."""


def lens_scale_px(p, camera, ctx_diag: float, width_px: float) -> float:
    """``K``: the CoC diameter in pixels at infinity, from the camera (with this effect's
    f-number and focus overrides) or ``max_blur``."""
    if p.coc_source == "max_blur":
        return p.max_blur * ctx_diag
    return camera.updated(f_number=p.f_number or camera.f_number,
                          focus_distance=focus_distance(p, camera)).coc_scale_px(width_px)


def focus_distance(p, camera) -> float:
    return p.focus_distance or camera.focus_distance


def coc_radius(depth, k_half: float, focus: float, clamp_r: float, offset: float = 0.0):
    """Signed CoC radius in px for planar depths (float64 NumPy; same rules as the kernel),
    plus a channel's axial-CA ``offset`` (px; invalid depths are in the focus plane)."""
    return np.clip(coc_signed(depth, k_half, focus) + offset, -clamp_r, clamp_r)


def lattice_level(radius: float, lattice: int, dense: float) -> int:
    """The prefilter level ``L`` of a neighbourhood radius (px): 0 (every pixel a tap) up to
    ``dense``, beyond it the smallest ``L >= 1`` whose lattice spacing ``2^L`` puts at most
    ``lattice`` taps along the radius."""
    if radius <= dense:
        return 0
    return max(1, int(math.ceil(math.log2(radius / max(lattice, 1)) - 1e-9)))


def lattice_levels(radii: np.ndarray, lattice: int, dense: float) -> np.ndarray:
    """:func:`lattice_level` of each of ``radii`` (int64, their shape), worked out once per
    distinct radius: a frame's tiles hold a handful (``np.vectorize`` called it for each of
    1080p's 2040 tiles, 1.5 ms a call and four calls a frame, before any gather could start)."""
    values, inverse = np.unique(np.asarray(radii, np.float64), return_inverse=True)
    per = np.empty(len(values), np.int64)
    for i, r in enumerate(values.tolist()):
        per[i] = lattice_level(r, lattice, dense)
    return per[inverse].reshape(np.shape(radii))


NEVER = 1e30
"""A tap's near or far distance that no coverage reaches: the tap serves the other field only."""


def tap_table(radius: float, lattice: int, aspect: float = 1.0, blades: int = 0,
              first: float = -0.5 * math.pi, roundness: float = 0.0,
              dense: float = 0.0, squeeze: float = 1.0, core: float = 0.0) -> np.ndarray:
    """The gather's taps for a neighbourhood radius ``radius`` (px): (n, 8) float32 rows of
    (offset x, offset y, near distance, far distance, area, aperture x, aperture y, level).

    Distances and areas are measured in aperture space: an offset ``(ox, oy)`` in pixels is
    ``(ox * squeeze, oy / aspect)`` there (x pixels of the CoC radius; the anamorphic
    ``squeeze`` makes the bokeh ``squeeze`` times narrower than high, the pixel ``aspect``
    stretches it over more rows), columns 5 and 6.  The taps are the points of a square
    lattice of spacing ``s = 2^L`` px (``L``: :func:`lattice_level`, column 7) within
    ``radius + s / 2`` there, each standing for its own area (``s^2 squeeze / aspect``): up to
    ``dense`` px every pixel (``L = 0``), so a single bright pixel spreads into an evenly lit
    disk; beyond, every ``s``-th pixel of a copy of the image prefiltered with the tent of
    half-width ``s`` (``dof_prefilter``: level ``L`` of a binomial a-trous pyramid).  The
    tents of a lattice of spacing ``s`` sum to 1 everywhere, so a bright pixel still spreads
    into an evenly lit disk (no sampling pattern, whatever the radius) and its rim, whose
    coverage ramp is ``s`` px wide for these taps, is a smooth ramp instead of a staircase.
    Distances are divided by the aperture's boundary radius in the direction of ``o`` (near
    taps: bokeh turned 180 degrees) or ``-o`` (far taps).

    ``core`` (px, > 0): the table of pixels in focus or nearly (CoC radius below ``core``)
    in a tile within reach of a larger near-field blur.  Their far field reaches no farther
    than their own radius, which a sparse lattice would blur by its tent (an in-focus
    subject beside a 40 px foreground post went soft, issue 35): with a lattice (``L > 0``)
    its taps serve the near field only (far distance :data:`NEVER`), and every pixel within
    ``core + 1/2`` (aperture space, ``L = 0``) serves the far field only (near distance
    :data:`NEVER`), listed first (the centre first).
    """
    level = lattice_level(radius, lattice, dense)
    s = 1 << level
    e = int(math.floor((radius + 0.5 * s) / squeeze / s))
    ey = int(math.floor((radius + 0.5 * s) * aspect / s))
    oy, ox = (np.mgrid[-ey:ey + 1, -e:e + 1] * s).astype(np.float64)
    keep = np.hypot(ox * squeeze, oy / aspect) <= radius + 0.5 * s
    ox, oy = ox[keep], oy[keep]
    order = np.lexsort((ox, oy, np.hypot(ox * squeeze, oy / aspect)))   # centre first
    ox, oy = ox[order], oy[order]
    area = np.full(ox.shape, s * s * squeeze / aspect)
    dx, dy = ox * squeeze, oy / aspect
    d = np.hypot(dx, dy)
    phi = np.arctan2(dy, dx)
    table = np.zeros((len(ox), 8), np.float32)
    table[:, 0], table[:, 1] = ox, oy
    table[:, 2] = d / aperture_radius(phi, blades, first, roundness)
    table[:, 3] = d / aperture_radius(phi + math.pi, blades, first, roundness)
    table[:, 4] = area
    table[:, 5], table[:, 6] = dx, dy
    table[:, 7] = level
    if level == 0 or not 0.0 < core < math.inf:
        return table
    table[:, 3] = NEVER
    inner = tap_table(core, lattice, aspect, blades, first, roundness, dense=core,
                      squeeze=squeeze)
    inner[:, 2] = NEVER
    return np.concatenate([inner, table])


def tap_counts(table: np.ndarray) -> np.ndarray:
    """For a tap table (:func:`tap_table`), ``counts[k]``: how many of its first taps hold
    every tap that can add to a pixel whose relevant radii are all at most ``k / 2`` px (the
    taps after them all lie at ``k / 2 + s / 2`` or farther in aperture space, ``s`` their
    lattice spacing: a coverage ramp ``clamp((radius - distance) / s + 1/2)`` that is 0
    there); the last entry is every tap.  ``dof_gather`` gathers only those (the sums are
    the same bits: what it leaves out adds exact zeros, what it keeps keeps its order)."""
    far = np.minimum(table[:, 2].astype(np.float64), table[:, 3]) - 0.5 * np.exp2(table[:, 7])
    k_max = int(math.ceil(2.0 * max(float(far.max()), 0.0))) + 1
    below = far[None, :] < 0.5 * np.arange(k_max + 1)[:, None]
    last = np.where(below.any(axis=1), len(far) - np.argmax(below[:, ::-1], axis=1), 0)
    return last.astype(np.int32)


def lattice_reach(radius: float, level: int, squeeze: float = 1.0,
                  aspect: float = 1.0) -> tuple[float, float]:
    """How far (x, y px) a gather of neighbourhood radius ``radius`` takes light from: its
    taps' reach (``radius + s / 2`` in aperture space for a lattice of spacing ``s = 2^level``,
    ``level`` the radius's :func:`lattice_level`) plus the prefilter tent's ``s - 1`` px (none
    for a dense table).  The half-resolution gather of the same radius reaches no further
    (its lattice is half as wide in its own pixels)."""
    if level == 0:
        return radius / squeeze, radius * aspect
    s = 1 << level
    return (radius + 0.5 * s) / squeeze + s - 1, (radius + 0.5 * s) * aspect + s - 1


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


def near_bounds(near: np.ndarray, table: np.ndarray, tile: int) -> np.ndarray:
    """Per tile of ``tile`` px, the bound of the radii in front of the focus plane that can
    light its pixels through the near field: the largest ``near`` (px per tile) of a tile
    that a tap of ``table`` (:func:`tap_table`) can read from it at an aperture distance
    within that tile's own ``near``.  A near tap adds light only within its own radius (its
    coverage ramp, ``d_near - s / 2`` with ``s = 2^L`` its lattice spacing, below ``|r|``),
    so a tile whose near radii fall short of every tap reaching it is left out: a small
    near blur far away no longer holds the table's every tap (the loop beyond the pixels'
    own radii, dof_tap_count).  A tap reads radii up to 2 px around it (dof_edges' 3 x 3,
    dof_mixed's split), from any pixel of the tile (a margin of 3 px more in x and rows)."""
    near = np.asarray(near, np.float64)
    # taps within a tile's neighbours: every one of those lies within the centre tap's
    # reach (its own near radius lights it), the bound is their largest near radius
    span = int(math.ceil((float(np.abs(table[:, :2]).max()) + 2.0) / tile))
    if span <= 1:
        return dilate_tiles(near, span)
    ox, oy = table[:, 0].astype(np.int64), table[:, 1].astype(np.int64)
    reach = np.minimum(table[:, 2].astype(np.float64), NEVER) - 0.5 * np.exp2(table[:, 7])
    # the tile offsets (dx, dy) a tap's read lands in: ox in [dx T - T - 4, dx T + T + 1]
    # (oy likewise, a margin wider than the rows need); per offset its taps' least reach
    lo_x, lo_y = -((tile + 1 - ox) // tile), -((tile + 1 - oy) // tile)
    span = int(max(np.abs(lo_x).max(), np.abs(lo_y).max())) + 3
    least = np.full((2 * span + 1, 2 * span + 1), np.inf)
    for kx in range(3):
        for ky in range(3):
            dx, dy = lo_x + kx, lo_y + ky
            hit = (dx * tile - tile - 4 <= ox) & (dy * tile - tile - 4 <= oy)
            np.minimum.at(least, (dy[hit] + span, dx[hit] + span), reach[hit])
    out = np.zeros_like(near)
    h, w = near.shape
    for dy, dx in zip(*np.nonzero(least < np.inf)):
        cut = least[dy, dx] - 1e-3       # a float32 rounding's margin
        dy, dx = int(dy) - span, int(dx) - span
        if abs(dy) >= h or abs(dx) >= w:
            continue
        ys, yd = slice(max(0, dy), h + min(0, dy)), slice(max(0, -dy), h + min(0, -dy))
        xs, xd = slice(max(0, dx), w + min(0, dx)), slice(max(0, -dx), w + min(0, -dx))
        there = near[ys, xs]
        out[yd, xd] = np.maximum(out[yd, xd], np.where(there >= cut, there, 0.0))
    return out


def refine_bounds(refine: float) -> tuple[float, float, float, float]:
    """``dof_gather``'s refine float4: the level's ``refine`` (a log-luminance span), and the
    ratios within 1e-4 of ``exp(refine)`` below and above which the span is known without
    its logarithm (the kernel takes one only between them; ``native_log`` is far more
    accurate than that)."""
    if refine == math.inf:
        return (refine, math.inf, math.inf, 0.0)
    e = math.exp(min(refine, 700.0))
    if e * (1.0 + 1e-4) > FLT_MAX:    # every finite ratio lies below, an infinite one not
        return (refine, FLT_MAX, FLT_MAX, 0.0)
    return (refine, e * (1.0 - 1e-4), e * (1.0 + 1e-4), 0.0)


def prefilter(rt, col, pheight: int, levels: int) -> None:
    """Fill planes 1..``levels`` of the padded colour ``col`` (planes of ``pheight`` rows)
    with the binomial a-trous pyramid of plane 0: plane L is plane L - 1 filtered with
    (1/4, 1/2, 1/4) at a spacing of ``2^(L - 1)`` px along x then y (clamped to the padded
    buffer: the image's clamp-to-edge), the tent of half-width ``2^L`` that a lattice of
    spacing ``2^L`` samples (:func:`tap_table`)."""
    if levels < 1:
        return
    knl = rt.kernel("dof.cl", "dof_prefilter")
    plane = col.pitch * pheight
    tmp = rt.image(Rect.from_size(col.pitch, pheight), 4)
    for lv in range(1, levels + 1):
        step = 1 << (lv - 1)
        rt.launch(knl, (col.pitch, pheight), col, (lv - 1) * plane, tmp, 0,
                  col.pitch, pheight, step, 0, local=(16, 4))
        rt.launch(knl, (col.pitch, pheight), tmp, 0, col, lv * plane,
                  col.pitch, pheight, step, 1, local=(16, 4))


@register
class Dof(Plugin):
    whole_frame = None   # tiles: the frame-wide tile tables are the step's (`Dof.frame`)
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
            IntParam("blades", -1, min=-1, max=32, exclude=NO_POLYGON, exclude_why=BLADES_WHY,
                     hint="Aperture blades; -1 = the camera block's, 0 = round."),
            FloatParam("blade_rotation", 0.0, min=-360.0, max=360.0,
                       hint="Extra rotation of the aperture polygon in degrees (clockwise)."),
            FloatParam("roundness", 0.0, min=0.0, max=1.0,
                       hint="0 = straight blades, 1 = round bokeh."),
            FloatParam("optical_vignetting", -1.0, min=-1.0, max=2.0, units="aperture radii",
                       hint="Cat-eye bokeh: offset of the lens barrel's circle at the frame "
                            "corner, growing linearly from the optical centre (0 = none, 1 = "
                            "the corner's bokeh cut to a cat's eye); -1 = the camera block's. "
                            "The rim behind the stop: the clip is shifted away from the frame "
                            "centre."),
            FloatParam("optical_vignetting_front", -1.0, min=-1.0, max=2.0,
                       units="aperture radii",
                       hint="Cat-eye bokeh from the front rim: as optical_vignetting, the "
                            "clip shifted towards the frame centre; with both, the corner's "
                            "bokeh is a pointed lemon (the aperture cut by two offset circles); "
                            "-1 = the camera block's.  E.g. the double-Gauss 50 mm f/2 "
                            "(lenses/double-gauss-50mm) wide open on full frame: rear 0.7, "
                            "front 0.7 (its last and first surfaces, traced paraxially)."),
            FloatParam("anamorphic_squeeze", 0.0, min=0.0, max=3.0, units="x",
                       hint="Anamorphic oval bokeh: height / width of the bokeh in the "
                            "desqueezed image (1.33, 1.8, 2); 0 = the camera block's, 1 = "
                            "round."),
            FloatParam("axial_ca_red", 0.0, min=-1000.0, max=1000.0, units="um",
                       hint="Axial chromatic aberration: focus of red behind green on the "
                            "sensor side, added to the camera block's (achromat: red and blue "
                            "~ +50 um; magenta rims in front of focus, green behind)."),
            FloatParam("axial_ca_blue", 0.0, min=-1000.0, max=1000.0, units="um",
                       hint="Axial chromatic aberration: focus of blue behind green (um), "
                            "added to the camera block's."),
        ),
        quality=LEVELS,
        spreads_light=True,
    )

    # -- the plan --------------------------------------------------------------------------
    def plan(self, p, ctx) -> DofPlan:
        lens = self.make_lens(p, ctx)
        tiles = self.depth_tiles(ctx)
        radii = tuple((off, read_only(*self._tile_radii(lens, tiles, off)))
                      for off in lens.offsets())
        lvl = self.level(ctx)
        gathers = tuple((off, self.gather_levels(r[0], lvl)) for off, r in radii)
        spread = self._spread(lens, gathers, ctx.pixel_aspect)
        plan = DofPlan(None, lens, radii, gathers, spread)
        if (lens.k_half == 0.0 and max(map(abs, lens.ca)) < 0.5) or lens.clamp_r < 0.25:
            return replace(plan, identity="the circle of confusion is 0 (max_blur, max_coc or "
                                          "aperture)")
        if ctx.depth is not None and float(_over_channels(radii).max()) < 0.5:
            return replace(plan, identity="circle of confusion below half a pixel everywhere")
        window = ctx.source.window.union(      # `output_window` (its regions read the plan)
            ctx.source.window.grown(*spread).intersect(ctx.output_limit))
        return replace(plan, frame=self._make_frame(ctx.runtime, p, ctx, plan, tiles, window))

    # -- geometry --------------------------------------------------------------------------
    def lens(self, p, ctx) -> Lens:
        """The frame's lens in pixels (CoC at infinity, focus, clamp, aperture shape, cat-eye
        strength, anamorphic squeeze, axial-CA radius offsets): the step's plan's."""
        return self.planned(p, ctx).lens

    def make_lens(self, p, ctx) -> Lens:
        """Build the frame's :class:`Lens` (once per step: :meth:`plan`)."""
        cam = ctx.camera
        k_half = 0.5 * lens_scale_px(p, cam, ctx.diagonal_px, ctx.width_px)
        clamp_r = 0.5 * p.max_coc * ctx.diagonal_px
        blades = cam.blades if p.blades < 0 else p.blades
        rot = cam.blade_rotation + p.blade_rotation
        squeeze = p.anamorphic_squeeze or cam.anamorphic_squeeze
        if squeeze < 1.0:
            raise ParamError(f"dof.anamorphic_squeeze = {squeeze:g}: expected 0 (the camera "
                             f"block's) or a squeeze in [1, 3]")
        cateye = cam.optical_vignetting if p.optical_vignetting < 0 else p.optical_vignetting
        front = (cam.optical_vignetting_front if p.optical_vignetting_front < 0
                 else p.optical_vignetting_front)
        ca = (0.0, 0.0)
        if p.axial_ca_red or p.axial_ca_blue or cam.axial_ca_red or cam.axial_ca_blue:
            # the chromatic focus shift over this effect's f-number (also with max_blur)
            eff = cam.updated(f_number=p.f_number or cam.f_number,
                              axial_ca_red=cam.axial_ca_red + p.axial_ca_red,
                              axial_ca_blue=cam.axial_ca_blue + p.axial_ca_blue)
            ca = tuple(0.5 * v for v in eff.axial_ca_px(ctx.width_px))
        return Lens(k_half, focus_distance(p, cam), clamp_r, blades, first_blade_angle(rot),
                    float(squeeze), float(cateye), ca, float(front))

    def cateye_args(self, lens: Lens, ctx, window, scale: int = 1):
        """``dof_gather``'s cateye float8 for a buffer over ``window`` (``scale``: its pixels
        per full-resolution pixel's): the centre of the first clipping circle
        (:meth:`Lens.cateye_strengths`) of buffer pixel (x, y) is ``(s0 (x + 0.5) + s1,
        s2 (y + 0.5) + s3)`` aperture radii, the second's (with both rims) likewise from
        ``s4..s7``."""
        d = ctx.display_window
        aspect = ctx.pixel_aspect
        half_diag = 0.5 * math.hypot(d.width, d.height / aspect)
        cx, cy = d.center
        out = []
        for strength in (lens.cateye_strengths() + (0.0, 0.0))[:2]:
            k = strength / half_diag
            out += (k * scale, k * (window.x0 - cx),
                    k * scale / aspect, k * (window.y0 - cy) / aspect)
        return tuple(out)

    def tile_radii(self, p, ctx, *, with_near: bool = False, offset: float | None = None):
        """Per 32 px tile of the frame's analysis window: the largest CoC radius any pixel
        within reach can have (px); with ``with_near`` also the smallest radius of the tile's
        own pixels and the largest radius of a pixel in front of the focus plane within reach
        (0 if none).  ``offset``: one channel's axial-CA radius offset; None: the largest over
        the channels.  The step's plan's."""
        radii = self.planned(p, ctx).radii
        if offset is not None:
            radii = tuple((o, r) for o, r in radii if o == offset)
        return _over_channels(radii, with_near)

    @staticmethod
    def depth_tiles(ctx) -> DepthTiles:
        """The :class:`DepthTiles` of the frame's scene analysis (in a tile of a tiled
        render, the whole frame's)."""
        an = ctx.analysis
        return DepthTiles(an.window, an.min_depth, an.max_depth, an.bad_depth,
                          an.nonfinite_count)

    @staticmethod
    def _tile_radii(lens: Lens, an: DepthTiles, offset: float):
        """(r_max, r_min, near) of :meth:`tile_radii` for one channel offset."""
        k_half, focus, clamp_r = lens[:3]
        w = an.window
        ty, tx = max(1, -(-w.height // TILE)), max(1, -(-w.width // TILE))
        if an.min_depth is None:
            full = np.full((ty, tx), clamp_r, np.float32)  # no tile statistics: no skipping
            return full, np.zeros_like(full), full
        # the CoC is monotonic in 1/z, so a tile's extremes come from its depth range
        r0 = coc_radius(an.min_depth, k_half, focus, clamp_r, offset)
        r1 = coc_radius(an.max_depth, k_half, focus, clamp_r, offset)
        r = np.maximum(np.abs(r0), np.abs(r1))
        if offset and an.bad_depth is not None:   # invalid depths: the focus plane's radius
            r = np.where(an.bad_depth > 0, np.maximum(r, min(abs(offset), clamp_r)), r)
        reach = max(int(math.ceil(r.max() / TILE)) if r.size else 0, 1)
        r_max = dilate_tiles(r, reach).astype(np.float32)
        # straddling the focus plane, or holding invalid depths (in focus): some pixel is sharp
        r_min = np.where((r0 * r1 <= 0) | (an.bad_depth > 0), 0.0,
                         np.minimum(np.abs(r0), np.abs(r1)))
        near = dilate_tiles(np.maximum(-r0, 0.0), reach)
        return r_max, r_min.astype(np.float32), near.astype(np.float32)

    @staticmethod
    def _tile_near(lens: Lens, an: DepthTiles, offset: float) -> np.ndarray:
        """Per tile of ``an``'s window the largest radius in front of the focus plane
        (px, >= 0) that a pixel of the tile can have: its nearest depth's, an invalid
        depth's (the ``offset`` alone), the clamp where the tile has no statistics; a bound
        on ``dof_prepare``'s float32 radii (a margin of 1e-5 of the radii and 1e-3 px)."""
        k_half, focus, clamp_r = lens[:3]
        w = an.window
        shape = (max(1, -(-w.height // TILE)), max(1, -(-w.width // TILE)))
        if an.min_depth is None:
            return np.full(shape, clamp_r)
        near = np.maximum(-coc_radius(an.min_depth, k_half, focus, clamp_r, offset), 0.0)
        if an.bad_depth is not None:
            near = np.where(an.bad_depth > 0, np.maximum(near, min(max(-offset, 0.0), clamp_r)),
                            near)
        near = np.where(np.isnan(near), clamp_r, near)
        return near + 1e-5 * (near + k_half + abs(offset)) + 1e-3

    def spread_px(self, p, ctx) -> tuple[int, int]:
        """How far (x, y px) light can land from its pixel: the step's plan's
        (:meth:`_spread`)."""
        return self.planned(p, ctx).spread

    @staticmethod
    def _spread(lens: Lens, gathers: tuple, aspect: float) -> tuple[int, int]:
        """:meth:`spread_px` from the ``gathers`` of the plan: the largest CoC radius of the
        frame over the channels (rounded up as the gather's), narrowed by the anamorphic
        squeeze in x and stretched by the pixel aspect in y, plus the coverage ramp's pixel
        (and a sparse lattice's wider ramp and prefilter, :func:`lattice_reach`)."""
        r = max(float(levels.max()) if levels.size else 0.0 for _, (levels, _) in gathers)
        if r == 0.0:
            return 0, 0
        level = max(lattice for _, (_, lattice) in gathers)   # the level of the largest radius
        rx, ry = lattice_reach(r, level, lens.squeeze, aspect)
        return int(math.ceil(rx)) + 1, int(math.ceil(ry)) + 1

    def gather_radii(self, p, ctx, offset: float = 0.0) -> tuple[np.ndarray, int]:
        """Per tile of the frame's analysis window the gather's radius and the lattice level
        of the largest, for the channel ``offset``: the step's plan's (:meth:`gather_levels`)."""
        return dict(self.planned(p, ctx).gathers)[offset]

    @staticmethod
    def gather_levels(r_max: np.ndarray, lvl: DofLevel) -> tuple[np.ndarray, int]:
        """Per tile the gather's radius (:func:`quantised_radius` of the tile radii
        ``r_max``) and the :func:`lattice_level` of the largest, which sets the padding, the
        prefilter pyramid's depth and the reach: once per window and channel offset in a
        step (the plan's), read by the regions (:meth:`spread_px`) and :meth:`frame`."""
        levels = read_only(quantised_radius(r_max))
        r = float(levels.max()) if levels.size else 0.0
        return levels, lattice_level(r, lvl.lattice, lvl.dense_radius)

    def tap_tables(self, rt, levels, lvl, aspect, blades, first, roundness, squeeze=1.0,
                   cores=None):
        """One concatenated tap table for the radii in ``levels`` and, per entry of
        ``levels``, (first, count, 0, 0); ``cores``: per entry of ``levels``' first axis the
        :func:`tap_table` core (None: none).  Each table is kept in the runtime's cache."""
        cores = tuple(cores) if cores is not None else (0.0,) * len(levels)
        parts, offsets, n = [], {}, 0
        for key_r in sorted({(r, c) for lv, c in zip(levels, cores)
                             for r in set(np.asarray(lv).ravel().tolist()) - {0.0}}):
            r, core = key_r
            key = ("dof.taps", r, lvl.lattice, lvl.dense_radius, aspect, blades, first,
                   roundness, squeeze, core)
            taps = rt.cache.get(key, lambda r=r, core=core: tap_table(
                r, lvl.lattice, aspect, blades, first, roundness,
                dense=lvl.dense_radius, squeeze=squeeze, core=core))
            offsets[key_r] = (n, len(taps))
            parts.append(taps)
            n += len(taps)
        table = np.concatenate(parts) if parts else np.zeros((1, 8), np.float32)
        info = np.zeros(np.shape(levels) + (4,), np.int32)
        for (r, core), (first_tap, count) in offsets.items():
            for i, c in enumerate(cores):
                if c == core:
                    info[i][levels[i] == r, :2] = (first_tap, count)
        return np.ascontiguousarray(table), np.ascontiguousarray(info)

    def clamp_warning(self, p, ctx, lens: Lens) -> str | None:
        """The warning when ``max_coc`` cuts a CoC this frame asks for through ``lens``, else
        None."""
        an = ctx.analysis
        if an.min_depth is None or not an.min_depth.size:
            return None
        asked = 2.0 * max(float(np.abs(np.concatenate([
            coc_signed(an.min_depth, lens.k_half, lens.focus).ravel(),
            coc_signed(an.max_depth, lens.k_half, lens.focus).ravel()]) + off).max())
            for off in lens.offsets())   # each channel's radius (axial CA)
        if asked <= 2.0 * lens.clamp_r * (1.0 + 1e-6):
            return None
        return (f"a CoC of {asked:.1f} px is asked for and clamped to "
                f"{2.0 * lens.clamp_r:.1f} px (max_coc = {p.max_coc:g} of the diagonal); "
                f"raise dof.max_coc to keep the lens")

    def region_of_definition(self, p, ctx):
        return ctx.source.window.grown(*self.spread_px(p, ctx))

    def region_of_interest(self, p, ctx, window):
        # the rows a band's render reads (`DofFrame.rows`), over the whole width: each band
        # gathers full rows of the whole render's tile grid
        frame = self.frame(p, ctx)
        rx = self.spread_px(p, ctx)[0]
        y0, y1 = frame.rows(window.y0, window.y1)
        return Rect(min(window.x0 - rx, frame.window.x0), min(y0, window.y0),
                    max(window.x1 + rx, frame.window.x1), max(y1, window.y1))

    # -- the frame -------------------------------------------------------------------------
    def frame(self, p, ctx) -> DofFrame:
        """The step's :class:`DofFrame`: the plan's, built on the whole frame before any
        band renders (a band's :class:`~clfx.host.Band` carries it); for a step the plan
        found to be an identity and rendered anyway (whole: a look skips it), made now."""
        plan = self.planned(p, ctx)
        if plan.frame is None and ctx.tiling is None:
            return self._make_frame(ctx.runtime, p, ctx, plan, self.depth_tiles(ctx),
                                    self.output_window(p, ctx))
        return plan.frame

    def _make_frame(self, rt, p, ctx, plan: DofPlan, an: DepthTiles,
                    window: Rect) -> DofFrame:
        """The :class:`DofFrame` of the whole frame ``ctx`` rendered over ``window`` (its
        tiles, caps, one gather plan per channel offset, the notes and the clamp warning),
        from the ``plan`` so far (the lens, the radii over the analysis window ``an``)."""
        lens = plan.lens
        warning = self.clamp_warning(p, ctx, lens)
        notes = []
        if window != ctx.source.window:
            # Light leaves the data window: the render covers the grown window, outside the
            # data window nothing (transparent black) at the edge's depth; its tiles are
            # taken over the grown window.
            notes.append(f"dof: grown to {window}")
        tiles = an if window == an.window else self._window_tiles(rt, ctx, window)
        ty, tx = max(1, -(-window.height // TILE)), max(1, -(-window.width // TILE))
        log_mean = rt.buffer(tx * ty * 4)
        src = ctx.source
        rt.launch(rt.kernel("dof.cl", "dof_tile_cap", fp64=self.level(ctx).fp64,
                            **ctx.luminance_defines), (tx, ty),
                  src, src.pitch, src.window.x0 - window.x0,
                  src.window.y0 - window.y0, src.width, src.height,
                  window.width, window.height, TILE, tx, ty, log_mean)
        offsets = lens.offsets()
        gathers = tuple(self._plan_gather(rt, p, ctx, plan, tiles, off) for off in offsets)
        said = [gathers[0].note]
        if len(offsets) > 1:
            said.append(f"axial CA: red {2 * lens.ca[0]:+.2f} px, blue {2 * lens.ca[1]:+.2f} px "
                        f"of CoC, {len(offsets)} gathers")
        if lens.cateye or lens.cateye_front:
            rims = [f"rear {lens.cateye:g}"] * bool(lens.cateye) + \
                   [f"front {lens.cateye_front:g}"] * bool(lens.cateye_front)
            said.append(f"optical vignetting {', '.join(rims)} (cat-eye bokeh)")
        if lens.squeeze != 1.0:
            said.append(f"anamorphic squeeze {lens.squeeze:g}")
        if tiles.nonfinite_count:
            said.insert(0, f"{tiles.nonfinite_count} non-finite pixels set to 0")
        if tiles.bad_depth is not None and int(tiles.bad_depth.sum()):
            said.insert(1 if tiles.nonfinite_count else 0,
                        f"{int(tiles.bad_depth.sum())} invalid depths treated as in focus")
        notes.append("dof: " + "; ".join(said))
        return DofFrame(window, tx, ty, log_mean, gathers, tuple(notes), warning)

    def _window_tiles(self, rt, ctx, window: Rect) -> DepthTiles:
        """The :class:`DepthTiles` of ``window``: the frame's analysis, or (a window grown
        past the data window: the beauty extended with transparent black, the depth by its
        edge values) the analysis of the grown frame, taken in bands of whole tile rows so
        no grown copy of the frame exists at once (a tile's statistics read its own pixels
        only: the same values as over the whole grown frame)."""
        if window == ctx.source.window:
            return self.depth_tiles(ctx)
        rows = max(1, BAND_PIXELS // max(window.width, 1) // TILE) * TILE
        parts = []
        for y in range(window.y0, window.y1, rows):
            band = Rect(window.x0, y, window.x1, min(y + rows, window.y1))
            depth = None if ctx.depth is None else rt.reframe(ctx.depth, band, "clamp")
            an = analyse(rt, rt.reframe(ctx.source, band, "zero"), depth=depth,
                         luminance_defines=ctx.luminance_defines)
            parts.append((an.min_depth, an.max_depth, an.bad_depth, an.nonfinite_count))
        if ctx.depth is None:
            stacked = (None, None, None)
        else:
            stacked = tuple(np.concatenate([part[i] for part in parts]) for i in range(3))
        return DepthTiles(window, *stacked, sum(part[3] for part in parts))

    def _plan_gather(self, rt, p, ctx, plan: DofPlan, tiles: DepthTiles,
                     offset: float) -> DofGather:
        """The :class:`DofGather` of the channel radius ``offset`` over ``tiles``' window
        (the plan's radii where that is the analysis window's)."""
        lvl = self.level(ctx)
        aspect = ctx.pixel_aspect
        lens = plan.lens
        blades, first = lens[3:5]
        if tiles.window == self.depth_tiles(ctx).window:
            radii, r_min, near = dict(plan.radii)[offset]
            levels, full_l = dict(plan.gathers)[offset]
        else:
            radii, r_min, near = self._tile_radii(lens, tiles, offset)
            levels, full_l = self.gather_levels(radii, lvl)
        # Tiles whose every pixel is far out of focus are gathered at half resolution.
        half = (r_min >= lvl.half_res_radius) & (levels > 0)
        r_max = float(levels.max())
        # pad by the taps' largest reach (+2 for rounding), quantised so buffers get reused
        s_max = 1 << full_l
        reach = r_max + (0.5 * s_max if s_max > 1 else 0.0)
        pad = int(math.ceil((reach * max(1.0, aspect) + 2) / 8.0) * 8)
        common = (lvl, aspect, blades, first, p.roundness, lens.squeeze)
        # the largest radius in front of the focus plane of a pixel of each tile (px): a
        # tap that no such radius (nor the pixels' own) reaches adds nothing (`_tile_table`)
        tile_near = self._tile_near(lens, tiles, offset)
        htaps = htiles = None
        half_l = hrows = 0
        if half.any():
            hlevels = quantised_radius(np.where(half, 0.5 * radii, 0.0))
            half_l = lattice_level(float(hlevels.max()), lvl.lattice, lvl.dense_radius)
            # dof_down2's radii: halved weighted means (a float32 rounding's margin)
            htaps, htiles, hrows = self._tile_table(rt, hlevels, hlevels, None, *common,
                                                    near=0.5 * tile_near * (1 + 1e-5), tile=TILE // 2)
            hrows += (1 << half_l) - 1     # the half-resolution prefilter's tent
        # full resolution: sharp pixels gather over their own reach and the near field's,
        # out-of-focus ones take the half-resolution result where it is smooth
        sharp = np.where(levels > 0, quantised_radius(np.maximum(near, lvl.sharp_radius)
                                                      if math.isfinite(lvl.sharp_radius)
                                                      else radii), 0.0)
        sharp = np.minimum(sharp, levels)
        mode = np.where(half, 1, 0) + np.where(levels <= lvl.dense_radius, 2, 0)
        taps, tile_info, rows = self._tile_table(rt, levels, sharp, mode, *common,
                                                 core=lvl.sharp_radius, near=tile_near)
        # rows a pixel reads: its farthest tap's, the prefilter's tent around it, or the
        # rows beyond it that a tap's mixed-pixel split reads (its 3 x 3 neighbours' edge-aware
        # radii, each from its own 3 x 3 neighbours)
        rows += max((1 << full_l) - 1, 2)
        note = (f"{int((levels == 0).sum())}/{radii.size} tiles in focus (copied), "
                f"{int(half.sum())} at half resolution")
        return DofGather(offset, full_l, read_only(half), half_l, pad, taps, tile_info, htaps,
                         htiles, rows, hrows, note)

    def _tile_table(self, rt, levels, sharp, mode, lvl, aspect, blades, first, roundness,
                    squeeze, *, near, core=0.0, tile=TILE):
        """``dof_gather``'s tap table and per-tile table (on the device): per tile (16 ints)
        the table of radius ``levels``, that of radius ``sharp`` for pixels in focus (with
        the :func:`tap_table` ``core``: their own radius's, below it), ``mode`` (bit 0:
        take the half-resolution result where it is smooth, bit 1: gather again where it is
        not), the two tables' lattice levels, the farthest offset (x or y, px) of a tap of
        the first (sharp <= levels), the bound of the radii in front of the focus plane that
        its taps can read and be lit by (float bits; :func:`near_bounds` of ``near``, px per
        tile of ``tile`` px), where the two tables' tap counts lie (:func:`tap_counts`,
        after the tiles) and their lengths; and the farthest row offset of a tap."""
        table, info = self.tap_tables(rt, np.stack([levels, sharp]), lvl, aspect, blades, first,
                                      roundness, squeeze, cores=(0.0, core))
        tiles = np.zeros(levels.shape + (16,), np.int32)
        tiles[..., :2], tiles[..., 2:4] = info[0, ..., :2], info[1, ..., :2]
        tiles[..., 4] = 0 if mode is None else mode
        tiles[..., 5] = lattice_levels(levels, lvl.lattice, lvl.dense_radius)
        tiles[..., 6] = lattice_levels(sharp, lvl.lattice, lvl.dense_radius)
        for start, n in {tuple(v) for v in info[0, ..., :2].reshape(-1, 2).tolist()}:
            if n:
                reach = int(np.abs(table[start:start + n, :2]).max())
                tiles[..., 7][(info[0, ..., 0] == start) & (info[0, ..., 1] == n)] = reach
        counts = []
        bound = near_bounds(near, table, tile).astype(np.float32)
        tiles[..., 8] = bound.view(np.int32)
        at = tiles.size
        for start, n in sorted({tuple(v) for v in info[:, ..., :2].reshape(-1, 2).tolist()}):
            if n:
                c = tap_counts(table[start:start + n])
                for t in (0, 1):
                    hit = (info[t, ..., 0] == start) & (info[t, ..., 1] == n)
                    tiles[..., 9 + 2 * t][hit], tiles[..., 10 + 2 * t][hit] = at, len(c)
                counts.append(c)
                at += len(c)
        flat = np.concatenate([tiles.ravel()] + counts).astype(np.int32)
        # the rows, then the columns (4 floats of padding each: a block of 4 taps reads
        # float4s of a column from any tap)
        n4 = len(table) + 4
        cols = np.zeros((8, n4), np.float32)
        cols[:, :len(table)] = table.T
        return ((rt.to_device(np.concatenate([table.ravel(), cols.ravel()])), np.int32(n4)),
                rt.to_device(flat), int(np.abs(table[:, 1]).max()))

    # -- render ----------------------------------------------------------------------------
    def render(self, rt, p, ctx):
        frame = self.frame(p, ctx)
        if frame.warning and frame.warning not in ctx.warnings:  # "frame N: dof: <warning>"
            ctx.warnings.append(frame.warning)
            ctx.notes.append(frame.warning)
        whole = frame.window
        if ctx.tiling is None:
            band = work = whole
        else:
            # a band of a tiled render: the rows of the whole render's grid it reads, from
            # the tile's source (its region of interest), filled past the data window as
            # the whole render fills them
            band = ctx.tiling.band
            y0, y1 = frame.rows(band.y0, band.y1)
            work = Rect(whole.x0, y0, whole.x1, y1).intersect(whole)
            have = ctx.source.window
            if not have.contains(work.intersect(ctx.tiling.whole)):
                raise RuntimeError(f"dof: a band {band} reads {work}; its source holds {have}")
        src = rt.reframe(ctx.source, work, "zero")
        depth = rt.reframe(ctx.depth, work, "clamp")
        lens = self.lens(p, ctx)
        passes = {off: self._render_pass(rt, p, ctx, lens, frame, frame.gather(off), src,
                                         depth, band)
                  for off in lens.offsets()}
        outs = {off: out for off, (out, _) in passes.items()}
        if len(outs) == 1:
            dst = outs[0.0]
        else:
            dst = outs[0.0].like()
            r, b = (outs[o] for o in lens.ca)
            rt.launch(rt.kernel("dof.cl", "dof_merge_channels"), (dst.width, dst.height),
                      r, outs[0.0], b, dst, dst.pitch, dst.width,
                      dst.height, local=(16, 4))
        ctx.notes.extend(frame.notes)
        self._note_mixed(rt, ctx, passes[0.0][1])
        return dst

    @staticmethod
    def _note_mixed(rt, ctx, count) -> None:
        """The report's line of the mixed edge pixels split (green's gather's device
        ``count`` of its band's rows; the bands of a tiled render add theirs up, the line
        said once, with the frame's total: the step's notes hold the bands' so far)."""
        total = int(rt.from_device(count, np.int32, 1)[0])
        if ctx.tiling is not None:
            total += sum(int(s.split()[1]) for s in ctx.notes if s.endswith(MIXED_NOTE))
        ctx.notes[:] = [s for s in ctx.notes if not s.endswith(MIXED_NOTE)]
        ctx.notes.append(f"dof: {total}{MIXED_NOTE}")

    def _render_pass(self, rt, p, ctx, lens: Lens, frame: DofFrame, g: DofGather, src,
                     depth, band: Rect):
        """The gather of every channel with the signed CoC radii offset by ``g.offset`` px
        (one channel's axial CA; 0 without) over the rows ``band`` of the whole render,
        from ``src`` and ``depth`` over the rows it reads (the whole window in a whole
        render)."""
        lvl = self.level(ctx)
        k_half, focus, clamp_r = lens[:3]
        whole = frame.window
        pad, full_l = g.pad, g.full_l
        w, h = src.width, src.height
        padded = Rect.from_size(-(-(w + 2 * pad + 4) // 4) * 4, h + 2 * pad)
        check_derived(padded.width * padded.height, 16 * (1 + full_l) + 8, whole.width, whole.height, rt.cache.max_bytes, f"dof: its {padded.width}x{padded.height} padded planes (the frame and {pad} px of CoC reach on every side)", per_pixel=DEVICE_BYTES_PER_PIXEL, hint="lower dof.max_coc or the lens's blur")
        # the colour, then its prefiltered copies for the sparse taps (planes 1..L)
        col = rt.image(Rect.from_size(padded.width, padded.height * (1 + full_l)), 4)
        coc0, coc = rt.image(padded, 1), rt.image(padded, 1)
        luma = ctx.luminance_defines     # log luminance of the working space
        prep = rt.kernel("dof.cl", "dof_prepare", fp64=lvl.fp64, **luma)
        rt.launch(prep, (-(-col.pitch // 16), padded.height), src, depth, src.pitch, w,
                  h, col, coc0, col.pitch, padded.height, pad, k_half,
                  focus, clamp_r, g.offset, frame.log_mean, frame.tiles_x, frame.tiles_y,
                  TILE, CAP_FACTOR, src.window.x0 - whole.x0, src.window.y0 - whole.y0)
        prefilter(rt, col, padded.height, full_l)
        rt.launch(rt.kernel("dof.cl", "dof_edges", fp64=lvl.fp64, **luma), (-(-w // 16), h),
                  col, coc0, coc, col.pitch, padded.height, pad, w, h,
                  local=(8, 4))
        del coc0
        mix, count = self._mixed(rt, col, coc, padded, pad, w, h, band.y0 - src.window.y0,
                                 band.height)
        circles = len(lens.cateye_strengths())
        variant = {"DOF_CATEYE": circles} if circles else {}
        gather = rt.kernel("dof.cl", "dof_gather", fp64=lvl.fp64, **variant, **luma)
        # where the buffers sit on the whole render's grid (its window's origin)
        top, row0 = band.y0 - whole.y0, src.window.y0 - whole.y0
        half_size = (-(-whole.width // 2), -(-whole.height // 2))
        hres = None
        if g.htaps is not None:
            hw, hh, hpad = -(-w // 2), -(-h // 2), pad // 2
            hpadded = Rect.from_size(-(-(hw + 2 * hpad + 4) // 4) * 4, hh + 2 * hpad)
            colh = rt.image(Rect.from_size(hpadded.width, hpadded.height * (1 + g.half_l)), 4)
            coch = rt.image(hpadded, 1)
            rt.launch(rt.kernel("dof.cl", "dof_down2", fp64=lvl.fp64, **luma),
                      (-(-colh.pitch // 4), hpadded.height), col, coc, col.pitch, padded.height,
                      colh, coch, colh.pitch, hpadded.height)
            prefilter(rt, colh, hpadded.height, g.half_l)
            # the half-resolution rows this band's upsampling reads (row0 is even:
            # `DofFrame.rows`)
            h0, h1 = DofFrame.half_rows(top, top + band.height)
            h0, h1 = max(h0, 0), min(h1, half_size[1])
            hres = rt.image((h1 - h0, hw), 4)
            self._gather(rt, gather, colh, coch, hpad, hres, g.htaps, g.htiles, frame, lvl,
                         self.cateye_args(lens, ctx, whole, 2), (0, h0, 0, row0 // 2),
                         tile=TILE // 2, plane=colh.pitch * hpadded.height, mix=None)
            del colh, coch
        dst = rt.image(band, 4)
        self._gather(rt, gather, col, coc, pad, dst, g.taps, g.tiles, frame, lvl,
                     self.cateye_args(lens, ctx, whole), (0, top, 0, row0),
                     hres=hres, hplace=(0, h0 if hres is not None else 0),
                     half_size=half_size, plane=col.pitch * padded.height, mix=mix)
        return dst, count

    def _mixed(self, rt, col, coc, padded: Rect, pad: int, w: int, h: int, y0: int,
               rows: int):
        """``dof_mixed`` over the padded colour ``col`` (plane 0) and edge-aware radii ``coc``
        of a ``w`` x ``h`` image: ``dof_gather``'s mixed-pixel arguments (the mixed edge
        pixels' near coverage, radii and colour difference, the flags of the image's 32 px
        tiles holding one and their counts in x and y) and the device count of those in its
        rows ``y0``..``y0 + rows`` (the band a render gives)."""
        mixa, mixr, mixd = (rt.image(padded, n) for n in (1, 2, 4))
        count = rt.to_device(np.zeros(1, np.int32))
        tx, ty = -(-w // TILE), -(-h // TILE)
        flags = rt.to_device(np.zeros(tx * ty, np.int32))
        rt.launch(rt.kernel("dof.cl", "dof_mixed"), (-(-w // 16), h), col, coc, mixa, mixr,
                  mixd, col.pitch, padded.height, pad, w, h, y0,
                  y0 + rows, count, flags, tx, local=(8, 4))
        return (mixa, mixr, mixd, flags, tx, ty), count

    def _gather(self, rt, knl, col, coc, pad, dst, taps, tiles, frame: DofFrame, lvl, cateye,
                place, *, tile=TILE, hres=None, hplace=(0, 0), half_size=(1, 1), plane=0,
                mix=None):
        """Launch ``dof_gather`` over ``dst`` with the tables ``taps``, ``tiles``
        (:meth:`_tile_table`) and the frame's caps; ``place``: (dst x, dst y, buffer x,
        buffer y) on the whole render's grid, ``hres``: the half-resolution result (rows from
        ``hplace``, ``half_size`` its whole size); ``plane``: pixels between the planes of
        ``col``'s prefilter pyramid (:func:`prefilter`); ``mix``: the mixed edge pixels
        (:meth:`_mixed`) the gather splits, None: none (the half-resolution gather)."""
        hres_args = ((hres, hres.pitch, half_size[0], half_size[1])
                     if hres is not None else (dst, dst.pitch, 1, 1))
        rt.launch(knl, (-(-dst.width // 4), dst.height), col, coc, col.pitch, pad,
                  dst, dst.pitch, dst.width, dst.height, *taps, tiles,
                  frame.log_mean, frame.tiles_x, frame.tiles_y, tile,
                  CAP_FACTOR, *hres_args, refine_bounds(lvl.refine), lvl.half_res_radius,
                  lvl.sharp_radius,
                  cateye, plane, place, (*hplace, 0, 0),
                  *(mix or (coc, coc, coc, coc, 0, 0)), local=LOCAL)
