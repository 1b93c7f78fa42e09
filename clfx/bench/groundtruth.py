"""Multisample ground truth for depth of field and motion blur of layered 2.5D scenes.

The renderer averages many complete renders of a :class:`clfx.bench.scene.Scene`, each for one
point on the lens aperture and one instant inside the shutter interval (distribution ray
tracing reduced to planes; Cook, Porter & Carpenter 1984, "Distributed ray tracing"; the
accumulation buffer of Haeberli & Akeley 1990).  Nothing is approximated per pixel: partial
occlusion of a blurred foreground, in-focus edges and moving layers all come out of the
visibility of each sample render.

Thin-lens geometry
------------------
A lens of focal length ``f`` focused at ``S`` puts the sensor at ``v = f S / (S - f)``.  A point
at planar depth ``z`` focuses at ``v_z = f z / (z - f)``; the ray through the lens point ``a``
(mm from the optical axis in the lens plane) meets the sensor displaced from the chief ray by

    d = a (1 - v / v_z) = a * f / (S - f) * (S / z - 1)       (mm on the sensor)

Over an aperture of diameter ``A = f / N`` the displacements span ``A f / (S - f) |1 - S/z|``:
exactly the circle of confusion of :meth:`clfx.core.camera.Camera.coc_px`.  clfx uses image
coordinates after the usual flip of the sensor image, and writes the shift of a layer as

    shift_px = p * coc_signed_px(z) / 2,     coc_signed_px(z) = K (1 - S / z)

with ``p`` the lens point in units of the aperture radius (|p| <= 1 on a round aperture) and
``K = A f / (S - f) * width_px / sensor_width`` (:meth:`clfx.core.camera.Camera.coc_scale_px`
and ``coc_signed_px``, the one copy of the formula the effects use too).  Behind the focus
plane (z > S) a point's bokeh is the aperture shape ``p``; in front of it, the shape turned
by 180 degrees.  A polygonal aperture of ``blades`` blades is inscribed in the unit circle
(the CoC is the circumscribed circle's diameter), its first vertex pointing up (-y) turned by
``blade_rotation`` degrees clockwise on screen (:func:`clfx.core.camera.aperture_radius`).
The magnification change with the lens point (``v`` instead of ``f``) is ignored: the layers
are described in screen space.

Lens geometry (the camera block's, as :mod:`clfx.plugins.dof` reads it): an anamorphic
squeeze scales the lens point's x by ``1 / anamorphic_squeeze`` (vertical oval bokeh); axial
chromatic aberration adds each channel's offset (:meth:`clfx.core.camera.Camera.axial_ca_px`)
to every layer's signed CoC, one composite per distinct offset (alpha from green's); optical
vignetting accepts a lens point ``l`` at pixel ``x`` only inside the barrel circle
``|l - c(x)| <= 1`` (:func:`clfx.core.camera.optical_vignetting_centre`, the frame's centre
and half diagonal; ``optical_vignetting_front`` adds the front rim's circle, its centre
that of minus its strength, shifted towards the frame's centre): each pixel accumulates its
accepted renders and their weights and is normalised by them (the clipped aperture; the darkening is not modelled, as in the effect).

Motion: at time ``t`` (frames) a layer is translated by ``velocity * t``.  The shutter is
open for ``shutter_angle / 360`` of a frame, centred on the frame time, starting at it
("opening") or ending at it ("closing") per ``Camera.shutter_offset``
(:meth:`clfx.core.camera.Camera.shutter_interval`, as the effects read it).

Sampling: ``samples`` lens points on a golden-angle spiral (uniform in the disk; mapped to
the polygon radially with Jacobian weights ``R(phi)^2``) paired with stratified shutter
times from a second low-discrepancy sequence and with one sub-pixel position per render
(the ``ss x ss`` positions of a pixel, or the taps of a wider pixel filter, cycled in a
scrambled order and weighted by the filter: an accumulation buffer that antialiases).  Each
layer is rasterised once at ``ss x ss`` sub-samples per pixel over its padded extent and
kept phase-major; a sample render places each layer at an integer sub-sample offset (its
shift rounded to ``1/ss`` px), composites "over" at pixel resolution and accumulates in
float64.  A spinning layer (:attr:`clfx.bench.scene.Layer.spin`) is rasterised exactly
for every render instead.  With ``samples`` = 0 aperture and 0 shutter it reproduces
:func:`clfx.bench.scene.render_sharp` with the same ``ss`` and filter exactly.

Renderer-like cases
-------------------
Renderers write a filtered beauty (many samples per pixel, box or Blackman-Harris filter)
and depth / velocity from one sample at the pixel centre.  :func:`make_case` with ``ss >= 4``
(:data:`RENDER_SS`) makes exactly that pair: the effects' input from
:func:`clfx.bench.scene.render_sharp` (``passes="centre"``) and the truth from
:func:`render_truth`, both through the same pixel filter.  ``ss = 1`` keeps the
single-sample mode (beauty, depth and velocity from the one centre sample).

That accumulation buffer shares one sub-pixel position (and one shutter instant) between
all pixels of a render, and the sharp frame samples the same ``ss x ss`` grid: sub-pixel
texture then carries one offset in the input and in the truth, which no renderer has
(issue 24).  ``make_case(jitter_seed=...)`` (the motion cases, :data:`JITTER_SEED`) samples
both as a path tracer does instead: every pixel its own jittered points in the ``ss x ss``
strata, and for the truth its own shutter instants (:func:`jittered_truth`); with
``noise_floor`` the truth is rendered again with another seed and its log-PSNR against the
truth kept (``floor``, the bench's ``truth_floor``).  Depth of field keeps the grid.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from clfx.bench.metrics import error_metrics
from clfx.bench.scene import (
    Scene,
    background_rgba,
    filter_margin,
    filter_taps,
    hash_uniform,
    rasterise_layer,
    render_sharp,
    sample_layer,
)
from clfx.core.camera import (
    Camera,
    aperture_radius,
    first_blade_angle,
    optical_vignetting_centre,
)
from clfx.core.frame import Frame
from clfx.io.write import write_frame

GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))
PLASTIC_INV = 0.7548776662466927  # 1 / plastic number: a second, independent Weyl sequence


# -- sampling --------------------------------------------------------------------------------
def aperture_samples(n: int, blades: int = 0, rotation_deg: float = 0.0, roundness: float = 0.0):
    """``n`` points over the aperture (unit circumradius) and their weights (sum 1).

    A golden-angle spiral is uniform over the unit disk; a point at angle ``phi`` is scaled
    by the boundary radius ``R(phi)`` and weighted by ``R(phi)^2`` (the Jacobian of the radial
    map), which keeps the estimate uniform over the polygon.
    """
    i = np.arange(n, dtype=np.float64)
    r = np.sqrt((i + 0.5) / n)
    phi = i * GOLDEN_ANGLE
    rad = aperture_radius(phi, blades, first_blade_angle(rotation_deg), roundness)
    pts = np.stack([r * rad * np.cos(phi), r * rad * np.sin(phi)], axis=1)
    w = rad ** 2
    return pts, w / w.sum()


def shutter_times(n: int, camera: Camera, positions: int = 1) -> np.ndarray:
    """``n`` stratified instants over the shutter interval for renders that cycle through
    ``positions`` sub-pixel positions (render ``i`` at position ``i % positions``).

    Every position gets one instant in each of the ``n / positions`` strata of the shutter
    (offset within the stratum by a Weyl sequence over the positions), so each sub-pixel
    position integrates the whole shutter; the strata are visited in a Weyl-shuffled order,
    so time is uncorrelated with the lens spiral (whose radius grows with ``i``).  A single
    Weyl sequence over ``i`` gave position ``m`` the instants ``0.5 + (m + 16 j) a`` (mod 1),
    which at 64 renders cover only 31% of the shutter per position: the truth's blur then
    depended on the direction of motion (a box filter sheared in x-t), up to 6 dB on fine
    texture moving 1-2 px/frame (issue 24).
    """
    t0, t1 = camera.shutter_interval()
    k = max(int(positions), 1)
    if n % k:
        u = np.mod(0.5 + np.arange(n) * PLASTIC_INV, 1.0)
    else:
        nb = n // k
        i = np.arange(n)
        stratum = np.argsort(np.mod(0.5 + np.arange(nb) * PLASTIC_INV, 1.0), kind="stable")
        u = (stratum[i // k] + np.mod(0.5 + (i % k) * PLASTIC_INV, 1.0)) / nb
    return t0 + (t1 - t0) * u


# -- renderer --------------------------------------------------------------------------------
@dataclass
class _Sprite:
    """A layer rasterised once over its padded extent, stored phase-major: ``phases[a, b]``
    is the pixel-resolution plane of sub-samples ``(r ss + a, c ss + b)``, so a sample render
    at any sub-sample offset reads one contiguous plane.  A spinning layer (``layer`` set)
    is rasterised again for every sample render instead."""

    phases: np.ndarray | None
    x0: int                  # frame pixel of phases[:, :, 0, 0]
    y0: int
    half_coc: float          # signed CoC / 2 in px: shift per unit lens position
    velocity: tuple
    layer: object = None     # a spinning Layer, rasterised per sample render
    box: tuple = ()          # its pixel box (x0, y0, x1, y1) in the frame


def _phase_major(rgba: np.ndarray, ss: int) -> np.ndarray:
    h, w = rgba.shape[0] // ss, rgba.shape[1] // ss
    return np.ascontiguousarray(rgba.reshape(h, ss, w, ss, 4).transpose(1, 3, 0, 2, 4))


def _sprite(scene: Scene, layer, t: float, pad_px: float, ss: int, half_coc: float) -> _Sprite:
    w, h = scene.width, scene.height
    pad = int(math.ceil(pad_px)) + 1
    b = layer.bounds(t, margin=1.0)
    if b is None:
        box = (-pad, -pad, w + pad, h + pad)
    else:
        box = (max(-pad, math.floor(b[0] - pad)), max(-pad, math.floor(b[1] - pad)),
               min(w + pad, math.ceil(b[2] + pad)), min(h + pad, math.ceil(b[3] + pad)))
    x0, y0, x1, y1 = (int(v) for v in box)
    x1, y1 = max(x1, x0), max(y1, y0)
    rgba = rasterise_layer(layer, x0, y0, x1 - x0, y1 - y0, ss, t)
    return _Sprite(_phase_major(rgba, ss), x0, y0, half_coc, tuple(layer.velocity))


def _place(out: np.ndarray, src: np.ndarray, ox: int, oy: int, first: bool) -> None:
    """Composite ``src`` with its top-left pixel at frame pixel (ox, oy) "over" ``out``."""
    H, W = out.shape[:2]
    h, w = src.shape[:2]
    fx0, fy0 = max(0, ox), max(0, oy)
    fx1, fy1 = min(W, ox + w), min(H, oy + h)
    if fx1 <= fx0 or fy1 <= fy0:
        return
    src = src[fy0 - oy:fy1 - oy, fx0 - ox:fx1 - ox]
    dst = out[fy0:fy1, fx0:fx1]
    if first:
        dst[...] = src
    else:
        dst *= 1.0 - src[..., 3:4]
        dst += src


def pixel_positions(ss: int, pixel_filter: str = "box", filter_width: float | None = None):
    """The sub-pixel sample positions of a render and their weights.

    Returns ``(jx, jy, w)``: sub-sample indices (position ``X + (j + 0.5) / ss`` in pixel
    ``X``; :func:`clfx.bench.scene.filter_taps`) of the separable filter's 2D taps, flattened,
    and their weights (sum 1).  ``ss = 1`` with a box: the pixel centre alone.
    """
    taps, w1 = filter_taps(ss, pixel_filter, filter_width)
    jy, jx = np.meshgrid(taps, taps, indexing="ij")
    return jx.ravel(), jy.ravel(), np.outer(w1, w1).ravel()


def _composite(out: np.ndarray, sprites: list, px: float, py: float, ts: float, ox: int,
               oy: int, ss: int, t: float) -> None:
    """One sample render into ``out``: every sprite shifted by the lens point ``(px, py)``
    (in CoC radii, after the anamorphic squeeze) times its half CoC, moved to the shutter
    instant ``ts`` and composited "over" at sub-pixel position ``(ox, oy)``."""
    for j, sp in enumerate(sprites):
        sx = px * sp.half_coc
        sy = py * sp.half_coc
        if sp.layer is not None:
            x0, y0, x1, y1 = sp.box
            if x1 > x0 and y1 > y0:
                img = rasterise_layer(sp.layer, x0 + (ox + 0.5) / ss - 0.5 - sx,
                                      y0 + (oy + 0.5) / ss - 0.5 - sy, x1 - x0, y1 - y0,
                                      1, t + ts, rim_px=1.0 / ss)
                _place(out, img, x0, y0, first=(j == 0))
            continue
        sx += sp.velocity[0] * ts
        sy += sp.velocity[1] * ts
        offx = ox - int(round(sx * ss))
        offy = oy - int(round(sy * ss))
        qx, ax = divmod(offx, ss)
        qy, ay = divmod(offy, ss)
        _place(out, sp.phases[ay, ax], sp.x0 - qx, sp.y0 - qy, first=(j == 0))


def render_truth(scene: Scene, camera: Camera, *, t: float = 0.0, samples: int = 256,
                 dof: bool = True, motion: bool = True, ss: int = 1,
                 pixel_filter: str = "box", filter_width: float | None = None,
                 exact_below_px: float = 4.0, progress=None,
                 jitter_seed: int | None = None) -> np.ndarray:
    """Multisample render of ``scene`` through ``camera``: the ground truth.

    Every sample render is the whole frame for one lens point, one shutter instant and one
    sub-pixel position (shared by all pixels, as in an accumulation buffer): the
    ``ss x ss`` positions of a pixel (or the taps of a wider ``pixel_filter``) are cycled
    through the renders in a fixed scrambled order and weighted by the filter.  With
    ``ss >= 4`` this is what a renderer writes: a beauty supersampled at least 4 x 4 per
    pixel, whose lens and shutter samples are spread over the pixel's area; pair it with
    :func:`clfx.bench.scene.render_sharp` ``(ss=ss, pixel_filter=..., passes="centre")``
    for the effects' input (depth and velocity at the pixel centre, never averaged).
    ``ss = 1`` is the single-sample mode (every render samples the pixel centre).

    Parameters
    ----------
    scene : Scene
    camera : Camera
        Lens (focal length, f-number, sensor width, focus distance, blades, blade rotation,
        optical vignetting, anamorphic squeeze, axial chromatic aberration) and shutter
        (angle, offset).
    t : float
        Frame time in frames relative to the scene's frame.
    samples : int
        Number of (lens point, shutter instant, pixel position) renders; rounded up to a
        multiple of the number of pixel positions (``ss * ss`` for a box).
    dof, motion : bool
        Integrate over the aperture / over the shutter interval.
    ss : int
        Sub-pixel positions per pixel and axis, and the resolution ``1/ss`` px to which
        lens and motion shifts of fast layers are rounded.
    exact_below_px : float
        Layers whose shifts over the aperture and shutter span less than this (px), and
        spinning layers, are rasterised exactly for every render instead of being rounded
        (rounding a path of a pixel to 1/4 px widens its blur by a tenth or more).
    pixel_filter : {"box", "blackman-harris"}
        Pixel filter of the beauty (:func:`clfx.bench.scene.pixel_filter_weight`).
    filter_width : float, optional
        Its width in px (default: 1 for the box, 1.5 for Blackman-Harris).
    progress : callable, optional
        Called as ``progress(done, total)``.
    jitter_seed : int, optional
        Sample like a path tracer instead (:func:`jittered_truth`, motion without depth of
        field, box filter): every pixel its own jittered sub-pixel points and shutter
        instants, seeded by this seed.

    Returns
    -------
    np.ndarray
        (height, width, 4) float32 premultiplied RGBA.

    Notes
    -----
    Memory: each fast or static layer is kept at ``ss x ss`` sub-samples over its extent
    (float32 RGBA), e.g. about 0.5 GB for a full-frame layer at 1920x1080 and ``ss = 4``.
    Time: one composite of every layer at pixel resolution per sample render, plus the
    rasterisation of the exact layers (about 0.5 s per render for a full-frame textured
    layer at 1920x1080).
    """
    if jitter_seed is not None:
        if dof:
            raise ValueError("the jittered truth integrates the shutter only: render depth of "
                             "field with jitter_seed=None (the accumulation buffer)")
        if pixel_filter != "box" or filter_width not in (None, 1.0):
            raise ValueError("the jittered truth is implemented for the one-pixel box filter only")
        return jittered_truth(scene, camera, t=t, samples=samples, motion=motion, ss=ss,
                              seed=jitter_seed, progress=progress)
    w, h = scene.width, scene.height
    jx, jy, fw = pixel_positions(ss, pixel_filter, filter_width)
    k = len(fw)
    n = -(-max(1, int(samples)) // k) * k if (dof or motion) else k
    lens, lens_w = aperture_samples(n, camera.blades, camera.blade_rotation)
    if not dof:
        lens = np.zeros_like(lens)
    times = shutter_times(n, camera, k) if motion else np.zeros(n)
    t_extent = float(np.abs(times).max()) if n else 0.0
    # pixel position of render i: every block of k renders visits each position once, in
    # an order scrambled against the lens spiral and the shutter sequence
    pos = np.random.default_rng(0x5EED).permutation(k)[np.arange(n) % k]
    weights = (lens_w if dof else np.full(n, 1.0 / n)) * fw[pos]
    if k > 1:
        weights = weights / weights.sum()
    reach = filter_margin(ss, jx) + 1   # pixels the filter's taps reach past a pixel

    def half_coc(z):
        return 0.0 if not dof else 0.5 * float(camera.coc_signed_px(z, w))

    # axial chromatic aberration: channels focusing elsewhere than green have their own
    # signed CoC (an additive offset, Camera.axial_ca_px); one composite per distinct offset
    ca = tuple(0.5 * v for v in camera.axial_ca_px(w)) if dof else (0.0, 0.0)
    groups: dict[float, list[int]] = {}
    for ch, off in ((1, 0.0), (0, ca[0]), (2, ca[1])):
        groups.setdefault(off, []).append(ch)
    offsets = list(groups)
    max_off = max(abs(o) for o in offsets)
    squeeze = camera.anamorphic_squeeze if dof else 1.0

    bg_half = half_coc(math.inf)
    bpad = int(abs(bg_half) + max_off) + 2 + reach
    bg = background_rgba(scene, -bpad, -bpad, w + 2 * bpad, h + 2 * bpad, ss)
    bg_phases = _phase_major(bg, ss)
    sprites = {o: [_Sprite(bg_phases, -bpad, -bpad, bg_half + o, (0.0, 0.0))] for o in offsets}
    del bg
    t_lo, t_hi = (float(times.min()), float(times.max())) if motion else (0.0, 0.0)
    for layer in scene.layers:
        hc = half_coc(layer.depth)
        hc_max = max(abs(hc + o) for o in offsets)
        speed = math.hypot(*layer.velocity) * t_extent
        travel = 2.0 * hc_max + math.hypot(*layer.velocity) * (t_hi - t_lo)
        if (motion and layer.spin != 0.0) or 0.0 < travel < exact_below_px:
            # rasterised for every render at its exact position: a spinning layer cannot be
            # translated, and rounding a short path to 1/ss px would blur it visibly more
            lo, hi = layer.bounds(t + t_lo, margin=1.0), layer.bounds(t + t_hi, margin=1.0)
            if lo is None:
                box = (0, 0, w, h)
            else:
                pad = hc_max + reach
                box = (max(math.floor(min(lo[0], hi[0]) - pad), 0),
                       max(math.floor(min(lo[1], hi[1]) - pad), 0),
                       min(math.ceil(max(lo[2], hi[2]) + pad), w),
                       min(math.ceil(max(lo[3], hi[3]) + pad), h))
            for o in offsets:
                sprites[o].append(_Sprite(None, box[0], box[1], hc + o, tuple(layer.velocity),
                                          layer, box))
        else:
            sp = _sprite(scene, layer, t, hc_max + speed + reach, ss, hc)
            for o in offsets:
                sprites[o].append(replace(sp, half_coc=hc + o))

    # optical vignetting: a lens point l is seen by pixel x only inside the barrel circle
    # |l - c(x)| <= 1 (clfx.core.camera.optical_vignetting_centre); each pixel averages its
    # accepted renders (mask-weighted sums over the mask weights)
    # (the rear rim's circle, shifted away from the centre) and |l - c_f(x)| <= 1 (the front
    # rim's, c_f the centre of minus optical_vignetting_front: shifted towards it)
    cat = None
    rims = [k for k in (camera.optical_vignetting, -camera.optical_vignetting_front) if k]
    if dof and rims:
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float64) + 0.5
        cat = [optical_vignetting_centre(xx, yy, strength=k, centre=(0.5 * w, 0.5 * h),
                                         half_diagonal=0.5 * math.hypot(w, h)) for k in rims]
        msum = np.zeros((h, w), np.float64)
        acc_all = np.zeros((h, w, 4), np.float64)

    acc = np.zeros((h, w, 4), np.float64)
    out = np.empty((h, w, 4), np.float32)
    for i in range(n):
        (px, py), ts = lens[i], times[i]
        ox, oy = int(jx[pos[i]]), int(jy[pos[i]])
        if len(offsets) > 1:
            sample = np.empty((h, w, 4), np.float32)
        for off, chans in groups.items():
            _composite(out, sprites[off], px / squeeze, py, ts, ox, oy, ss, t)
            if len(offsets) == 1:
                sample = out
            else:
                sample[..., chans] = out[..., chans]
                if 1 in chans:
                    sample[..., 3] = out[..., 3]
        if cat is None:
            acc += weights[i] * sample
        else:
            inside = True
            for cx, cy in cat:
                inside = inside & (((px - cx) ** 2 + (py - cy) ** 2) <= 1.0)
            m = weights[i] * inside
            acc += m[..., None] * sample
            msum += m
            acc_all += weights[i] * sample
        if progress is not None:
            progress(i + 1, n)
    if cat is not None:
        # where no render was accepted (a barrel that closes the aperture), the unclipped mean
        acc = np.where(msum[..., None] > 0, acc / np.maximum(msum, 1e-300)[..., None], acc_all)
    return acc.astype(np.float32)


_TRUTH_KEY = 10
"""Dimension keys of the jittered truth's random numbers (10 ...: apart from the sharp
frame's 0 and 1, :func:`clfx.bench.scene.jittered_grid`, so one seed gives both independent
streams)."""


def jittered_truth(scene: Scene, camera: Camera, *, t: float = 0.0, samples: int = 256,
                   motion: bool = True, ss: int = 4, seed: int = 1,
                   progress=None) -> np.ndarray:
    """Motion-blurred render of ``scene`` sampled as a path tracer samples a pixel.

    Every pixel draws its own ``samples`` camera rays (rounded up to a multiple of ``ss x
    ss``): render ``i`` gives each pixel one uniform random point in the sub-pixel stratum
    ``i mod ss^2`` (visited in a scrambled order) and one instant in a stratum of the shutter
    (``n`` strata, their order a per-pixel permutation ``i -> (a_p i + b_p) mod n``, ``a_p``
    prime to ``n``), both jittered within their strata.  So no sub-pixel position is tied
    to an instant (each pixel pairs them differently; each position still meets instants
    spread over the whole shutter), and no two pixels share their positions: unlike the
    accumulation buffer of :func:`render_truth`, no fixed sub-pixel grid is common to the
    input and the truth.  Each ray sees the layers, moved (and turned) to its own instant,
    evaluated exactly (:func:`clfx.bench.scene.sample_layer`) and composited "over"; the
    pixel is the mean of its rays (a one-pixel box filter).  All random numbers hash
    (``seed``, pixel, render, dimension) (:func:`clfx.bench.scene.hash_uniform`): the same
    call gives the same image; another ``seed`` an independent render of the same truth.

    ``motion=False``: ``ss x ss`` renders at t, the jittered sharp frame (another sequence
    than :func:`clfx.bench.scene.render_sharp`'s with the same seed).

    Returns (height, width, 4) float32 premultiplied RGBA.
    """
    w, h = scene.width, scene.height
    jx, jy, _ = pixel_positions(ss)
    k = len(jx)
    n = -(-max(1, int(samples)) // k) * k if motion else k
    t0, t1 = camera.shutter_interval() if motion else (0.0, 0.0)
    pos = np.random.default_rng(0x5EED).permutation(k)[np.arange(n) % k]
    yy, xx = np.mgrid[0:h, 0:w]
    pixel = yy * 65536 + xx
    units = np.array([a for a in range(1, n + 1) if math.gcd(a, n) == 1], np.int64)
    key = _TRUTH_KEY
    a_p = units[(hash_uniform(seed, key, pixel) * len(units)).astype(np.int64)]
    b_p = (hash_uniform(seed, key + 1, pixel) * n).astype(np.int64)
    boxes = []   # each layer's pixels over the shutter (its box at both ends, and between)
    for layer in scene.layers:
        lo, hi = layer.bounds(t + t0, margin=1.0), layer.bounds(t + t1, margin=1.0)
        if lo is None:
            boxes.append((0, 0, w, h))
            continue
        x0, y0 = max(math.floor(min(lo[0], hi[0])), 0), max(math.floor(min(lo[1], hi[1])), 0)
        x1, y1 = min(math.ceil(max(lo[2], hi[2])), w), min(math.ceil(max(lo[3], hi[3])), h)
        boxes.append((x0, y0, x1, y1) if x1 > x0 and y1 > y0 else None)
    acc = np.zeros((h, w, 4), np.float64)
    for i in range(n):
        xs = xx + (jx[pos[i]] + hash_uniform(seed, i, key + 2, pixel)) / ss
        ys = yy + (jy[pos[i]] + hash_uniform(seed, i, key + 3, pixel)) / ss
        if motion:
            stratum = (a_p * i + b_p) % n
            ts = t + t0 + (t1 - t0) * (stratum + hash_uniform(seed, i, key + 4, pixel)) / n
        else:
            ts = np.full((h, w), float(t))
        out = background_rgba(scene, 0, 0, w, h, ys=ys)
        for layer, box in zip(scene.layers, boxes):
            if box is None:
                continue
            x0, y0, x1, y1 = box
            sl = np.s_[y0:y1, x0:x1]
            src = sample_layer(layer, xs[sl], ys[sl], ts[sl], rim_px=1.0 / ss)
            dst = out[sl]
            dst *= 1.0 - src[..., 3:4]
            dst += src
        acc += out
        if progress is not None:
            progress(i + 1, n)
    return (acc / n).astype(np.float32)


# -- cases -----------------------------------------------------------------------------------
RENDER_SS = 4
"""Sub-samples per pixel and axis of renderer-like cases (4 x 4 = 16 positions per pixel)."""

JITTER_SEED = 1
"""Seed of the renderer-like motion cases (``make_case(jitter_seed=...)``): their sharp frame
and truth sampled at jittered points, no grid shared by the two; the noise floor's second
truth uses ``JITTER_SEED + 1``.  Depth of field keeps the accumulation buffer's grid: its
truths take 16384 renders, which the jittered sampler cannot afford."""


@dataclass
class GroundTruthCase:
    """A scene, its sharp frame with passes (the effects' input) and the multisample truth."""

    scene: Scene
    camera: Camera
    sharp: object            # clfx.core.frame.Frame
    truth: np.ndarray
    samples: int
    seconds: float           # wall time of the truth render
    settings: dict = field(default_factory=dict)
    floor: float | None = None
    """log-PSNR (dB) of a second truth (another seed) against ``truth``: its own noise
    floor, for jittered truths rendered with ``noise_floor``."""


def make_case(scene: Scene, camera: Camera, *, t: float = 0.0, samples: int = 256,
              dof: bool = True, motion: bool = False, ss: int = 1,
              pixel_filter: str = "box", filter_width: float | None = None,
              passes: str = "centre", jitter_seed: int | None = None,
              noise_floor: bool = False) -> GroundTruthCase:
    """Render the sharp frame and the ground truth of ``scene`` through the same pixel filter.

    Parameters
    ----------
    scene, camera, t, samples, dof, motion
        As :func:`render_truth`.
    ss : int
        Sub-samples per pixel and axis of both renders: 1 = single sample (beauty and passes
        from the pixel centre), :data:`RENDER_SS` (4) or more = renderer-like (beauty
        supersampled, passes from the centre).
    pixel_filter, filter_width
        The beauty's pixel filter, ``"box"`` or ``"blackman-harris"``
        (:func:`clfx.bench.scene.pixel_filter_weight`).
    passes : {"centre", "coverage"}
        How the sharp frame's depth and velocity are written (``centre``: as a renderer,
        from the surface at the pixel centre; see :func:`clfx.bench.scene.render_sharp`).
    jitter_seed : int, optional
        Render both as a path tracer samples (motion only, box filter): the sharp frame at
        ``samples`` stratified jittered points per pixel (:func:`clfx.bench.scene.render_sharp`;
        as many as the truth's rays, so the input is no noisier than the truth), the truth
        with :func:`jittered_truth`, both from this seed (independent streams).  None: both on
        the regular ``ss x ss`` grid (the accumulation buffer; depth of field needs it).
    noise_floor : bool
        With ``jitter_seed``, render the truth a second time (seed ``jitter_seed + 1``) and
        keep its log-PSNR against the truth as ``floor`` (doubles the truth's time).

    Returns
    -------
    GroundTruthCase
        ``sharp`` (a Frame with rgba, depth, velocity) is the effects' input, ``truth``
        the (h, w, 4) float32 multisample render to compare with.
    """
    sharp = render_sharp(scene, t, ss=ss, pixel_filter=pixel_filter, filter_width=filter_width,
                         passes=passes, jitter_seed=jitter_seed,
                         samples=None if jitter_seed is None else samples)
    t0 = time.perf_counter()
    kw = dict(t=t, samples=samples, dof=dof, motion=motion, ss=ss, pixel_filter=pixel_filter,
              filter_width=filter_width)
    truth = render_truth(scene, camera, jitter_seed=jitter_seed, **kw)
    seconds = time.perf_counter() - t0
    floor = None
    if noise_floor and jitter_seed is not None:
        again = render_truth(scene, camera, jitter_seed=jitter_seed + 1, **kw)
        floor = error_metrics(again, truth)["psnr_log"]
    return GroundTruthCase(scene, camera, sharp, truth, samples, seconds,
                           dict(t=t, dof=dof, motion=motion, ss=ss, pixel_filter=pixel_filter,
                                filter_width=filter_width, passes=passes,
                                jitter_seed=jitter_seed), floor)


def case_dict(case: GroundTruthCase, params: dict | None = None, **extra) -> dict:
    """A bench case (:mod:`clfx.bench.cases`) from a ground-truth case: source, passes,
    camera, truth and the truth's render time."""
    f = case.sharp
    if case.floor is not None:
        extra.setdefault("truth_floor", case.floor)
    return dict(source=f.rgba, depth=f.depth, velocity=f.velocity, params=dict(params or {}),
                camera=case.camera, truth=case.truth, truth_seconds=case.seconds, **extra)


def write_case(case: GroundTruthCase, directory, *, name: str = "case",
               overwrite: bool = True) -> dict:
    """Write ``<name>.sharp.exr`` (beauty + Z + forward.u/v) and ``<name>.truth.exr`` (float).

    Returns the paths written.  Uses :func:`clfx.io.write.write_frame` (imported lazily).
    """
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    attrs = {"clfx:camera": str(case.camera.as_dict()), "clfx:samples": int(case.samples)}
    paths = {"sharp": d / f"{name}.sharp.exr", "truth": d / f"{name}.truth.exr"}
    write_frame(case.sharp, paths["sharp"], bit_depth="float", overwrite=overwrite,
                attributes=attrs)
    write_frame(Frame.from_array(case.truth), paths["truth"], bit_depth="float",
                overwrite=overwrite, attributes=attrs, write_passes=False)
    return paths
