"""The motion effects against Blender Cycles' own renders (clfx.bench.cycles, issue 24).

The renders are checked in (clfx/bench/cycles/data, made by render_scenes.py with bpy and
packed by pack.py): these tests need neither Blender nor a render, only the files.
"""
from __future__ import annotations

import numpy as np
import pytest

from clfx.bench import cases, cycles
from clfx.bench.runner import _case_context, error_metrics
from clfx.core.frame import crop_to
from clfx.plugins import get_plugin

MOTION = [(e, v) for e in ("motion_blur", "camera_blur", "rolling_shutter")
          for v in cases.for_effect(e).variants if v.startswith("cycles_")]

DATA_BUDGET = 1_500_000
"""Bytes of every checked-in render together."""


def _have(name):
    if not cycles.available(name):
        pytest.skip(f"no Cycles data for {name} under {cycles.DATA}")


def test_cycles_data_is_small_and_read_as_blender_writes_it():
    _have("spin")
    assert sum(p.stat().st_size for p in cycles.data_files()) < DATA_BUDGET
    d = cycles.load("spin")
    h, w = cycles.HEIGHT, cycles.WIDTH
    assert d["source"].shape == (h, w, 4) and d["truth"].shape == (h, w, 4)
    # Blender's Vector pass has both halves: clfx reads ZW as forward, XY as backward.
    assert d["velocity"] is not None and d["velocity_back"] is not None
    assert np.all(np.isfinite(d["depth"])) and float(d["depth"].min()) > 0
    speed = np.hypot(*np.moveaxis(d["velocity"], -1, 0))
    assert speed.max() > 40.0          # the wheel's rim at 72 deg/frame
    # The two halves differ on the spinning wheel (a curve, not a line).
    assert float(np.abs(d["velocity"] - d["velocity_back"]).max()) > 10.0
    assert cycles.noise_floor("spin") is not None


def _score(rt, effect, variant, quality="final"):
    spec = cases.for_effect(effect)
    case = spec.maker(variant)(cycles.WIDTH, cycles.HEIGHT, None)
    cls = get_plugin(effect)
    params = cls.params(**case.get("params", {}))
    ctx = _case_context(rt, case, quality)
    img = cls().render(rt, params, ctx)
    out = crop_to(rt.download(img), img.window, ctx.source.window)
    truth = np.asarray(case["truth"], np.float64)
    scores = {"final": error_metrics(out, truth)["psnr_log"],
              "input": error_metrics(case["source"], truth)["psnr_log"]}
    if spec.naive is not None:
        naive = np.asarray(spec.naive.make(case, params, _case_context(rt, case, "final"))())
        scores["naive"] = error_metrics(naive, truth)["psnr_log"]
    for label, peer in (case.get("peer_images") or {}).items():
        scores["Blender Vector Blur"] = error_metrics(peer, truth)["psnr_log"]
    return scores, case.get("truth_floor")


@pytest.mark.parametrize("effect,variant", MOTION, ids=[f"{e}:{v}" for e, v in MOTION])
def test_final_beats_input_naive_and_blender_on_cycles_renders(rt, effect, variant):
    """Issue 24's "done when": on Cycles' own motion-blurred renders, ``final`` scores above
    the unchanged input, the naive line blur and Blender's Vector Blur, and the truth's
    noise floor lies above every score (the comparison is not lost in the truth's noise)."""
    scores, floor = _score(rt, effect, variant)
    mine = scores.pop("final")
    for what, theirs in scores.items():
        assert mine > theirs, f"{effect}:{variant}: final {mine:.2f} dB <= {what} {theirs:.2f} dB"
    if floor is not None:
        assert floor > mine, f"{effect}:{variant}: noise floor {floor:.1f} dB <= final {mine:.1f}"
