"""Bench cases of dof: ground truth that looks like a real render, and the naive baseline.

Every case is a layered scene (:mod:`clfx.bench.scene`) with its multisample thin-lens
truth (:mod:`clfx.bench.groundtruth`).  Like a renderer's output, the beauty is supersampled
(``ss x ss`` box) while the depth pass is point-sampled at the pixel centre, so antialiased
edge pixels mix two layers' colours under one layer's depth (the runner caches cases with a
truth on disk).

``CASE`` is the bench frame (the demo scene through a shallow lens, CoC up to ~40 px at 1920
wide); ``SCENES`` are the classes of the depth-of-field table of issue 11, each at any size
(features scale with the width; sizes below are at 320 px wide):

- ``subject``: a sharp subject over a background blurred ~12 px with HDR lights;
- ``bokeh``: HDR point lights far out of focus (~24 px bokeh), one cut by an in-focus edge;
- ``bar``: a thin foreground bar blurred ~15 px over a sharp background, lights beside it;
- ``physical``: 85 mm f/1.35 focused at 1.2 m (40 px CoC), default settings;
- ``lines``: 1-px lines at several depths;
- ``large``: large CoC over each other (radii 22-45 px, 60 at infinity): a lit wall, a
  sign and an in-focus subject crossed by two foreground posts;
- ``cateye``, ``anamorphic``, ``axial_ca``: the lens geometry in the bokeh (issue 15): HDR
  point lights far out of focus over the whole frame, corners included, and a few in front
  of the focus plane (:func:`corners_scene`), through a lens with optical vignetting 1.0
  (cat-eye bokeh), an anamorphic squeeze of 1.8 (vertical ovals), or 80 um of axial
  chromatic aberration of red and blue behind green (an achromat: green rims behind the
  focus plane, magenta in front);
- ``cateye_front``, ``cateye_both``: the same lights clipped by the front rim (1.0, the
  clip shifted towards the centre) and by both rims (rear 0.7, front 0.7: pointed lemons).

``cycles_large`` is ``large``'s set-up rendered by Blender Cycles (:mod:`clfx.bench.cycles`,
scene ``dof_large``: a 200 mm f/2 at 2 m, CoC radii 27-41 px over each other): the pinhole
frame with Blender's Depth pass as the input, Cycles' thin lens as the truth (its noise floor
beside), Blender's compositor Defocus node as the peer row.

``naive(case, params, ctx)`` is the classic baseline (each pixel averages the source over the
disk of its own CoC, no layering), with the same aperture model as the effect (squeeze,
barrel clipping, per-channel radii) when the lens has them; ``NAIVE_LABEL`` names it in the
bench table.
"""
from __future__ import annotations

import math
import sys
import time

import numpy as np

from clfx.bench import cycles
from clfx.bench.cache import load_case
from clfx.bench.cases import Case, Naive
from clfx.bench.groundtruth import RENDER_SS, case_dict, make_case
from clfx.bench.metrics import EDGE_BAND_PX, edge_band, error_metrics
from clfx.bench.scene import Layer, Light, Scene, Texture, demo_scene
from clfx.core.camera import Camera, coc_signed, optical_vignetting_centre
from clfx.core.frame import crop_to
from clfx.host import RenderContext
from clfx.plugins.dof import Dof

SS = RENDER_SS
"""Beauty and truth sub-samples per pixel and axis (a renderer's antialiasing: 4 x 4)."""

SAMPLES = 16384
"""Sample renders of the truth: each one a lens point and one of the 16 sub-pixel positions
(:func:`clfx.bench.groundtruth.render_truth`), so 1024 lens points per position; HDR bokeh
needs that many (4096 renders leave the truth's noise 1.3 dB above the gather's error)."""

NAIVE_LABEL = "naive per-pixel-CoC gather"


def bench_camera(width: int) -> Camera:
    """A 50 mm f/2.2 lens focused on the demo subject at 3 m: CoC up to ~40 px at 1920 wide."""
    return Camera(focal_length=50.0, f_number=2.2, sensor_width=36.0, focus_distance=3.0,
                  shutter_angle=180.0)


def render_case(scene: Scene, camera: Camera, *, ss: int = SS, samples: int = SAMPLES,
                params: dict | None = None) -> dict:
    """The effect's inputs and truth for ``scene`` (:func:`clfx.bench.groundtruth.make_case`):
    beauty supersampled ``ss x ss`` (box), depth at the pixel centres, truth through the same
    pixel filter."""
    # the 4x4 grid, not jittered like motion (issue 24): ~6x per ray, ~2 h a truth at 16384 rays
    case = make_case(scene, camera, samples=samples, dof=True, motion=False, ss=ss,
                     passes="centre")
    out = case_dict(case, params, scene=scene.name)
    out["velocity"] = None        # a still frame: dof reads no velocity
    return out


def make(width: int, height: int, rng=None) -> dict:
    """The demo scene through a shallow lens, with its multisample ground truth (``truth``);
    beauty and truth 2 x 2 supersampled, centre depth, 2048 renders (512 lens points per
    sub-pixel position: about 3 minutes at 1080p, cached by the runner)."""
    scene = demo_scene(12, int(width), int(height))
    return render_case(scene, bench_camera(width), ss=2, samples=2048)


# -- ground-truth scenes (sizes at 320 px wide, scaled with the width) -----------------------
def lens_for(coc_at_infinity_px: float, width: int, *, focus: float = 3.0,
             focal_length: float = 50.0, f_number: float = 2.0, blades: int = 0) -> Camera:
    """A camera whose CoC at infinity is ``coc_at_infinity_px`` px at 320 px wide (the sensor
    width is solved for), the same framing at any ``width``."""
    k_mm = (focal_length / f_number) * focal_length / (focus * 1000.0 - focal_length)
    return Camera(focal_length=focal_length, f_number=f_number, focus_distance=focus,
                  sensor_width=k_mm * 320.0 / coc_at_infinity_px, blades=blades)


def _lights(rng, n, s, box, lum=(50.0, 2000.0), radius=(0.6, 1.5), avoid=None):
    """``n`` lights in ``box`` (offsets at 320 px wide, times ``s``), none inside ``avoid``
    (offsets (x0, y0, x1, y1)): a light hidden in the pinhole view is in no input."""
    x0, y0, x1, y1 = box
    out = []
    while len(out) < n:
        v = float(math.exp(rng.uniform(math.log(lum[0]), math.log(lum[1]))))
        tint = rng.uniform(0.3, 1.0, 3)
        tint /= tint.max()
        x, y = float(rng.uniform(x0, x1)), float(rng.uniform(y0, y1))
        if avoid is not None and avoid[0] <= x <= avoid[2] and avoid[1] <= y <= avoid[3]:
            continue
        out.append(Light((x * s, y * s), tuple(float(t * v) for t in tint),
                         float(rng.uniform(*radius) * s)))
    return tuple(out)


def subject_scene(width: int, height: int) -> tuple[Scene, Camera]:
    """A sharp subject (3 m) before a wall with lit windows at 30 m blurred ~12 px."""
    s = width / 320.0
    rng = np.random.default_rng(11)
    wall = Layer(depth=30.0, texture=Texture("blocks", (0.10, 0.09, 0.08), (0.02, 0.02, 0.03),
                                             period=8.0 * s, seed=3),
                 shape="full", center=(0.5 * width, 0.5 * height), name="wall",
                 # no light within a bokeh radius behind the subject (no input shows those)
                 lights=_lights(rng, 40, s, (-160, -90, 160, 90), avoid=(-77, -42, 45, 60)))
    card = Layer(depth=3.0, texture=Texture("checker", (0.7, 0.7, 0.65), (0.05, 0.05, 0.06),
                                            period=9.0 * s, angle=8.0),
                 shape="rounded", center=(0.45 * width, 0.55 * height),
                 size=(0.34 * width, 0.5 * height), corner=8.0 * s,
                 lights=(Light((0.1 * width, -0.15 * height), (2000.0, 300.0, 150.0), 1.0 * s),),
                 name="subject")
    label = Layer(depth=2.99, texture=Texture("blocks", (0.85, 0.82, 0.7), (0.1, 0.1, 0.12),
                                              period=6.0 * s, seed=11),
                  shape="rect", center=(0.45 * width, 0.66 * height),
                  size=(0.24 * width, 0.09 * height), name="label")
    scene = Scene(width, height, (wall, card, label), name="sharp subject, background ~12 px")
    return scene, lens_for(13.3, width)


def bokeh_scene(width: int, height: int) -> tuple[Scene, Camera]:
    """HDR point lights at 200 m (~24 px bokeh) over a dark sky, one just behind the edge of
    an in-focus post that cuts its bokeh."""
    s = width / 320.0
    rng = np.random.default_rng(5)
    lights = list(_lights(rng, 14, s, (-150, -80, 60, 80), lum=(100.0, 5000.0)))
    post_x = 0.78 * width
    lights.append(Light((post_x - 0.5 * width - 4.0 * s, 0.0), (3000.0, 2500.0, 1500.0), 1.0 * s))
    lights.append(Light((post_x - 0.5 * width + 30.0 * s, -40.0 * s), (800.0, 900.0, 1500.0),
                        1.2 * s))
    sky = Layer(depth=200.0, shape="none", center=(0.5 * width, 0.5 * height),
                lights=tuple(lights), name="lights")
    post = Layer(depth=3.0, texture=Texture("noise", (0.35, 0.3, 0.25), (0.15, 0.12, 0.1),
                                            period=5.0 * s, seed=2),
                 shape="rect", center=(post_x + 10.0 * s, 0.5 * height),
                 size=(20.0 * s, 1.2 * height), name="post")
    scene = Scene(width, height, (sky, post), background=((0.01, 0.012, 0.02), (0.03, 0.03, 0.04)),
                  name="HDR lights ~24 px bokeh")
    return scene, lens_for(24.5, width)


def bar_scene(width: int, height: int) -> tuple[Scene, Camera]:
    """A thin bar at 1 m (CoC ~15 px) over an in-focus textured wall with small lights beside
    its edges (some half hidden by it)."""
    s = width / 320.0
    bx = 0.5 * width
    lights = [Light((dx * s, dy * s), (v, 0.8 * v, 0.6 * v), 0.8 * s)
              for dx, dy, v in ((-6.0, -50.0, 800.0), (5.5, -25.0, 400.0), (-4.0, 0.0, 1500.0),
                                (3.6, 22.0, 300.0), (-5.2, 45.0, 600.0), (40.0, -30.0, 900.0),
                                (-4.5, 65.0, 1000.0), (4.2, -70.0, 500.0), (5.0, 10.0, 2000.0))]
    wall = Layer(depth=3.0, texture=Texture("noise", (0.45, 0.4, 0.32), (0.08, 0.08, 0.1),
                                            period=4.0 * s, seed=9),
                 shape="full", center=(bx, 0.5 * height), lights=tuple(lights), name="wall")
    bar = Layer(depth=1.0, texture=Texture("stripes", (0.05, 0.05, 0.06), (0.6, 0.55, 0.5),
                                           period=30.0 * s, angle=90.0),
                shape="rect", center=(bx, 0.5 * height), size=(7.0 * s, 1.2 * height),
                name="bar")
    scene = Scene(width, height, (wall, bar), name="thin bar ~15 px over a sharp wall")
    return scene, lens_for(7.5, width)


def physical_scene(width: int, height: int) -> tuple[Scene, Camera]:
    """85 mm f/1.35 focused at 1.2 m (the camera block's real values): a portrait card, a
    background at 5 m, lights at 20 m (CoC ~40 px), a leaf at 0.8 m."""
    s = width / 320.0
    rng = np.random.default_rng(3)
    bg = Layer(depth=5.0, texture=Texture("noise", (0.25, 0.3, 0.2), (0.05, 0.07, 0.04),
                                          period=12.0 * s, seed=4),
               shape="rect", center=(0.5 * width, 0.75 * height), size=(1.2 * width, 0.55 * height),
               name="hedge")
    far = Layer(depth=20.0, shape="none", center=(0.5 * width, 0.5 * height),
                lights=_lights(rng, 12, s, (-170, -88, 170, -45), lum=(50.0, 1500.0)),
                name="lights")
    card = Layer(depth=1.2, texture=Texture("checker", (0.75, 0.6, 0.5), (0.2, 0.12, 0.1),
                                            period=7.0 * s, angle=5.0),
                 shape="rounded", center=(0.55 * width, 0.55 * height),
                 size=(0.28 * width, 0.6 * height), corner=14.0 * s, name="subject")
    leaf = Layer(depth=0.8, texture=Texture("noise", (0.05, 0.25, 0.06), (0.15, 0.45, 0.1),
                                            period=6.0 * s, seed=5),
                 shape="disk", center=(0.1 * width, 0.85 * height),
                 size=(0.3 * width, 0.45 * height), name="leaf")
    scene = Scene(width, height, (far, bg, card, leaf), name="85 mm f/1.35 at 1.2 m")
    cam = Camera(focal_length=85.0, f_number=1.35, sensor_width=36.0, focus_distance=1.2)
    return scene, cam


def large_scene(width: int, height: int) -> tuple[Scene, Camera]:
    """Large circles of confusion over each other: a sharp subject (3 m) between a lit wall
    at 12 m (CoC radius 45 px), a sign at 6 m (30 px), and two foreground posts at 1.8 m
    (-40 px) and 2.2 m (-22 px) crossing the subject and the background."""
    s = width / 320.0
    rng = np.random.default_rng(17)
    wall = Layer(depth=12.0, texture=Texture("blocks", (0.16, 0.12, 0.09), (0.03, 0.03, 0.05),
                                             period=10.0 * s, seed=6),
                 shape="full", center=(0.5 * width, 0.5 * height), name="wall",
                 lights=_lights(rng, 16, s, (-160, -90, 160, 90), lum=(30.0, 800.0),
                                avoid=(-60, -50, 40, 70)))
    sign = Layer(depth=6.0, texture=Texture("stripes", (0.8, 0.7, 0.3), (0.1, 0.15, 0.3),
                                            period=14.0 * s, angle=30.0),
                 shape="rect", center=(0.78 * width, 0.35 * height),
                 size=(0.3 * width, 0.3 * height), name="sign")
    card = Layer(depth=3.0, texture=Texture("checker", (0.75, 0.7, 0.6), (0.08, 0.07, 0.06),
                                            period=8.0 * s, angle=6.0),
                 shape="rounded", center=(0.45 * width, 0.55 * height),
                 size=(0.3 * width, 0.6 * height), corner=10.0 * s, name="subject")
    post = Layer(depth=1.8, texture=Texture("noise", (0.35, 0.1, 0.06), (0.1, 0.05, 0.03),
                                            period=6.0 * s, seed=8),
                 shape="rect", center=(0.3 * width, 0.5 * height),
                 size=(0.07 * width, 1.2 * height), name="near post")
    rail = Layer(depth=2.2, texture=Texture("noise", (0.1, 0.3, 0.35), (0.05, 0.1, 0.1),
                                            period=6.0 * s, seed=9),
                 shape="rect", center=(0.6 * width, 0.85 * height),
                 size=(0.9 * width, 0.06 * height), name="rail")
    scene = Scene(width, height, (wall, sign, card, post, rail),
                  name="large CoC: 20-45 px over each other")
    return scene, lens_for(120.0, width)


def lines_scene(width: int, height: int) -> tuple[Scene, Camera]:
    """1-px lines (horizontal and vertical) at 1.5, 2, 3 (in focus), 6 and 30 m over a grey
    wall at infinity."""
    s = width / 320.0
    layers = [Layer(depth=math.inf,
                    texture=Texture("noise", (0.3, 0.3, 0.3), (0.15, 0.15, 0.18), period=10.0 * s,
                                    seed=1), shape="full", name="wall")]
    specs = ((30.0, 0.18, (2.0, 2.0, 1.6)), (6.0, 0.36, (0.02, 0.02, 0.02)),
             (3.0, 0.52, (1.5, 1.2, 0.8)), (2.0, 0.68, (0.01, 0.01, 0.01)),
             (1.5, 0.84, (3.0, 3.0, 3.0)))
    for depth, f, col in specs:
        tex = Texture("flat", col)
        layers.append(Layer(depth=depth, texture=tex, shape="rect",
                            center=(0.5 * width, round(f * height) + 0.5), size=(0.8 * width, 1.0),
                            name=f"h {depth} m"))
        layers.append(Layer(depth=depth, texture=tex, shape="rect",
                            center=(round(f * width) + 0.5, 0.5 * height),
                            size=(1.0, 0.8 * height), name=f"v {depth} m"))
    layers.sort(key=lambda l: -l.depth)
    scene = Scene(width, height, tuple(layers), name="1-px lines at several depths")
    return scene, lens_for(10.0, width)


def corners_scene(width: int, height: int) -> tuple[Scene, Camera]:
    """HDR point lights at 200 m (~24 px bokeh) over the whole frame, the corners and edges
    included (where optical vignetting cuts the bokeh), and a few at 2 m in front of the
    focus plane (~12 px), over a dark sky."""
    s = width / 320.0
    rng = np.random.default_rng(15)
    grid = [Light((x * s, y * s), (v, 0.9 * v, 0.75 * v), 1.0 * s)
            for x, y, v in ((-140, -70, 2000.0), (140, -70, 1500.0), (-140, 70, 1200.0),
                            (140, 70, 2500.0), (0, -70, 1000.0), (-140, 0, 1800.0),
                            (140, 0, 900.0), (0, 70, 1400.0), (0, 0, 3000.0),
                            (-70, -35, 700.0), (70, 35, 800.0))]
    lights = tuple(grid) + _lights(rng, 8, s, (-150, -80, 150, 80), lum=(100.0, 3000.0))
    sky = Layer(depth=200.0, shape="none", center=(0.5 * width, 0.5 * height), lights=lights,
                name="far lights")
    # lamps in front of the focus plane: a small dark housing carries each light's depth
    front = tuple(Layer(depth=2.0, texture=Texture("flat", (0.02, 0.02, 0.02)), shape="disk",
                        center=(0.5 * width + x * s, 0.5 * height + y * s),
                        size=(3.0 * s, 3.0 * s), lights=(Light((0.0, 0.0), (v, v, v), 0.8 * s),),
                        name=f"lamp {i}")
                  for i, (x, y, v) in enumerate(((-95, 45, 600.0), (95, -45, 500.0),
                                                 (-30, -50, 400.0))))
    scene = Scene(width, height, (sky, *front),
                  background=((0.01, 0.012, 0.02), (0.03, 0.03, 0.04)),
                  name="HDR lights over the frame, corners included")
    return scene, lens_for(24.5, width)


def _with_camera(make, **camera):
    def scene_with(width: int, height: int):
        scene, cam = make(width, height)
        return scene, cam.updated(**camera)
    return scene_with


SCENES = {"subject": subject_scene, "bokeh": bokeh_scene, "bar": bar_scene,
          "physical": physical_scene, "lines": lines_scene, "large": large_scene,
          "cateye": _with_camera(corners_scene, optical_vignetting=1.0),
          "cateye_front": _with_camera(corners_scene, optical_vignetting_front=1.0),
          "cateye_both": _with_camera(corners_scene, optical_vignetting=0.7,
                                      optical_vignetting_front=0.7),
          "anamorphic": _with_camera(corners_scene, anamorphic_squeeze=1.8),
          "axial_ca": _with_camera(corners_scene, axial_ca_red=80.0, axial_ca_blue=80.0)}


def make_scene(name: str, width: int = 320, height: int = 180, *, ss: int = SS,
               samples: int = SAMPLES) -> dict:
    """One of ``SCENES`` as a bench case (inputs, camera, truth)."""
    scene, cam = SCENES[name](int(width), int(height))
    return render_case(scene, cam, ss=ss, samples=samples)


# -- the naive baseline ------------------------------------------------------------------------
def naive_dof(src: np.ndarray, depth: np.ndarray, *, k_half: float, focus: float,
              clamp_r: float, squeeze: float = 1.0, cateye=None,
              ca: tuple = (0.0, 0.0), cateye_front=None) -> np.ndarray:
    """Per-pixel-CoC gather without layering: the mean of the source over the pixel centres
    within ``|r| + 0.5`` of the pixel (``r`` its signed CoC radius; clamp-to-edge).

    Pixels are grouped by the disk their radius selects (one OpenCV box-normalised disk
    filter per distinct disk), so any radius runs in seconds.  With the lens geometry of
    the effect: ``squeeze`` (the disk ``squeeze`` times narrower than high), ``cateye`` =
    ``(cx, cy)`` barrel centres per pixel (aperture radii; the disk clipped as the effect's,
    :func:`_naive_shaped`), ``cateye_front``: the front rim's centres likewise, ``ca``: red
    and blue radius offsets (px), one gather per channel.
    """
    import cv2  # lazy: OpenCV is optional (test extra); the bench's peers go without it

    src = np.asarray(src, np.float32)
    src = np.where(np.isfinite(src), src, 0.0).astype(np.float32)
    if squeeze != 1.0 or cateye is not None or cateye_front is not None or any(ca):
        out = None
        for chans, off in (((0, 1, 2, 3), 0.0), ((0,), ca[0]), ((2,), ca[1])):
            if out is not None and off == 0.0:
                continue        # green's radius: already there
            r = np.clip(coc_signed(depth, 2.0 * k_half, focus) * 0.5 + off, -clamp_r, clamp_r)
            res = _naive_shaped(src, r, squeeze, cateye, cateye_front)
            if out is None:
                out = res
            else:
                out[..., list(chans)] = res[..., list(chans)]
        return out
    r = np.abs(np.clip(coc_signed(depth, 2.0 * k_half, focus) * 0.5, -clamp_r, clamp_r))
    # the disk {o : |o| <= r + 0.5} changes only where (r + 0.5)^2 passes a sum of two squares
    rmax = int(math.ceil(float(r.max()))) + 1 if r.size else 0
    sq = np.unique([dx * dx + dy * dy for dx in range(rmax + 1) for dy in range(dx, rmax + 1)])
    idx = np.searchsorted(sq, (r + 0.5) ** 2, side="right") - 1   # largest d^2 inside
    out = np.empty_like(src)
    for k in np.unique(idx):
        d2 = int(sq[k])
        e = int(math.isqrt(d2))
        oy, ox = np.mgrid[-e:e + 1, -e:e + 1]
        kern = (ox * ox + oy * oy <= d2).astype(np.float32)
        kern /= kern.sum()
        sel = idx == k
        filt = cv2.filter2D(src, -1, kern, borderType=cv2.BORDER_REPLICATE)
        out[sel] = filt[sel]
    return out


CATEYE_STEP = 0.05
"""The naive gather's barrel centres are rounded to this (aperture radii) to group pixels."""


def _naive_shaped(src: np.ndarray, r: np.ndarray, squeeze: float, cateye,
                  cateye_front=None) -> np.ndarray:
    """The naive gather with the effect's aperture: pixel p averages the source over the
    offsets o with ``|o'| <= |r| + 0.5`` and (cat-eye) ``|o' + c r| <= |r| + 0.5`` for the
    rear rim's centre c and the front rim's (``cateye_front``), ``o' = (o_x squeeze, o_y)``
    (the bokeh of a point with p's radius, seen from p).  Pixels are grouped by radius
    (rounded to 1/4 px) and circle centres (rounded to :data:`CATEYE_STEP`), one
    normalised filter each over the pixels' bounding box."""
    import cv2  # lazy: OpenCV is optional (test extra); the bench's peers go without it

    h, w = r.shape
    rq = np.round(r * 4.0) / 4.0
    cs = []
    for c in (cateye, cateye_front):
        if c is None:
            cs += [np.zeros((h, w), np.int64)] * 2
        else:
            cs += [np.round(np.asarray(v) / CATEYE_STEP).astype(np.int64) for v in c]
    e = int(math.ceil(float(np.abs(rq).max()) + 0.5)) + 1 if rq.size else 1
    padded = cv2.copyMakeBorder(src, e, e, e, e, cv2.BORDER_REPLICATE)
    keys = np.stack([rq.ravel()] + [c.ravel() for c in cs], axis=1)
    uniq, inv = np.unique(keys, axis=0, return_inverse=True)
    inv = inv.reshape(h, w)
    out = np.empty_like(src)
    for k, (rad, bx, by, fx, fy) in enumerate(uniq):
        ar = abs(rad)
        ey, ex = int(math.ceil(ar + 0.5)), int(math.ceil((ar + 0.5) / squeeze))
        oy, ox = np.mgrid[-ey:ey + 1, -ex:ex + 1].astype(np.float64)
        ax = ox * squeeze
        kern = np.hypot(ax, oy) <= ar + 0.5
        if cateye is not None:
            kern &= np.hypot(ax + bx * CATEYE_STEP * rad, oy + by * CATEYE_STEP * rad) <= ar + 0.5
        if cateye_front is not None:
            kern &= np.hypot(ax + fx * CATEYE_STEP * rad, oy + fy * CATEYE_STEP * rad) <= ar + 0.5
        kern = kern.astype(np.float32)
        kern /= kern.sum()
        ys, xs = np.nonzero(inv == k)
        y0, y1, x0, x1 = ys.min(), ys.max() + 1, xs.min(), xs.max() + 1
        crop = padded[y0 + e - ey:y1 + e + ey, x0 + e - ex:x1 + e + ex]
        filt = cv2.filter2D(crop, -1, kern, borderType=cv2.BORDER_REPLICATE)[ey:-ey, ex:-ex]
        out[ys, xs] = filt[ys - y0, xs - x0]
    return out


def naive(case: dict, params, ctx) -> np.ndarray:
    """The naive baseline on a bench case with the effect's lens (``params``, ``ctx``):
    the same aperture (squeeze, cat-eye barrel, per-channel CA radii) as the effect."""
    lens = Dof().lens(params, ctx)
    d = ctx.display_window
    h, w = np.asarray(case["depth"]).shape
    win = ctx.source.window
    ys, xs = np.mgrid[0:h, 0:w] + 0.5

    def centres(strength):
        if strength == 0:
            return None
        return optical_vignetting_centre(xs + win.x0, ys + win.y0, strength=strength,
                                         centre=d.center,
                                         half_diagonal=0.5 * math.hypot(
                                             d.width, d.height / ctx.pixel_aspect),
                                         pixel_aspect=ctx.pixel_aspect)

    return naive_dof(case["source"], case["depth"], k_half=lens.k_half, focus=lens.focus,
                     clamp_r=lens.clamp_r, squeeze=lens.squeeze, cateye=centres(lens.cateye),
                     ca=lens.ca, cateye_front=centres(-lens.cateye_front))


SCENE_SIZE = (320, 180)
"""The scene classes are measured at this size whatever the bench size: their truths take
16384 renders (~45 s each here, then cached on disk)."""


def _scene_maker(name: str):
    def make_variant(width: int, height: int, rng=None) -> dict:
        return make_scene(name, *SCENE_SIZE)
    make_variant.__name__ = f"make_{name}"
    return make_variant


CASE = Case(make=make,
            naive=Naive(NAIVE_LABEL, lambda case, params, ctx: (lambda: naive(case, params, ctx))),
            variants={**{name: _scene_maker(name) for name in SCENES},
                      **({"cycles_large": cycles.maker("dof_large")}
                         if cycles.available("dof_large") else {})})


# -- the ground-truth table --------------------------------------------------------------------
COLUMNS = ("draft", "preview", "final", "reference", "naive", "input")


def scene_table(rt, width: int = 320, height: int = 180, *, names=None, repeat: int = 3,
                log=None) -> dict:
    """Every level of dof, the naive gather and the unchanged input on each of ``SCENES``:
    log-PSNR (dB) and edge-band RMSE against the truth, median ms of ``repeat`` warm runs.
    Cases are cached on disk like the runner's (rendering one takes tens of seconds)."""
    plugin, out = Dof(), {}
    for name in names or SCENES:
        spec = Case(make=lambda w, h, rng=None, name=name: make_scene(name, w, h))
        case = load_case(sys.modules[__name__], spec, f"dof-{name}", width, height)
        p = Dof.params(**case.get("params", {}))
        truth = np.asarray(case["truth"], np.float64)
        edge = edge_band(case["depth"], None, EDGE_BAND_PX)
        rows = {}
        for q in COLUMNS[:4]:
            ctx = RenderContext(rt, rt.upload(case["source"]), depth=rt.upload(case["depth"]),
                                camera=case["camera"], quality=q)
            times = []
            for i in range(repeat + 1):
                t0 = time.perf_counter()
                img = plugin.render(rt, p, ctx.for_step(q))   # a new step: plans again
                rt.finish()
                times.append((time.perf_counter() - t0) * 1e3)
            got = crop_to(rt.download(img), img.window, ctx.source.window)
            rows[q] = {**error_metrics(got, truth, edge), "ms": float(np.median(times[1:]))}
        ctx = RenderContext(rt, rt.upload(case["source"]), depth=rt.upload(case["depth"]),
                            camera=case["camera"], quality="final")
        t0 = time.perf_counter()
        rows["naive"] = {**error_metrics(naive(case, p, ctx), truth, edge),
                         "ms": (time.perf_counter() - t0) * 1e3}
        rows["input"] = error_metrics(case["source"], truth, edge)
        out[name] = rows
        if log:
            log(f"dof scene {name}: " + ", ".join(f"{k} {v['psnr_log']:.1f} dB"
                                                   for k, v in rows.items()))
    return out


def table_markdown(results: dict) -> str:
    """``scene_table``'s results as a markdown table: log-PSNR / edge RMSE (ms)."""
    lines = ["| case | " + " | ".join(COLUMNS) + " |", "|---|" + "---|" * len(COLUMNS)]
    for name, rows in results.items():
        cells = []
        for c in COLUMNS:
            m = rows[c]
            ms = f" ({m['ms']:.0f} ms)" if "ms" in m else ""
            cells.append(f"{m['psnr_log']:.1f} / {m.get('edge_rmse', float('nan')):.3g}{ms}")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":   # python -m clfx.bench.cases.dof [WIDTHxHEIGHT [REPEAT]]
    import sys

    from clfx.device.runtime import Runtime

    size = sys.argv[1] if len(sys.argv) > 1 else "320x180"
    w, h = (int(v) for v in size.split("x"))
    res = scene_table(Runtime.get(), w, h, repeat=int(sys.argv[2]) if len(sys.argv) > 2 else 3,
                      log=lambda s: print(s, file=sys.stderr))
    print(f"dof against {SAMPLES}-ray thin-lens truth at {w}x{h} (beauty {SS}x{SS} "
          f"supersampled, depth at pixel centres): log-PSNR dB / edge-band RMSE (median ms)\n")
    print(table_markdown(res))
