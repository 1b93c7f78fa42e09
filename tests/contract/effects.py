"""What the contract and fuzz suites feed every registered effect: small synthetic frames,
synthetic depth / velocity passes (read from ``descriptor.clips``), a camera, and the few
parameters an effect needs before it does any work on them.

Everything else is read from the descriptors, so a new effect is covered by adding its
module (and, only if its defaults are a no-op or leave a code path idle, one line to
``ACTIVE``).
"""
from __future__ import annotations

import functools

import numpy as np

from clfx.io.lenses import read_lens
from clfx.pipeline.look import read_image_rgba
from clfx.core.camera import Camera
from clfx.core.plugin import QUALITY_LEVELS, BoolParam, FloatParam, IntParam
from clfx.core.rect import Rect
from clfx.host import RenderContext
from clfx.plugins import discover
from tests.effects import render_effect

EFFECTS = sorted(discover())
QUALITIES = QUALITY_LEVELS

SIZE = (48, 64)   # (h, w): small keeps the suite fast
"""The default frame shape of the contract suite."""

CAMERA = Camera(focal_length=35.0, f_number=1.4, focus_distance=2.0, sensor_width=12.0,
                shutter_angle=180.0, blades=6)
"""A fast lens on a small sensor, focused at 2 m, six aperture blades: on a 64 px frame every
camera-driven effect acts (depth of field blurs the far rows by several pixels)."""

ACTIVE: dict[str, dict] = {
    # Only effects whose defaults are a no-op on the contract frame, need a choice (a lens),
    # or leave a code path idle.
    "bleed": {"size": 0.05},
    # a static camera never breathes: scale from a reference focus of 0.5 m (the frame widens
    # 5.6%, past the frame's edges: the clamp and its warning)
    "breathing": {"amount": 1.0, "reference_focus": 0.5},
    "camera_blur": {"length": 0.03, "roll": 2.0, "zoom": 0.02},
    "defocus": {"size": 0.02},
    "distortion": {"amount": 0.15, "p1": 0.01},
    "keystone": {"tilt": 12.0, "swing": -8.0},
    "lens": {"maker": "Canon", "model": "Canon EF 24-70mm f/2.8L II USM"},
    # physical ghosts of the frame's 5-nit lights are far below visible (1e-5 of the light):
    # a large gain makes them draw, so the physical path is what the suite checks
    "lens_flare": {"gain": 1e5, "light_level": 1e4},   # 2000x for a 5-nit light, as before
    "sensor_noise": {"prnu": 0.01},   # all three noise terms
    "vignette": {"amount": 0.4},
}
"""Parameters (over the defaults) that make each effect do visible work on ``scene()``."""

HIGHLIGHT = 50.0
"""Highlights of the contract frame: above every effect's default threshold."""


def params(name: str, **override):
    """The active parameters of ``name`` (defaults + ``ACTIVE`` + ``override``)."""
    cls = discover()[name]
    return cls.params(**{**ACTIVE.get(name, {}), **override})


def scene(shape=SIZE, seed: int = 0) -> np.ndarray:
    """A smooth textured RGBA frame in [0.05, 1] with a few highlights, alpha 1."""
    h, w = shape
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    rgba = np.empty((h, w, 4), np.float32)
    for c in range(3):
        fx, fy, ph = rng.uniform(0.05, 0.4, 2).tolist() + [rng.uniform(0, 6.3)]
        rgba[..., c] = 0.5 + 0.45 * np.sin(fx * x + ph) * np.cos(fy * y)
    rgba[..., :3] += rng.uniform(-0.02, 0.02, (h, w, 3)).astype(np.float32)
    rgba[..., :3] = np.clip(rgba[..., :3], 0.05, 1.0)
    rgba[..., 3] = 1.0
    for fy, fx in ((0.3, 0.25), (0.6, 0.7), (0.5, 0.5)):
        rgba[int(fy * (h - 1)), int(fx * (w - 1)), :3] = HIGHLIGHT
    return rgba


def depth_pass(shape=SIZE) -> np.ndarray:
    """Planar depth in metres: a ramp from 0.8 m (bottom) to 30 m with an infinite sky row."""
    h, w = shape
    z = np.geomspace(30.0, 0.8, h, dtype=np.float32)[:, None] * np.ones((1, w), np.float32)
    z[: max(h // 8, 0)] = np.inf
    return np.ascontiguousarray(z)


def velocity_pass(shape=SIZE) -> np.ndarray:
    """Forward velocity in px/frame: a smooth swirl of a few pixels, +x right, +y down."""
    h, w = shape
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    cx, cy = (w - 1) / 2, (h - 1) / 2
    v = np.stack([4.0 - 0.15 * (y - cy), 1.5 + 0.15 * (x - cx)], axis=2)
    return np.ascontiguousarray(v, np.float32)


def clip_names(name: str) -> set[str]:
    """The passes ``name`` reads (required or optional), from its descriptor."""
    return {c.name for c in discover()[name].descriptor.clips if c.name != "source"}


READERS = {"read_lens": read_lens, "read_image": read_image_rgba}
"""What the pipeline hands every effect (lens prescriptions, kernel images), as a look does."""


def passes(name: str, shape) -> dict:
    """Synthetic ``depth`` / ``velocity`` keyword arguments for every pass ``name`` reads."""
    make = {"depth": depth_pass, "velocity": velocity_pass}
    return {c: make[c](shape) for c in sorted(clip_names(name))}


@functools.cache
def plugin(name: str):
    """One instance per effect, reused like a look's step reuses it over a sequence."""
    return discover()[name]()


def apply(rt, name: str, src: np.ndarray, p=None, *, quality: str = "final", frame: int = 7,
          seed: int = 11, **kw):
    """Render ``src`` through ``name`` with synthetic passes and the contract camera, on the
    production path (`tests.effects.render_effect`: the pipeline's readers)."""
    kw = {**passes(name, src.shape[:2]), "camera": CAMERA, **kw}
    return render_effect(rt, plugin(name), p if p is not None else params(name), src,
                         quality=quality, frame=frame, seed=seed, **kw)


def context(rt, name: str, src: np.ndarray, *, quality: str = "final", window: Rect = None,
            display_window: Rect = None, **kw) -> RenderContext:
    """A render context like the pipeline builds (passes uploaded, contract camera)."""
    window = window or Rect.from_size(src.shape[1], src.shape[0])
    up = {k: rt.upload(v, window) for k, v in passes(name, src.shape[:2]).items()}
    return RenderContext(rt, rt.upload(src, window), display_window=display_window or window,
                         camera=CAMERA, quality=quality, frame=7, seed=11, **up,
                         **{**READERS, **kw})


def neutral_candidates(name: str) -> list[dict]:
    """Parameter settings that may turn ``name`` into a no-op, read from its descriptor.

    Each numeric parameter whose hard range holds 0 and whose active value is not 0, set to
    0 on its own; each switch that is on, turned off; then everything of both kinds at once
    (effects whose no-op needs several, e.g. vignette's ``natural`` and ``amount``).
    """
    active = params(name).as_dict()
    single = []
    for prm in discover()[name].descriptor.params:
        value = active[prm.name]
        if isinstance(prm, (FloatParam, IntParam)) and prm.min <= 0 <= prm.max and value != 0:
            single.append({prm.name: type(value)(0)})
        elif isinstance(prm, BoolParam) and value:
            single.append({prm.name: False})
    everything = {k: v for d in single for k, v in d.items()}
    return single + ([everything] if len(single) > 1 else [])


HARD_VALUES = {"nan": np.nan, "+inf": np.inf, "-inf": -np.inf, "+1e38": 1e38, "-1e38": -1e38,
               "65504": 65504.0}
"""Unusual pixel values: non-finite, near float32's largest, half's largest."""


def with_value(value, shape=SIZE, alpha: bool = False) -> np.ndarray:
    """``scene()`` with unusual values in a few pixels: corners, an edge, the interior, beside
    a highlight; whole colour triples and single channels (and two alphas with ``alpha``).
    ``value`` is one number or a sequence cycled over those pixels."""
    values = np.resize(np.asarray(value, np.float32), 7)
    src = scene(shape)
    h, w = shape
    src[0, 0, :3] = values[0]                             # corner, every colour channel
    src[h - 1, w - 1, 0] = values[1]                      # opposite corner, red only
    src[h // 4, w - 1, :3] = values[2]                    # right edge
    src[h // 2, w // 3, 1] = values[3]                    # interior, green only
    src[int(0.3 * (h - 1)), int(0.25 * (w - 1)) + 1, :3] = values[4]   # beside a highlight
    if alpha:
        src[h // 3, w // 2, 3] = values[5]
        src[h - 2, 1, :] = values[6]
    return src


NONFINITE = (np.nan, np.inf, -np.inf)


def transparent_scene(shape=SIZE) -> np.ndarray:
    """``scene()`` with alpha-0 pixels: a transparent black hole, emission with no coverage
    (premultiplied colour over alpha 0) and a half-transparent quarter."""
    src = scene(shape)
    h, w = shape
    src[:, : w // 4] = 0.0
    src[: h // 3, w // 4: w // 2, 3] = 0.0
    src[h // 2:, w // 2:] *= 0.5
    return src
