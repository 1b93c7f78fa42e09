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
  relative to the scene's frame) the whole layer is translated by ``velocity * t``.

:func:`render_sharp` evaluates every layer analytically at ``ss x ss`` sub-pixel positions
per pixel, composites them "over" (premultiplied alpha, far to near) and box-filters to pixels.
Its depth pass is the depth of the nearest layer whose pixel coverage exceeds 0.5 (+inf for
the background) and its velocity pass the forward velocity of that same layer (0 for the
background), in clfx's conventions (:mod:`clfx.core.frame`).

This is a generator for tests and demos, not an effect: vectorised NumPy on the host.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

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
        Forward screen-space velocity in pixels per frame (+x right, +y down).
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

    def __post_init__(self):
        if self.shape not in SHAPES:
            raise ValueError(f"layer {self.name!r}: shape {self.shape!r} is not one of {SHAPES}")
        if self.texture.pattern not in PATTERNS:
            raise ValueError(f"layer {self.name!r}: pattern {self.texture.pattern!r} is not one "
                             f"of {PATTERNS}")
        if not self.depth > 0:
            raise ValueError(f"layer {self.name!r}: depth must be > 0, got {self.depth!r}")

    def moved(self, t: float) -> "Layer":
        """This layer translated by ``velocity * t`` (t in frames)."""
        if t == 0.0:
            return self
        return replace(self, center=(self.center[0] + self.velocity[0] * t,
                                     self.center[1] + self.velocity[1] * t))

    def bounds(self, t: float = 0.0, margin: float = 0.0):
        """(x0, y0, x1, y1) in pixels enclosing the layer at time ``t``, or None for ``full``."""
        if self.shape == "full":
            return None
        cx = self.center[0] + self.velocity[0] * t
        cy = self.center[1] + self.velocity[1] * t
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


def rasterise_layer(layer: Layer, x0: float, y0: float, width: int, height: int,
                    ss: int = 2, t: float = 0.0) -> np.ndarray:
    """Premultiplied RGBA (height*ss, width*ss, 4) float32 of ``layer`` at time ``t``.

    Samples sit at ``x0 + (i + 0.5) / ss`` (and likewise in y): ``ss x ss`` per pixel of the
    region whose top-left pixel corner is ``(x0, y0)``.
    """
    lay = layer.moved(t)
    out = np.zeros((height * ss, width * ss, 4), np.float32)
    if width <= 0 or height <= 0:
        return out
    xs = (x0 + (np.arange(width * ss, dtype=np.float64) + 0.5) / ss - lay.center[0]).astype(np.float32)
    ys = (y0 + (np.arange(height * ss, dtype=np.float64) + 0.5) / ss - lay.center[1]).astype(np.float32)
    u, v = np.meshgrid(xs, ys)
    alpha = _shape_alpha(lay, u, v) * np.float32(lay.opacity)
    if lay.shape != "none" and alpha.any():
        m = texture_mix(lay.texture, u, v)[..., None]
        c0 = np.asarray(lay.texture.color, np.float32)
        c1 = np.asarray(lay.texture.color2, np.float32)
        out[..., :3] = (c0 + (c1 - c0) * m) * alpha[..., None]
        out[..., 3] = alpha
    for lt in lay.lights:
        # Evaluate each light only over its own few sub-samples (scenes hold many lights).
        lx = lay.center[0] + lt.offset[0] - x0
        ly = lay.center[1] + lt.offset[1] - y0
        reach = lt.radius + 1.0
        i0, i1 = max(0, int((lx - reach) * ss)), min(width * ss, int(math.ceil((lx + reach) * ss)))
        j0, j1 = max(0, int((ly - reach) * ss)), min(height * ss, int(math.ceil((ly + reach) * ss)))
        if i1 <= i0 or j1 <= j0:
            continue
        # Antialiased disk: coverage falls from 1 to 0 across one sample spacing at the rim.
        d = np.hypot(u[j0:j1, i0:i1] - np.float32(lt.offset[0]),
                     v[j0:j1, i0:i1] - np.float32(lt.offset[1]))
        cov = np.clip((lt.radius - d) * ss + 0.5, 0.0, 1.0).astype(np.float32)[..., None]
        col = np.asarray(lt.color, np.float32)
        o = out[j0:j1, i0:i1]
        o[..., :3] = o[..., :3] * (1 - cov) + col * cov
        o[..., 3:] = o[..., 3:] * (1 - cov) + cov
    return out


def background_rgba(scene: Scene, x0: float, y0: float, width: int, height: int,
                    ss: int = 2) -> np.ndarray:
    """The background gradient (premultiplied RGBA) over a region, sampled like a layer."""
    ys = y0 + (np.arange(height * ss, dtype=np.float64) + 0.5) / ss
    f = np.clip(ys / max(scene.height, 1), 0.0, 1.0).astype(np.float32)[:, None, None]
    top = np.asarray(scene.background[0], np.float32)
    bottom = np.asarray(scene.background[1], np.float32)
    a = np.float32(scene.background_alpha)
    rgb = (top + (bottom - top) * f) * a
    out = np.empty((height * ss, width * ss, 4), np.float32)
    out[..., :3] = rgb
    out[..., 3] = a
    return out


def box_downsample(img: np.ndarray, ss: int) -> np.ndarray:
    """Mean over ``ss x ss`` blocks (the pixel box filter of the sub-samples)."""
    if ss == 1:
        return img
    h, w = img.shape[0] // ss, img.shape[1] // ss
    return img.reshape(h, ss, w, ss, *img.shape[2:]).mean(axis=(1, 3), dtype=np.float64)


def _clip_box(bounds, width, height):
    """Integer pixel box (x0, y0, x1, y1) of ``bounds`` inside the frame, or None if empty."""
    if bounds is None:
        return 0, 0, width, height
    x0 = max(0, int(math.floor(bounds[0])))
    y0 = max(0, int(math.floor(bounds[1])))
    x1 = min(width, int(math.ceil(bounds[2])))
    y1 = min(height, int(math.ceil(bounds[3])))
    if x1 <= x0 or y1 <= y0:
        return None
    return x0, y0, x1, y1


def render_sharp(scene: Scene, t: float = 0.0, *, ss: int = 2):
    """Render the pinhole (all-sharp, instantaneous) frame at time ``t`` with its passes.

    Parameters
    ----------
    scene : Scene
    t : float
        Time in frames relative to the scene's frame.
    ss : int
        Sub-samples per pixel along each axis (antialiasing).

    Returns
    -------
    clfx.core.frame.Frame
        ``rgba`` premultiplied scene-linear; ``depth`` planar z in metres of the nearest layer
        covering more than half the pixel (+inf = background); ``velocity`` that layer's
        forward velocity in px/frame (0 for the background).
    """
    from clfx.core.frame import Frame

    w, h = scene.width, scene.height
    acc = background_rgba(scene, 0, 0, w, h, ss)
    depth = np.full((h, w), np.inf, np.float32)
    velocity = np.zeros((h, w, 2), np.float32)
    for layer in scene.layers:   # far to near: nearer layers overwrite the passes
        box = _clip_box(layer.bounds(t, margin=1.0), w, h)
        if box is None:
            continue
        x0, y0, x1, y1 = box
        rgba = rasterise_layer(layer, x0, y0, x1 - x0, y1 - y0, ss, t)
        sl = np.s_[y0 * ss:y1 * ss, x0 * ss:x1 * ss]
        acc[sl] = rgba + acc[sl] * (1 - rgba[..., 3:4])
        cover = box_downsample(rgba[..., 3], ss) > 0.5
        depth[y0:y1, x0:x1][cover] = layer.depth
        velocity[y0:y1, x0:x1][cover] = layer.velocity
    rgba = box_downsample(acc, ss).astype(np.float32)
    return Frame.from_array(rgba, depth=depth, velocity=velocity)


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
