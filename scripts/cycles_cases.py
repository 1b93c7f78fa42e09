"""Motion effects and depth of field against Blender Cycles' renders (clfx.bench.cycles),
one table.

    PYTHONPATH=$PWD python scripts/cycles_cases.py [--effects motion_blur,camera_blur,rolling_shutter,dof]
        [--cases spin,truck] [--repeat 1]

Runs ``clfx bench``'s own measurement (:func:`clfx.bench.effects.bench_effect`) on every
``cycles_*`` variant of the effects and prints :func:`clfx.bench.report.truth_markdown`:
log-PSNR (dB) of the input, the naive method, Blender's Vector Blur or Defocus, each level,
and the truth's noise floor; then each case's edge-band RMSE (linear, the band of
:func:`clfx.bench.metrics.edge_band` around depth and motion edges).  ``clfx bench --effects ... --looks none --sequence-frames 0`` prints
the same table after its others.
"""
from __future__ import annotations

import argparse

from clfx.bench import cases
from clfx.bench.effects import bench_effect
from clfx.bench.report import truth_markdown
from clfx.core.plugin import QUALITY_LEVELS
from clfx.device.runtime import Runtime


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--effects", default="motion_blur,camera_blur,rolling_shutter,dof")
    ap.add_argument("--cases", default="", help="scene names (default: every one)")
    ap.add_argument("--repeat", type=int, default=1)
    a = ap.parse_args()
    rt = Runtime.get()
    results = {"effects": []}
    for effect in a.effects.split(","):
        for variant in cases.for_effect(effect).variants:
            if not variant.startswith("cycles_"):
                continue
            if a.cases and variant[len("cycles_"):] not in a.cases.split(","):
                continue
            res = bench_effect(rt, effect, 320, 180, a.repeat, variant=variant)
            results["effects"].append(res.as_dict())
            print("\n".join(truth_markdown({"effects": [res.as_dict()]})[-1:]), flush=True)
    print("\n".join(truth_markdown(results)))
    print("\n".join(edge_markdown(results)))


def edge_markdown(results: dict) -> list[str]:
    """Edge-band RMSE (linear) of the input, the naive method, the peers and each level."""
    lines = ["", "Edge-band RMSE (linear; lower is better):", "",
             "| case | input | naive | peer | " + " | ".join(QUALITY_LEVELS) + " |",
             "|---|---|---|---|" + "---|" * len(QUALITY_LEVELS)]
    for e in results["effects"]:
        base = {}
        for b in e.get("baselines", []):
            base.setdefault(b["baseline"], b)
        rows = {r["quality"]: r for r in e["rows"]}
        cells = [base.get(k, {}).get("edge_rmse") for k in ("input", "naive", "peer")]
        cells += [rows.get(q, {}).get("edge_rmse") for q in QUALITY_LEVELS]
        lines.append(f"| {e['effect']} | " + " | ".join("-" if v is None else f"{v:.4f}"
                                                       for v in cells) + " |")
    return lines


if __name__ == "__main__":
    main()
