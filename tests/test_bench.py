"""`clfx bench`: runs on a small size, error falls as quality rises, analysis skips what it should.

No wall-time assertions: timings are reported, never asserted.
"""
import json
import os

import numpy as np
import pytest
from click.testing import CliRunner

from clfx.bench import timing
from clfx.bench.effects import EffectResult, _flag_levels, bench_effect
from clfx.bench.looks import analysis_frames
from clfx.bench.metrics import error_metrics
from clfx.bench.report import losing_levels, markdown, summary_markdown
from clfx.bench.timing import SHORT_RUNS, timed_pair
from clfx.cli import cli
from clfx.core.plugin import QUALITY_LEVELS
from clfx.plugins import discover
from clfx.pipeline.presets import load_look

SIZE = (192, 108)  # large enough that each effect differs between levels (CoC, rings)
# Relative slack when comparing errors of neighbouring levels: two levels may be equally
# accurate (e.g. exact closed forms), and float32 round-off differs between code paths.
SLACK = 1.05
FLOOR = 1e-6


@pytest.fixture(scope="module")
def effect_results(rt):
    """Every effect's bench on the test size, each operation run once to warm up and once
    timed (no warm-up series, no `SHORT_RUNS`): these tests read errors and rows, never
    times, and the series were most of this fixture's minute (`timing` has its own tests
    below)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(timing, "WARMUP_SHORT_S", 0.0)
        return {name: bench_effect(rt, name, *SIZE, repeat=1) for name in discover()}


@pytest.mark.parametrize("name", sorted(discover()))
def test_every_effect_is_benchmarked(effect_results, name):
    res = effect_results[name]
    assert res.note == "", f"{name}: {res.note}"
    assert [r["quality"] for r in res.rows] == list(QUALITY_LEVELS)
    for r in res.rows:
        assert r["ms"] >= 0 and np.isfinite(r["rmse"])


@pytest.mark.parametrize("name", sorted(discover()))
def test_error_falls_monotonically_as_quality_rises(effect_results, name):
    # Error after the log tone map: linear RMSE of HDR frames is decided by a few lights.
    rows = {r["quality"]: r for r in effect_results[name].rows}
    errors = [rows[q].get("log_rmse", rows[q]["rel_rmse"]) for q in QUALITY_LEVELS]
    _assert_ordered(name, errors, SLACK, FLOOR)


def _assert_ordered(what: str, errors, slack: float, floor: float) -> None:
    """Each quality level's error (``errors`` in ``QUALITY_LEVELS`` order) is at most the
    cheaper level's times ``slack`` plus ``floor``."""
    for lo, hi, e_lo, e_hi in zip(QUALITY_LEVELS, QUALITY_LEVELS[1:], errors, errors[1:]):
        assert e_hi <= e_lo * slack + floor, f"{what}: {hi} error {e_hi:.4g} > {lo} error {e_lo:.4g}"


# Effects whose level table was fixed for a level that lost to a cheaper one (issue 35), on
# their bench case at the size the issue measured: lens_flare's preview (5 even wavelengths
# integrated the colour matching functions worse than draft's three primaries).
ORDERED_CASES = ["lens_flare"]


@pytest.mark.parametrize("name", ORDERED_CASES)
def test_bench_case_error_falls_level_by_level(rt, name):
    """Each level's error at most the cheaper one's (1 % slack), linear and after the log
    tone map; against a ground truth, final within 5 % of reference's error."""
    res = bench_effect(rt, name, 320, 180, repeat=1)
    rows = {r["quality"]: r for r in res.rows}
    for key in ("rel_rmse", "log_rmse"):
        errors = [rows[q][key] for q in QUALITY_LEVELS]
        _assert_ordered(f"{name} {key}", errors, 1.01, 1e-12)
        if res.reference_kind == "ground truth":   # else reference's error is 0 by definition
            assert errors[2] <= errors[3] * 1.05 + 1e-12, f"{name} {key}: final {errors[2]:.4g}"


def test_error_metrics():
    ref = np.ones((4, 4, 4))
    m = error_metrics(ref, ref)
    assert m["rmse"] == 0 and m["psnr_log"] == float("inf")
    worse = error_metrics(ref * 1.1, ref)
    assert worse["rel_rmse"] == pytest.approx(0.1) and np.isfinite(worse["psnr_log"])


def test_bench_cli_json_small(rt, tmp_path):
    r = CliRunner().invoke(cli, ["bench", "--size", "64x48", "--repeat", "1", "--effects", "vignette",
                                 "--looks", "default", "--sequence-frames", "2", "--json",
                                 "--markdown", str(tmp_path / "b.md")], catch_exceptions=False)
    assert r.exit_code == 0, r.output
    data = json.loads(r.stdout)
    assert data["effects"][0]["effect"] == "vignette" and data["looks"][0]["look"] == "default"
    assert data["sequence"]["frames"] == 2
    assert "| vignette | draft |" in (tmp_path / "b.md").read_text()


def test_scene_analysis_skips_what_frames_a_b_c_do_not_need(rt):
    """Frame (a) needs everything; (b) static, dim, in focus needs nothing spatial;
    (c) needs only motion blur, and only in the moving tiles."""
    from clfx.pipeline.look import render_frame
    from clfx.pipeline.presets import load_look

    look = load_look("cinema")
    frames = analysis_frames(256, 144, look.camera)
    ran = {}
    for key, frame in frames.items():
        _, report = render_frame(rt, look, frame, frame_number=1)
        ran[key] = {s.effect: s for s in report.steps}
    spatial = {"dof", "motion_blur", "glare", "streaks"}
    present = spatial & set(ran["a_needs_everything"])
    assert present == spatial, f"cinema look lacks {spatial - present}"
    assert all(ran["a_needs_everything"][e].ran for e in spatial)
    b = ran["b_static_dim_in_focus"]
    assert not any(b[e].ran for e in spatial), {e: b[e].reason for e in spatial}
    assert "velocity" in b["motion_blur"].reason and "threshold" in b["glare"].reason
    c = ran["c_small_region_moves"]
    assert c["motion_blur"].ran and not c["dof"].ran and not c["glare"].ran


def test_every_effect_reports_the_unchanged_input(effect_results):
    for name, res in effect_results.items():
        rows = [b for b in res.baselines if b["baseline"] == "input"]
        assert len(rows) == 1 and np.isfinite(rows[0]["rmse"]), name
        assert all(r["beats_input"] in (True, False) for r in res.rows), name


def test_distortion_levels_beat_its_naive_method_and_the_input(effect_results):
    res = effect_results["distortion"]
    assert [b["baseline"] for b in res.baselines] == ["naive", "input"]
    assert "bilinear remap on the exact map" in res.baselines[0]["label"]
    assert res.reference_kind == "ground truth"
    for r in res.rows:
        assert r["beats_naive"] is True and r["beats_input"] is True, r
    text = markdown({"size": list(SIZE), "repeat": 1, "device": "test",
                     "effects": [res.as_dict()], "looks": []})
    assert "| distortion | naive: bilinear remap on the exact map" in text
    assert "| distortion | input: unchanged input |" in text
    assert "| distortion | final |" in text and "| yes / yes |" in text


def test_case_variants_are_benchmarked_under_their_own_name(rt):
    res = bench_effect(rt, "distortion", 96, 54, repeat=1, variant="moustache")
    assert res.effect == "distortion:moustache" and len(res.rows) == len(QUALITY_LEVELS)
    assert all(r["effect"] == "distortion:moustache" for r in res.rows)


def test_a_peer_and_its_level_are_timed_run_for_run():
    """The timed runs of a peer and of the level it is compared with alternate (warm-ups
    before), so drift on a shared machine reaches both and every run follows one of the
    other; short operations get SHORT_RUNS each."""
    calls = []
    out, peer, level = timed_pair(lambda: calls.append("peer") or "P",
                                   lambda: calls.append("level"), repeat=3)
    assert out == "P" and len(peer) == len(level) == SHORT_RUNS
    assert calls[-2 * SHORT_RUNS:] == ["peer", "level"] * SHORT_RUNS
    first_level = calls.index("level")
    assert calls[:first_level] == ["peer"] * first_level and first_level >= 4   # warm-ups


def test_peer_rows_time_the_level_beside_the_peer(rt, monkeypatch):
    """Each peer is paired with the run of the level it names (the run's context says which)."""
    import clfx.bench.effects as effects

    paired = []

    def spy(fn, other, repeat):
        paired.append(other.__defaults__[0].quality)     # run(ctx=..., reason=...)
        return real(fn, other, repeat)

    real = effects.timed_pair
    monkeypatch.setattr(effects, "timed_pair", spy)
    res = bench_effect(rt, "distortion", 96, 54, repeat=1)
    rows = {p["peer"]: p for p in res.peers}
    assert {"cv2.remap bilinear", "cv2.remap cubic", "cv2.remap lanczos4"} <= set(rows)
    assert paired == [p["clfx_level"] for p in res.peers]
    assert paired[:3] == ["draft", "preview", "final"]
    for p in rows.values():
        assert p["clfx_ms"] > 0 and p["clfx_time_ratio"] > 0
        level = next(r for r in res.rows if r["quality"] == p["clfx_level"])
        assert p["clfx_rel_rmse"] == level["rel_rmse"]


def test_a_level_that_loses_to_a_baseline_is_flagged():
    res = EffectResult("demo", rows=[{"quality": q, "psnr_log": p, "ms": 1.0, "ms_min": 1.0,
                                      "ms_max": 1.0, "rel_rmse": 0.1}
                                     for q, p in zip(QUALITY_LEVELS, (20.0, 31.0, 32.0, 33.0))],
                       baselines=[{"baseline": "naive", "label": "plain", "psnr_log": 30.0},
                                  {"baseline": "input", "label": "unchanged input", "psnr_log": 25.0}])
    _flag_levels(res)
    assert [r["beats_naive"] for r in res.rows] == [False, True, True, True]
    assert [r["beats_input"] for r in res.rows] == [False, True, True, True]
    assert losing_levels(res.as_dict()) == ["draft loses to the naive and the input"]
    summary = summary_markdown({"effects": [res.as_dict()]})
    assert "30.0 / 25.0" in summary and "NO / NO (draft loses to the naive and the input)" in summary


def _grain_levels(rt, width, height, size):
    """The grain bench case at ``width`` x ``height`` with grain ``size`` (px at 2K), and
    each level's output over its window."""
    from clfx.bench.cases.grain import make
    from clfx.bench.cases.shared import case_context
    from clfx.core.frame import crop_to

    case = make(width, height, np.random.default_rng(1))
    case["params"]["size"] = size
    cls = discover()["grain"]
    plugin, p = cls(), cls.params(**case["params"])
    outs = {}
    for q in QUALITY_LEVELS:
        ctx = case_context(rt, case, q)
        img = plugin.render(rt, p, ctx)
        outs[q] = crop_to(rt.download(img), img.window, ctx.source.window)
    return case, outs


def test_grain_is_scored_by_its_statistics_not_its_pixels(rt):
    """Draft's white noise has the right strength but not the grain size: it scores between
    no grain (the input, 0 dB) and the filtered levels; the reference against itself is
    exact.  Size 20 px at 2K is a grain of ~1 px at 96 px wide (at the nominal size it is
    nearly white there, and draft nearly right)."""
    from clfx.bench.cases.grain import CASE, grain_statistics_metrics

    assert CASE.metrics is grain_statistics_metrics
    case, outs = _grain_levels(rt, 96, 64, size=20.0)
    ref = outs["reference"].astype(np.float64)
    m = {q: grain_statistics_metrics(outs[q], ref, case) for q in QUALITY_LEVELS}
    none = grain_statistics_metrics(case["source"], ref, case)
    assert none["rel_rmse"] == pytest.approx(1.0) and none["psnr_log"] == pytest.approx(0.0, abs=1e-9)
    assert m["reference"]["rel_rmse"] == 0 and m["reference"]["psnr_log"] == float("inf")
    for q in QUALITY_LEVELS:
        assert m[q]["psnr_log"] > none["psnr_log"], (q, m[q])
        assert m[q]["blocks"] > 0 and np.isfinite(m[q]["rmse"]) and np.isfinite(m[q]["max_err"])
    for q in ("preview", "final"):
        assert m[q]["psnr_log"] > m["draft"]["psnr_log"] + 20, (q, m[q], m["draft"])
    assert 0.1 < m["draft"]["rel_rmse"] < 0.9 and m["draft"]["acf_err"] > 0.1


def test_grain_bench_scores_the_input_by_the_same_statistics(rt):
    res = bench_effect(rt, "grain", 96, 64, repeat=1)
    (inp,) = [b for b in res.baselines if b["baseline"] == "input"]
    assert inp["rel_rmse"] == pytest.approx(1.0) and "std_rel_err" in inp
    assert all(r["beats_input"] is True and "acf_err" in r for r in res.rows), res.rows
    assert losing_levels(res.as_dict()) == []
    text = markdown({"size": (96, 64), "repeat": 1, "device": "test",
                     "effects": [res.as_dict()]})
    assert "- grain: Score a grain output by its statistics" in text   # the table says so


def test_case_modules_import_only_the_shared_helpers():
    """A case module imports the case protocol, the shared helpers (`clfx.bench.cases.shared`,
    ``metrics``, ``cache``, ``scene``, ``groundtruth``, ``cycles``) and the library, never the
    bench's drivers (``runner``, ``effects``, ``looks``) nor another case module."""
    import ast
    from pathlib import Path

    from clfx.bench import cases

    drivers = {"clfx.bench.runner", "clfx.bench.effects", "clfx.bench.looks",
               "clfx.bench.report", "clfx.bench.plots", "clfx.bench.timing"}
    folder = Path(cases.__file__).parent
    effects = {p.stem for p in folder.glob("*.py")} - {"__init__", "shared"}
    bad = []
    for path in sorted(folder.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            else:
                continue
            for name in names:
                if name in drivers or (name.startswith("clfx.bench.cases.")
                                       and name.split(".")[3] in effects):
                    bad.append(f"{path.name}:{node.lineno} imports {name}")
    assert not bad, bad
    assert {"distortion", "motion_blur", "dof"} <= effects   # the check sees the modules


def test_bench_sequence_says_where_each_frames_time_and_cpu_went(rt, tmp_path):
    """Issue 37: read, upload, every step (its host share), download and write, each with
    wall and CPU ms alone and in the stream, and the stream's ratio to its I/O alone."""
    r = CliRunner().invoke(cli, ["bench", "--size", "64x48", "--repeat", "1", "--effects", "none",
                                 "--looks", "default", "--sequence-frames", "2", "--json",
                                 "--markdown", str(tmp_path / "b.md")], catch_exceptions=False)
    assert r.exit_code == 0, r.output
    seq = json.loads(r.stdout)["sequence"]
    parts = [row["part"] for row in seq["rows"]]
    steps = [s.id for s in load_look("default").steps]
    assert parts == ["read", "upload", *steps, "download", "write", "read + write",
                     "look (device)"]
    for row in seq["rows"]:
        assert row["alone_cpu_ms"] is not None and row["alone_cpu_ms"] >= 0, row
    for row in seq["rows"][2:-4]:
        assert row["host_ms"] is not None and row["host_ms"] <= row["stream_ms"] + 1e-6, row
    assert seq["io_ms"] > 0 and seq["stream_vs_io"] == pytest.approx(seq["ms_per_frame"] / seq["io_ms"])
    assert seq["stream_cpu_vs_io"] == pytest.approx(seq["cpu_ms_per_frame"] / seq["io_cpu_ms"])
    rows = {row["part"]: row for row in seq["rows"]}
    # a read and the write beside it share the codec threads: their CPU in the stream is
    # one figure (each used to hold the other's), the stream's less its renders'
    assert rows["read"]["stream_cpu_ms"] is None and rows["write"]["stream_cpu_ms"] is None
    both = rows["read + write"]
    assert both["alone_cpu_ms"] == pytest.approx(rows["read"]["alone_cpu_ms"]
                                                 + rows["write"]["alone_cpu_ms"])
    assert both["stream_cpu_ms"] == pytest.approx(seq["io_cpu_in_stream_ms"])
    assert both["stream_cpu_ms"] < seq["cpu_ms_per_frame"]
    md = (tmp_path / "b.md").read_text()
    assert "| part | alone ms | in stream ms | in stream / alone | host ms |" in md
    assert "| upload |" in md and "| download |" in md


def test_bench_sequence_reads_alone_the_frames_it_streams(rt, monkeypatch):
    """Issue 37: "alone" and "stream" read the same files (it read the first frame only,
    which its page cache and one picture's compressibility favour)."""
    from clfx.bench.looks import bench_sequence
    from clfx.pipeline.plan import BatchPlan

    seen = []
    real = BatchPlan.read
    monkeypatch.setattr(BatchPlan, "read", lambda self, job: seen.append(
        os.path.basename(job.input)) or real(self, job))
    seq = bench_sequence(rt, "default", 32, 24, frames=3, repeat=4)
    assert seq["frames"] == 3
    streamed = {f"in.{i:04d}.exr" for i in (1, 2, 3)}
    alone = seen[1:3] + seen[6:]     # after the warm-up: two before the stream, two after
    assert len(seen) == 8 and set(alone) == streamed, seen


def test_pareto_plot_is_one_panel_per_family_with_naive_and_input_marked(tmp_path):
    """Issue 37: small multiples per effect family, not every effect on one chart."""
    from clfx.bench.plots import pareto_figure, pareto_plot

    def effect(name, naive=True):
        rows = [{"quality": q, "ms": 10.0 * (i + 1), "rel_rmse": 0.1 / (i + 1)}
                for i, q in enumerate(("draft", "preview", "final"))]
        rows.append({"quality": "reference", "ms": 99.0, "rel_rmse": 0.0})
        base = [{"baseline": "input", "rel_rmse": 0.5}]
        if naive:
            base.insert(0, {"baseline": "naive", "ms": 50.0, "rel_rmse": 0.2})
        return {"effect": name, "rows": rows, "baselines": base}

    results = {"size": [64, 48], "effects": [effect("glare"), effect("streaks", naive=False),
                                             effect("distortion:moustache"), effect("grain")]}
    fig = pareto_figure(results)
    panels = {ax.get_title(): ax for ax in fig.axes if ax.get_visible()}
    assert set(panels) == {"Glare", "Lens", "Film"}
    lens = panels["Lens"]     # glare is a lens effect (its descriptor's group)
    assert sorted(t.get_text() for t in lens.get_legend().get_texts()) == \
        ["distortion:moustache", "glare"]
    assert [t.get_text() for t in panels["Glare"].get_legend().get_texts()] == ["streaks"]
    hollow = [ln for ln in panels["Glare"].lines if ln.get_markerfacecolor() == "none"]
    assert hollow == []           # streaks has no naive method here
    hollow = [ln for ln in lens.lines if ln.get_markerfacecolor() == "none"]
    assert len(hollow) == 2 and list(hollow[0].get_xydata()[0]) == [50.0, 0.2]  # naive
    dotted = [ln for ln in lens.lines if ln.get_linestyle() == ":"]
    assert len(dotted) == 2 and all(ln.get_ydata()[0] == 0.5 for ln in dotted)  # input
    pareto_plot(results, str(tmp_path / "p.png"))
    assert (tmp_path / "p.png").stat().st_size > 0
