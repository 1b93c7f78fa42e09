"""Accuracy table of motion_blur (or camera_blur) on its ground-truth cases.

    PYTHONPATH=$PWD python scripts/motion_cases.py [--size 320x180] [--samples 256]
        [--cases layers,spin] [--effect motion_blur]

Prints, per case, the log-PSNR (dB) and edge-band RMSE of every quality level, the case
module's naive baseline and the unchanged input against the multisample truth
(clfx.bench.metrics.error_metrics; edge band: clfx.bench.metrics.edge_band, 4 px), and the
truth's own noise floor (a second truth, another seed, against it).
"""
from __future__ import annotations

import argparse
import importlib
import time

import numpy as np

from clfx.bench.metrics import edge_band
from clfx.bench.cases.shared import case_context
from clfx.bench.metrics import EDGE_BAND_PX, error_metrics
from clfx.core.frame import crop_to
from clfx.core.plugin import QUALITY_LEVELS
from clfx.device.runtime import Runtime
from clfx.plugins import get_plugin


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", default="320x180")
    ap.add_argument("--samples", type=int, default=256)
    ap.add_argument("--cases", default="")
    ap.add_argument("--effect", default="motion_blur")
    a = ap.parse_args()
    w, h = (int(v) for v in a.size.split("x"))
    mod = importlib.import_module(f"clfx.bench.cases.{a.effect}")
    cases = getattr(mod, "CASES", {a.effect: mod.CASE.make})
    names = a.cases.split(",") if a.cases else list(cases)
    rt = Runtime.get()
    cls = get_plugin(a.effect)
    cols = list(QUALITY_LEVELS) + ["naive", "input"]
    print(f"{a.effect} at {w}x{h}, truth {a.samples} rays per pixel (jittered points and instants)")
    print("| case | " + " | ".join(cols) + " |")
    print("|---|" + "---|" * len(cols))
    for name in names:
        t0 = time.perf_counter()
        case = cases[name](w, h, np.random.default_rng(1), truth_samples=a.samples)
        truth = np.asarray(case["truth"], np.float64)
        edge = case.get("edge_mask")
        if edge is None:
            edge = edge_band(case.get("depth"), case.get("velocity"), EDGE_BAND_PX)
        params = cls.params(**case.get("params", {}))
        outs = {}
        for q in QUALITY_LEVELS:
            ctx = case_context(rt, case, q)
            reason = cls().is_identity(params, ctx)
            img = ctx.source if reason else cls().render(rt, params, ctx)
            outs[q] = crop_to(rt.download(img), img.window, ctx.source.window)
        ctx = case_context(rt, case, "final")
        outs["naive"] = mod.naive(case, params, ctx)
        outs["input"] = case["source"]
        cells = []
        for c in cols:
            m = error_metrics(outs[c], truth, edge)
            cells.append(f"{m['psnr_log']:.2f} / {m.get('edge_rmse', float('nan')):.4f}")
        floor = case.get("truth_floor")
        floor = "" if floor is None else f", truth's noise floor {floor:.2f} dB"
        print(f"| {name} | " + " | ".join(cells) + f" |  ({time.perf_counter() - t0:.0f} s{floor})",
              flush=True)


if __name__ == "__main__":
    main()
