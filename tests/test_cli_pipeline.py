"""A quiet, informative CLI (issue 13): compiler chatter kept off stderr, progress on a
terminal, usage errors exit 2, steps dropped or skipped from --set, wrong raw sizes caught
before anything is written, a lens table, reproducible outputs (--look-from), a demo that
keeps earlier files, --log."""
import json
import os
import pty
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from tests.clirun import run

ROOT = Path(__file__).resolve().parents[1]
CLFX = [sys.executable, "-m", "clfx.cli"]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


def small_sequence(folder: Path, frames=(1, 2), size=(24, 16)):
    from clfx.core.frame import Frame
    from clfx.io.write import write_frame

    w, h = size
    img = np.random.default_rng(0).uniform(0.05, 0.6, (h, w, 4)).astype(np.float32)
    img[..., 3] = 1.0
    img[4:8, 6:10, :3] = 30.0
    for f in frames:
        write_frame(Frame.from_array(img), folder / f"in.{f:04d}.exr", bit_depth="float")
    return folder / "in.#.exr"


# -- usage errors ------------------------------------------------------------------------
@pytest.mark.parametrize("frames", ["5-1", "1-", "１-３", "a-b", "1-10y3"])
def test_bad_frames_value_is_a_usage_error(tmp_path, frames):
    r = run("render", tmp_path / "in.#.exr", tmp_path / "o.#.exr", "--frames", frames,
            code=2)
    assert "Invalid value for '--frames'" in r.stderr and not list(tmp_path.iterdir())


def test_look_and_look_from_together_is_a_usage_error(tmp_path):
    r = run("render", "a.exr", "b.exr", "--look", "cinema", "--look-from", "c.exr", code=2)
    assert "not both" in r.stderr


# -- raw pipes ---------------------------------------------------------------------------
def raw_frames(n, w, h, seed=1):
    return np.random.default_rng(seed).uniform(0, 1, (n, 3, h, w)).astype(np.float32).tobytes()


def test_cinema_on_a_raw_pipe_skips_what_needs_a_pass_with_one_warning_each(rt):
    """Every built-in look skips a step whose pass the input lacks, as default does: one
    warning line per step for the whole stream, even with -q; ``missing_passes=error``
    makes it an error again, and ``enabled=false`` drops the step silently."""
    w, h = 40, 24
    r = subprocess.run(CLFX + ["-q", "render", "-", "-", "--raw", f"{w}x{h}", "--look", "cinema"],
                       input=raw_frames(3, w, h), capture_output=True, env=ENV, timeout=300)
    assert r.returncode == 0, r.stderr
    assert len(r.stdout) == 3 * 3 * w * h * 4
    assert r.stderr.decode().splitlines() == [
        "clfx: warning: frame 0: dof: skipped: no depth pass in the input (missing_passes: skip)",
        "clfx: warning: frame 0: motion_blur: skipped: no velocity pass in the input "
        "(missing_passes: skip)"]
    r = subprocess.run(CLFX + ["-q", "render", "-", "-", "--raw", f"{w}x{h}", "--look", "cinema",
                               "--set", "dof.missing_passes=error"],
                       input=raw_frames(1, w, h), capture_output=True, env=ENV, timeout=300)
    assert r.returncode == 1 and b"--set dof.enabled=false" in r.stderr
    r = subprocess.run(CLFX + ["-q", "render", "-", "-", "--raw", f"{w}x{h}", "--look", "cinema",
                               "--set", "dof.enabled=false", "--explain"],
                       input=raw_frames(2, w, h), capture_output=True, env=ENV, timeout=300)
    assert r.returncode == 0, r.stderr
    err = r.stderr.decode()
    assert "skipped motion_blur" in err and "no velocity pass" in err and " dof " not in err


def test_no_built_in_look_needs_a_pass():
    from clfx.pipeline.presets import available_looks, load_look

    looks = [name for name, (kind, _) in available_looks().items() if kind == "built-in"]
    assert "cinema" in looks and len(looks) > 10
    assert {name: load_look(name).required_clips() for name in looks
            if load_look(name).required_clips()} == {}


def test_wrong_raw_size_is_caught_before_anything_is_written(rt, tmp_path):
    w, h = 16, 8
    data = tmp_path / "frames.raw"
    data.write_bytes(raw_frames(3, w, h))
    # a regular file on stdin: its length is checked before the first frame is read
    with open(data, "rb") as f:
        r = subprocess.run(CLFX + ["render", "-", "-", "--raw", "16x9", "--look", "wide-angle"],
                           stdin=f, capture_output=True, env=ENV, timeout=300)
    assert r.returncode == 1 and r.stdout == b""
    assert b"--raw 16x9: stdin holds 4608 bytes, 2.67 frames" in r.stderr
    # a pipe: the first short read fails before anything is written
    r = subprocess.run(CLFX + ["render", "-", "-", "--raw", "16x12", "--look", "wide-angle"],
                       input=raw_frames(1, w, h), capture_output=True, env=ENV, timeout=300)
    assert r.returncode == 1 and r.stdout == b"" and b"truncated raw frame 0" in r.stderr
    # a pipe whose second frame is short: the first is not written either
    r = subprocess.run(CLFX + ["render", "-", "-", "--raw", "16x6", "--look", "wide-angle"],
                       input=raw_frames(1, w, h), capture_output=True, env=ENV, timeout=300)
    assert r.returncode == 1 and r.stdout == b"" and b"truncated raw frame 1" in r.stderr


# -- listings ----------------------------------------------------------------------------
def test_lenses_table_has_a_header_and_json():
    out = run("lenses", "canon 50mm", "--limit", "3").stdout.splitlines()
    assert out[0].split()[:4] == ["MAKER", "MODEL", "FOCAL", "mm"] and "MAX f/" in out[0]
    assert len(out) == 4 and all(line.startswith("Canon") for line in out[1:])
    model_col = out[0].index("MODEL")
    assert all(line[model_col:].startswith("Canon EF 50mm") for line in out[1:])
    rows = json.loads(run("lenses", "canon 50mm", "--limit", "3", "--json").stdout)
    assert len(rows) == 3 and {"maker", "model", "focal_range"} <= set(rows[0])


# -- reproducibility, demo, log ------------------------------------------------------------
def test_look_from_renders_a_shot_again_from_its_file(rt, tmp_path):
    from clfx.io.probe import header_attribute
    from clfx.io.read import read_frame

    pattern = small_sequence(tmp_path)
    run("render", pattern, tmp_path / "a.#.exr", "--look", "cinema", "--float",
        "--set", "glare.strength=0.2", "--set", "camera.focus_distance=1:1.0,2:3.0",
        "--set", "dof.missing_passes=skip", "--set", "motion_blur.enabled=false")
    stamped = header_attribute(tmp_path / "a.0002.exr", "clfx:commandLine")
    assert stamped.startswith("clfx ") and "glare.strength=0.2" in stamped
    look = json.loads(header_attribute(tmp_path / "a.0002.exr", "clfx:lookJSON"))
    assert look["camera"]["focus_distance"] == {"1": 1.0, "2": 3.0}
    assert json.loads(header_attribute(tmp_path / "a.0002.exr", "clfx:values")) == \
        {"camera.focus_distance": 3.0}
    run("render", pattern, tmp_path / "b.#.exr", "--look-from", tmp_path / "a.0001.exr",
        "--float")
    for f in (1, 2):
        a, b = (read_frame(tmp_path / f"{x}.{f:04d}.exr") for x in "ab")
        np.testing.assert_array_equal(a.rgba, b.rgba)
        assert a.metadata["clfx:paramsHash"] == b.metadata["clfx:paramsHash"]
    shown = run("look", "show", tmp_path / "a.0001.exr", "--frame", "2").stdout
    assert "camera.focus_distance=3" in shown
    r = run("render", pattern, tmp_path / "c.#.exr", "--look-from", pattern.parent / "in.0001.exr",
            code=1)
    assert "no clfx:lookJSON" in r.stderr


def test_demo_keeps_an_earlier_demo_unless_overwrite(rt, tmp_path):
    args = ["demo", tmp_path / "d", "--frames", "1", "--size", "32x18", "-q"]
    run("-q", *args[:-1])
    before = (tmp_path / "d" / "demo.0001.exr").stat().st_mtime_ns
    r = run("-q", *args[:-1], code=1)
    assert "exists" in r.stderr and "--overwrite" in r.stderr
    assert (tmp_path / "d" / "demo.0001.exr").stat().st_mtime_ns == before
    run("-q", *args[:-1], "--overwrite")


def test_log_file_gets_reports_warnings_and_summary(rt, tmp_path):
    pattern = small_sequence(tmp_path)
    run("-q", "render", pattern, tmp_path / "o.#.exr", "--look", "film-35mm",
        "--log", tmp_path / "render.log")
    text = (tmp_path / "render.log").read_text()
    assert text.count("frame 1:") == 1 and "frame 2:" in text and "ran     grain" in text
    assert "2 frame(s) rendered with look 'film-35mm'" in text
    run("-q", "render", pattern, tmp_path / "j.#.exr", "--look", "film-35mm",
        "--log", tmp_path / "render.jsonl")
    lines = [json.loads(x) for x in (tmp_path / "render.jsonl").read_text().splitlines()]
    assert [x.get("frame") for x in lines[:2]] == [1, 2] and lines[-1]["summary"]


# -- quiet and informative ------------------------------------------------------------------
def test_compiler_chatter_stays_off_stderr_unless_verbose(rt, tmp_path, capfd):
    """A kernel with a real warning: PoCL's 'N warnings generated.' and pyopencl's
    CompilerWarning become one KernelBuildWarning, shown only with -v."""
    from clfx.cli import _compiler_messages
    from clfx.device.runtime import KernelBuildWarning, Runtime

    (tmp_path / "w.cl").write_text("kernel void k(global float *a) { int y = 3.5f; a[0] = y; }")
    fresh = Runtime(device=rt.device)
    fresh.kernel_dir = tmp_path
    with warnings.catch_warnings():
        _compiler_messages(1)
        fresh.kernel("w.cl", "k", arg_types="buf a",
                     SALT=np.random.default_rng().integers(1 << 30))
    assert capfd.readouterr().err == ""
    with warnings.catch_warnings(record=True) as caught:
        _compiler_messages(2)
        fresh.kernel("w.cl", "k", arg_types="buf a",
                     SALT=np.random.default_rng().integers(1 << 30))
    said = [w for w in caught if issubclass(w.category, KernelBuildWarning)]
    assert said and "implicit conversion from 'float' to 'int'" in str(said[0].message)
    assert "warnings generated" not in capfd.readouterr().err


def run_on_a_terminal(args):
    """Run clfx with stderr on a pseudo-terminal; return (exit code, what it showed)."""
    master, slave = pty.openpty()
    proc = subprocess.Popen(CLFX + args, stdout=subprocess.DEVNULL, stderr=slave, env=ENV)
    os.close(slave)
    chunks = []
    while True:
        try:
            data = os.read(master, 4096)
        except OSError:
            break
        if not data:
            break
        chunks.append(data)
    os.close(master)
    return proc.wait(timeout=300), b"".join(chunks).decode("utf-8", "replace")


def test_progress_on_a_terminal_only_and_never_with_q(rt, tmp_path):
    pattern = small_sequence(tmp_path, frames=(1, 2, 3))
    code, shown = run_on_a_terminal(["render", str(pattern), str(tmp_path / "t.#.exr"),
                                     "--look", "film-35mm"])
    assert code == 0, shown
    assert "3/3" in shown and "fps" in shown and "ETA" in shown and "0:00:0" in shown
    code, shown = run_on_a_terminal(["-q", "render", str(pattern), str(tmp_path / "q.#.exr"),
                                     "--look", "film-35mm"])
    assert code == 0 and shown.strip() == "", shown
    r = subprocess.run(CLFX + ["render", str(pattern), str(tmp_path / "p.#.exr"), "--look",
                               "film-35mm"], capture_output=True, env=ENV, timeout=300)
    assert r.returncode == 0 and b"fps" in r.stderr and b"ETA" not in r.stderr   # summary only


def test_nonfinite_pixels_are_set_to_0_with_one_line_whatever_q_says(rt, tmp_path):
    """A file with NaN and Inf pixels: one warning line on stderr (even with -q), finite
    output."""
    from clfx.core.frame import Frame
    from clfx.io.read import read_frame
    from clfx.io.write import write_frame

    img = np.full((16, 24, 4), 0.25, np.float32)
    img[2, 3, 0], img[5, 7, 1], img[9, 9, 2] = np.nan, np.inf, -np.inf
    write_frame(Frame.from_array(img), tmp_path / "in.exr", bit_depth="float")
    r = run("-q", "render", tmp_path / "in.exr", tmp_path / "out.exr", "--look", "film-35mm")
    said = [x for x in r.stderr.splitlines() if "NaN or infinite" in x]
    assert len(said) == 1 and said[0].startswith("clfx: warning:") and "3 pixel(s)" in said[0], \
        r.stderr
    assert np.isfinite(read_frame(tmp_path / "out.exr").rgba).all()


def test_a_step_skipped_for_a_missing_pass_is_said_once(rt, tmp_path):
    """phone-pan on frames without velocity: its motion blur and rolling shutter are skipped
    (missing_passes: skip), each said once on stderr for the batch, even with -q."""
    pattern = small_sequence(tmp_path, frames=(1, 2, 3))
    r = run("-q", "render", pattern, tmp_path / "o.#.exr", "--look", "phone-pan")
    lines = r.stderr.strip().splitlines()
    for effect in ("motion_blur", "rolling_shutter"):
        said = [x for x in lines if f"{effect}: skipped: no velocity pass" in x]
        assert len(said) == 1 and said[0].startswith("clfx: warning:"), r.stderr
