"""Bench cases rendered by Blender Cycles: a real path tracer's motion blur and depth of
field as the truth.

The scenes are made by :mod:`clfx.bench.cycles.render_scenes` (run with ``bpy``, Python
3.13; the ``cycles`` bench extra, not needed by the tests) and packed by
``python -m clfx.bench.cycles.pack RENDER_DIR`` into ``data/`` here, two files per scene
(320x180, half float, ZIP; 3.3 MB in all: textured frames do not compress far losslessly):

- ``<name>.exr``: the sharp frame as Blender writes it, one part with Blender's multilayer
  names: ``ViewLayer.Combined.RGBA``, ``ViewLayer.Depth.Z`` (float), ``ViewLayer.Vector.XYZW``
  (both halves of the vector pass: XY previous - current, ZW current - next, pixels, y-up).
  It is read through clfx's own EXR reader (:func:`clfx.io.read.read_frame`), so the bench
  sees the passes as a user's Blender render gives them;
- ``<name>.ref.exr``: ``truth.RGB``, the frame rendered with Cycles' motion blur (180 degree
  shutter centred on the frame; ``truck_rolling``: Cycles' rolling shutter), seed 1, and
  ``vectorblur.RGB``, Blender's compositor Vector Blur node of the sharp frame's passes
  (shutter 0.5, 32 samples), the peer row.

The depth-of-field scenes (``dof_*``, :data:`DOF_SCENES`) are still: the sharp frame is the
pinhole render (depth of field off) with its Depth pass and no Vector pass, the truth is
Cycles' thin lens (:func:`dof_camera`'s lens: the aperture that gives Cycles clfx's circle of
confusion, render_scenes.cycles_fstop) and the peer is Blender's compositor Defocus node of
the sharp frame's Depth pass (``defocus.RGB``: the same f-number and focus, round bokeh).

The same frame rendered with seed 2 scores ``log-PSNR(seed 2, truth)`` against it: the
truth's own noise floor (no method can be shown to score above it), stored in the header
and printed beside every Cycles case (:func:`noise_floor`).
"""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

from clfx.core.camera import Camera
from clfx.io.probe import header_attribute
from clfx.io.read import read_channels, read_frame

DATA = Path(__file__).resolve().parent / "data"

WIDTH, HEIGHT = 320, 180
FOCAL_MM, SENSOR_MM = 50.0, 36.0

PEER_LABEL = "Blender Vector Blur (compositor, 32 samples)"
DEFOCUS_LABEL = "Blender Defocus (compositor, Z buffer, round bokeh)"
PEERS = {"vectorblur": PEER_LABEL, "defocus": DEFOCUS_LABEL}
"""Each peer layer of ``<name>.ref.exr`` and its label in the bench table."""

SCENES = {
    "spin": "a wheel spinning 72 deg/frame with a rim light, a propeller turning 60 deg/frame, "
            "a box moving 40 px/frame",
    "truck": "the camera trucking sideways past posts at 2.5-10 m over a wall at 20 m "
             "(parallax: 40 to 5 px/frame)",
    "pan": "the camera panning 2.5 deg/frame while trucking the other way (parallax in a pan)",
    "crossing": "a near card (3 m, 36 px/frame) crossing a far disk (8 m, -22 px/frame)",
    "slow": "fine stripes, grain and a 2.5 px checker moving 1-3 px/frame",
    "truck_rolling": "the truck through a rolling shutter (top first, 0.75 frame readout)",
    "dof_large": "200 mm f/2 at 2 m: a lit wall (CoC radius 41 px), a sign (30 px), an in-focus "
                 "subject, posts in front (-40 and -27 px) crossing it",
}
"""Every scene, in a few words (render_scenes.py has the exact set-up)."""

PAN_DEG = 2.5
"""The pan: degrees per frame (render_scenes.PAN_DEG)."""

TRUCK_PX_AT_2_5_M = 40.0
"""The truck: the post at 2.5 m moves this many px/frame (render_scenes.TRUCK_M)."""


DOF_SCENES = ("dof_large",)
"""The depth-of-field scenes (still frames: no Vector pass)."""

DOF_FOCAL_MM, DOF_F_NUMBER, DOF_FOCUS_M = 200.0, 2.0, 2.0
"""Their lens (render_scenes.DOF_*): a 200 mm f/2 focused at 2 m on the 36 mm sensor, CoC
diameter at infinity 98.8 px at 320 wide."""

FLOOR_ATTRIBUTE = "clfx:noise_floor_log_psnr"
"""Header attribute of ``<name>.ref.exr``: log-PSNR of the seed-2 render against the truth."""


def base_scene(name: str) -> str:
    """The scene whose sharp frame ``name`` uses (``truck_rolling``: ``truck``)."""
    return name[: -len("_rolling")] if name.endswith("_rolling") else name


def files(name: str) -> tuple[Path, Path]:
    """(sharp frame, references) of scene ``name``."""
    return DATA / f"{base_scene(name)}.exr", DATA / f"{name}.ref.exr"


def available(name: str) -> bool:
    return all(p.exists() for p in files(name))


def read_layers(path: Path) -> dict[str, np.ndarray]:
    """The layers of a data file (``truth.R/G/B`` -> ``truth``), (h, w, n) float32, their
    channels in the file's order (`clfx.io.read.read_channels`)."""
    out: dict[str, list] = {}
    for name, plane in read_channels(path).items():
        out.setdefault(name.rpartition(".")[0], []).append(plane)
    return {k: np.stack(v, -1) for k, v in out.items()}


@lru_cache(maxsize=None)
def load(name: str) -> dict:
    """The scene's sharp frame (through clfx's reader), truth, its noise floor and
    Blender's Vector Blur (where rendered)."""
    sharp, ref = files(name)
    frame = read_frame(str(sharp))
    layers = read_layers(ref)
    floor = header_attribute(ref, FLOOR_ATTRIBUTE)
    alpha = np.ones(layers["truth"].shape[:2] + (1,), np.float32)
    rgba = {k: np.concatenate([v[..., :3], alpha], -1) for k, v in layers.items()}
    return dict(source=np.ascontiguousarray(frame.rgba, np.float32),
                depth=frame.depth, velocity=frame.velocity, velocity_back=frame.velocity_back,
                truth=rgba["truth"], vector_blur=rgba.get("vectorblur"),
                peers={PEERS[k]: v for k, v in rgba.items() if k in PEERS},
                floor=None if floor is None else float(floor))


def noise_floor(name: str) -> float | None:
    """log-PSNR of the second seed's render against the truth (None: rendered once)."""
    return load(name)["floor"]


def camera():
    return Camera(focal_length=FOCAL_MM, sensor_width=SENSOR_MM, shutter_angle=180.0,
                  shutter_offset="centered")


def dof_camera():
    """The depth-of-field scenes' lens as clfx's camera: Cycles rendered the truth with the
    aperture that gives this camera's CoC (``f^2 / (N (S - f))``), Blender's Defocus node
    uses this f-number."""
    return Camera(focal_length=DOF_FOCAL_MM, f_number=DOF_F_NUMBER, sensor_width=SENSOR_MM,
                  focus_distance=DOF_FOCUS_M)


def truck_m_per_frame() -> float:
    """The truck's speed in metres per frame (the nearest post, 2.5 m, moves 40 px/frame)."""
    return TRUCK_PX_AT_2_5_M * 2.5 / camera().focal_length_px(WIDTH)


def case(name: str, *, params: dict | None = None, velocity: bool = True) -> dict:
    """A bench case dict of scene ``name`` (the :class:`clfx.bench.cases.Case` protocol) with
    ``truth_floor`` and Blender's own post-process (Vector Blur, Defocus) as ``peer_images``."""
    d = load(name)
    velocity = velocity and name not in DOF_SCENES
    out = dict(source=d["source"], depth=d["depth"],
               velocity=d["velocity"] if velocity else None,
               velocity_back=d["velocity_back"] if velocity else None,
               params=dict(params or {}),
               camera=dof_camera() if name in DOF_SCENES else camera(), truth=d["truth"],
               truth_floor=noise_floor(name), scene=f"cycles:{name}")
    if d["peers"]:
        out["peer_images"] = dict(d["peers"])
    return out


def maker(name: str, **kw):
    """A ``make(width, height, rng)`` of scene ``name`` (always 320x180: the renders are)."""
    def make(width: int, height: int, rng=None, **_):
        if not available(name):
            raise FileNotFoundError(f"Cycles bench data for {name!r} is missing under {DATA} "
                                    "(re-make it: clfx/bench/cycles/render_scenes.py)")
        return case(name, **kw)
    make.__doc__ = f"Cycles scene {name!r}: {SCENES[name]} (320x180, rendered truth)."
    make.cached = False     # read from files: the bench's case cache is not needed
    return make


def variants(names, **kw) -> dict:
    """``{"cycles_<name>": make}`` for the scenes whose data is present."""
    return {f"cycles_{n}": maker(n, **kw) for n in names if available(n)}


def data_files() -> list[Path]:
    """Every data file (the Cycles cases are not cached: `maker` reads them per run)."""
    return sorted(DATA.glob("*.exr")) if DATA.exists() else []
