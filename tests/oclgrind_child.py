"""Render small frames through clfx in a process of its own, on whatever device the
environment selects; `tests/test_oclgrind.py` runs this under Oclgrind and reads its log.

    python tests/oclgrind_child.py effect NAME LEVEL[,LEVEL...]
    python tests/oclgrind_child.py look NAME LEVEL[,LEVEL...]
    python tests/oclgrind_child.py fx NAME LEVEL       (a helper of clfx.fx, ``FX``)
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
    "keystone": {"tilt": 10.0, "swing": 5.0},
    "dof": {"coc_source": "max_blur", "max_blur": 0.1, "max_coc": 0.2},
    "lens": {"maker": "Canon", "model": "Canon EF 24-70mm f/2.8L II USM", "fit": "fill"},
    "lens_flare": {"threshold": 5.0, "cull": 0.0, "gain": 100.0},
}

EXTRA = {
    # (level, frame, params, options): one more render in the effect's group, for the kernels
    # that PARAMS on the main frames never reach (scripts/oclgrind_coverage.py fails on any
    # kernel no group launches).  options: "working_space" renders in another space,
    # "keep_overscan" keeps what the effects grow, "before" (effect, params) runs first.
    # r = 11 px > bleed's fused radius (10): bleed_highlights -> FFT -> bleed_mix; preview's
    # split gathers the 1e4 lights exactly (fftconv_count_bright, _compact_bright, _gather)
    # threshold 5, 200 px wide: the support is the lights' tiles, not the frame (the scene's
    # first light is 40 px in): its highlights are read from the source part
    # (<effect>_highlights_at)
    "bleed": [("preview", (106, 24), {"size": 0.1}, {}),
              ("draft", (200, 24), {"size": 0.1, "threshold": 5.0}, {})],
    # trucking/dolly: camera_blur_velocity
    "camera_blur": [("draft", ODD, {"length": 0.05, "truck": [0.01, 0.0], "dolly": 0.01}, {})],
    # first ring >= 2 x 6 px (draft's ring_px): the pattern at reduced resolution (corona_down); ACEScg: the
    # spectral model carried into Rec.709 and back (image_rgb_matrix)
    "corona": [("draft", (2 * W, 2 * H), {"size": 0.2, "extent": 1.5}, {"working_space": "ACEScg"})],
    # sigma past the direct passes: the pyramid (blur_gather_h, _v)
    "defocus": [("draft", (W, H), {"size": 0.25}, {})],
    # CoC radius > 16 px: the lattice over the prefiltered colour (dof_prefilter); bleed with
    # the overscan kept grows the window first, so depth is reframed to it (image_reframe)
    "dof": [("draft", (32, 16), {"coc_source": "max_blur", "max_blur": 0.25, "max_coc": 1.0,
                                "focus_distance": 100.0},
             {"before": ("bleed", {"size": 0.02}), "keep_overscan": True})],
    "glare": [("draft", (200, 24), {"size": 0.08, "threshold": 5.0}, {})],
    "lens_flare": [("draft", (W, H), {"model": "artistic", "threshold": 5.0}, {})],
    "soft_focus": [("draft", (200, 24), {"threshold": 5.0}, {})],
    # streaks' passes streamed in chunks of 3 rows through ring buffers, as at 8K (RING = 1);
    # more lights than the host draws the windows of: the seeds' flags grown on the device
    "streaks": [("final", (W, H), {}, {"streaks_streamed": True}),
                ("final", (W, H), {}, {"streaks_seeds_read": 0})],
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


def effect_look(name: str, masked: bool, params: dict | None = None,
                before: tuple[str, dict] | None = None) -> dict:
    step = {"effect": name, "params": PARAMS.get(name, {}) if params is None else params}
    if masked:
        step["mask"] = {"channel": "m"}
    steps = [{"effect": before[0], "params": before[1]}] if before else []
    return {"name": f"oclgrind-{name}", "schema": 1, "camera": CAMERA, "seed": 3,
            "effects": steps + [step]}


def render(look, level: str, size, label: str, tile_pixels: int = 0,
           working_space: str | None = None, keep_overscan: bool = False,
           streaks_streamed: bool = False, streaks_seeds_read: int | None = None) -> dict:
    from clfx import api
    from clfx.device.runtime import Runtime
    import clfx.plugins.streaks as streaks

    t0 = time.perf_counter()
    rgba, depth, vel, channels = scene(*size)
    os.environ["CLFX_TILE_PIXELS"] = str(tile_pixels)   # 0: whole frames
    kept = streaks.streams, streaks.CHUNK_PIXELS, streaks.SEEDS_READ
    if streaks_streamed:
        streaks.streams, streaks.CHUNK_PIXELS = (lambda *a: True), 3 * size[0]
    if streaks_seeds_read is not None:
        streaks.SEEDS_READ = streaks_seeds_read
    try:
        res = api.render_array(rgba, look, depth=depth, velocity=vel, channels=channels,
                               quality=level, frame=1, working_space=working_space,
                               keep_overscan=keep_overscan)
    finally:
        streaks.streams, streaks.CHUNK_PIXELS, streaks.SEEDS_READ = kept
    rt = Runtime.get()
    rt.finish()
    rep = res.report.as_dict()
    return {"render": label, "level": level, "size": list(size), "device": rt.description,
            "ran": rep.get("ran"), "skipped": rep.get("skipped"),
            "finite": bool(np.isfinite(res.rgba).all()),
            "entry_points": sorted(LAUNCHED.pop(label, ())),
            "seconds": round(time.perf_counter() - t0, 2)}


LAUNCHED: dict[str, set] = {}
"""Per render label: the entry points it launched, as "file:kernel" with ":f64" for a
``CLFX_FP64`` build (its buffers hold doubles: other offsets, other bounds)."""


def record_launches(label_of) -> None:
    """Wrap ``Runtime.launch`` so that every launch adds its entry point to ``LAUNCHED`` under
    the label ``label_of()`` returns."""
    from clfx.device.runtime import Runtime

    launch = Runtime.launch

    def recorded(rt, knl, *args, **kw):
        for (file, name, defines, _), k in rt._kernels.items():
            if k is knl:
                f64 = ":f64" if ("CLFX_FP64", "1") in defines else ""
                LAUNCHED.setdefault(label_of(), set()).add(f"{file}:{name}{f64}")
                break
        return launch(rt, knl, *args, **kw)

    Runtime.launch = recorded


def sanitizers(level: str) -> dict:
    """The NaN/Inf scrubbers of ``clfx.fx.blur`` (defocus) and ``clfx.fx.motion`` (camera_blur,
    motion_blur, rolling_shutter) on an odd-sized frame holding NaN, +Inf and -Inf.  A render
    never reaches them with the first effect: the upload scrubs the frame once
    (``clfx.pipeline.look._upload``); they run when an earlier step wrote a non-finite value."""
    from clfx.device.runtime import Runtime
    from clfx.fx.blur import sanitize_nonfinite
    from clfx.fx.motion import sanitized_copy

    t0 = time.perf_counter()
    rt = Runtime.get()
    rgba = scene(*ODD)[0]
    rgba[1, 2, 0], rgba[3, 12, 3], rgba[6, 5, 1:3] = np.nan, np.inf, -np.inf
    want = np.where(np.isfinite(rgba), rgba, 0.0)
    src = rt.upload(rgba)
    blur, n_bad = sanitize_nonfinite(rt, src)
    got = [rt.download(blur), rt.download(sanitized_copy(rt, src))]
    rt.finish()
    return {"render": "sanitizers", "level": level, "size": list(ODD), "device": rt.description,
            "ran": ["blur_sanitize", "motion_sanitize"], "skipped": None,
            "finite": all(bool(np.isfinite(g).all()) for g in got),
            "exact": n_bad == 3 and all(np.array_equal(g, want) for g in got),
            "seconds": round(time.perf_counter() - t0, 2)}


FX = {"sanitizers": sanitizers}
"""Helpers of clfx.fx whose kernels no render of these frames reaches, by name."""


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
    if kind == "fx":
        for level in levels:
            print(json.dumps(FX[name](level)), flush=True)
        return 0
    current = [""]
    record_launches(lambda: current[0])
    banded: set = set()     # entry points already run in bands
    for level in levels:
        if kind == "effect":
            runs = [(effect_look(name, masked=False), (W, H), f"{name}@{level}")]
            if level == "draft":   # the mask and an odd size, at the cheapest level
                runs += [(effect_look(name, masked=True), ODD, f"{name}@{level}+mask {ODD}"),
                         (effect_look(name, masked=False), ODD, f"{name}@{level} {ODD}")]
            for lvl, size, params, opts in EXTRA.get(name, ()):
                if lvl == level:
                    look = effect_look(name, False, params, opts.get("before"))
                    runs.append((look, size, f"{name}@{level} {size} {params} {opts}",
                                 {k: v for k, v in opts.items() if k != "before"}))
        else:      # a group of looks in one process: each program is compiled once
            runs = [(look, LOOK_SIZE, f"look {look}@{level}") for look in name.split(",")]
        for look, size, label, *opts in runs:
            current[0] = label
            rec = render(look, level, size, label, **(opts[0] if opts else {}))
            print(json.dumps(rec), flush=True)
            if kind == "effect" and tiles(name) and size == (W, H) and label == runs[0][2]:
                # and in bands of 8 rows (`clfx.pipeline.look.render_tiled`), where this
                # level's main frame launched an entry point no banded render has run
                if not set(rec["entry_points"]) <= banded:
                    current[0] = label = f"{name}@{level} tiled"
                    tiled = render(effect_look(name, masked=False), level, (W, H), label,
                                   tile_pixels=W * TILE_ROWS)
                    banded.update(tiled["entry_points"])
                    print(json.dumps(tiled), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
