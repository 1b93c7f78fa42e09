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

Motion: at time ``t`` (frames) a layer is translated by ``velocity * t``.  The shutter is
open for ``shutter_angle / 360`` of a frame, centred on the frame time, starting at it
("opening") or ending at it ("closing") per ``Camera.shutter_offset``
(:meth:`clfx.core.camera.Camera.shutter_interval`, as the effects read it).

Sampling: ``samples`` lens points on a golden-angle spiral (uniform in the disk; mapped to
the polygon radially with Jacobian weights ``R(phi)^2``) paired with stratified shutter
times from a second low-discrepancy sequence.  Each layer is rasterised once at ``ss x ss``
sub-samples per pixel over its padded extent; a sample render places it with an integer
sub-sample offset (the shift rounded to ``1/ss`` px), composites "over" and accumulates in
float64.  The rounding quantises the aperture to the sub-sample grid; with ``samples`` = 0
aperture and 0 shutter it reproduces :func:`clfx.bench.scene.render_sharp` exactly.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from clfx.bench.scene import (
    Scene,
    background_rgba,
    box_downsample,
    rasterise_layer,
    render_sharp,
)
from clfx.core.camera import Camera, aperture_radius, first_blade_angle

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


def shutter_times(n: int, camera: Camera) -> np.ndarray:
    """``n`` stratified instants over the shutter interval (a Weyl sequence, shuffled
    against the lens spiral so lens position and time are uncorrelated)."""
    t0, t1 = camera.shutter_interval()
    u = np.mod(0.5 + np.arange(n) * PLASTIC_INV, 1.0)
    return t0 + (t1 - t0) * u


# -- renderer --------------------------------------------------------------------------------
@dataclass
class _Sprite:
    """A layer rasterised once over its padded extent (sub-sample units)."""

    rgba: np.ndarray
    x0: int                  # position of rgba[0, 0] in sub-samples of the frame
    y0: int
    half_coc: float          # signed CoC / 2 in px: shift per unit lens position
    velocity: tuple


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
    if layer is None:
        raise ValueError("layer is None")
    rgba = rasterise_layer(layer, x0, y0, x1 - x0, y1 - y0, ss, t)
    return _Sprite(rgba, x0 * ss, y0 * ss, half_coc, tuple(layer.velocity))


def _place(out: np.ndarray, sp: _Sprite, dx: int, dy: int, first: bool) -> None:
    """Composite sprite ``sp`` shifted by (dx, dy) sub-samples over ``out`` (or copy it)."""
    H, W = out.shape[:2]
    h, w = sp.rgba.shape[:2]
    ox, oy = sp.x0 + dx, sp.y0 + dy
    fx0, fy0 = max(0, ox), max(0, oy)
    fx1, fy1 = min(W, ox + w), min(H, oy + h)
    if fx1 <= fx0 or fy1 <= fy0:
        return
    src = sp.rgba[fy0 - oy:fy1 - oy, fx0 - ox:fx1 - ox]
    dst = out[fy0:fy1, fx0:fx1]
    if first:
        dst[...] = src
    else:
        dst *= 1.0 - src[..., 3:4]
        dst += src


def render_truth(scene: Scene, camera: Camera, *, t: float = 0.0, samples: int = 256,
                 dof: bool = True, motion: bool = True, ss: int = 1,
                 progress=None) -> np.ndarray:
    """Multisample render of ``scene`` through ``camera``: the ground truth.

    Parameters
    ----------
    scene : Scene
    camera : Camera
        Lens (focal length, f-number, sensor width, focus distance, blades, blade rotation)
        and shutter (angle, offset).
    t : float
        Frame time in frames relative to the scene's frame.
    samples : int
        Number of (lens point, shutter instant) pairs.
    dof, motion : bool
        Integrate over the aperture / over the shutter interval.
    ss : int
        Sub-samples per pixel and axis (antialiasing and shift resolution ``1/ss`` px).
    progress : callable, optional
        Called as ``progress(done, total)``.

    Returns
    -------
    np.ndarray
        (height, width, 4) float32 premultiplied RGBA.
    """
    w, h = scene.width, scene.height
    n = max(1, int(samples)) if (dof or motion) else 1
    lens, weights = aperture_samples(n, camera.blades, camera.blade_rotation)
    if not dof:
        lens = np.zeros_like(lens)
    times = shutter_times(n, camera) if motion else np.zeros(n)
    t_extent = float(np.abs(times).max()) if n else 0.0

    def half_coc(z):
        return 0.0 if not dof else 0.5 * float(camera.coc_signed_px(z, w))

    bg_half = half_coc(math.inf)
    sprites = []
    bg = background_rgba(scene, -(int(abs(bg_half)) + 2), -(int(abs(bg_half)) + 2),
                         w + 2 * (int(abs(bg_half)) + 2), h + 2 * (int(abs(bg_half)) + 2), ss)
    sprites.append(_Sprite(bg, -(int(abs(bg_half)) + 2) * ss, -(int(abs(bg_half)) + 2) * ss,
                           bg_half, (0.0, 0.0)))
    for layer in scene.layers:
        hc = half_coc(layer.depth)
        speed = math.hypot(*layer.velocity) * t_extent
        sprites.append(_sprite(scene, layer, t, abs(hc) + speed, ss, hc))

    acc = np.zeros((h * ss, w * ss, 4), np.float64)
    out = np.empty((h * ss, w * ss, 4), np.float32)
    for i in range(n):
        (px, py), ts = lens[i], times[i]
        for j, sp in enumerate(sprites):
            sx = px * sp.half_coc + sp.velocity[0] * ts
            sy = py * sp.half_coc + sp.velocity[1] * ts
            _place(out, sp, int(round(sx * ss)), int(round(sy * ss)), first=(j == 0))
        acc += weights[i] * out if dof else out / n
        if progress is not None:
            progress(i + 1, n)
    return box_downsample(acc, ss).astype(np.float32)


# -- cases -----------------------------------------------------------------------------------
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


def make_case(scene: Scene, camera: Camera, *, t: float = 0.0, samples: int = 256,
              dof: bool = True, motion: bool = False, ss: int = 1) -> GroundTruthCase:
    """Render the sharp frame (same ``ss``) and the ground truth of ``scene``."""
    sharp = render_sharp(scene, t, ss=ss)
    t0 = time.perf_counter()
    truth = render_truth(scene, camera, t=t, samples=samples, dof=dof, motion=motion, ss=ss)
    return GroundTruthCase(scene, camera, sharp, truth, samples, time.perf_counter() - t0,
                           dict(t=t, dof=dof, motion=motion, ss=ss))


def write_case(case: GroundTruthCase, directory, *, name: str = "case",
               overwrite: bool = True) -> dict:
    """Write ``<name>.sharp.exr`` (beauty + Z + forward.u/v) and ``<name>.truth.exr`` (float).

    Returns the paths written.  Uses :func:`clfx.io.write.write_frame` (imported lazily).
    """
    from clfx.core.frame import Frame
    from clfx.io.write import write_frame

    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    attrs = {"clfx:camera": str(case.camera.as_dict()), "clfx:samples": int(case.samples)}
    paths = {"sharp": d / f"{name}.sharp.exr", "truth": d / f"{name}.truth.exr"}
    write_frame(case.sharp, paths["sharp"], bit_depth="float", overwrite=overwrite,
                attributes=attrs)
    write_frame(Frame.from_array(case.truth), paths["truth"], bit_depth="float",
                overwrite=overwrite, attributes=attrs, write_passes=False)
    return paths
