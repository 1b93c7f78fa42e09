"""`clfx bench`: what accuracy costs in time, and what a scene calls for.

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

import math
import os
import tempfile
import time
from dataclasses import dataclass, field

import numpy as np

from clfx.bench import cases
from clfx.core.camera import Camera
from clfx.core.frame import Frame
from clfx.core.plugin import QUALITY_LEVELS
from clfx.core.frame import crop_to
from clfx.host import RenderContext
from clfx.pipeline.look import read_image_rgba, read_lens_dict
from clfx.plugins import discover
from clfx.core.rect import Rect


# -- metrics -----------------------------------------------------------------------------
def _rgb(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, np.float64)
    return a[..., :3] if a.ndim == 3 else a


def error_metrics(out: np.ndarray, ref: np.ndarray, edge: np.ndarray | None = None) -> dict:
    """RMSE / max in linear light, relative RMSE, RMSE and PSNR after log(1 + x) (what an
    eye sees of HDR errors: linear RMSE is dominated by the brightest pixels), edge-band RMSE."""
    o, r = _rgb(out), _rgb(ref)
    finite = np.isfinite(r)
    o = np.where(finite, np.nan_to_num(o, nan=1e30, posinf=1e30, neginf=-1e30), 0.0)
    r = np.where(finite, r, 0.0)
    diff = o - r
    rmse = float(np.sqrt(np.mean(diff ** 2))) if diff.size else 0.0
    rms_ref = float(np.sqrt(np.mean(r ** 2))) if r.size else 0.0
    lo, lr = np.log1p(np.maximum(o, 0)), np.log1p(np.maximum(r, 0))
    peak = max(float(lr.max()) if lr.size else 0.0, 1e-12)
    mse_log = float(np.mean((lo - lr) ** 2)) if lo.size else 0.0
    psnr = float("inf") if mse_log == 0 else 10 * math.log10(peak ** 2 / mse_log)
    m = {"rmse": rmse, "max_err": float(np.abs(diff).max()) if diff.size else 0.0,
         "rel_rmse": rmse / rms_ref if rms_ref > 0 else rmse, "psnr_log": psnr,
         "log_rmse": math.sqrt(mse_log)}
    if edge is not None and edge.any():
        m["edge_rmse"] = float(np.sqrt(np.mean(diff[edge] ** 2)))
    return m


WARMUP_SHORT_S = 0.1
"""Every measurement gets a second warm-up run; operations shorter than this keep warming up
for `WARMUP_S` (at least 2 more runs).  After a level's one-off set-up (seconds of host NumPy
for a map) the first runs of a millisecond kernel were 1.5-2.5x slower than the rest, for
a dozen runs at times (distortion draft at 1080p: 5.8, 8.8, 8.5, then 4.4-4.5 ms)."""

WARMUP_S = 0.25
"""Warm-up time of an operation shorter than `WARMUP_SHORT_S`: at most this, and at most 50
of its runs (50 runs of a 5 ms kernel; tiny test frames warm up for milliseconds)."""

SHORT_RUNS = 25
"""Timed runs of an operation shorter than `WARMUP_SHORT_S` (``repeat`` if more): on this
2-core PoCL machine a few-millisecond kernel takes one of two times: distortion draft at
1080p ~2.4 ms, or, in 10-25 % of runs and in spells, ~5-6 ms, its time on one PoCL thread
(5.0-5.1 ms with POCL_MAX_PTHREAD_COUNT=1); a median of 5 runs fell on either, the median
of 25 is the usual time (the slow runs show in the max)."""


def _warm(fn, repeat: int) -> tuple[object, int]:
    """Warm ``fn`` up; its last result and the number of timed runs it needs."""
    result = fn()  # warm-up: compiles kernels, builds plans and caches
    t0 = time.perf_counter()
    result = fn()
    once = time.perf_counter() - t0
    if once < WARMUP_SHORT_S:
        start, runs = time.perf_counter(), 0
        budget = min(WARMUP_S, 50 * once)
        while runs < 2 or time.perf_counter() - start < budget:
            result = fn()
            runs += 1
        repeat = max(repeat, SHORT_RUNS)
    return result, repeat


def _timed(fn, repeat: int) -> tuple[object, list[float]]:
    result, repeat = _warm(fn, repeat)
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = fn()
        times.append((time.perf_counter() - t0) * 1e3)
    return result, times


def _timed_pair(fn, other, repeat: int) -> tuple[object, list[float], list[float]]:
    """``fn`` and ``other`` timed alternately, run for run: ``fn``'s last result, its times
    and ``other``'s.  These shared machines drift (the same kernel 4.5 ms in one minute and
    5.8 ms in the next, with nothing else running here), so a peer timed a minute after the
    level it is compared with can win or lose on the drift alone; alternating exposes both
    to the same spells.  Every run follows one of the other (f o f o ...), as in a pipeline
    where each runs after other work: neither finds its own data left in the cache by its
    previous run.  (Distortion draft against cv2.remap bilinear at 1080p: 0.82-0.93 this
    way; 0.97-0.99 each run back to back in blocks of ten; 0.93-1.02 when the order also
    alternated, half the runs following their own.)"""
    result, n = _warm(fn, repeat)
    _, m = _warm(other, repeat)
    times, others = [], []
    for _ in range(max(n, m)):
        t0 = time.perf_counter()
        result = fn()
        t1 = time.perf_counter()
        other()
        t2 = time.perf_counter()
        times.append((t1 - t0) * 1e3)
        others.append((t2 - t1) * 1e3)
    return result, times, others


def _stats(times: list[float]) -> dict:
    return {"ms": float(np.median(times)), "ms_min": float(min(times)), "ms_max": float(max(times))}


# -- effects x levels --------------------------------------------------------------------
EDGE_BAND_PX = 4.0
"""Pixels within this distance of a depth or velocity discontinuity form the edge band."""

CACHE_VERSION = 1


def _case_cache_path(module, name: str, width: int, height: int, seed: int):
    """A cache file for a case with a costly ground truth, keyed by the sources that make it."""
    import hashlib
    import inspect

    from clfx.bench import groundtruth
    from clfx.bench import scene

    import importlib

    h = hashlib.sha1(f"{CACHE_VERSION}:{name}:{width}x{height}:{seed}".encode())
    depends = [importlib.import_module(m) for m in getattr(module, "TRUTH_DEPENDS", ())]
    for mod in (module, scene, groundtruth, *depends):
        h.update(inspect.getsource(mod).encode())
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "clfx", "bench", f"{name}-{width}x{height}-{h.hexdigest()[:12]}.pickle")


def load_case(module, spec: "cases.Case", name: str, width: int, height: int, seed: int = 1,
              variant: str | None = None) -> dict:
    """The effect's bench case (or one of its ``variants``); cases with a multisample
    ``truth`` are cached on disk (minutes to render at 1080p) and reused while their sources
    are unchanged."""
    import pickle

    maker = spec.maker(variant)
    if getattr(maker, "cached", True) is False:    # read from files: nothing to cache
        return maker(width, height, np.random.default_rng(seed))
    path = _case_cache_path(module, case_label(name, variant), width, height, seed)
    if os.path.exists(path):
        try:
            with open(path, "rb") as f:
                return pickle.load(f)
        except Exception:
            pass  # a damaged cache entry is rebuilt
    case = maker(width, height, np.random.default_rng(seed))
    if case.get("truth") is not None:
        os.makedirs(os.path.dirname(path), exist_ok=True)
        tmp = f"{path}.tmp-{os.getpid()}"
        with open(tmp, "wb") as f:
            pickle.dump(case, f, protocol=pickle.HIGHEST_PROTOCOL)
        os.replace(tmp, path)
    return case


def case_label(effect: str, variant: str | None = None) -> str:
    """``effect`` for the main case, ``effect:variant`` for a variant."""
    return effect if variant is None else f"{effect}:{variant}"


@dataclass
class EffectResult:
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


def _case_context(rt, case: dict, quality: str):
    src = np.asarray(case["source"], np.float32)
    window = case.get("data_window") or Rect.from_size(src.shape[1], src.shape[0])
    up = rt.upload(src, window)
    depth = rt.upload(np.asarray(case["depth"], np.float32), window) if case.get("depth") is not None else None
    vel = rt.upload(np.asarray(case["velocity"], np.float32), window) if case.get("velocity") is not None else None
    back = case.get("velocity_back")
    back = rt.upload(np.asarray(back, np.float32), window) if back is not None else None
    return RenderContext(rt, up, depth=depth, velocity=vel, velocity_back=back,
                         display_window=case.get("display_window") or window,
                         pixel_aspect=case.get("pixel_aspect", 1.0), frame=case.get("frame", 1),
                         seed=case.get("seed", 0), camera=case.get("camera") or Camera(),
                         quality=quality, display_referred=case.get("display_referred", False),
                         read_image=read_image_rgba, read_lens=read_lens_dict)


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
        ctx = _case_context(rt, case, level)
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
        img, times = _timed(run, repeat)
        outputs[level] = crop_to(rt.download(img), img.window, window)
        res.rows.append({"effect": res.effect, "quality": level, **_stats(times),
                         "identity": reason or None})
    truth = case.get("truth")
    ref = np.asarray(truth, np.float64) if truth is not None else outputs["reference"].astype(np.float64)
    res.reference_kind = "ground truth" if truth is not None else "reference level"
    edge = case.get("edge_mask")
    if edge is None and truth is not None and (case.get("depth") is not None or case.get("velocity") is not None):
        from clfx.bench.metrics import edge_band

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
    peer_ctx = _case_context(rt, case, "final")
    res.baselines = _baselines(case, params, peer_ctx, ref, repeat, res.effect,
                               spec.naive, lambda out, ref_: metric(out, ref_, case))
    _flag_levels(res)
    peers = spec.peers
    for label, peer_fn in ((peers(case, params, peer_ctx) if peers else None) or {}).items():
        fn, level = peer_fn if isinstance(peer_fn, tuple) else (peer_fn, "final")
        mine_run = runs[level]          # a level the effect lacks is the case's bug: raise
        try:
            out, times, mine_times = _timed_pair(fn, mine_run, repeat)
        except Exception as exc:  # a peer missing on this machine is reported, not fatal
            res.peers.append({"effect": res.effect, "peer": label, "error": str(exc)})
            continue
        peer = {"effect": res.effect, "peer": label, **_stats(times), **metric(out, ref, case)}
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
            out, times = _timed(naive.make(case, params, ctx), repeat)
        except Exception as exc:  # reported in the table, not fatal
            row["error"] = f"{type(exc).__name__}: {exc}"
        else:
            out = np.asarray(out)
            if out.shape[:2] != (window.height, window.width):
                row["error"] = f"naive output {out.shape} does not cover the window {window}"
            else:
                row.update(_stats(times), **score(out, ref))
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


def losing_levels(effect: dict) -> list[str]:
    """``level: loses to naive/input`` for every flagged level of an effect's results."""
    out = []
    for r in effect.get("rows", []):
        lost = [b for b, k in (("naive", "beats_naive"), ("input", "beats_input"),
                               ("peer", "beats_peer")) if r.get(k) is False]
        if lost:
            out.append(f"{r['quality']} loses to the {' and the '.join(lost)}")
    return out


def _yes_no(value) -> str:
    return "-" if value is None else ("yes" if value else "NO")


# -- looks -------------------------------------------------------------------------------
def _demo_frame(width: int, height: int, frame: int = 12) -> Frame:
    from clfx.bench.scene import demo_scene, render_sharp

    return render_sharp(demo_scene(frame, width, height))


def bench_look(rt, look_name: str, frame: Frame, repeat: int, quality: str | None = None) -> dict:
    """Milliseconds per frame of a look with a per-effect breakdown (median of runs)."""
    from clfx.pipeline.look import render_frame
    from clfx.pipeline.presets import load_look

    look = load_look(look_name)
    render_frame(rt, look, frame, frame_number=1, quality=quality)  # warm-up
    totals, per_effect = [], {}
    report = None
    for _ in range(repeat):
        _, report = render_frame(rt, look, frame, frame_number=1, quality=quality)
        totals.append(report.total_ms)
        for s in report.steps:
            per_effect.setdefault(s.effect, []).append(s.ms if s.ran else 0.0)
    return {"look": look_name, "quality": quality or "final", **_stats(totals),
            "effects": {k: round(float(np.median(v)), 2) for k, v in per_effect.items()},
            "skipped": {s.effect: s.reason for s in report.steps if not s.ran}}


def bench_io(frame: Frame, repeat: int) -> dict:
    """Reading and writing one frame as half-float EXR (zip), the floor of a frame's cost."""
    from clfx.io.read import read_frame
    from clfx.io.write import write_frame

    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "io.exr")
        write_frame(frame, path, overwrite=True)
        w, r = [], []
        for _ in range(max(repeat, 1)):
            t0 = time.perf_counter()
            write_frame(frame, path, overwrite=True)
            w.append((time.perf_counter() - t0) * 1e3)
            t0 = time.perf_counter()
            read_frame(path)
            r.append((time.perf_counter() - t0) * 1e3)
    return {"write_ms": float(np.median(w)), "read_ms": float(np.median(r)),
            "io_ms": float(np.median(w) + np.median(r))}


def bench_sequence(rt, look_name: str, width: int, height: int, frames: int,
                   repeat: int = 3) -> dict:
    """A stream as fast as its parts?  The look over ``frames`` EXR frames through `clfx
    render`'s batch pipeline (phased or overlapped, `clfx.pipeline.batch.stream_mode`), beside the same
    parts measured alone in the same run: the look on the first frame (per effect), reading
    a frame and writing its output (median of ``repeat`` warm runs each, half of them before
    the stream and half after).

    The inputs are the demo scene as a renderer writes it: float RGBA, depth and velocity, in
    the default EXR compression (`clfx.io.write`); outputs keep the input's type and
    compression.  The stream runs after the parts, so set-up (kernels, maps, spectra) is
    already done: this is the steady state.  ``stream_vs_parts`` (stream ms per frame over
    look + read + write alone) and the CPU seconds per frame do not depend on how loaded the
    machine is as much as milliseconds do: below 1 the overlap wins time, above 1 the
    parts slow each other down."""
    from clfx.bench.scene import demo_scene, render_sharp
    from clfx.io.write import write_frame
    from clfx.pipeline.batch import (Batch, RenderOptions, available_cores, codec_threads_for,
                                     io_threads, stream_mode)
    from clfx.pipeline.look import render_frame
    from clfx.pipeline.presets import load_look

    def timed(fn):
        c0, t0 = time.process_time(), time.perf_counter()
        out = fn()
        return out, (time.perf_counter() - t0) * 1e3, (time.process_time() - c0) * 1e3

    look = load_look(look_name)
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(1, frames + 1):
            write_frame(render_sharp(demo_scene(i, width, height)),
                        os.path.join(tmp, f"in.{i:04d}.exr"), bit_depth="float")
        batch = Batch(look=look, input_path=os.path.join(tmp, "in.####.exr"),
                      output_path=os.path.join(tmp, "out.####.exr"),
                      options=RenderOptions(overwrite=True), verbosity=0)
        batch.prepare()
        job = batch.jobs[0]
        alone = Batch(look=look, input_path=job.input,
                      output_path=os.path.join(tmp, "alone.exr"),
                      options=RenderOptions(overwrite=True), verbosity=0)
        alone.prepare()
        reads, renders, writes = [], [], []

        def parts(n):   # each part alone, with the codecs as the stream runs them
            with io_threads(codec_threads_for(rt)):
                reads.extend(timed(lambda: alone.plan.read(alone.jobs[0])) for _ in range(n))
                renders.extend(timed(lambda: render_frame(rt, look, read.views[0],
                                                          frame_number=job.frame))
                               for _ in range(n))
                out, report = renders[-1][0]
                writes.extend(timed(lambda: alone.plan.write(out, alone.jobs[0], report))
                              for _ in range(n))

        with io_threads(codec_threads_for(rt)):
            read = alone.plan.read(alone.jobs[0])
            render_frame(rt, look, read.views[0], frame_number=job.frame)  # warm-up
        parts(max(1, repeat // 2))     # half the runs before the stream, half after: a
        c0, t0 = time.process_time(), time.perf_counter()   # machine's load drifts
        summary = batch.run(rt)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        parts(max(1, repeat - repeat // 2))
    reports = summary["reports"]
    effects = [s.effect for s in renders[0][0][1].steps]

    def med(values):
        values = [v for v in values if v is not None]
        return float(np.median(values)) if values else None

    def step_ms(rep, effect):
        return next((s.ms if s.ran else 0.0 for s in rep.steps if s.effect == effect), None)

    rows = [{"part": e, "alone_ms": med([step_ms(r[0][1], e) for r in renders]),
             "stream_ms": med([step_ms(r, e) for r in reports])} for e in effects]
    rows += [{"part": "look (device)", "alone_ms": med([r[1] for r in renders]),
              "stream_ms": med([r.total_ms for r in reports])},
             {"part": "read", "alone_ms": med([r[1] for r in reads]),
              "stream_ms": med([r.read_ms for r in reports])},
             {"part": "write", "alone_ms": med([r[1] for r in writes]),
              "stream_ms": med([r.write_ms for r in reports])}]
    for r in rows:
        a, b = r["alone_ms"], r["stream_ms"]
        r["ratio"] = b / a if a and b is not None and a > 0.5 else None
    parts_ms = sum(r["alone_ms"] for r in rows[-3:])
    parts_cpu = sum(med([x[2] for x in xs]) for xs in (renders, reads, writes))
    ms_per_frame = 1e3 * wall / max(len(reports), 1)
    return {"look": look_name, "frames": len(reports), "fps": summary["fps"],
            "stream": stream_mode(rt, width * height),
            "ms_per_frame": ms_per_frame, "device_ms_mean": summary["device_ms_mean"],
            "parts_ms": parts_ms, "stream_vs_parts": ms_per_frame / parts_ms if parts_ms else None,
            "cpu_ms_per_frame": 1e3 * cpu / max(len(reports), 1), "parts_cpu_ms": parts_cpu,
            "cores": available_cores(),
            "load_avg": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
            "rows": rows}


def analysis_frames(width: int, height: int, camera: Camera) -> dict[str, Frame]:
    """Frames (a) needs everything, (b) static dim all-in-focus, (c) (b) with a moving patch."""
    a = _demo_frame(width, height)
    base = np.clip(a.rgba * 0.3, 0.0, 0.4).astype(np.float32)  # below every highlight knee
    base[..., 3] = 1.0
    depth = np.full((height, width), camera.focus_distance, np.float32)
    still = np.zeros((height, width, 2), np.float32)
    b = Frame.from_array(base, depth=depth, velocity=still)
    vel = still.copy()
    ph, pw = max(1, height // 5), max(1, width // 5)
    y0, x0 = height // 3, width // 3
    vel[y0:y0 + ph, x0:x0 + pw] = (12.0 * width / 1920 + 2.0, 0.0)
    c = Frame.from_array(base.copy(), depth=depth, velocity=vel)
    return {"a_needs_everything": a, "b_static_dim_in_focus": b, "c_small_region_moves": c}


def bench_analysis(rt, look_name: str, width: int, height: int, repeat: int) -> dict:
    from clfx.pipeline.presets import load_look

    look = load_look(look_name)
    frames = analysis_frames(width, height, look.camera)
    io = bench_io(frames["a_needs_everything"], repeat)
    out = {"look": look_name, **io, "frames": {}}
    for key, frame in frames.items():
        r = bench_look(rt, look_name, frame, repeat)
        r["vs_io"] = (r["ms"] + io["io_ms"]) / io["io_ms"] if io["io_ms"] > 0 else None
        out["frames"][key] = r
    return out


# -- reporting ---------------------------------------------------------------------------
def summary_markdown(results: dict) -> str:
    """One row per effect (and case variant): median ms and relative RMSE (vs the reference
    level or the ground truth) at each quality level, the log-PSNR of the naive method and of
    the unchanged input, and the levels that lose to either."""
    lines = ["| effect | " + " | ".join(QUALITY_LEVELS) + " | naive / input PSNR log (dB) | "
             "every level beats naive / input | error measured against |",
             "|---|" + "---|" * len(QUALITY_LEVELS) + "---|---|---|"]
    for e in results.get("effects", []):
        rows = {r["quality"]: r for r in e["rows"]}
        if not rows:
            lines.append(f"| {e['effect']} | {e['note']} |" + " |" * (len(QUALITY_LEVELS) + 2))
            continue
        cells = []
        for q in QUALITY_LEVELS:
            r = rows[q]
            err = r["rel_rmse"]
            baseline = q == "reference" and e["reference"] == "reference level"
            cells.append(f"{r['ms']:.0f} ms, " + ("baseline" if baseline else
                                                   "0" if err == 0 else f"{err:.1e}"))
        base = {b["baseline"]: b for b in e.get("baselines", [])}
        psnr = " / ".join(_psnr_cell(base.get(k)) for k in ("naive", "input"))
        flags = " / ".join(_all_yes(e["rows"], k) for k in ("beats_naive", "beats_input"))
        lost = losing_levels(e)
        lines.append(f"| {e['effect']} | " + " | ".join(cells) + f" | {psnr} | {flags}"
                     + (f" ({'; '.join(lost)})" if lost else "") + f" | {e['reference']} |")
    return "\n".join(lines) + "\n"


def _psnr_cell(row: dict | None) -> str:
    if row is None:
        return "-"
    if "error" in row:
        return "failed"
    return f"{row['psnr_log']:.1f}"


def _all_yes(rows: list[dict], key: str) -> str:
    values = [r.get(key) for r in rows]
    if all(v is None for v in values):
        return "-"
    return "NO" if any(v is False for v in values) else "yes"


def markdown(results: dict) -> str:
    lines = [f"clfx bench at {results['size'][0]}x{results['size'][1]}, {results['repeat']} warm "
             f"runs, device: {results['device']}", ""]
    if results.get("effects"):
        lines += ["Time per frame and relative RMSE of each quality level:", "",
                  summary_markdown(results), "Details (each effect's levels, then its naive "
                  "method and the unchanged input, scored against the same reference):", ""]
    if results.get("effects"):
        lines += ["| effect | level | ms (min-max) | speed-up vs ref | RMSE | max err | rel. RMSE | "
                  "PSNR log (dB) | edge RMSE | beats naive / beats input | reference |",
                  "|---|---|---|---|---|---|---|---|---|---|---|"]
        for e in results["effects"]:
            for r in e["rows"]:
                sp = r.get("speedup_vs_reference")
                flags = f"{_yes_no(r.get('beats_naive'))} / {_yes_no(r.get('beats_input'))}"
                lines.append(
                    f"| {r['effect']} | {r['quality']} | {r['ms']:.1f} ({r['ms_min']:.1f}-{r['ms_max']:.1f}) | "
                    f"{sp:.2f}x | {r['rmse']:.3g} | {r['max_err']:.3g} | {r['rel_rmse']:.3g} | "
                    f"{r['psnr_log']:.1f} | {r.get('edge_rmse', float('nan')):.3g} | {flags} | "
                    f"{r['reference']} |"
                    if sp else f"| {r['effect']} | {r['quality']} | identity | | | | | | | | |")
            for b in e.get("baselines", []):
                what = f"{b['baseline']}: {b['label']}"
                if "error" in b:
                    lines.append(f"| {b['effect']} | {what} | failed: {b['error']} | | | | | | | | |")
                    continue
                ms = f"{b['ms']:.1f} ({b['ms_min']:.1f}-{b['ms_max']:.1f})" if "ms" in b else "-"
                lines.append(
                    f"| {b['effect']} | {what} | {ms} | | {b['rmse']:.3g} | {b['max_err']:.3g} | "
                    f"{b['rel_rmse']:.3g} | {b['psnr_log']:.1f} | {b.get('edge_rmse', float('nan')):.3g} "
                    f"| | {e['reference']} |")
            notes = [f"- {e['effect']}: {e['metric']}" for e in results["effects"] if e.get("metric")]
        if notes:
            lines += ["", "Scored by the case's own metric (RMSE, max err, rel. RMSE and PSNR log "
                          "above are its quantities):", *notes]
        peers = [p for e in results["effects"] for p in e["peers"]]
        if peers:
            lines += ["", "Peers, each timed alternately with the clfx level it is compared with "
                          "(clfx ms: that level's median in those runs; clfx / peer time: the "
                          "median of the runs' ratios):",
                      "", "| effect | peer | peer ms | clfx level | clfx ms | clfx / peer time | "
                          "peer rel. RMSE | clfx rel. RMSE | peer / clfx PSNR log (dB) | peer max err |",
                      "|---|---|---|---|---|---|---|---|---|---|"]
            for p in peers:
                if "error" in p:
                    lines.append(f"| {p['effect']} | {p['peer']} | failed: {p['error']} | | | | | | | |")
                else:
                    lines.append(f"| {p['effect']} | {p['peer']} | {p['ms']:.1f} | {p['clfx_level']} | "
                                 f"{p['clfx_ms']:.1f} | {p['clfx_time_ratio']:.2f} | {p['rel_rmse']:.3g} | "
                                 f"{p['clfx_rel_rmse']:.3g} | {p['psnr_log']:.1f} / "
                                 f"{p.get('clfx_psnr_log', float('nan')):.1f} | {p['max_err']:.3g} |")
    lines += truth_markdown(results)
    if results.get("looks"):
        lines += ["", "| look | ms/frame (min-max) | per effect (ms) |", "|---|---|---|"]
        for lk in results["looks"]:
            per = ", ".join(f"{k} {v:.0f}" for k, v in lk["effects"].items())
            lines.append(f"| {lk['look']} | {lk['ms']:.0f} ({lk['ms_min']:.0f}-{lk['ms_max']:.0f}) | {per} |")
    if results.get("sequence"):
        lines += ["", *sequence_markdown(results["sequence"])]
    if results.get("analysis"):
        a = results["analysis"]
        lines += ["", f"What a scene calls for (look {a['look']}; EXR read {a['read_ms']:.0f} ms + "
                      f"write {a['write_ms']:.0f} ms = {a['io_ms']:.0f} ms):", "",
                  "| frame | device ms | (device + I/O) / I/O | skipped |", "|---|---|---|---|"]
        for k, r in a["frames"].items():
            skipped = "; ".join(f"{e}: {why}" for e, why in r["skipped"].items()) or "-"
            lines.append(f"| {k} | {r['ms']:.0f} | {r['vs_io']:.2f} | {skipped} |")
    return "\n".join(lines) + "\n"


def truth_markdown(results: dict) -> list[str]:
    """The cases rendered by a path tracer, one row each: log-PSNR (dB) of the input, the
    naive method, every peer image (Blender's Vector Blur), each level, and the truth's own
    noise floor (a second render with another seed, against the truth)."""
    cases = [e for e in results.get("effects", []) if e.get("truth_floor") is not None
             or str(e.get("scene", "")).startswith("cycles:")
             or any(b["baseline"] == "peer" for b in e.get("baselines", []))]
    if not cases:
        return []
    lines = ["", "Against a path tracer's render (log-PSNR dB; noise floor: the same render with "
                 "another seed, against the truth):", "",
             "| case | input | naive | peer | " + " | ".join(QUALITY_LEVELS)
             + " | noise floor | final beats input / naive / peer |",
             "|---|---|---|---|" + "---|" * len(QUALITY_LEVELS) + "---|---|"]
    for e in cases:
        base = {}
        for b in e.get("baselines", []):
            base.setdefault(b["baseline"], b)
        rows = {r["quality"]: r for r in e["rows"]}
        levels = " | ".join(f"{rows[q]['psnr_log']:.1f}" if q in rows and "psnr_log" in rows[q]
                            else "-" for q in QUALITY_LEVELS)
        floor = e.get("truth_floor")
        fin = rows.get("final", {})
        flags = " / ".join(_yes_no(fin.get(k)) for k in ("beats_input", "beats_naive", "beats_peer"))
        lines.append(f"| {e['effect']} | {_psnr_cell(base.get('input'))} | "
                     f"{_psnr_cell(base.get('naive'))} | {_psnr_cell(base.get('peer'))} | {levels} | "
                     f"{'-' if floor is None else f'{floor:.1f}'} | {flags} |")
    return lines


def sequence_markdown(s: dict) -> list[str]:
    """The sequence table: the stream end to end, then each part alone and in the stream."""
    def ms(v):
        return "-" if v is None else f"{v:.0f}"

    load = f", load average {s['load_avg']:.1f} on {s['cores']} cores" if s.get("load_avg") is not None else ""
    mode = f", {s['stream']} stream" if s.get("stream") else ""
    lines = [f"Sequence (look {s['look']}, {s['frames']} frames, EXR read and write included"
             f"{mode}{load}): {s['ms_per_frame']:.0f} ms/frame ({s['fps']} fps) end to end; the same "
             f"parts one after another take {s['parts_ms']:.0f} ms, so the stream takes "
             f"{s['stream_vs_parts']:.2f}x its parts' sum.  CPU time: {s['cpu_ms_per_frame']:.0f} ms "
             f"per frame in the stream, {s['parts_cpu_ms']:.0f} ms for the parts alone.", "",
             "| part | alone ms | in stream ms | in stream / alone |", "|---|---|---|---|"]
    for r in s["rows"]:
        ratio = "-" if r["ratio"] is None else f"{r['ratio']:.2f}x"
        lines.append(f"| {r['part']} | {ms(r['alone_ms'])} | {ms(r['stream_ms'])} | {ratio} |")
    return lines


def pareto_plot(results: dict, path: str) -> None:
    """Time vs relative error, one line per effect (needs matplotlib: the [plot] extra)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:
        from clfx.core.errors import ClfxError

        raise ClfxError("--plot needs matplotlib: pip install 'clfx[plot]'") from exc
    fig, ax = plt.subplots(figsize=(8, 5.5))
    styles = [(ls, m) for ls in ("-", "--", ":") for m in ("o", "s", "^", "D", "v", "P")]
    for i, e in enumerate(results["effects"]):
        # error 0 (a level identical to the reference, or the reference itself) has no place
        # on a log axis: such points are left out
        pts = [(r["ms"], r["rel_rmse"]) for r in e["rows"]
               if not r.get("identity") and r["rel_rmse"] > 0]
        if pts:
            xs, ys = zip(*pts)
            ls, m = styles[i % len(styles)]
            ax.plot(xs, ys, linestyle=ls, marker=m, label=e["effect"])
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("time per frame (ms)")
    ax.set_ylabel("relative RMSE vs reference level / ground truth\n(levels with error 0 not shown)")
    ax.set_title(f"clfx: what accuracy costs ({results['size'][0]}x{results['size'][1]})")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def run_bench(rt, *, effects=None, looks=None, width=1920, height=1080, repeat=5,
              sequence_frames=8, analysis=True, log=print) -> dict:
    reg = discover()
    effect_names = list(reg) if effects is None else list(effects)
    results = {"size": [width, height], "repeat": repeat, "device": rt.description,
               "effects": [], "looks": []}
    for name in effect_names:
        if name not in reg:
            from clfx.plugins import get_plugin

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
        from clfx.pipeline.presets import available_looks

        names = list(looks) if looks else [n for n, (o, _) in available_looks().items() if o == "built-in"]
        frame = _demo_frame(width, height)
        for n in names:
            results["looks"].append(bench_look(rt, n, frame, repeat))
            log(f"clfx bench: look {n} done")
        if sequence_frames:
            results["sequence"] = bench_sequence(rt, "cinema" if "cinema" in names else names[0],
                                                 width, height, sequence_frames, repeat)
        if analysis and ("cinema" in names):
            results["analysis"] = bench_analysis(rt, "cinema", width, height, repeat)
    return results
