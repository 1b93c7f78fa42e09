"""`clfx bench`: what accuracy costs in time, and what a scene calls for (`run_bench`).

Three parts, all measured in one run so ratios compare like with like:

1. Effects x quality levels.  Each effect has a case module, ``clfx.bench.cases.<effect>``
   (see that package for the protocol): its representative hard case.  Every level is timed on the device (median, min and max
   of ``repeat`` warm runs after a warm-up), and its output is compared with a reference:
   the case's ``truth`` when it has one (the multisample ground truth for depth of field and
   motion blur), else the effect's own ``reference`` level (float64 / direct evaluation).
   Errors: RMSE and max in linear light, relative RMSE (RMSE / RMS of the reference), PSNR
   after a log tone map, and edge-band RMSE where the case marks an edge band
   (``edge_mask``).  Noise effects, whose levels draw different samples, supply
   ``metrics(out, ref, case)`` comparing statistics with the reference's instead; it
   scores the levels, the baselines and the peers alike.  Peers
   (OpenCV, SciPy, naive methods) doing the same operation are timed beside it where a case
   declares them with ``peers(case, params, ctx)``: host callables returning RGBA arrays, or
   ``(callable, level)`` to compare with the clfx level doing the same work (else final);
   a peer and that level are timed alternately, run for run, and their time ratio is the
   median of the runs' ratios (the machine's drift during a bench reaches both alike).
   Beside the levels every effect gets two baselines scored against the same reference:
   the unchanged input and, where the case declares one (``Case(naive=Naive(...))``), the
   naive method the effect exists to beat; each level is flagged ``beats naive`` /
   ``beats input`` (higher log-PSNR) in the JSON, the markdown and the summary.  A case's
   ``variants`` (other scene classes) are measured like the main case, as
   ``<effect>:<variant>``.
2. Whole looks: each built-in look at the bench size, ms per frame with a per-effect
   breakdown, and sequence throughput with EXR reading and writing included.
3. Scene analysis: the cinema look on (a) a frame that needs everything, (b) a static, dim,
   all-in-focus frame, (c) the same with a small moving region, next to the cost of reading
   and writing the frame.
"""
from __future__ import annotations

import time

from clfx.bench import cases
from clfx.bench.cache import case_label
from clfx.bench.effects import bench_effect
from clfx.bench.looks import bench_analysis, bench_look, bench_sequence, demo_frame
from clfx.bench.report import losing_levels
from clfx.pipeline.presets import available_looks
from clfx.plugins import discover, get_plugin

__all__ = ["run_bench"]


def run_bench(rt, *, effects=None, looks=None, width=1920, height=1080, repeat=5,
              sequence_frames=8, analysis=True, log=print) -> dict:
    """Every part of the bench (module docstring) in one run: ``effects`` (None: all) with
    their case variants, ``looks`` (None: the built-in ones; empty: none), the sequence of
    ``sequence_frames`` frames and the scene analysis (with the cinema look).  One broken
    effect is reported and the others measured.  ``log`` gets one line per part done."""
    reg = discover()
    effect_names = list(reg) if effects is None else list(effects)
    results = {"size": [width, height], "repeat": repeat, "device": rt.description,
               "effects": [], "looks": []}
    for name in effect_names:
        if name not in reg:
            get_plugin(name)  # raises with a suggestion
        spec = cases.for_effect(name)
        for variant in [None, *(spec.variants if spec is not None else ())]:
            label = case_label(name, variant)
            t0 = time.perf_counter()
            try:
                res = bench_effect(rt, name, width, height, repeat, variant=variant)
            except Exception as exc:  # one broken effect must not hide the others' figures
                results["effects"].append({"effect": label, "rows": [], "peers": [],
                                           "baselines": [], "reference": "",
                                           "note": f"failed: {exc!r}"})
                log(f"clfx bench: {label} FAILED: {exc!r}")
                continue
            results["effects"].append(res.as_dict())
            floor = "" if res.truth_floor is None else f" (truth's noise floor {res.truth_floor:.1f} dB)"
            log(f"clfx bench: {label} done in {time.perf_counter() - t0:.1f} s{floor}")
            for lost in losing_levels(res.as_dict()):
                log(f"clfx bench: {label}: {lost} in log-PSNR")
    if looks is None or looks:
        names = list(looks) if looks else [n for n, (o, _) in available_looks().items() if o == "built-in"]
        frame = demo_frame(width, height)
        for n in names:
            results["looks"].append(bench_look(rt, n, frame, repeat))
            log(f"clfx bench: look {n} done")
        if sequence_frames:
            results["sequence"] = bench_sequence(rt, "cinema" if "cinema" in names else names[0],
                                                 width, height, sequence_frames, repeat)
        if analysis and ("cinema" in names):
            results["analysis"] = bench_analysis(rt, "cinema", width, height, repeat)
    return results
