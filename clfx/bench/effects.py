"""The bench's first part: every quality level of an effect on its case, against its
reference, beside the naive method, the unchanged input and the peers (`bench_effect`).

These renders are in memory (a case's arrays uploaded, the plugin's ``render`` called,
the output downloaded), timed run by run: no file is read or written, so they are not a
read/render/write loop (that is `clfx.pipeline.stream.render_stream`'s alone).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from clfx.bench import cases
from clfx.bench.cache import case_label, load_case
from clfx.bench.cases.shared import case_context
from clfx.bench.metrics import EDGE_BAND_PX, edge_band, error_metrics
from clfx.bench.timing import stats, timed, timed_pair
from clfx.core.frame import crop_to
from clfx.core.plugin import QUALITY_LEVELS
from clfx.plugins import discover


@dataclass
class EffectResult:
    """One effect's (or case variant's) bench results: a row per quality level, the peers,
    the baselines (naive method, unchanged input, another tool's images) and what they were
    scored against."""

    effect: str
    rows: list[dict] = field(default_factory=list)
    peers: list[dict] = field(default_factory=list)
    baselines: list[dict] = field(default_factory=list)
    reference_kind: str = "reference level"
    note: str = ""
    metric: str = ""
    """The case's own metric, in one line (its docstring's first), if it has one."""
    truth_floor: float | None = None
    """log-PSNR of a second render of the truth (another seed) against it: the truth's own
    noise floor, for cases rendered by a path tracer (``case["truth_floor"]``)."""
    scene: str = ""

    def as_dict(self) -> dict:
        return {"effect": self.effect, "rows": self.rows, "peers": self.peers,
                "baselines": self.baselines, "reference": self.reference_kind, "note": self.note,
                "metric": self.metric, "truth_floor": self.truth_floor, "scene": self.scene}


def bench_effect(rt, name: str, width: int, height: int, repeat: int,
                 rng_seed: int = 1, variant: str | None = None) -> EffectResult:
    """Time every quality level of one effect on its bench case (or a variant) and measure
    its error, beside the unchanged input and the case's naive method."""
    cls = discover()[name]
    spec, module = cases.for_effect(name), cases.module_for(name)
    res = EffectResult(case_label(name, variant))
    if spec is None:
        res.note = "no bench case"
        return res
    case = load_case(module, spec, name, width, height, rng_seed, variant)
    res.truth_floor = case.get("truth_floor")
    res.scene = str(case.get("scene", ""))
    plugin = cls()
    params = cls.params(**case.get("params", {}))
    outputs, runs = {}, {}
    for level in QUALITY_LEVELS:
        ctx = case_context(rt, case, level)
        window = ctx.source.window
        reason = plugin.is_identity(params, ctx)

        def run(ctx=ctx, reason=reason):
            if reason:
                return ctx.source
            # a new step each run: its plan is built (and timed) every time, as in a look
            img = plugin.render(rt, params, ctx.for_step(level))
            rt.finish()
            return img

        runs[level] = run
        img, times = timed(run, repeat)
        outputs[level] = crop_to(rt.download(img), img.window, window)
        res.rows.append({"effect": res.effect, "quality": level, **stats(times),
                         "identity": reason or None})
    truth = case.get("truth")
    ref = np.asarray(truth, np.float64) if truth is not None else outputs["reference"].astype(np.float64)
    res.reference_kind = "ground truth" if truth is not None else "reference level"
    edge = case.get("edge_mask")
    if edge is None and truth is not None and (case.get("depth") is not None or case.get("velocity") is not None):
        edge = edge_band(case.get("depth"), case.get("velocity"), EDGE_BAND_PX)
    ref_ms = next(r["ms"] for r in res.rows if r["quality"] == "reference")
    # Noise-like effects compare statistics, not pixels: a module may supply its own metric.
    metric = spec.metrics or (lambda out, ref_, c: error_metrics(out, ref_, edge))
    if spec.metrics is not None:
        res.metric = ((spec.metrics.__doc__ or "").strip().splitlines() or [""])[0] + \
            f" ({spec.metrics.__module__}.{spec.metrics.__name__})"
    for row in res.rows:
        row.update(metric(outputs[row["quality"]], ref, case))
        row["speedup_vs_reference"] = ref_ms / row["ms"] if row["ms"] > 0 else None
        row["reference"] = res.reference_kind
    ref_err = next(r for r in res.rows if r["quality"] == "reference")["rel_rmse"]
    for row in res.rows:
        row["error_ratio_vs_reference"] = (row["rel_rmse"] / ref_err) if ref_err > 0 else None
    peer_ctx = case_context(rt, case, "final")
    res.baselines = _baselines(case, params, peer_ctx, ref, repeat, res.effect,
                               spec.naive, lambda out, ref_: metric(out, ref_, case))
    _flag_levels(res)
    peers = spec.peers
    for label, peer_fn in ((peers(case, params, peer_ctx) if peers else None) or {}).items():
        fn, level = peer_fn if isinstance(peer_fn, tuple) else (peer_fn, "final")
        mine_run = runs[level]          # a level the effect lacks is the case's bug: raise
        try:
            out, times, mine_times = timed_pair(fn, mine_run, repeat)
        except Exception as exc:  # a peer missing on this machine is reported, not fatal
            res.peers.append({"effect": res.effect, "peer": label, "error": str(exc)})
            continue
        peer = {"effect": res.effect, "peer": label, **stats(times), **metric(out, ref, case)}
        mine = next(r for r in res.rows if r["quality"] == level)
        peer["clfx_level"] = level
        peer["clfx_ms"] = float(np.median(mine_times))   # the level's runs between the peer's
        peer["clfx_rel_rmse"] = mine["rel_rmse"]
        peer["clfx_psnr_log"] = mine.get("psnr_log")
        ratios = [a / b for a, b in zip(mine_times, times) if b > 0]
        peer["clfx_time_ratio"] = float(np.median(ratios)) if ratios else None
        res.peers.append(peer)
    return res


def _baselines(case, params, ctx, ref, repeat: int, label: str, naive, score) -> list[dict]:
    """The unchanged input's row and the ``naive`` method's row (when the case declares one),
    scored against ``ref`` like the levels: ``score(out, ref)`` is the levels' metric."""
    window = ctx.source.window
    src = np.asarray(case["source"], np.float32)
    rows = []
    if naive is not None:
        row = {"effect": label, "baseline": "naive", "label": naive.label}
        try:
            out, times = timed(naive.make(case, params, ctx), repeat)
        except Exception as exc:  # reported in the table, not fatal
            row["error"] = f"{type(exc).__name__}: {exc}"
        else:
            out = np.asarray(out)
            if out.shape[:2] != (window.height, window.width):
                row["error"] = f"naive output {out.shape} does not cover the window {window}"
            else:
                row.update(stats(times), **score(out, ref))
        rows.append(row)
    rows.append({"effect": label, "baseline": "input", "label": "unchanged input",
                 **score(src, ref)})
    for what, img in (case.get("peer_images") or {}).items():   # another tool's output
        rows.append({"effect": label, "baseline": "peer", "label": what,
                     **score(np.asarray(img, np.float32), ref)})
    return rows


def _flag_levels(res: EffectResult) -> None:
    """``beats_naive`` / ``beats_input`` (/ ``beats_peer``: every peer image of the case,
    e.g. Blender's Vector Blur) on every level row: True when its log-PSNR is higher than the
    baseline's, None when there is nothing to compare."""
    scores = {b["baseline"]: b.get("psnr_log") for b in res.baselines
              if "error" not in b and b["baseline"] != "peer"}
    peers = [b.get("psnr_log") for b in res.baselines if b["baseline"] == "peer" and "error" not in b]
    if peers:
        scores["peer"] = max(peers)
    for row in res.rows:
        for key, base in (("beats_naive", "naive"), ("beats_input", "input"), ("beats_peer", "peer")):
            theirs, mine = scores.get(base), row.get("psnr_log")
            row[key] = None if theirs is None or mine is None else bool(mine > theirs)
