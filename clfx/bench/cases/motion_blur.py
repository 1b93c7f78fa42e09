"""Bench cases of motion_blur: renderer-like frames against a multisample ground truth.

Every case is a layered scene (:mod:`clfx.bench.scene`) rendered the way a path tracer writes
it (beauty from ``truth_samples`` rays per pixel at stratified jittered sub-pixel points, 4 x
4 strata, depth and velocity from the surface at the pixel centre:
:func:`clfx.bench.groundtruth.make_case` with ``ss = RENDER_SS`` and ``jitter_seed``) and its
truth, as many rays per pixel, each at its own jittered point and shutter instant
(:func:`clfx.bench.groundtruth.jittered_truth`); the case carries the truth's noise floor
(``truth_floor``: a second truth, another seed, against it).

``CASE`` is the representative hard case (``layers``).  ``CASES`` lists every case of the
effect, ``{name: make}``, each ``make(width, height, rng, *, truth=True, truth_samples=...)``
with the :class:`clfx.bench.cases.Case` ``make`` protocol (``noise_floor=False``: no
second truth, no ``truth_floor``):

- ``layers``: a drifting wall with a light, a fast striped ball, a card moving diagonally and
  a near leaf (moving up to 60 px/frame at 1920 px wide), 180 degree shutter;
- ``crossing``: two objects at different depths crossing in opposite directions in front of a
  textured wall, the near one over the far one at the frame time;
- ``spin``: a spinning propeller-like bar and a wheel (velocity varies across each, the truth
  follows arcs, the velocity pass gives tangents);
- ``fast_light``: small HDR lights (1000-5000) streaking across a dark scene;
- ``shutter_270``: ``layers`` through a 270 degree shutter;
- ``slow_stripes``: a finely striped panel (stripes 2 px wide) moving 2 px/frame: blur lengths
  of one pixel, where a reconstruction easily ends further from the truth than the input;
- ``slow_checker``: a finely checkered card (squares of 3 px on the pixel grid) drifting 1.7
  px/frame (and 0.3 down) over a fine static wall (blocks of 3 px): a 0.85 px smear of hard
  edges near the pixel frequency, where the reconstruction between pixels decides the result
  (issue 35: the clamped cubic ended 6 dB behind the naive line blur, exact on such edges).

Speeds and sizes scale with the width (the same shot at any size), except ``slow_stripes``,
``slow_stripes`` and ``slow_checker``, whose feature sizes and speeds are in pixels (the cases
are about sub-pixel detail).

``naive(case, params, ctx)`` is the baseline (``LINE_BLUR_LABEL``): every pixel averaged along its
own velocity over the shutter (bilinear, midpoint rule, no depth, no tiles, no scatter).
"""
from __future__ import annotations

import numpy as np

from clfx.bench import cycles
from clfx.bench.cases import Case, Naive
from clfx.bench.cases.shared import LINE_BLUR_LABEL, line_blur_per_pixel
from clfx.bench.groundtruth import JITTER_SEED, RENDER_SS, case_dict, make_case
from clfx.bench.scene import Layer, Light, Scene, Texture, moving_scene, render_sharp
from clfx.core.camera import Camera
from clfx.fx.motion import shutter_from


TRUTH_SAMPLES = 256
"""Sample renders of a truth (16 per sub-pixel position at ``RENDER_SS`` = 4)."""

CENTRED_180 = Camera(shutter_angle=180.0, shutter_offset="centered")


def _case(scene: Scene, camera: Camera, truth: bool, truth_samples: int,
          noise_floor: bool = True) -> dict:
    if not truth:
        f = render_sharp(scene, 0.0, ss=RENDER_SS, passes="centre", jitter_seed=JITTER_SEED,
                         samples=truth_samples)
        return dict(source=f.rgba, depth=f.depth, velocity=f.velocity, params={},
                    camera=camera)
    gt = make_case(scene, camera, samples=truth_samples, dof=False, motion=True, ss=RENDER_SS,
                   jitter_seed=JITTER_SEED, noise_floor=noise_floor)
    return case_dict(gt, scene=scene.name)


def _radius(px_at_640: float, width: int) -> float:
    """A light's radius: ``px_at_640`` scaled with the width, at least a pixel (smaller
    lights fall between the pixel centres where the passes are sampled)."""
    return max(px_at_640 * width / 640.0, 1.0)


def _wall(width: int, height: int, *, velocity=(0.0, 0.0), lights=True) -> Layer:
    s = width / 640.0
    lts = ((Light((0.1 * width, -0.2 * height), (200.0, 150.0, 100.0), _radius(2.0, width)),
            Light((-0.3 * width, 0.25 * height), (60.0, 80.0, 120.0), _radius(1.5, width)))
           if lights else ())
    return Layer(depth=20.0, texture=Texture("blocks", (0.5, 0.45, 0.4), (0.05, 0.05, 0.06),
                                             period=12.0 * s, seed=3),
                 shape="full", lights=lts, velocity=velocity, name="wall")


# -- the cases -------------------------------------------------------------------------------
def make_layers(width: int, height: int, rng=None, *, truth: bool = True,
                truth_samples: int = TRUTH_SAMPLES, noise_floor: bool = True, moving_fraction=None,
                camera: Camera = CENTRED_180) -> dict:
    """Layers at several depths moving up to 60 px/frame at 1920 px wide (scaled with the
    width); with ``moving_fraction`` only a small ball moves (see
    :func:`clfx.bench.scene.moving_scene`)."""
    scene = moving_scene(width, height, 60.0 * width / 1920.0, moving_fraction)
    return _case(scene, camera, truth, truth_samples, noise_floor)


def crossing_scene(width: int, height: int) -> Scene:
    """A near card (2 m) moving right over a far disk (6 m) moving left, crossing at the
    frame time in front of a static textured wall (20 m)."""
    s = width / 640.0
    far = Layer(depth=6.0, texture=Texture("stripes", (0.9, 0.3, 0.1), (0.95, 0.85, 0.6),
                                           period=10.0 * s, angle=60.0),
                shape="disk", center=(0.52 * width, 0.50 * height),
                size=(0.30 * height, 0.30 * height), velocity=(-0.015 * width, 0.0),
                lights=(Light((0.0, -0.08 * height), (400.0, 300.0, 200.0), _radius(1.5, width)),),
                name="far disk")
    near = Layer(depth=2.0, texture=Texture("checker", (0.75, 0.75, 0.7), (0.05, 0.06, 0.08),
                                            period=8.0 * s, angle=-10.0),
                 shape="rounded", center=(0.45 * width, 0.56 * height),
                 size=(0.16 * width, 0.22 * height), corner=6.0 * s,
                 velocity=(0.03 * width, -0.004 * width), name="near card")
    return Scene(width, height, (_wall(width, height), far, near), name="crossing")


def make_crossing(width: int, height: int, rng=None, *, truth: bool = True,
                  truth_samples: int = TRUTH_SAMPLES, noise_floor: bool = True) -> dict:
    """Two objects at different depths crossing (58 and 29 px/frame at 1920 wide)."""
    return _case(crossing_scene(width, height), CENTRED_180, truth, truth_samples, noise_floor)


def spin_scene(width: int, height: int) -> Scene:
    """A spinning bar with a light at its tip (10 deg/frame, tips ~38 px/frame at 1080 high)
    and a slower striped wheel spinning the other way, over a static wall."""
    s = width / 640.0
    r = 0.22 * height
    bar = Layer(depth=3.0, texture=Texture("stripes", (0.85, 0.85, 0.8), (0.1, 0.1, 0.12),
                                           period=9.0 * s),
                shape="rounded", center=(0.36 * width, 0.5 * height),
                size=(2 * r, 0.07 * height), corner=3.0 * s, spin=10.0, angle=20.0,
                lights=(Light((r * 0.9, 0.0), (2000.0, 1200.0, 600.0), _radius(1.5, width)),),
                name="propeller")
    rw = 0.16 * height
    wheel = Layer(depth=5.0, texture=Texture("checker", (0.2, 0.5, 0.8), (0.9, 0.9, 0.85),
                                             period=7.0 * s),
                  shape="disk", center=(0.72 * width, 0.45 * height), size=(2 * rw, 2 * rw),
                  spin=-6.0, velocity=(0.004 * width, 0.0), name="wheel")
    return Scene(width, height, (_wall(width, height), wheel, bar), name="spin")


def make_spin(width: int, height: int, rng=None, *, truth: bool = True,
              truth_samples: int = TRUTH_SAMPLES, noise_floor: bool = True) -> dict:
    """A spinning bar and wheel: velocity varies across each object."""
    return _case(spin_scene(width, height), CENTRED_180, truth, truth_samples, noise_floor)


def fast_light_scene(width: int, height: int) -> Scene:
    """Small HDR lights streaking across a dim scene: a single bright one (5000) crossing at
    80 px/frame at 1920 wide in front of a slower pair (1000), over a dark wall."""
    s = width / 640.0
    r = _radius(1.2, width)
    dark = Layer(depth=30.0, texture=Texture("noise", (0.02, 0.02, 0.025), (0.06, 0.05, 0.04),
                                             period=14.0 * s, seed=9),
                 shape="full", name="dark wall")
    light = Layer(depth=4.0, shape="none", center=(0.4 * width, 0.35 * height),
                  lights=(Light((0.0, 0.0), (5000.0, 4500.0, 3500.0), r),),
                  velocity=(0.042 * width, 0.012 * width), name="fast light")
    pair = Layer(depth=8.0, shape="none", center=(0.6 * width, 0.65 * height),
                 lights=(Light((0.0, 0.0), (300.0, 600.0, 1000.0), r),
                         Light((0.05 * width, 0.02 * height), (1000.0, 500.0, 200.0), r)),
                 velocity=(-0.02 * width, 0.005 * width), name="light pair")
    post = Layer(depth=3.0, texture=Texture("flat", (0.15, 0.15, 0.15)), shape="rect",
                 center=(0.55 * width, 0.5 * height), size=(0.02 * width, 1.2 * height),
                 name="post")
    return Scene(width, height, (dark, pair, light, post), name="fast light")


def make_fast_light(width: int, height: int, rng=None, *, truth: bool = True,
                    truth_samples: int = TRUTH_SAMPLES, noise_floor: bool = True) -> dict:
    """Small HDR lights streaking across (the bright one partly behind a static post)."""
    return _case(fast_light_scene(width, height), CENTRED_180, truth, truth_samples, noise_floor)


def make_shutter_270(width: int, height: int, rng=None, *, truth: bool = True,
                     truth_samples: int = TRUTH_SAMPLES, noise_floor: bool = True) -> dict:
    """``layers`` through a 270 degree shutter (centred)."""
    return make_layers(width, height, rng, truth=truth, truth_samples=truth_samples,
                       noise_floor=noise_floor,
                       camera=Camera(shutter_angle=270.0, shutter_offset="centered"))


def slow_stripes_scene(width: int, height: int) -> Scene:
    """A panel of stripes 2 px wide (4 px period, at 15 degrees) moving 2 px/frame in front of
    a static wall, with a slower text-like card: blur lengths of about a pixel."""
    panel = Layer(depth=4.0, texture=Texture("stripes", (0.8, 0.78, 0.7), (0.08, 0.08, 0.1),
                                             period=4.0, angle=15.0),
                  shape="rect", center=(0.45 * width, 0.5 * height),
                  size=(0.5 * width, 0.6 * height), velocity=(2.0, 0.0), name="striped panel")
    card = Layer(depth=3.0, texture=Texture("blocks", (0.85, 0.82, 0.7), (0.1, 0.1, 0.12),
                                            period=5.0, seed=11),
                 shape="rect", center=(0.78 * width, 0.3 * height),
                 size=(0.18 * width, 0.2 * height), velocity=(0.0, 1.5), name="label")
    return Scene(width, height, (_wall(width, height, lights=False), panel, card),
                 name="slow stripes")


def make_slow_stripes(width: int, height: int, rng=None, *, truth: bool = True,
                      truth_samples: int = TRUTH_SAMPLES, noise_floor: bool = True) -> dict:
    """Fine stripes moving 2 px/frame (180 degree shutter: a one-pixel blur)."""
    return _case(slow_stripes_scene(width, height), CENTRED_180, truth, truth_samples, noise_floor)


def slow_checker_scene(width: int, height: int) -> Scene:
    """A card checkered in 3 px squares on the pixel grid drifting 1.7 px/frame (and 0.3 down)
    over a static wall of 3 px blocks: a smear of 0.86 px through a 180 degree shutter."""
    wall = Layer(depth=12.0, texture=Texture("blocks", (0.55, 0.5, 0.45), (0.06, 0.06, 0.07),
                                             period=3.0, seed=5),
                 shape="full", name="fine wall")
    card = Layer(depth=3.0, texture=Texture("checker", (0.85, 0.85, 0.8), (0.05, 0.05, 0.06),
                                            period=3.0),
                 shape="rect", center=(0.5 * width, 0.5 * height),
                 size=(0.55 * width, 0.6 * height), velocity=(1.7, 0.3), name="checker card")
    return Scene(width, height, (wall, card), name="slow checker")


def make_slow_checker(width: int, height: int, rng=None, *, truth: bool = True,
                      truth_samples: int = TRUTH_SAMPLES, noise_floor: bool = True) -> dict:
    """A fine checker drifting 1.7 px/frame over a fine static wall (a 0.85 px smear)."""
    return _case(slow_checker_scene(width, height), CENTRED_180, truth, truth_samples, noise_floor)


CASES = {
    "layers": make_layers,
    "crossing": make_crossing,
    "spin": make_spin,
    "fast_light": make_fast_light,
    "shutter_270": make_shutter_270,
    "slow_stripes": make_slow_stripes,
    "slow_checker": make_slow_checker,
}
"""Every motion_blur case, ``{name: make}`` (``CASE.make`` is ``layers``)."""


# -- the naive baseline ----------------------------------------------------------------------
def naive(case: dict, params, ctx) -> np.ndarray:
    """The naive baseline of a case (:data:`LINE_BLUR_LABEL`), RGBA like the effect's output."""
    t0, t1 = shutter_from(params, ctx.camera)
    return line_blur_per_pixel(np.asarray(case["source"], np.float32),
                               np.asarray(case["velocity"], np.float32), t0, t1)


CYCLES_SCENES = ("spin", "truck", "pan", "crossing", "slow")
"""Scenes rendered by Blender Cycles (:mod:`clfx.bench.cycles`), each a variant
``cycles_<name>`` scored against Cycles' own motion blur, Blender's Vector Blur beside."""

CASE = Case(make=make_layers,
            naive=Naive(LINE_BLUR_LABEL, lambda case, params, ctx: lambda: naive(case, params, ctx)),
            variants={"slow_checker": make_slow_checker, **cycles.variants(CYCLES_SCENES)})
