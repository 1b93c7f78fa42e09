"""Motion blur: object motion reconstructed from a velocity pass (and optional depth pass).

Model
-----
During the open shutter ``[t0, t1]`` (frames, relative to the frame time) a surface point seen
at pixel ``y`` at the frame time sits at ``y + v_y t``, with ``v_y`` the velocity pass (forward
px/frame, +x right, +y down; :mod:`clfx.core.frame`).  The shutter interval comes from the camera
block (``shutter_angle / 360`` of a frame, ``shutter_offset`` centred / opening / closing, as in
:func:`clfx.bench.groundtruth.shutter_interval`) or from this effect's overrides.  The blurred pixel
``x`` is the time average of whatever surface covers ``x``; a post-process only knows the
surfaces visible at the frame time, so it reconstructs that average by gathering.

Algorithm (McGuire, Hennessy, Bukowski & Osman 2012, "A reconstruction filter for plausible
motion blur"; Jimenez 2014, "Next generation post processing in Call of Duty: Advanced
Warfare"; Guertin, McGuire & Nowrouzezahrai 2014)
--------------------------------------------------------------------------------------------
1. *Prepare*: velocities sanitised (NaN/Inf -> 0) and clamped so that no pixel reaches farther
   than the maximum blur radius ``R`` (``max_blur`` x diagonal, at most ``MAX_RADIUS_PX``);
   depth sanitised (NaN, <= 0, +inf -> "far").
2. *TileMax* over ``k x k`` tiles, ``k`` = ``R`` rounded up to a multiple of 4 (at least 8),
   with ``R`` taken from the frame's actual peak speed (``ctx.analysis``) when smaller, then
   *NeighborMax* over 3 x 3 tiles: the dominant velocity ``v_n`` of every pixel that can reach
   into the tile.
3. *Classification*: the small NeighborMax grid is read back; tiles whose ``v_n`` smears less
   than half a pixel are skipped outright (the output starts as a copy of the input), the
   others form a compact list, and the gather runs over that list only.  A tile's sample
   count follows its own blur length (``ceil(length / spacing)``, capped per quality level).
4. *Gather*: each work-item shades 4 pixels sharing the tile's ``v_n``.  Pixel ``x`` takes N
   samples ``y_i = x - v_n t_i`` with ``t_i`` stratified over ``[t0, t1]`` and one per-pixel
   jitter (interleaved gradient noise, shifted per frame: no low-frequency pattern).  With
   ``d = x - y``, the sample's smear reaches ``x`` if ``d . v_y / |v_y|`` lies in
   ``|v_y| [t0, t1]`` (and ``d`` is within a pixel of y's line of motion); its weight is the
   source length per sample (``|v_n| dt``) times the smear's density there (1 / its length,
   edges softened over one pixel or one sample spacing).  A soft depth test (2% of depth)
   sorts samples into *occluders* (in front of x) and the *layer behind* (same depth: weighted
   by their own smear; farther: by x's own smear, i.e. the background revealed behind x's
   blurred edge).  Output = occluders (normalised if their coverage exceeds 1) + the remaining
   coverage times the normalised layer behind, or times the centre pixel when no sample
   belongs to it.  For one uniform velocity this reduces to the exact box line blur; a
   constant image stays constant; static pixels next to moving ones keep their colour where
   nothing passes in front of them.

Without a depth pass all pixels count as one depth (no occlusion ordering).  Blur extends only
inside the source window (clamp-to-edge reads); the region of definition is not grown.

References
----------
M. McGuire, P. Hennessy, M. Bukowski, B. Osman, "A reconstruction filter for plausible motion
blur", I3D 2012.  J. Jimenez, "Next generation post processing in Call of Duty: Advanced
Warfare", SIGGRAPH 2014 course.  J.-P. Guertin, M. McGuire, D. Nowrouzezahrai, "A fast and
stable feature-aware motion blur filter", HPG 2014.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from clfx.core.errors import ClipError
from clfx.core.plugin import ChoiceParam, Clip, Descriptor, FloatParam
from clfx.host import Plugin, register

KERNEL = "motion_blur.cl"

MAX_RADIUS_PX = 512
"""Hard cap of the blur radius (reach of one pixel's smear) in pixels, whatever the params:
a 1000 px/frame velocity is clamped to it (the tile size equals the radius)."""

SHUTTER_OFFSETS = ("camera", "centered", "opening", "closing")
LOCAL = 64
"""Work-group size of the 1D gather launch (pinned: PoCL compiles one work-group function)."""


@dataclass(frozen=True)
class Level:
    """What one quality level does (see the descriptor's ``quality`` texts)."""

    max_samples: int     # samples per pixel, at most
    spacing: float       # target distance between samples along the blur, px
    bilinear: bool       # bilinear colour fetches (else nearest)
    double: bool         # float64 accumulation
    jitter: bool = True  # per-pixel jitter (else midpoint rule: exact quadrature, may band)


LEVELS = {
    "draft": Level(8, 1.0, False, False),
    "preview": Level(16, 1.0, False, False),
    "final": Level(32, 0.5, True, False),
    "reference": Level(256, 0.25, True, True, jitter=False),
}


# -- shutter and geometry (shared with camera_blur) ------------------------------------------
def shutter_interval(angle_deg: float, offset: str) -> tuple[float, float]:
    """(t0, t1): the open shutter in frames relative to the frame time.

    ``centered``: ``[-s/2, s/2]``; ``opening``: ``[0, s]``; ``closing``: ``[-s, 0]``, with
    ``s = angle / 360`` (same convention as :func:`clfx.bench.groundtruth.shutter_interval`).
    """
    s = angle_deg / 360.0
    if offset == "opening":
        return 0.0, s
    if offset == "closing":
        return -s, 0.0
    return -0.5 * s, 0.5 * s


def shutter_from(p, camera) -> tuple[float, float]:
    """The shutter interval from the params' overrides, else from the camera block."""
    angle = camera.shutter_angle if p.shutter_angle < 0 else p.shutter_angle
    offset = camera.shutter_offset if p.shutter_offset == "camera" else p.shutter_offset
    return shutter_interval(angle, offset)


def reach_factor(t0: float, t1: float) -> float:
    """How far (in frames of motion) a pixel's smear reaches from its own position."""
    return max(abs(t0), abs(t1))


def tile_size(radius_px: float) -> int:
    """TileMax tile size: the blur radius rounded up to a multiple of 4, at least 8 px."""
    return int(max(8, 4 * math.ceil(min(radius_px, MAX_RADIUS_PX) / 4.0)))


def accumulation_defines(rt, double: bool) -> dict:
    """Build defines that switch the gather's accumulators to float64."""
    if not (double and rt.has_fp64):
        return {}
    return {"ACC": "double", "ACC4": "double4", "ACC16": "double16",
            "CONVERT_ACC4": "convert_double4", "CONVERT_ACC16": "convert_double16",
            "CONVERT_FROM_ACC4": "convert_float4", "CONVERT_FROM_ACC16": "convert_float16",
            "MASK4": "long4"}


@dataclass
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
    knl = rt.kernel(KERNEL, "motion_blur_sanitize")
    rt.launch(knl, (src.pitch // 4, src.height), src, out, np.int32(src.pitch),
              np.int32(src.height))
    return out


def reconstruct(rt, src, velocity, depth=None, *, t0: float, t1: float, max_radius_px: float,
                peak_speed: float, quality: str = "final", frame: int = 0, nonfinite: int = 0):
    """Motion blur of ``src`` from a velocity pass (and optional depth) on the device.

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
    quality : str
        One of ``LEVELS``.
    frame : int
        Shifts the jitter pattern per frame.
    nonfinite : int
        Number of non-finite source pixels (> 0 makes a sanitised copy first).

    Returns
    -------
    (DeviceImage, BlurStats)
    """
    level = LEVELS[quality]
    w, h, pitch = src.width, src.height, src.pitch
    reach_t = reach_factor(t0, t1)
    radius = float(min(max(peak_speed, 0.0) * reach_t, max_radius_px, MAX_RADIUS_PX))
    col = sanitized_copy(rt, src) if nonfinite else src
    dst = rt.copy(col)
    if w == 0 or h == 0 or reach_t <= 0.0 or radius * (t1 - t0) / reach_t < 0.5:
        return dst, BlurStats(0, radius, 0, 0, 0)
    k = tile_size(radius)
    vmax = radius / reach_t
    defines = dict(BILINEAR=int(level.bilinear), JITTER=int(level.jitter),
                   HAS_DEPTH=int(depth is not None),
                   **accumulation_defines(rt, level.double))
    i32, f32 = np.int32, np.float32

    aux = rt.image(src.window, 4)
    dummy = rt.buffer(16)
    rt.launch(rt.kernel(KERNEL, "motion_blur_prepare", **defines), (pitch // 4, h), velocity,
              depth if depth is not None else dummy, aux, i32(pitch), i32(h), f32(vmax))

    tx, ty = -(-w // k), -(-h // k)
    tmax = rt.buffer(tx * ty * 16)
    nmax = rt.buffer(tx * ty * 16)
    rt.launch(rt.kernel(KERNEL, "motion_blur_tilemax", **defines), (tx, ty), aux, tmax,
              i32(pitch), i32(w), i32(h), i32(tx), i32(ty), i32(k))
    rt.launch(rt.kernel(KERNEL, "motion_blur_neighbormax", **defines), (tx, ty), tmax, nmax,
              i32(tx), i32(ty))

    # Classification on the host: a few thousand floats, the only read-back.
    nm = rt.from_device(nmax, np.float32, tx * ty * 4).reshape(ty, tx, 4)
    length = nm[..., 2].astype(np.float64) * (t1 - t0)     # blur length of the tile's v_n
    ys, xs = np.nonzero(length >= 0.5)
    if xs.size == 0:
        return dst, BlurStats(k, radius, tx * ty, 0, 0)
    n = np.clip(np.ceil(length[ys, xs] / level.spacing), 2, level.max_samples).astype(np.int32)
    table = rt.to_device(np.stack([xs, ys, n], axis=1).astype(np.int32).ravel())
    qpt = k * k // 4
    total = xs.size * qpt
    rt.launch(rt.kernel(KERNEL, "motion_blur_gather", **defines), (total,), col, aux, nmax,
              table, i32(xs.size), dst, i32(pitch), i32(w), i32(h), i32(tx), i32(k), f32(t0),
              f32(t1), i32(frame), local=(LOCAL,))
    return dst, BlurStats(k, radius, tx * ty, int(xs.size), int(n.max()))


QUALITY_TEXT = {
    lvl: (f"up to {L.max_samples} samples per pixel (one per {L.spacing:g} px of the tile's "
          f"blur length), {'bilinear' if L.bilinear else 'nearest'} colour fetches, "
          f"{'float64' if L.double else 'float32'} accumulation, "
          f"{'per-pixel jitter' if L.jitter else 'midpoint rule (no jitter)'}; "
          f"static tiles copied")
    for lvl, L in LEVELS.items()
}


@register
class MotionBlur(Plugin):
    descriptor = Descriptor(
        name="motion_blur", label="Motion blur", group="Camera", kernel=KERNEL,
        summary="Object motion blur reconstructed from the velocity pass (McGuire 2012 "
                "reconstruction filter with tile classification), depth-aware.",
        clips=(Clip("source"),
               Clip("velocity", channels=2,
                    hint="Forward screen-space motion in px/frame (+x right, +y down)."),
               Clip("depth", optional=True, channels=1,
                    hint="Planar depth (m); orders occluders. Without it, one depth is assumed.")),
        params=(
            FloatParam("shutter_angle", -1.0, min=-1.0, max=720.0,
                       hint="Shutter angle in degrees (180 = open half the frame); -1 = the "
                            "camera block's.", units="deg"),
            ChoiceParam("shutter_offset", "camera", choices=SHUTTER_OFFSETS,
                        hint="Shutter interval centred on the frame time, opening at it or "
                             "closing at it; 'camera' = the camera block's."),
            FloatParam("max_blur", 0.05, min=0.001, max=0.25,
                       hint="Largest blur radius (reach of one pixel's smear) as a fraction of "
                            "the frame diagonal; faster pixels are clamped to it (and to "
                            f"{MAX_RADIUS_PX} px)."),
        ),
        quality=QUALITY_TEXT,
    )

    def shutter(self, p, ctx):
        return shutter_from(p, ctx.camera)

    def max_radius_px(self, p, ctx) -> float:
        return min(p.max_blur * ctx.diagonal_px, MAX_RADIUS_PX)

    def is_identity(self, p, ctx):
        t0, t1 = self.shutter(p, ctx)
        if t1 - t0 <= 0.0:
            return "shutter angle is 0"
        if ctx.velocity is None:
            return None
        peak = ctx.analysis.peak_speed
        if peak * (t1 - t0) < 0.5:
            return (f"velocity below half a pixel everywhere (peak {peak:.3g} px/frame over "
                    f"a {t1 - t0:.3g}-frame shutter)")
        return None

    def region_of_interest(self, p, ctx, window):
        return window.grown(int(math.ceil(self.max_radius_px(p, ctx))))

    def render(self, rt, p, ctx):
        src, vel = ctx.source, ctx.velocity
        if vel is None or vel.window != src.window:
            raise ClipError("motion_blur: the velocity pass must cover the source window "
                            f"{src.window} (it covers {None if vel is None else vel.window})")
        depth = ctx.depth if ctx.depth is not None and ctx.depth.window == src.window else None
        t0, t1 = self.shutter(p, ctx)
        a = ctx.analysis
        out, stats = reconstruct(
            rt, src, vel, depth, t0=t0, t1=t1, max_radius_px=self.max_radius_px(p, ctx),
            peak_speed=a.peak_speed, quality=ctx.quality, frame=ctx.frame,
            nonfinite=a.nonfinite_count)
        ctx.notes.append(f"motion_blur: {stats.moving_tiles}/{stats.tiles} tiles of "
                         f"{stats.tile} px moving, radius {stats.radius_px:.1f} px, "
                         f"<= {stats.max_samples} samples"
                         + (f", {a.nonfinite_count} non-finite pixels zeroed"
                            if a.nonfinite_count else ""))
        return out


# -- benchmark ---------------------------------------------------------------------------------
def moving_scene(width: int, height: int, max_speed_px: float = 60.0, moving_fraction=None):
    """A layered test scene for motion blur: a slowly drifting textured wall, a fast striped
    ball (``max_speed_px`` px/frame), a card moving diagonally and a near leaf.

    Speeds scale with ``max_speed_px``; with ``moving_fraction`` (e.g. 0.1) only a small
    ball moves, covering about that fraction of the frame's tiles, over a static wall.
    """
    from clfx.bench.scene import Layer, Light, Scene, Texture

    s = width / 640.0
    v = max_speed_px
    wall = Layer(depth=20.0, texture=Texture("blocks", (0.5, 0.45, 0.4), (0.05, 0.05, 0.06),
                                             period=12.0 * s, seed=3),
                 shape="full", name="wall",
                 lights=(Light((0.1 * width, -0.2 * height), (200.0, 150.0, 100.0), 2.0 * s),),
                 velocity=(0.0, 0.0) if moving_fraction else (0.05 * v, 0.0))
    if moving_fraction:
        r = 0.5 * math.sqrt(moving_fraction * width * height / math.pi) * 0.8
        ball = Layer(depth=5.0, texture=Texture("stripes", (0.9, 0.25, 0.1), (0.95, 0.9, 0.8),
                                                period=14.0 * s, angle=30.0),
                     shape="disk", center=(0.5 * width, 0.5 * height), size=(2 * r, 2 * r),
                     velocity=(v, 0.0), name="ball")
        return Scene(width, height, (wall, ball), name="motion blur, 10% moving")
    r = 0.12 * height
    layers = (
        wall,
        Layer(depth=5.0, texture=Texture("stripes", (0.9, 0.25, 0.1), (0.95, 0.9, 0.8),
                                         period=14.0 * s, angle=30.0),
              shape="disk", center=(0.3 * width, 0.45 * height), size=(2 * r, 2 * r),
              velocity=(v, 0.0), name="ball"),
        Layer(depth=3.0, texture=Texture("checker", (0.7, 0.7, 0.65), (0.05, 0.05, 0.06),
                                         period=12.0 * s, angle=8.0),
              shape="rounded", center=(0.68 * width, 0.55 * height),
              size=(0.22 * width, 0.32 * height), corner=8.0 * s,
              velocity=(-0.4 * v, 0.3 * v), name="card"),
        Layer(depth=1.0, texture=Texture("noise", (0.05, 0.25, 0.06), (0.15, 0.45, 0.1),
                                         period=9.0 * s, seed=5),
              shape="disk", center=(0.1 * width, 0.9 * height), size=(0.3 * width, 0.45 * height),
              opacity=0.9, velocity=(0.0, -0.2 * v), name="leaf"),
    )
    return Scene(width, height, layers, name="motion blur test scene")


def bench_case(width: int, height: int, rng, *, truth: bool = True, truth_samples: int = 64,
               moving_fraction=None):
    """A representative hard case: layers at several depths moving up to 60 px/frame at
    1920 px wide (scaled with the width), with the multisample ground truth (``truth``)."""
    from clfx.core.camera import Camera
    from clfx.bench.groundtruth import render_truth
    from clfx.bench.scene import render_sharp

    scene = moving_scene(width, height, 60.0 * width / 1920.0, moving_fraction)
    camera = Camera(shutter_angle=180.0, shutter_offset="centered")
    sharp = render_sharp(scene, 0.0, ss=2)
    case = dict(source=sharp.rgba, depth=sharp.depth, velocity=sharp.velocity,
                params={}, camera=camera)
    if truth:
        case["truth"] = render_truth(scene, camera, samples=truth_samples, dof=False,
                                     motion=True, ss=2)
    return case
