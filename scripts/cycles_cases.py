"""Motion effects against Blender Cycles' renders (clfx.bench.cycles), one table.

    PYTHONPATH=$PWD python scripts/cycles_cases.py [--effects motion_blur,camera_blur,rolling_shutter]
        [--cases spin,truck] [--repeat 1]

Runs ``clfx bench``'s own measurement (:func:`clfx.bench.effects.bench_effect`) on every
``cycles_*`` variant of the effects and prints :func:`clfx.bench.report.truth_markdown`:
log-PSNR (dB) of the input, the naive method, Blender's Vector Blur, each level, and the
truth's noise floor.  ``clfx bench --effects ... --looks none --sequence-frames 0`` prints
the same table after its others.
"""
from __future__ import annotations

import argparse

from clfx.bench import cases
from clfx.bench.effects import bench_effect
from clfx.bench.report import truth_markdown
from clfx.device.runtime import Runtime


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--effects", default="motion_blur,camera_blur,rolling_shutter")
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


if __name__ == "__main__":
    main()
