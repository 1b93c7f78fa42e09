"""A small layered 2.5D scene model: textured, partly transparent planes at several depths.

Used to generate test and demo frames with exact depth and velocity passes, and (with
:mod:`clfx.bench.groundtruth`) multisample ground truth for depth of field and motion blur.

Model
-----
A :class:`Scene` is a ``width x height`` pixel frame holding a background (a vertical
gradient at depth +inf) and a list of :class:`Layer` objects ordered far to near.  A layer is
a plane parallel to the sensor at planar depth ``depth`` (metres), described directly in
screen space (pixels, +x right, +y down, pixel centres at +0.5):

- a shape mask (``full``, ``rect``, ``disk`` = ellipse, ``rounded`` = rounded rectangle, or
  ``none`` = only its lights) of size ``size`` centred on ``center``, times ``opacity``;
- a procedural :class:`Texture` (flat, checker, stripes, value noise, text-like blocks)
  anchored to the layer's centre, so it moves with the layer;
- HDR emissive :class:`Light` spots (small antialiased disks, values of 50-5000), which are
  opaque and add their radiance on top of the texture;
- a constant screen-space velocity ``velocity`` in pixels per frame: at time ``t`` (frames,
  relative to the scene's frame) the whole layer is translated by ``velocity * t``, and
  turned about its centre by ``spin * t`` degrees (``angle`` at t = 0): a spinning layer's
  velocity varies across it (:meth:`Layer.velocity_at`).

:func:`render_sharp` evaluates every layer analytically at ``ss x ss`` sub-pixel positions
per pixel, composites them "over" (premultiplied alpha, far to near) and filters to pixels
(a box, or Blackman-Harris: :func:`filter_taps`).  Its depth pass is the depth of the
nearest layer owning the pixel (+inf for the background) and its velocity pass that layer's
forward velocity at the pixel centre (0 for the background), in clfx's conventions
(:mod:`clfx.core.frame`); a layer owns a pixel by coverage (more than half its sub-samples)
or, as renderers write passes, by the one sample at the pixel centre (``passes="centre"``).

This is a generator for tests and demos, not an effect: vectorised NumPy on the host.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from clfx.core.frame import Frame

SHAPES = ("full", "rect", "disk", "rounded", "none")
PATTERNS = ("flat", "checker", "stripes", "noise", "blocks")


# -- description -----------------------------------------------------------------------------
@dataclass(frozen=True)
class Texture:
    """A procedural texture in layer-local pixel coordinates.

    Parameters
    ----------
    pattern : {"flat", "checker", "stripes", "noise", "blocks"}
        ``blocks`` looks like lines of text (random dark blocks on ``color``).
    color, color2 : tuple of 3 floats
        Scene-linear RGB of the two tones (``color2`` unused by ``flat``).
    period : float
        Feature size in pixels (checker square, stripe pair, noise cell, text line height).
    angle : float
        Rotation of the pattern in degrees.
    seed : int
        Seed of the noise and block patterns.
    """

    pattern: str = "flat"
    color: tuple = (0.5, 0.5, 0.5)
    color2: tuple = (0.1, 0.1, 0.1)
    period: float = 16.0
    angle: float = 0.0
    seed: int = 0


@dataclass(frozen=True)
class Light:
    """An emissive disk of ``radius`` px at ``offset`` px from its layer's centre."""

    offset: tuple
    color: tuple = (1000.0, 1000.0, 1000.0)
    radius: float = 1.5


@dataclass(frozen=True)
class Layer:
    """A textured, partly transparent plane parallel to the sensor (see the module notes).

    Parameters
    ----------
    depth : float
        Planar depth in scene units (metres), > 0; ``math.inf`` is allowed.
    texture : Texture
    shape : {"full", "rect", "disk", "rounded", "none"}
    center, size : tuple of 2 floats
        Centre (at t = 0) and full width/height of the shape, in pixels.
    corner : float
        Corner radius in pixels of ``rounded``.
    opacity : float
        Alpha of the shape (lights are always opaque).
    lights : tuple of Light
    velocity : tuple of 2 floats
        Forward screen-space velocity of the centre in pixels per frame (+x right, +y down).
    angle : float
        Orientation in degrees (shape, texture and lights turned about ``center``; positive
        turns +x towards +y, i.e. clockwise on screen).
    spin : float
        Angular velocity in degrees per frame (same sense as ``angle``): a point at ``r`` from
        the centre moves with ``velocity + omega (-r_y, r_x)`` (omega in rad/frame).
    name : str
    """

    depth: float
    texture: Texture = Texture()
    shape: str = "full"
    center: tuple = (0.0, 0.0)
    size: tuple = (0.0, 0.0)
    corner: float = 0.0
    opacity: float = 1.0
    lights: tuple = ()
    velocity: tuple = (0.0, 0.0)
    name: str = ""
    angle: float = 0.0
    spin: float = 0.0

    def __post_init__(self):
        if self.shape not in SHAPES:
            raise ValueError(f"layer {self.name!r}: shape {self.shape!r} is not one of {SHAPES}")
        if self.texture.pattern not in PATTERNS:
            raise ValueError(f"layer {self.name!r}: pattern {self.texture.pattern!r} is not one "
                             f"of {PATTERNS}")
        if not self.depth > 0:
            raise ValueError(f"layer {self.name!r}: depth must be > 0, got {self.depth!r}")

    def moved(self, t: float) -> "Layer":
        """This layer translated by ``velocity * t`` and turned by ``spin * t`` (t in frames)."""
        if t == 0.0:
            return self
        return replace(self, center=(self.center[0] + self.velocity[0] * t,
                                     self.center[1] + self.velocity[1] * t),
                       angle=self.angle + self.spin * t)

    @property
    def turned(self) -> bool:
        """Whether the layer is (or becomes) rotated: its sprite cannot just be translated."""
        return self.angle != 0.0 or self.spin != 0.0

    def velocity_at(self, x, y):
        """Forward velocity (px/frame) of the layer's points at screen positions ``x, y``
        (arrays, time 0): the centre's translation plus the spin about the centre."""
        vx = np.full(np.shape(x), self.velocity[0], np.float32)
        vy = np.full(np.shape(y), self.velocity[1], np.float32)
        if self.spin != 0.0:
            om = math.radians(self.spin)
            vx = vx - np.float32(om) * (np.asarray(y, np.float32) - np.float32(self.center[1]))
            vy = vy + np.float32(om) * (np.asarray(x, np.float32) - np.float32(self.center[0]))
        return vx, vy

    def bounds(self, t: float = 0.0, margin: float = 0.0):
        """(x0, y0, x1, y1) in pixels enclosing the layer at time ``t``, or None for ``full``."""
        if self.shape == "full":
            return None
        cx = self.center[0] + self.velocity[0] * t
        cy = self.center[1] + self.velocity[1] * t
        if self.turned:   # any orientation: the circle around every part
            r = 0.5 * math.hypot(*self.size) if self.shape != "none" else 0.0
            for lt in self.lights:
                r = max(r, math.hypot(*lt.offset) + lt.radius + 1.0)
            return (cx - r - margin, cy - r - margin, cx + r + margin, cy + r + margin)
        boxes = []
        if self.shape != "none":
            boxes.append((cx - self.size[0] / 2, cy - self.size[1] / 2,
                          cx + self.size[0] / 2, cy + self.size[1] / 2))
        for lt in self.lights:
            r = lt.radius + 1.0
            boxes.append((cx + lt.offset[0] - r, cy + lt.offset[1] - r,
                          cx + lt.offset[0] + r, cy + lt.offset[1] + r))
        if not boxes:
            return (cx, cy, cx, cy)
        b = np.array(boxes)
        return (b[:, 0].min() - margin, b[:, 1].min() - margin,
                b[:, 2].max() + margin, b[:, 3].max() + margin)


@dataclass(frozen=True)
class Scene:
    """A frame of layers (far to near) over a background gradient at depth +inf.

    ``background`` is (top RGB, bottom RGB), ``background_alpha`` its alpha.
    """

    width: int
    height: int
    layers: tuple = ()
    background: tuple = ((0.02, 0.03, 0.06), (0.10, 0.09, 0.08))
    background_alpha: float = 1.0
    name: str = ""

    def moved(self, t: float) -> "Scene":
        return replace(self, layers=tuple(l.moved(t) for l in self.layers))


# -- evaluation ------------------------------------------------------------------------------
def _hash2(ix: np.ndarray, iy: np.ndarray, seed: int) -> np.ndarray:
    """Uniform [0, 1) from integer lattice coordinates (lowbias32-style integer hash)."""
    h = (ix.astype(np.int64) * 0x27D4EB2D + iy.astype(np.int64) * 0x165667B1 + seed * 0x9E3779B9)
    h = (h & 0xFFFFFFFF).astype(np.uint32)
    h ^= h >> np.uint32(16)
    h *= np.uint32(0x7FEB352D)
    h ^= h >> np.uint32(15)
    h *= np.uint32(0x846CA68B)
    h ^= h >> np.uint32(16)
    return (h >> np.uint32(8)).astype(np.float32) * np.float32(1.0 / 16777216.0)


def _value_noise(u, v, seed):
    iu, iv = np.floor(u), np.floor(v)
    fu, fv = u - iu, v - iv
    fu = fu * fu * (3 - 2 * fu)
    fv = fv * fv * (3 - 2 * fv)
    iu, iv = iu.astype(np.int64), iv.astype(np.int64)
    a, b = _hash2(iu, iv, seed), _hash2(iu + 1, iv, seed)
    c, d = _hash2(iu, iv + 1, seed), _hash2(iu + 1, iv + 1, seed)
    return (a + (b - a) * fu) * (1 - fv) + (c + (d - c) * fu) * fv


def texture_mix(tex: Texture, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Blend factor in [0, 1] between ``color`` (0) and ``color2`` (1) at local coords."""
    if tex.pattern == "flat":
        return np.zeros_like(u)
    ang = math.radians(tex.angle)
    ca, sa = math.cos(ang), math.sin(ang)
    ru = (ca * u + sa * v) / tex.period
    rv = (-sa * u + ca * v) / tex.period
    if tex.pattern == "checker":
        return ((np.floor(ru) + np.floor(rv)) % 2).astype(np.float32)
    if tex.pattern == "stripes":
        return (np.floor(2 * ru) % 2).astype(np.float32)
    if tex.pattern == "noise":
        n = 0.6 * _value_noise(ru, rv, tex.seed) + 0.4 * _value_noise(2.7 * ru, 2.7 * rv, tex.seed + 1)
        return np.clip(n, 0, 1).astype(np.float32)
    # blocks: text-like lines; each line holds "words" of random length separated by gaps
    line = np.floor(rv)
    in_line = (rv - line) < 0.55
    cell = np.floor(ru * 3.0)
    word = _hash2(cell.astype(np.int64), line.astype(np.int64), tex.seed) > 0.3
    in_cell = (ru * 3.0 - cell) < 0.8
    return (in_line & word & in_cell).astype(np.float32)


def _shape_alpha(layer: Layer, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    hw, hh = layer.size[0] / 2.0, layer.size[1] / 2.0
    if layer.shape == "full":
        return np.ones_like(u)
    if layer.shape == "none":
        return np.zeros_like(u)
    if layer.shape == "rect":
        return ((np.abs(u) <= hw) & (np.abs(v) <= hh)).astype(np.float32)
    if layer.shape == "disk":
        return ((u / max(hw, 1e-6)) ** 2 + (v / max(hh, 1e-6)) ** 2 <= 1.0).astype(np.float32)
    r = min(layer.corner, hw, hh)
    qx = np.maximum(np.abs(u) - (hw - r), 0.0)
    qy = np.maximum(np.abs(v) - (hh - r), 0.0)
    inside = (np.abs(u) <= hw) & (np.abs(v) <= hh) & (qx * qx + qy * qy <= r * r)
    return inside.astype(np.float32)


def _unturn(u, v, angle):
    """Screen offsets ``u, v`` from a layer's centre into its own (unturned) frame, for a
    layer turned by ``angle`` radians (a scalar or one per point)."""
    ca, sa = np.float32(np.cos(angle)), np.float32(np.sin(angle))
    return ca * u + sa * v, -sa * u + ca * v


def _shade_surface(layer: Layer, u, v, out: np.ndarray) -> None:
    """The layer's shape times its texture (premultiplied RGBA) at layer-frame ``u, v``,
    written into ``out`` (zeros; lights are added by the caller)."""
    alpha = _shape_alpha(layer, u, v) * np.float32(layer.opacity)
    if layer.shape != "none" and alpha.any():
        m = texture_mix(layer.texture, u, v)[..., None]
        c0 = np.asarray(layer.texture.color, np.float32)
        c1 = np.asarray(layer.texture.color2, np.float32)
        out[..., :3] = (c0 + (c1 - c0) * m) * alpha[..., None]
        out[..., 3] = alpha


def rasterise_layer(layer: Layer, x0: float, y0: float, width: int, height: int,
                    ss: int = 2, t: float = 0.0, *, rim_px: float | None = None) -> np.ndarray:
    """Premultiplied RGBA (height*ss, width*ss, 4) float32 of ``layer`` at time ``t``.

    Samples sit at ``x0 + (i + 0.5) / ss`` (and likewise in y): ``ss x ss`` per pixel of the
    region whose top-left pixel corner is ``(x0, y0)``.  Lights' rims are antialiased over
    ``rim_px`` (default one sample spacing, ``1 / ss``); shapes and textures are point-sampled.
    """
    sharp = ss if rim_px is None else 1.0 / float(rim_px)   # 1 / rim width
    lay = layer.moved(t)
    out = np.zeros((height * ss, width * ss, 4), np.float32)
    if width <= 0 or height <= 0:
        return out
    xs = (x0 + (np.arange(width * ss, dtype=np.float64) + 0.5) / ss - lay.center[0]).astype(np.float32)
    ys = (y0 + (np.arange(height * ss, dtype=np.float64) + 0.5) / ss - lay.center[1]).astype(np.float32)
    u, v = np.meshgrid(xs, ys)
    if lay.angle != 0.0:   # into the layer's own (unturned) frame
        u, v = _unturn(u, v, math.radians(lay.angle))
    _shade_surface(lay, u, v, out)
    for lt in lay.lights:
        # Evaluate each light only over its own few sub-samples (scenes hold many lights).
        ox, oy = lt.offset
        if lay.angle != 0.0:   # the light's offset turned with the layer, on screen
            a = math.radians(lay.angle)
            ox, oy = ox * math.cos(a) - oy * math.sin(a), ox * math.sin(a) + oy * math.cos(a)
        lx = lay.center[0] + ox - x0
        ly = lay.center[1] + oy - y0
        reach = lt.radius + 1.0
        i0, i1 = max(0, int((lx - reach) * ss)), min(width * ss, int(math.ceil((lx + reach) * ss)))
        j0, j1 = max(0, int((ly - reach) * ss)), min(height * ss, int(math.ceil((ly + reach) * ss)))
        if i1 <= i0 or j1 <= j0:
            continue
        # Antialiased disk: coverage falls from 1 to 0 across one sample spacing at the rim.
        d = np.hypot(u[j0:j1, i0:i1] - np.float32(lt.offset[0]),
                     v[j0:j1, i0:i1] - np.float32(lt.offset[1]))
        cov = _light_cover(d, lt.radius, sharp)
        col = np.asarray(lt.color, np.float32)
        o = out[j0:j1, i0:i1]
        o[..., :3] = o[..., :3] * (1 - cov) + col * cov
        o[..., 3:] = o[..., 3:] * (1 - cov) + cov
    return out


def sample_layer(layer: Layer, x: np.ndarray, y: np.ndarray, t=0.0, *,
                 rim_px: float = 0.25) -> np.ndarray:
    """Premultiplied RGBA (``x.shape + (4,)``) float32 of ``layer`` point-sampled at screen
    positions ``x, y`` (float arrays of one shape), each at its own time ``t`` (frames; a
    scalar or an array of that shape): what a path tracer's camera ray sees of the layer.

    The same evaluation as :func:`rasterise_layer` (shape, texture, lights antialiased over
    ``rim_px``), at arbitrary positions and times instead of a regular grid at one instant.
    """
    x = np.asarray(x, np.float64)
    y = np.asarray(y, np.float64)
    t = np.asarray(t, np.float64)   # a scalar stays one: one angle for every point
    out = np.zeros(x.shape + (4,), np.float32)
    if x.size == 0:
        return out
    vx, vy = layer.velocity
    u = (x - (layer.center[0] + vx * t)).astype(np.float32)
    v = (y - (layer.center[1] + vy * t)).astype(np.float32)
    if layer.turned:   # into the layer's own (unturned) frame, each point at its own angle
        u, v = _unturn(u, v, np.radians(layer.angle + layer.spin * t))
    _shade_surface(layer, u, v, out)
    for lt in layer.lights:
        # only the points near the light (in the layer's frame: u, v are already turned)
        reach = lt.radius + 1.0
        near = np.nonzero((np.abs(u - np.float32(lt.offset[0])) < reach)
                          & (np.abs(v - np.float32(lt.offset[1])) < reach))
        if not near[0].size:
            continue
        d = np.hypot(u[near] - np.float32(lt.offset[0]), v[near] - np.float32(lt.offset[1]))
        cov = _light_cover(d, lt.radius, 1.0 / float(rim_px))
        o = out[near]
        o[:, :3] = o[:, :3] * (1 - cov) + np.asarray(lt.color, np.float32) * cov
        o[:, 3:] = o[:, 3:] * (1 - cov) + cov
        out[near] = o
    return out


def _light_cover(d: np.ndarray, radius: float, sharp: float) -> np.ndarray:
    """An antialiased disk's coverage at distances ``d``: 1 to 0 across ``1 / sharp`` px at
    the rim, shaped (..., 1) float32."""
    return np.clip((radius - d) * sharp + 0.5, 0.0, 1.0).astype(np.float32)[..., None]


def background_rgba(scene: Scene, x0: float, y0: float, width: int, height: int,
                    ss: int = 2, *, ys: np.ndarray | None = None) -> np.ndarray:
    """The background gradient (premultiplied RGBA) over a region, sampled like a layer
    (or, given ``ys``, an array of screen rows, at those rows: shaped ``ys.shape + (4,)``)."""
    if ys is None:
        ys = (y0 + (np.arange(height * ss, dtype=np.float64) + 0.5) / ss)[:, None]
        shape = (height * ss, width * ss)
    else:
        shape = np.shape(ys)
    f = np.clip(np.asarray(ys) / max(scene.height, 1), 0.0, 1.0).astype(np.float32)[..., None]
    top = np.asarray(scene.background[0], np.float32)
    bottom = np.asarray(scene.background[1], np.float32)
    a = np.float32(scene.background_alpha)
    rgb = (top + (bottom - top) * f) * a
    out = np.empty(shape + (4,), np.float32)
    out[..., :3] = rgb
    out[..., 3] = a
    return out


# -- stratified jittered sampling (renderer-like) ----------------------------------------------
def _mix32(h: np.ndarray) -> np.ndarray:
    """lowbias32 finaliser of a uint32 array (Wellons' integer hash)."""
    h = h ^ (h >> np.uint32(16))
    h = h * np.uint32(0x7FEB352D)
    h = h ^ (h >> np.uint32(15))
    h = h * np.uint32(0x846CA68B)
    return h ^ (h >> np.uint32(16))


def hash_uniform(*keys) -> np.ndarray:
    """Uniform [0, 1) float64 from integer keys (scalars or broadcastable arrays), each key
    mixed in turn: deterministic per (seed, pixel, sample, dimension), uncorrelated across
    any of them."""
    shape = np.broadcast_shapes(*(np.shape(k) for k in keys)) or (1,)
    h = np.array(0x9E3779B9, np.uint32)   # grows to the keys' shape (scalar keys first: cheap)
    with np.errstate(over="ignore"):   # uint32 arithmetic wraps, as a hash wants
        for k in keys:
            h = _mix32(h ^ (np.asarray(k, np.int64) & 0xFFFFFFFF).astype(np.uint32))
    h = np.broadcast_to(h, shape)
    return (h >> np.uint32(8)).astype(np.float64) * (1.0 / 16777216.0)


def jittered_grid(x0: int, y0: int, width: int, height: int, ss: int, seed: int,
                  index: int = 0):
    """Screen positions ``(x, y)`` ((height ss, width ss) float64) of a stratified jittered
    pixel sampling of a region: one uniform random point in each of the ``ss x ss`` strata
    of every pixel, hashed from ``seed``, the pass ``index``, the frame pixel and the stratum
    (the same pixel gets the same points in any region)."""
    gy, gx = np.mgrid[0:height * ss, 0:width * ss]
    X, Y = x0 + gx // ss, y0 + gy // ss
    pixel = (Y & 0xFFFF) * 65536 + (X & 0xFFFF)
    key = (gy % ss) * ss + gx % ss
    x = X + ((gx % ss) + hash_uniform(seed, index, 0, pixel, key)) / ss
    y = Y + ((gy % ss) + hash_uniform(seed, index, 1, pixel, key)) / ss
    return x, y


PIXEL_FILTERS = ("box", "blackman-harris")
"""Pixel reconstruction filters of the supersampled renders (:func:`filter_taps`)."""

DEFAULT_FILTER_WIDTH = {"box": 1.0, "blackman-harris": 1.5}
"""Filter widths (px) used when none is given: a one-pixel box; Blackman-Harris 1.5 px wide,
Cycles' default pixel filter."""


def pixel_filter_weight(d, pixel_filter: str = "box", width: float | None = None):
    """Weight of a sample ``d`` px (array) from the pixel centre along one axis (unnormalised).

    ``box``: 1 inside ``|d| < width / 2``.  ``blackman-harris``: the 4-term Blackman-Harris
    window over ``[-width / 2, width / 2]`` (Cycles' ``filter_func_blackman_harris``); both
    are applied separably in x and y.
    """
    if pixel_filter not in PIXEL_FILTERS:
        raise ValueError(f"pixel filter {pixel_filter!r} is not one of {PIXEL_FILTERS}")
    w = DEFAULT_FILTER_WIDTH[pixel_filter] if width is None else float(width)
    if not w > 0:
        raise ValueError(f"pixel filter width must be > 0, got {width!r}")
    d = np.asarray(d, np.float64)
    inside = np.abs(d) < 0.5 * w
    if pixel_filter == "box":
        return inside.astype(np.float64)
    x = 2.0 * math.pi * (d / w + 0.5)
    bh = 0.35875 - 0.48829 * np.cos(x) + 0.14128 * np.cos(2 * x) - 0.01168 * np.cos(3 * x)
    return np.where(inside, bh, 0.0)


def filter_taps(ss: int, pixel_filter: str = "box", width: float | None = None):
    """Sub-sample taps of a pixel filter on an ``ss``-per-pixel grid, along one axis.

    Returns ``(j, w)``: integer sub-sample indices relative to the pixel's first sub-sample
    (tap ``j`` sits at ``X + (j + 0.5) / ss`` for pixel ``X``, i.e. ``(j + 0.5) / ss - 0.5`` px
    from its centre; negative or >= ``ss`` reach into the neighbours) and their weights (sum
    1).  A one-pixel box gives ``j = 0 .. ss-1`` with equal weights.
    """
    ss = int(ss)
    if ss < 1:
        raise ValueError(f"sub-samples per pixel must be >= 1, got {ss}")
    w = DEFAULT_FILTER_WIDTH.get(pixel_filter, 1.0) if width is None else float(width)
    reach = int(math.ceil(0.5 * w * ss)) + 1
    j = np.arange(-reach, ss + reach)
    wt = pixel_filter_weight((j + 0.5) / ss - 0.5, pixel_filter, width)
    keep = wt > 0
    if not keep.any():   # a filter narrower than the grid: the nearest sub-sample(s)
        d = np.abs((j + 0.5) / ss - 0.5)
        keep = d <= d.min() + 1e-12
        wt = np.ones_like(wt)
    return j[keep], wt[keep] / wt[keep].sum()


def filter_margin(ss: int, taps) -> int:
    """Pixels beyond the frame a filter with sub-sample ``taps`` reads on each side."""
    taps = np.asarray(taps)
    return int(max(0, -(-int(-taps.min()) // ss), -(-int(taps.max() - ss + 1) // ss)))


def box_downsample(img: np.ndarray, ss: int) -> np.ndarray:
    """Mean over ``ss x ss`` blocks (the pixel box filter of the sub-samples)."""
    if ss == 1:
        return img
    h, w = img.shape[0] // ss, img.shape[1] // ss
    return img.reshape(h, ss, w, ss, *img.shape[2:]).mean(axis=(1, 3), dtype=np.float64)


def filter_downsample(img: np.ndarray, ss: int, taps, weights, margin: int) -> np.ndarray:
    """Pixels from sub-samples through a separable pixel filter (float64).

    ``img`` holds ``ss`` sub-samples per pixel over the frame grown by ``margin`` pixels on
    every side; the result is the frame: ``out[Y, X] = sum w_a w_b img[(Y + m) ss + a,
    (X + m) ss + b]`` over the taps ``a, b`` (:func:`filter_taps`).
    """
    out = np.asarray(img)
    for axis in (0, 1):
        n = out.shape[axis] // ss - 2 * margin
        acc = None
        for j, w in zip(np.asarray(taps), np.asarray(weights)):
            start = margin * ss + int(j)
            sl = [slice(None)] * out.ndim
            sl[axis] = slice(start, start + (n - 1) * ss + 1, ss)
            term = w * out[tuple(sl)].astype(np.float64)
            acc = term if acc is None else acc + term
        out = acc
    return out


def _clip_box(bounds, width, height, x_lo=0, y_lo=0):
    """Integer pixel box (x0, y0, x1, y1) of ``bounds`` inside ``[x_lo, width) x [y_lo,
    height)``, or None if empty."""
    if bounds is None:
        return x_lo, y_lo, width, height
    x0 = max(x_lo, int(math.floor(bounds[0])))
    y0 = max(y_lo, int(math.floor(bounds[1])))
    x1 = min(width, int(math.ceil(bounds[2])))
    y1 = min(height, int(math.ceil(bounds[3])))
    if x1 <= x0 or y1 <= y0:
        return None
    return x0, y0, x1, y1


PASS_MODES = ("coverage", "centre")
"""How :func:`render_sharp` writes depth and velocity: from the nearest layer covering more
than ``pass_alpha`` of the pixel's sub-samples, or (as renderers write them) from the nearest
layer whose alpha at the pixel centre exceeds ``pass_alpha`` (one point: never averaged)."""


def render_sharp(scene: Scene, t: float = 0.0, *, ss: int = 2, pixel_filter: str = "box",
                 filter_width: float | None = None, passes: str = "coverage",
                 pass_alpha: float = 0.5, jitter_seed: int | None = None,
                 samples: int | None = None):
    """Render the pinhole (all-sharp, instantaneous) frame at time ``t`` with its passes.

    Parameters
    ----------
    scene : Scene
    t : float
        Time in frames relative to the scene's frame.
    ss : int
        Sub-samples per pixel along each axis (antialiasing).
    pixel_filter : {"box", "blackman-harris"}
        Filter from sub-samples to pixels (:func:`pixel_filter_weight`); wider than a pixel,
        it reads sub-samples of the neighbours (the scene is rendered past the frame).
    filter_width : float, optional
        Its width in px (default :data:`DEFAULT_FILTER_WIDTH`).
    passes : {"coverage", "centre"}
        How depth and velocity are written (:data:`PASS_MODES`); ``centre`` is what a
        renderer writes beside a filtered beauty: the surface at the pixel centre.
    pass_alpha : float
        Alpha (coverage or at the centre) above which a layer owns the pixel's passes.
    jitter_seed : int, optional
        Sample the beauty as a renderer does, at one jittered point in each of the ``ss x ss``
        strata of a pixel (:func:`jittered_grid`, seeded per pixel and stratum by this seed)
        instead of at the strata's centres (box filter only).  The passes stay the layers at
        the pixel centre (or their coverage of the regular grid).
    samples : int, optional
        With ``jitter_seed``: points per pixel, rounded up to a multiple of ``ss x ss`` (that
        many jittered passes over the strata, averaged; default one pass, ``ss x ss``).

    Returns
    -------
    clfx.core.frame.Frame
        ``rgba`` premultiplied scene-linear; ``depth`` planar z in metres of the nearest layer
        owning the pixel (+inf = background); ``velocity`` that layer's forward velocity at
        the pixel centre in px/frame (0 for the background), in clfx's conventions
        (:mod:`clfx.core.frame`).
    """
    if passes not in PASS_MODES:
        raise ValueError(f"passes {passes!r} is not one of {PASS_MODES}")
    w, h = scene.width, scene.height
    taps, weights = filter_taps(ss, pixel_filter, filter_width)
    m = filter_margin(ss, taps)
    plain_box = m == 0 and len(taps) == ss and np.all(taps == np.arange(ss))
    if jitter_seed is not None and not plain_box:
        raise ValueError("jittered sampling is implemented for the one-pixel box filter only, "
                         f"not {pixel_filter!r} of width {filter_width!r}")
    if jitter_seed is None:
        acc = _beauty_samples(scene, t, ss, (-m, -m, w + m, h + m))
    else:
        passes_n = max(1, -(-int(samples or ss * ss) // (ss * ss)))
        acc = sum(_beauty_samples(scene, t, ss, (0, 0, w, h), (jitter_seed, p))
                  for p in range(passes_n)) / np.float32(passes_n)
    depth = np.full((h, w), np.inf, np.float32)
    velocity = np.zeros((h, w, 2), np.float32)
    for layer in scene.layers:   # far to near: nearer layers overwrite the passes
        fb = _clip_box(layer.bounds(t, margin=1.0), w, h)
        if fb is None:
            continue
        fx0, fy0, fx1, fy1 = fb
        if passes == "coverage":
            sub = rasterise_layer(layer, fx0, fy0, fx1 - fx0, fy1 - fy0, ss, t)[..., 3]
            cover = box_downsample(sub, ss) > pass_alpha
        else:
            cover = rasterise_layer(layer, fx0, fy0, fx1 - fx0, fy1 - fy0, 1, t,
                                    rim_px=1.0 / ss)[..., 3] > pass_alpha
        depth[fy0:fy1, fx0:fx1][cover] = layer.depth
        if layer.spin != 0.0:
            gy, gx = np.mgrid[fy0:fy1, fx0:fx1] + 0.5
            vx, vy = layer.moved(t).velocity_at(gx, gy)
            velocity[fy0:fy1, fx0:fx1][cover] = np.stack([vx, vy], -1)[cover]
        else:
            velocity[fy0:fy1, fx0:fx1][cover] = layer.velocity
    if plain_box:
        rgba = box_downsample(acc, ss)
    else:
        rgba = filter_downsample(acc, ss, taps, weights, m)
    return Frame.from_array(rgba.astype(np.float32), depth=depth, velocity=velocity)


def _beauty_samples(scene: Scene, t: float, ss: int, region, jitter=None) -> np.ndarray:
    """The composited sub-samples (``ss`` per pixel and axis, premultiplied RGBA) of the
    pixel ``region`` (x0, y0, x1, y1) at time ``t``: on the regular grid, or with ``jitter``
    = (seed, pass) at that pass's stratified jittered points (:func:`jittered_grid`)."""
    rx0, ry0, rx1, ry1 = region
    if jitter is None:
        acc = background_rgba(scene, rx0, ry0, rx1 - rx0, ry1 - ry0, ss)
    else:
        xs, ys = jittered_grid(rx0, ry0, rx1 - rx0, ry1 - ry0, ss, *jitter)
        acc = background_rgba(scene, rx0, ry0, rx1 - rx0, ry1 - ry0, ss, ys=ys)
    for layer in scene.layers:   # far to near
        box = _clip_box(layer.bounds(t, margin=1.0), rx1, ry1, rx0, ry0)
        if box is None:
            continue
        x0, y0, x1, y1 = box
        sl = np.s_[(y0 - ry0) * ss:(y1 - ry0) * ss, (x0 - rx0) * ss:(x1 - rx0) * ss]
        if jitter is None:
            rgba = rasterise_layer(layer, x0, y0, x1 - x0, y1 - y0, ss, t)
        else:
            rgba = sample_layer(layer, xs[sl], ys[sl], t, rim_px=1.0 / ss)
        acc[sl] = rgba + acc[sl] * (1 - rgba[..., 3:4])
    return acc


def render_rows(scene: Scene, t: float, y0: int, y1: int, *, ss: int = 2,
                jitter_seed: int | None = None, samples: int | None = None) -> np.ndarray:
    """Rows ``[y0, y1)`` of :func:`render_sharp`'s box-filtered beauty at time ``t`` (the same
    samples, ``jitter_seed`` and ``samples`` included, rendered over those rows only: a
    rolling shutter's truth renders each row at its own time without rendering the whole
    frame per row)."""
    region = (0, y0, scene.width, y1)
    if jitter_seed is None:
        return box_downsample(_beauty_samples(scene, t, ss, region), ss).astype(np.float32)
    passes_n = max(1, -(-int(samples or ss * ss) // (ss * ss)))
    acc = sum(_beauty_samples(scene, t, ss, region, (jitter_seed, p)) for p in range(passes_n))
    return box_downsample(acc / np.float32(passes_n), ss).astype(np.float32)


# -- the built-in demo -----------------------------------------------------------------------
def _wrap(x, lo, hi):
    """``x`` wrapped into [lo, hi) (objects leaving one side come back on the other)."""
    return lo + (x - lo) % (hi - lo)


def demo_scene(frame: int, width: int = 640, height: int = 360) -> Scene:
    """The built-in demo scene at ``frame``: lights, textures at several depths, motion.

    Content (sizes and speeds scale with ``width``, so any resolution shows the same shot):
    a night sky with a bright moon (HDR ~60) at 1 km; a city wall at 20 m with lit windows
    (HDR 50-400) drifting slowly; a string of small lights at 8 m (HDR 200-5000); a
    striped ball crossing the frame fast at 5 m (~12 px/frame at 640 wide); the subject, a
    checkered card with a text-like label swaying slowly at 3 m; and a partly transparent
    noisy leaf at 1 m in the lower-left corner.  Everything moves smoothly with ``frame``;
    velocities are the time derivatives of the positions.
    """
    s = width / 640.0
    f = float(frame)
    layers = []

    moon = Layer(depth=1000.0, shape="none", center=(0.82 * width, 0.16 * height),
                 lights=(Light((0.0, 0.0), (60.0, 58.0, 50.0), 9.0 * s),),
                 velocity=(0.05 * s, 0.0), name="moon")
    layers.append(moon.moved(f))

    # City wall at 20 m: its top edge is a skyline against the sky (a depth discontinuity).
    wall_v = (0.3 * s, 0.0)
    wall_lights = []
    rng = np.random.default_rng(7)
    for i in range(60):
        ox = rng.uniform(-1.5, 1.5) * width
        oy = rng.uniform(-0.2, 0.4) * 0.55 * height
        lum = float(rng.choice([50.0, 120.0, 400.0]))
        wall_lights.append(Light((ox, oy), (lum, 0.8 * lum, 0.5 * lum), 1.2 * s))
    wall = Layer(depth=20.0, texture=Texture("blocks", (0.12, 0.11, 0.10), (0.03, 0.03, 0.035),
                                             period=10.0 * s, seed=3),
                 shape="rect", center=(0.5 * width, 0.70 * height),
                 size=(4.0 * width, 0.62 * height), lights=tuple(wall_lights),
                 velocity=wall_v, name="wall")
    layers.append(wall.moved(f))

    # String of lights at 8 m, swinging gently.
    amp, omega = 6.0 * s, 2 * math.pi / 96.0
    dy = amp * math.sin(omega * f)
    bulbs = []
    for i in range(9):
        lum = [200.0, 800.0, 5000.0][i % 3]
        col = [(lum, 0.6 * lum, 0.2 * lum), (0.3 * lum, 0.5 * lum, lum), (lum, lum, lum)][i % 3]
        bulbs.append(Light(((i - 4) * 0.09 * width, 10.0 * s * math.cos(math.pi * (i - 4) / 8)),
                           col, (1.0 + 0.5 * (i % 2)) * s))
    layers.append(Layer(depth=8.0, shape="none", center=(0.45 * width, 0.22 * height + dy),
                        lights=tuple(bulbs), velocity=(0.0, amp * omega * math.cos(omega * f)),
                        name="light string"))

    # Ball crossing fast at 5 m.
    speed = 12.0 * s
    r = 0.09 * height
    bx = _wrap(-r + speed * f, -r, width + r)
    layers.append(Layer(depth=5.0, texture=Texture("stripes", (0.9, 0.25, 0.1), (0.95, 0.9, 0.8),
                                                   period=14.0 * s, angle=30.0),
                        shape="disk", center=(bx, 0.52 * height), size=(2 * r, 2 * r),
                        velocity=(speed, 0.0), name="ball"))

    # Subject at 3 m: a checkered card with a label, swaying slowly.
    sway, om2 = 10.0 * s, 2 * math.pi / 150.0
    cx = 0.40 * width + sway * math.sin(om2 * f)
    vx = sway * om2 * math.cos(om2 * f)
    layers.append(Layer(depth=3.0, texture=Texture("checker", (0.7, 0.7, 0.65), (0.05, 0.05, 0.06),
                                                   period=12.0 * s, angle=8.0),
                        shape="rounded", center=(cx, 0.60 * height),
                        size=(0.30 * width, 0.42 * height), corner=10.0 * s,
                        lights=(Light((0.12 * width, -0.17 * height), (3000.0, 300.0, 200.0),
                                      1.5 * s),),
                        velocity=(vx, 0.0), name="subject"))
    layers.append(Layer(depth=2.99, texture=Texture("blocks", (0.85, 0.82, 0.7), (0.1, 0.1, 0.12),
                                                    period=7.0 * s, seed=11),
                        shape="rect", center=(cx, 0.60 * height + 0.13 * height),
                        size=(0.22 * width, 0.08 * height), velocity=(vx, 0.0),
                        name="label"))

    # Near leaf at 1 m, partly transparent, slow drift up and down.
    ny = 0.92 * height + 8.0 * s * math.sin(2 * math.pi * f / 200.0)
    nvy = 8.0 * s * 2 * math.pi / 200.0 * math.cos(2 * math.pi * f / 200.0)
    layers.append(Layer(depth=1.0, texture=Texture("noise", (0.05, 0.25, 0.06), (0.15, 0.45, 0.1),
                                                   period=9.0 * s, seed=5),
                        shape="disk", center=(0.08 * width, ny), size=(0.34 * width, 0.5 * height),
                        opacity=0.9, velocity=(0.0, nvy), name="leaf"))
    return Scene(width, height, tuple(layers), name=f"demo frame {frame}")


# -- the motion blur test scene --------------------------------------------------------------
def moving_scene(width: int, height: int, max_speed_px: float = 60.0,
                 moving_fraction: float | None = None) -> Scene:
    """A layered test scene for motion blur: a slowly drifting textured wall, a fast striped
    ball (``max_speed_px`` px/frame), a card moving diagonally and a near leaf.

    Speeds scale with ``max_speed_px``; with ``moving_fraction`` (e.g. 0.1) only a small
    ball moves, covering about that fraction of the frame's tiles, over a static wall.
    """
    s = width / 640.0
    v = max_speed_px
    wall = Layer(depth=20.0, texture=Texture("blocks", (0.5, 0.45, 0.4), (0.05, 0.05, 0.06),
                                             period=12.0 * s, seed=3),
                 shape="full", name="wall",
                 lights=(Light((0.1 * width, -0.2 * height), (200.0, 150.0, 100.0),
                               max(2.0 * s, 1.0)),),
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


def synthetic_plate(w: int, h: int):
    """A synthetic plate with depth, velocity and a few hot lights (no scene rasteriser:
    cheap at 8K): what the tiled renders of the cinema look are checked and measured on
    (tests/test_plan.py, scripts/tile_8k.py)."""
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    rgba = np.empty((h, w, 4), np.float32)
    rgba[..., 0] = 0.3 + 0.2 * np.sin(x * 0.013) * np.cos(y * 0.011)
    rgba[..., 1] = 0.3 + 0.2 * np.sin(x * 0.007 + 1.0)
    rgba[..., 2] = 0.3 + 0.2 * np.cos(y * 0.009)
    rgba[..., 3] = 1.0
    for fx, fy in ((0.2, 0.3), (0.7, 0.6), (0.5, 0.5)):
        cy, cx = int(fy * h), int(fx * w)
        rgba[cy - 2:cy + 3, cx - 2:cx + 3, :3] = 400.0
    depth = (1.0 + 20.0 * x / w + 3.0 * y / h).astype(np.float32)
    vel = np.stack([np.full_like(x, 3.0), 1.0 + 2.0 * y / h], axis=2).astype(np.float32)
    del x, y
    return Frame.from_array(rgba, depth=depth, velocity=vel)
