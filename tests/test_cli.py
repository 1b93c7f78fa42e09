"""The command line on real files: render, apply, probe, listings, bad input, interrupts."""
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from clfx.cli import cli
from tests.clirun import run

BEACH = "Beachball/singlepart.{:04d}.exr"


def one_line_error(result, *fragments):
    err = result.stderr.strip()
    assert err.startswith("clfx: error:") and "\n" not in err, err
    for f in fragments:
        assert f in err, err
    return err


def no_temp_files(folder: Path):
    return [p.name for p in folder.iterdir() if ".tmp" in p.name]


# -- listings -----------------------------------------------------------------------------
def test_devices_marks_the_device_in_use(rt):
    out = run("devices").stdout
    assert out.count("* [") == 1 and "in use" in out


def test_devices_with_impossible_selector_fails_naming_the_fix():
    r = run("--device", "nonexistent-device", "devices", code=1)
    one_line_error(r, "pocl-opencl-icd")


def test_plugins_describe_looks_and_look_show():
    assert "vignette" in run("plugins").stdout
    d = json.loads(run("describe", "vignette", "--json").stdout)
    assert d["name"] == "vignette" and set(d["quality"]) == {"draft", "preview", "final", "reference"}
    assert "quality levels:" in run("describe", "vignette").stdout
    assert "default" in run("looks").stdout
    shown = json.loads(run("look", "show", "default", "--json").stdout)
    assert shown["name"] == "default" and shown["effects"]
    one_line_error(run("describe", "vignete", code=1), "did you mean 'vignette'")


def test_probe_beachball(exr_images):
    out = run("probe", exr_images / BEACH.format(1)).stdout
    assert "depth: Z" in out and "forward" in out and "2048x1556" in out


# -- render / apply on real files ------------------------------------------------------------
def test_render_beachball_sequence_keeps_windows_and_resumes(rt, small_beachball, tmp_path):
    from clfx.io.read import read_frame

    # three of Beachball's frames (decimated by 4: tests/plates.py), a sequence of their own:
    # the render finds them on disk (2-4) as it finds all eight
    pattern = small_beachball.pattern("singlepart", (2, 3, 4))
    out = tmp_path / "out.#.exr"
    r = run("render", pattern, out, "--look", "default", "--json")
    lines = [json.loads(line) for line in r.stdout.splitlines()]
    assert [rec["frame"] for rec in lines[:-1]] == [2, 3, 4]
    assert lines[-1]["summary"] and lines[-1]["frames"] == 3
    written = sorted(tmp_path.glob("out.*.exr"))
    assert len(written) == 3 and not no_temp_files(tmp_path)
    src = read_frame(small_beachball.path("singlepart", 3))
    dst = read_frame(tmp_path / "out.0003.exr")
    # the display window is kept; the data window grows where motion blur and depth of field
    # spread light past the tight source window (never past the display window)
    assert dst.display_window == src.display_window
    assert dst.data_window.union(src.data_window) == dst.data_window != src.data_window
    assert dst.display_window.union(dst.data_window) == dst.display_window
    assert dst.metadata.get("clfx:look") == "default"
    # an existing output is refused, --skip-existing resumes, --frames subsets
    one_line_error(run("render", pattern, out, code=1), "exists", "--overwrite")
    (tmp_path / "out.0003.exr").unlink()
    r = run("render", pattern, out, "--skip-existing", "--json")
    assert [json.loads(x)["frame"] for x in r.stdout.splitlines()[:-1]] == [3]
    r = run("render", pattern, tmp_path / "sub.#.exr", "--frames", "2-4x2", "--json")
    assert [json.loads(x)["frame"] for x in r.stdout.splitlines()[:-1]] == [2, 4]


def test_frame_alone_equals_frame_in_batch(rt, small_beachball, tmp_path):
    from clfx.io.read import read_frame

    pattern = small_beachball.pattern("singlepart", (2, 3))
    run("render", pattern, tmp_path / "batch.#.exr", "--frames", "2-3", "--float")
    run("render", small_beachball.path("singlepart", 3), tmp_path / "alone.exr", "--float")
    a = read_frame(tmp_path / "batch.0003.exr").rgba
    b = read_frame(tmp_path / "alone.exr").rgba
    assert np.array_equal(a, b)


def test_apply_one_effect_on_exr_and_png(rt, small_beachball, tmp_path):
    from clfx.io.read import read_frame

    run("apply", "vignette", small_beachball.path("singlepart", 1), tmp_path / "v.exr",
        "amount=0.5")
    run("apply", "vignette", tmp_path / "v.exr", tmp_path / "v.png", "amount=0.2", "roundness=0")
    png = read_frame(tmp_path / "v.png")
    assert png.display_referred and png.rgba.shape[2] == 4
    run("apply", "vignette", tmp_path / "v.png", tmp_path / "v2.png", "amount=0.2")
    one_line_error(run("apply", "vignette", tmp_path / "v.exr", tmp_path / "x.exr", "amout=1", code=1),
                   "did you mean 'amount'")
    one_line_error(run("apply", "vignette", tmp_path / "v.exr", tmp_path / "x.exr", "amount=5", code=1),
                   "outside the allowed range")
    assert not (tmp_path / "x.exr").exists()


def test_explain_reports_skipped_effects(rt, small_beachball, tmp_path):
    r = run("render", small_beachball.path("singlepart", 1), tmp_path / "e.exr", "--explain",
            "--set", "vignette.amount=0", "--set", "vignette.natural=0")
    assert "skipped vignette" in r.stderr and "natural and amount are 0" in r.stderr


def test_input_is_never_overwritten(rt, exr_images, tmp_path):
    import shutil

    src = tmp_path / "in.exr"
    shutil.copy(exr_images / BEACH.format(1), src)
    before = src.read_bytes()
    one_line_error(run("render", src, src, "--overwrite", code=1), "never overwrites")
    assert src.read_bytes() == before


# -- bad input -------------------------------------------------------------------------------
def test_missing_file(tmp_path):
    one_line_error(run("render", tmp_path / "nope.exr", tmp_path / "o.exr", code=1), "nope.exr")


def test_missing_frames_named_or_skipped(rt, small_beachball, tmp_path):
    import shutil

    for f in (1, 2, 5):
        shutil.copy(small_beachball.path("singlepart", f), tmp_path / f"s.{f:04d}.exr")
    r = run("render", tmp_path / "s.#.exr", tmp_path / "o.#.exr", "--frames", "1-5", code=1)
    one_line_error(r, "missing", "3-4")
    assert not list(tmp_path.glob("o.*"))
    r = run("render", tmp_path / "s.#.exr", tmp_path / "o.#.exr", "--frames", "1-5",
            "--skip-missing", "--json")
    assert [json.loads(x)["frame"] for x in r.stdout.splitlines()[:-1]] == [1, 2, 5]


def test_bad_looks_from_the_cli(tmp_path, exr_images):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: bad\neffects:\n  - effect: vignette\n    params: {amount: 9}\n")
    r = run("render", exr_images / BEACH.format(1), tmp_path / "o.exr", "--look", bad, code=1)
    one_line_error(r, f"{bad}:4", "params.amount")
    bad.write_text("name: bad\neffects: [\n")
    one_line_error(run("render", exr_images / BEACH.format(1), tmp_path / "o.exr", "--look", bad, code=1),
                   "malformed YAML")
    one_line_error(run("render", exr_images / BEACH.format(1), tmp_path / "o.exr", "--look", "nolook", code=1),
                   "unknown look")
    one_line_error(run("render", exr_images / BEACH.format(1), tmp_path / "o.exr",
                       "--set", "glaare.size=1", code=1), "has no effect 'glaare'")
    assert not (tmp_path / "o.exr").exists()


def test_unwritable_output_folder(exr_images, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    r = run("render", exr_images / BEACH.format(1), blocker / "o.exr", code=1)
    one_line_error(r, str(blocker))


def test_every_damaged_file_is_rejected_cleanly(rt, exr_images, tmp_path):
    damaged = sorted((exr_images / "Damaged").iterdir())
    damaged = [p for p in damaged if p.suffix != ".rst"]
    assert len(damaged) > 100
    for path in damaged:
        r = run("render", path, tmp_path / "o.exr", code=1)
        one_line_error(r, path.name)
    assert not list(tmp_path.iterdir())


def test_usage_error_exit_code_2():
    run("render", code=2)
    run("nosuchcommand", code=2)


@pytest.mark.parametrize("args, fragments", [
    (["gallery", "out", "--only", "vignete"], ["--only", "unknown effect or look 'vignete'",
                                               "did you mean 'vignette'"]),
    (["bench", "--looks", "cinma"], ["--looks", "unknown look 'cinma'"]),
    (["render", "a.exr", "b.exr", "--velocity-channels", "u"], ["--velocity-channels",
                                                                "two channel names"]),
    (["render", "a.exr", "b.exr", "--device", "0:0"], ["--device goes before the command"]),
])
def test_usage_errors_are_one_line_before_anything_runs(tmp_path, monkeypatch, args,
                                                        fragments):
    """Checked before anything renders or measures (a bad --only rendered the whole gallery,
    a bad --looks ran every effect's bench first): one ``clfx: error:`` line, exit 2."""
    monkeypatch.chdir(tmp_path)   # the gallery's relative ``out`` lands here if it is made
    r = CliRunner().invoke(cli, args, catch_exceptions=False)
    assert r.exit_code == 2, r.output
    one_line_error(r, *fragments)
    assert not (tmp_path / "out").exists()


def test_progress_counts_elapsed_time_from_the_start_of_the_render():
    """The elapsed time includes device set-up and the first frame (it started when the first
    frame was done); frames per second count from the first frame's start."""
    from types import SimpleNamespace

    from clfx.cli import _Progress

    now = [100.0]
    bar = _Progress(clock=lambda: now[0])
    try:
        now[0] = 130.0                      # set-up, then a first frame of 2.5 s
        bar(1, 10, SimpleNamespace(total_ms=2000.0, read_ms=500.0))
        assert bar.bar.tasks[0].fields["elapsed"] == "0:30"
        now[0] = 132.5
        bar(2, 10, SimpleNamespace(total_ms=2000.0, read_ms=500.0))
        task = bar.bar.tasks[0]
        assert task.fields["elapsed"] == "0:32" and task.fields["fps"] == "0.40 fps"
        now[0] = 3800.0
        bar(3, 10, None)                    # a failed frame (a cluster's): no report
        assert bar.bar.tasks[0].fields["elapsed"] == "1:01:40"
    finally:
        bar.close()


# -- interrupts ------------------------------------------------------------------------------
@pytest.mark.parametrize("sig, code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_a_signal_leaves_no_partial_file(rt, exr_images, tmp_path, sig, code):
    """SIGTERM exits 143 and SIGINT (Ctrl-C) 130, with every file present complete and no
    temp file left: the signal comes while the first 2K frame is being written (its temp
    file is there; waiting for the first output, it came between writes)."""
    pattern = str(exr_images / "Beachball" / "singlepart.#.exr")
    env = dict(os.environ)
    proc = subprocess.Popen([sys.executable, "-m", "clfx.cli", "render", pattern,
                             str(tmp_path / "o.#.exr"), "--float", "--compression", "zip"],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.time() + 60
    while time.time() < deadline and proc.poll() is None and not no_temp_files(tmp_path):
        time.sleep(0.002)
    assert no_temp_files(tmp_path), "no frame was caught being written"
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode in (code, 0), err  # 0 only if it finished before the signal
    assert not no_temp_files(tmp_path), err
    from clfx.io.read import read_frame

    for p in tmp_path.glob("o.*.exr"):
        read_frame(p)  # every file present is complete


def test_demo_writes_frames_previews_and_contact_sheet(rt, tmp_path):
    r = run("demo", tmp_path / "demo", "--frames", "3", "--size", "160x90", "--json")
    summary = json.loads(r.stdout.splitlines()[-1])
    assert summary["frames"] == 3
    names = sorted(p.name for p in (tmp_path / "demo").iterdir())
    for f in (1, 2, 3):
        assert f"demo.{f:04d}.exr" in names and f"demo.{f:04d}.png" in names
        assert f"scene.{f:04d}.exr" in names
    assert "contact_sheet.png" in names
    from clfx.io.read import read_frame

    scene = read_frame(tmp_path / "demo" / "scene.0002.exr")
    assert scene.depth is not None and scene.velocity is not None
    # the look ran over the float scene files (render_stream) and wrote half, as before
    out = read_frame(tmp_path / "demo" / "demo.0002.exr")
    assert scene.bit_depth == "float" and out.bit_depth == "half"
    assert out.metadata.get("clfx:quality") == "final"     # stamped like `clfx render`


def test_radial_depth_uses_the_look_camera_focal_length(rt, tmp_path):
    """--depth-mode distance converts radial distance to planar z with f_px from the look."""
    from clfx.core.frame import Frame
    from clfx.io.read import read_frame
    from clfx.io.write import write_frame

    h, w = 20, 40
    cam_f_px = 50.0 * w / 36.0  # the default look's 50 mm on a 36 mm sensor
    ys, xs = np.mgrid[0:h, 0:w] + 0.5
    planar = np.full((h, w), 4.0, np.float32)
    radial = planar * np.sqrt(1 + ((xs - w / 2) ** 2 + (ys - h / 2) ** 2) / cam_f_px ** 2)
    texture = np.random.default_rng(5).uniform(0, 1, (h, w, 4)).astype(np.float32)
    texture[..., 3] = 1.0
    write_frame(Frame.from_array(texture, depth=radial.astype(np.float32)),
                tmp_path / "in.exr", bit_depth="float")

    def render(name, *focal):
        run("render", tmp_path / "in.exr", tmp_path / name, "--depth-mode", "distance",
            *focal, "--float", "--set", "glare.strength=0", "--set", "camera.focus_distance=0.2",
            "--set", "dof.max_coc=0.25")       # a CoC of a few px at 4 m on this tiny frame
        return read_frame(tmp_path / name)

    auto = render("out.exr")
    # the input's depth is written through as stored (radial) and reads back the same way
    np.testing.assert_array_equal(auto.depth, read_frame(tmp_path / "in.exr").depth)
    from clfx.io.read import PassSpec
    back = read_frame(tmp_path / "out.exr",
                      passes=PassSpec(depth_mode="distance", focal_length_px=cam_f_px))
    np.testing.assert_allclose(back.depth, planar, rtol=1e-5)
    # dof saw the planar depth of the look's focal length: the same pixels as giving it
    assert np.array_equal(auto.rgba, render("given.exr", "--focal-length-px", str(cam_f_px)).rgba)
    assert not np.array_equal(auto.rgba, render("wrong.exr", "--focal-length-px", "5").rgba)
    info = json.loads(run("probe", tmp_path / "in.exr", "--depth-mode", "distance",
                          "--focal-length-px", str(cam_f_px), "--json").stdout)
    assert info["depth"]["mode"] == "distance"


def test_raw_pipe_round_trip(rt):
    """`clfx render - - --raw WxH` reads ffmpeg gbrpf32le frames (planes G, B, R) from stdin
    and writes them to stdout: 3 frames in, 3 out, centre nearly unchanged by a vignette."""
    w, h = 64, 36
    frames = [np.stack([np.full((h, w), v, np.float32) for v in (0.2 * i, 0.1, 0.5)]) for i in range(3)]
    proc = subprocess.run([sys.executable, "-m", "clfx.cli", "-q", "render", "-", "-", "--look",
                           "wide-angle", "--raw", f"{w}x{h}"], input=b"".join(f.tobytes() for f in frames),
                          capture_output=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    out = np.frombuffer(proc.stdout, np.float32).reshape(3, 3, h, w)
    np.testing.assert_allclose(out[:, :, h // 2, w // 2], np.stack(frames)[:, :, h // 2, w // 2], rtol=3e-3)
    assert (out[:, 2, 0, 0] < out[:, 2, h // 2, w // 2]).all()  # corners darker (red plane)


def test_raw_pipe_needs_a_size():
    """A usage error (exit 2, as docs/reliability.md says), before anything is read."""
    r = run("render", "-", "-", code=2)
    assert "--raw WxH" in r.stderr
    # raw frames to files (issue 33): a sequence pattern, said before anything is read
    assert "has no frame token" in run("render", "-", "out.exr", "--raw", "4x4", code=1).stderr


def test_pass_options_are_declared_once_for_every_command():
    """render, apply and probe take the same pass options, with the same help (issue 9)."""
    from clfx.cli import apply, probe, render
    from clfx.pipeline.options import PassOptions

    def options(cmd):
        return {p.name: (p.opts, p.help, p.default) for p in cmd.params if p.name in PassOptions.names()}

    assert set(options(probe)) == set(PassOptions.names())
    assert options(render) == options(apply) == options(probe)
    run("render", "-", "-", "--depth-scale", "-1", code=2)
    run("probe", "x.exr", "--velocity-scale", "nan", code=2)


def test_batch_options_are_typed_and_its_state_declared(tmp_path):
    """RenderOptions is a frozen dataclass built by the CLI; Batch holds no attribute its
    dataclass does not declare, before or after prepare (issue 9)."""
    import dataclasses

    from clfx.pipeline.batch import Batch
    from clfx.pipeline.options import RenderOptions
    from clfx.pipeline.presets import load_look

    opts = RenderOptions(raw_size="8x4", quality="draft")
    with pytest.raises(dataclasses.FrozenInstanceError):
        opts.overwrite = True
    batch = Batch(load_look("wide-angle"), "-", "-", options=opts)
    declared = {f.name for f in dataclasses.fields(Batch)}
    assert set(vars(batch)) <= declared
    batch.prepare()
    assert set(vars(batch)) <= declared and batch.raw_size == (8, 4)


def test_cluster_progress_counts_frames_as_they_finish_and_agrees_with_the_summary(monkeypatch):
    """Issue 33: with --workers the bar jumped 0/4 -> 4/4 (frames were counted only as they
    were said in frame order) and said 1.06 fps against the summary's 0.36 (it timed from
    the first frame's own start, the summary from the end of the cluster's start-up).  Chunks
    finishing 3, 1, 2: the bar counts 1, 2, 3 as they finish; its frames per second count
    from when rendering began, as the summary's; the bar is gone before the summary."""
    from types import SimpleNamespace

    import clfx.pipeline.distributed as dist
    from clfx.cli import _Progress
    from clfx.pipeline.plan import Job
    from clfx.pipeline.look import FrameReport
    from clfx.pipeline.report import FrameResult, Reporter, ReportOptions

    now = [0.0]
    events = []

    class Bar(_Progress):
        def __call__(self, done, total, report):
            events.append(("bar", done))
            super().__call__(done, total, report)

        def close(self):
            events.append(("close",))
            super().close()

    jobs = [Job(f, f"i.{f}.exr", f"o.{f}.exr") for f in (1, 2, 3)]

    class Future:
        def __init__(self, i):
            self.i, self.status = i, "finished"

        def result(self):
            now[0] += 10.0                           # each chunk finishes 10 s after the last
            return [FrameResult(jobs[self.i].frame, report=FrameReport(jobs[self.i].frame))]

        def release(self):
            pass

    client = SimpleNamespace(loop=None, submit=lambda fn, shipped, a, b, *args, **kw: Future(a))
    monkeypatch.setattr(dist, "as_completed", lambda futures, loop=None: sorted(
        futures, key=lambda f: [2, 0, 1].index(f.i)))
    bar = Bar(clock=lambda: now[0])
    reporter = Reporter(SimpleNamespace(name="x", clips_used=lambda: set()),
                        ReportOptions(verbosity=1), on_frame=bar)
    monkeypatch.setattr(dist.time, "perf_counter", lambda: now[0])
    monkeypatch.setattr("clfx.pipeline.report.time.perf_counter", lambda: now[0])
    monkeypatch.setattr(reporter, "err", lambda line, end="\n": events.append(("say", line)))
    try:
        reporter.start(3)
        now[0] = 5.0                                 # the cluster's start-up
        reporter.rendering(5.0)
        dist._collect(reporter, client, None, jobs, [(0, 1), (1, 2), (2, 3)], False)
        assert [e[1] for e in events if e[0] == "bar"] == [1, 2, 3]
        assert bar.bar.tasks[0].fields["fps"] == "0.10 fps"          # 3 frames in 30 s
        summary = reporter.summary(cluster=dist.ClusterInfo(2, 1, None, 5.0))
        assert summary["fps"] == 0.1
        assert events[-2] == ("close",) and events[-1][0] == "say"   # the bar, then the line
    finally:
        bar.close()


def test_demo_contact_sheet_is_labelled_before_and_after(rt, tmp_path):
    """Issue 33: the demo's sheet had neither labels nor the input; now each frame's input
    (before) sits beside its output (after), each tile labelled with the frame and which."""
    import OpenImageIO as oiio

    from clfx.gallery import text_mask

    run("-q", "demo", tmp_path / "d", "--frames", "2", "--size", "160x90")
    inp = oiio.ImageInput.open(str(tmp_path / "d" / "contact_sheet.png"))
    sheet = np.asarray(inp.read_image("uint8"))
    inp.close()
    gap, tw, th = 4, 160, 90
    assert sheet.shape[:2] == (th + 2 * gap, 4 * (tw + gap) + gap)     # 2 frames x 2 tiles
    tiles = []
    for k, (frame, what) in enumerate([(1, "before"), (1, "after: default"),
                                       (2, "before"), (2, "after: default")]):
        x = gap + k * (tw + gap)
        tile = sheet[gap:gap + th, x:x + tw, :3]
        for row, text in ((1, f"frame {frame}"), (10, what)):
            mask = text_mask(text, 1)
            cut = tile[row:row + mask.shape[0], 1:1 + mask.shape[1]]
            assert np.all(cut[mask[:, :cut.shape[1]]] == 255), (k, text)   # the label, in white
        tiles.append(tile[20:].astype(int))
    assert np.abs(tiles[0] - tiles[1]).mean() > 1 and np.abs(tiles[2] - tiles[3]).mean() > 1
