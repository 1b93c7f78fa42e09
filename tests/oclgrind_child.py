"""Render small frames through clfx in a process of its own, on whatever device the
environment selects; `tests/test_oclgrind.py` runs this under Oclgrind and reads its log.

    python tests/oclgrind_child.py effect NAME LEVEL[,LEVEL...]
    python tests/oclgrind_child.py look NAME LEVEL[,LEVEL...]
    python tests/oclgrind_child.py kernel FILE.cl     (one kernel ``k(global float *x, int n)``)

Prints one JSON line per render on stdout: what ran, on which device, and whether the output
is finite.  ``CLFX_TEST_OPT_DISABLE=1`` adds ``-cl-opt-disable`` to every program's build
options (see ``tests/test_oclgrind.py``: Oclgrind 21.10 mis-executes some of its own ``-Oz``
code).
"""
from __future__ import annotations

import json
import os
import sys
import time

import numpy as np

W, H = 40, 24
"""An effect's main frame: two 32-pixel analysis tiles across (the second partial), one
partial tile down; two and a half work-groups of 16 across, one and a half down.  Oclgrind's
time is simulated work-items (pixels x taps): the effects' groups took 173 CPU s at 48x32
with the mask there, 117 at 40x24 with the mask at ``ODD``, and every group launches the
same kernels both ways (scripts/oclgrind_coverage.py)."""

LOOK_SIZE = (48, 32)
"""The built-in looks' frame: at 40x24 the glare of ``anamorphic-night`` and ``sunny-flare``
goes direct, and no group would run the FFT convolution (``fftconv_pack``, ``_multiply``,
``_unpack``, ``_down2``, ``_up2``) or ``sunny-flare``'s ghosts."""

ODD = (13, 7)
"""A second, odd-sized frame (no multiple of 4 or 16 anywhere), at the ``draft`` level, with
and without the mask."""

CAMERA = {"focal_length": 35, "f_number": 2.0, "sensor_width": 24.89, "focus_distance": 3.0,
          "shutter_angle": 180, "iso": 800, "blades": 7}

PARAMS = {
    # what makes each effect do work on these frames (the defaults of several are identity)
    "bleed": {"size": 0.05},
    # a small corona: the FFT grid (and VkFFT's tolerated race reports, ~1 per element) stay small
    "corona": {"size": 0.015, "extent": 3.0},
    # a small glare: its direct gather (PSFs <= 21x21 taps) costs Oclgrind ~taps x pixels;
    # the FFT paths it shares with corona (clfx.fx.fftconv) run through corona
    "glare": {"size": 0.08},
    "breathing": {"amount": 0.5, "reference_focus": 1.0},
    "camera_blur": {"length": 0.05, "roll": 2.0, "zoom": 0.02},
    "defocus": {"size": 0.03},
    "distortion": {"k1": -0.1, "p1": 0.01},
    "dof": {"coc_source": "max_blur", "max_blur": 0.1, "max_coc": 0.2},
    "lens": {"maker": "Canon", "model": "Canon EF 24-70mm f/2.8L II USM", "fit": "fill"},
    "lens_flare": {"threshold": 5.0, "cull": 0.0, "gain": 100.0},
}


def scene(w: int, h: int):
    """RGBA with 1e4 lights (one on the edge), depth with near/far edges and a sky at +inf,
    velocity from 0 to 20 px, and a soft mask channel ``m``."""
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    rgba = np.empty((h, w, 4), np.float32)
    rgba[..., 0] = 0.05 + 0.7 * xx / max(w - 1, 1)
    rgba[..., 1] = 0.05 + 0.5 * yy / max(h - 1, 1)
    rgba[..., 2] = 0.2
    rgba[..., 3] = 1.0
    for x, y in ((w // 5, h // 4), (w - 1, h - 1), (w // 2, h // 2)):
        rgba[min(y, h - 1), min(x, w - 1), :3] = 1e4
    depth = np.where(xx < w / 2, 1.2, 8.0).astype(np.float32)
    depth[(xx - w * 0.7) ** 2 + (yy - h * 0.5) ** 2 < (min(w, h) * 0.25) ** 2] = 3.0
    depth[: max(h // 6, 1), w - max(w // 6, 1):] = np.inf
    vel = np.zeros((h, w, 2), np.float32)
    vel[..., 0] = np.where(xx >= w / 2, 6.0, 0.0)
    vel[..., 1] = np.where(yy >= h / 2, -3.0, 0.0)
    vel[: max(h // 4, 1), : max(w // 4, 1)] = (20.0, 5.0)
    mask = np.clip((xx - w * 0.25) / max(w * 0.25, 1), 0.0, 1.0).astype(np.float32)
    return rgba, depth, vel, {"m": mask}


TILE_ROWS = 8
"""An effect that tiles also renders in bands of this many rows of the main frame."""


def tiles(name: str) -> bool:
    """Whether effect ``name`` renders in tiles (`clfx.host.Plugin.whole_frame` None)."""
    from clfx.plugins import get_plugin

    return get_plugin(name).whole_frame is None


def effect_look(name: str, masked: bool) -> dict:
    step = {"effect": name, "params": PARAMS.get(name, {})}
    if masked:
        step["mask"] = {"channel": "m"}
    return {"name": f"oclgrind-{name}", "schema": 1, "camera": CAMERA, "seed": 3,
            "effects": [step]}


def render(look, level: str, size, label: str, tile_pixels: int = 0) -> dict:
    from clfx import api
    from clfx.device.runtime import Runtime

    t0 = time.perf_counter()
    rgba, depth, vel, channels = scene(*size)
    os.environ["CLFX_TILE_PIXELS"] = str(tile_pixels)   # 0: whole frames
    res = api.render_array(rgba, look, depth=depth, velocity=vel, channels=channels,
                           quality=level, frame=1)
    rt = Runtime.get()
    rt.finish()
    rep = res.report.as_dict()
    return {"render": label, "level": level, "size": list(size), "device": rt.description,
            "ran": rep.get("ran"), "skipped": rep.get("skipped"),
            "finite": bool(np.isfinite(res.rgba).all()),
            "seconds": round(time.perf_counter() - t0, 2)}


def run_kernel(path: str) -> dict:
    from clfx.device.runtime import BUILD_OPTIONS, Runtime

    rt = Runtime.get()
    cl = rt.cl
    prg = cl.Program(rt.ctx, open(path).read()).build(options=list(BUILD_OPTIONS))
    n = 16
    buf = cl.Buffer(rt.ctx, cl.mem_flags.READ_WRITE, n * 4)
    cl.enqueue_fill_buffer(rt.queue, buf, np.float32(0), 0, n * 4)
    prg.k(rt.queue, (n,), (n,), buf, np.int32(n))
    rt.finish()
    return {"render": path, "device": rt.description}


def main(argv) -> int:
    if os.environ.get("CLFX_TEST_OPT_DISABLE") == "1":
        from clfx.device import runtime

        runtime.BUILD_OPTIONS = tuple(runtime.BUILD_OPTIONS) + ("-cl-opt-disable",)
    kind, name = argv[0], argv[1]
    if kind == "kernel":
        print(json.dumps(run_kernel(name)), flush=True)
        return 0
    levels = argv[2].split(",")
    for level in levels:
        if kind == "effect":
            runs = [(effect_look(name, masked=False), (W, H), f"{name}@{level}")]
            if level == "draft":   # the mask and an odd size, at the cheapest level
                runs += [(effect_look(name, masked=True), ODD, f"{name}@{level}+mask {ODD}"),
                         (effect_look(name, masked=False), ODD, f"{name}@{level} {ODD}")]
            if tiles(name):        # and in bands of 8 rows (`clfx.pipeline.look.render_tiled`)
                runs += [(effect_look(name, masked=False), (W, H), f"{name}@{level} tiled",
                          W * TILE_ROWS)]
        else:
            runs = [(name, LOOK_SIZE, f"look {name}@{level}")]
        for look, size, label, *tile_pixels in runs:
            print(json.dumps(render(look, level, size, label, *tile_pixels)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
