"""A pipeline TD's first day (issue 33): flags anywhere on the command line, a pass-only file
probed, the notices ``-q`` keeps, one hash for a look wherever it is shown, steps placed in
an inherited look, and the kernel cache announced, prebuilt and independent of frame size."""
from __future__ import annotations

import json

import numpy as np
import pytest

from tests.clirun import run
from tests.test_io_depth import write_exr


def rgba(h=12, w=16, seed=1):
    px = np.random.default_rng(seed).uniform(0.0, 2.0, (h, w, 4)).astype(np.float32)
    px[..., 3] = 1.0
    return {c: px[..., i] for i, c in enumerate("RGBA")}


# -- item 9: command-line edges ----------------------------------------------------------------
def test_quiet_and_verbose_are_taken_after_the_command(rt, tmp_path):
    src = write_exr(tmp_path / "in.exr", rgba())
    r = run("apply", "vignette", src, tmp_path / "a.exr", "-q")
    assert r.stderr == "", r.stderr
    loud = run("apply", "vignette", src, tmp_path / "b.exr", "-v")
    assert "frame(s) rendered" in loud.stderr
    # -q anywhere wins over -v anywhere, as before the command
    assert run("-v", "apply", "vignette", src, tmp_path / "c.exr", "-q").stderr == ""
    assert run("look", "show", "default", "-q").stdout


def test_y_is_overwrite(rt, tmp_path):
    src = write_exr(tmp_path / "in.exr", rgba())
    out = tmp_path / "o.exr"
    run("apply", "vignette", src, out, "-q")
    r = run("apply", "vignette", src, out, code=1)
    assert "--overwrite" in r.stderr
    before = out.stat().st_mtime_ns
    run("apply", "vignette", src, out, "-y", "-q")
    assert out.stat().st_mtime_ns != before


def test_quiet_keeps_the_depth_no_hit_line(rt, tmp_path):
    """README: the depth "no hit" convention a file was read with is said whatever -q says."""
    ch = rgba()
    z = np.full((12, 16), 5.0, np.float32)
    z[:, :8] = 0.0                      # background at 0: read as no hit
    src = write_exr(tmp_path / "in.exr", {**ch, "Z": z})
    r = run("-q", "apply", "dof", src, tmp_path / "o.exr", "camera.focus_distance=5")
    lines = [ln for ln in r.stderr.splitlines() if "read as no hit" in ln]
    assert len(lines) == 1 and "in.exr" in lines[0], r.stderr


def test_probe_shows_a_pass_only_file(tmp_path):
    z = np.linspace(1.0, 9.0, 6 * 8, dtype=np.float32).reshape(6, 8)
    path = write_exr(tmp_path / "depth.exr", {"Z": z})
    text = run("probe", path).stdout
    assert "channels: Z" in text and "beauty: none" in text and "pass-only" in text
    assert "depth: Z" in text and "8x6" in text
    info = json.loads(run("probe", path, "--json").stdout)
    assert info["rgb"] is False and info["beauty"] is None
    assert info["depth"]["channel"] == "Z" and info["parts"][0]["channels"] == ["Z"]
    assert info["parts"][0]["data_window"]["width"] == 8
    # a render still refuses it, naming what it is
    r = run("render", path, tmp_path / "o.exr", code=1)
    assert "no beauty channels" in r.stderr and "depth pass only" in r.stderr


# -- item 2: frame patterns ------------------------------------------------------------------
def test_frame_patterns_on_the_command_line(rt, tmp_path):
    """oiiotool's padding (# = 4 digits, @ = 1), the file a missing frame was looked for, and
    one line for a Nuke-style ``####`` (16 digits here)."""
    for f in (1, 2):
        write_exr(tmp_path / f"in.{f:04d}.exr", rgba(seed=f))
    run("apply", "vignette", tmp_path / "in.@@@@.exr", tmp_path / "o.#@.exr", "-q")
    assert sorted(p.name for p in tmp_path.glob("o.*")) == ["o.00001.exr", "o.00002.exr"]
    r = run("apply", "vignette", tmp_path / "in.#.exr", tmp_path / "p.#.exr", "--frames",
            "1-3", code=1)
    assert f"missing frame 3 of {tmp_path / 'in.#.exr'}: no file {tmp_path / 'in.0003.exr'}" \
        in r.stderr, r.stderr
    r = run("apply", "vignette", tmp_path / "in.####.exr", tmp_path / "q.#.exr", code=1)
    assert "in.0000000000000001.exr" in r.stderr and "@@@@ or %04d" in r.stderr, r.stderr
    r = run("-q", "apply", "vignette", tmp_path / "in.#.exr", tmp_path / "s.##.exr")
    assert "s.##.exr: each # is 4 digits" in r.stderr and r.stderr.count("\n") == 1, r.stderr
    assert (tmp_path / "s.00000001.exr").is_file()


# -- item 8: one hash for a look ---------------------------------------------------------------
def stamp(path, name="clfx:paramsHash"):
    from clfx.io.probe import header_attribute

    return header_attribute(path, name)


def test_look_show_prints_the_hash_renders_are_stamped_with(rt, tmp_path):
    """The hash ``look show`` prints is the ``clfx:paramsHash`` of a render with the look (at
    the same quality level), the one ``--json`` and ``--explain`` say, and the one of the
    look read back from the output; the file's formatting does not change it."""
    look = tmp_path / "grade.yaml"
    look.write_text("name: grade\nseed: 3\neffects:\n  - effect: vignette\n"
                    "    params: {amount: 0.4}\n  - effect: grain\n    quality: draft\n")
    shown = json.loads(run("look", "show", look, "--json").stdout)["params_hash"]
    src = write_exr(tmp_path / "in.exr", rgba())
    r = run("render", src, tmp_path / "o.exr", "--look", look, "--json", "--explain")
    assert stamp(tmp_path / "o.exr") == shown
    summary = json.loads(r.stdout.splitlines()[-1])
    assert summary["params_hash"] == shown and summary["quality"] == "final"
    assert f"params hash {shown}" in r.stderr
    # read back from the output: the same hash, and the same again through --look-from
    assert json.loads(run("look", "show", tmp_path / "o.exr", "--json").stdout)[
        "params_hash"] == shown
    run("render", src, tmp_path / "again.exr", "--look-from", tmp_path / "o.exr", "-q")
    assert stamp(tmp_path / "again.exr") == shown
    # at another level: another hash, the same on both sides
    draft = json.loads(run("look", "show", look, "--quality", "draft", "--json").stdout)
    assert draft["params_hash"] != shown
    run("render", src, tmp_path / "d.exr", "--look", look, "--quality", "draft", "-q")
    assert stamp(tmp_path / "d.exr") == draft["params_hash"]
    # the file's formatting (key order, a default spelt out, comments) is not hashed
    same = tmp_path / "same.yaml"
    same.write_text("# approved\nseed: 3\nname: other-name\neffects:\n  - effect: vignette\n"
                    "    params: {amount: 0.4}\n  - {effect: grain, quality: draft}\n")
    assert json.loads(run("look", "show", same, "--json").stdout)["params_hash"] == shown


def test_look_show_cinema_hash_is_its_render_stamp():
    """cinema's shown hash was 6ffbc746... and its renders' d836a463... (issue 33 item 8):
    the look as shown and as a render resolves it hash the same."""
    from clfx.pipeline.options import resolve_quality
    from clfx.pipeline.presets import load_look

    look = load_look("cinema")
    shown = json.loads(run("look", "show", "cinema", "--json").stdout)["params_hash"]
    assert shown == resolve_quality(look, None)[0].params_hash() == look.params_hash("final")


def test_render_frame_stamps_the_hash_of_the_level_it_renders_at(rt):
    """`render_frame` given a look as written and a level stamps the look at that level
    (the hash ``look show --quality`` prints), not the look at ``final``."""
    from clfx.core.frame import Frame
    from clfx.pipeline.look import render_frame
    from clfx.pipeline.presets import look_from_dict

    look = look_from_dict({"name": "g", "effects": [{"effect": "vignette"}, {"effect": "grain"}]})
    px = np.stack(list(rgba().values()), axis=-1)
    out, _ = render_frame(rt, look, Frame.from_array(px), frame_number=1, quality="draft")
    assert out.metadata["clfx:paramsHash"] == look.params_hash("draft") != look.params_hash()
    assert json.loads(out.metadata["clfx:lookJSON"])["effects"][0]["quality"] == "draft"


# -- item 3: placing a step in an inherited look ---------------------------------------------
def look_file(tmp_path, name, text):
    path = tmp_path / f"{name}.yaml"
    path.write_text(text)
    return path


def steps_of(path):
    return [(s["effect"] if "id" not in s else s["id"], s["from"])
            for s in json.loads(run("look", "show", path, "--json").stdout)["effects"]]


def test_before_and_after_place_a_step_in_an_inherited_look(tmp_path):
    child = look_file(tmp_path, "child", "name: child\nbase: cinema\neffects:\n"
                      "  - effect: halation\n    before: grain\n"
                      "  - effect: vignette\n    params: {amount: 0.2}\n"
                      "  - effect: dof\n    after: distortion\n"
                      "  - effect: glare\n    enabled: false\n")
    got = steps_of(child)
    assert [s for s, _ in got] == ["motion_blur", "streaks", "chromatic_aberration",
                                   "distortion", "dof", "vignette", "halation", "grain"]
    assert dict(got)["halation"] == "child" and dict(got)["grain"] == "cinema"
    text = run("look", "show", child).stdout
    assert "halation  [own]" in text and "grain  [inherited from cinema]" in text
    assert "vignette  [inherited from cinema, changed here]" in text
    # the moved step keeps its parameters
    from clfx.pipeline.presets import load_look

    base, moved = load_look("cinema"), load_look(str(child))
    dof = lambda look: next(s for s in look.steps if s.effect == "dof")  # noqa: E731
    assert dof(moved).params == dof(base).params


@pytest.mark.parametrize("entries, fragments", [
    ("  - effect: halation\n    before: halo\n",
     [":5: effects[0].before: no step 'halo'", "(steps: dof,"]),
    ("  - {effect: halation, before: grain, after: dof}\n",
     [":4: effects[0].after: give before: or after:, not both"]),
    ("  - effect: halation\n    enabled: false\n",
     [":5: effects[0].enabled: enabled: false drops nothing", "no step 'halation'"]),
])
def test_placing_a_step_names_the_key_and_line(tmp_path, entries, fragments):
    child = look_file(tmp_path, "child", "name: child\nbase: cinema\neffects:\n" + entries)
    r = run("look", "show", child, code=1)
    for fragment in fragments:
        assert fragment in r.stderr, r.stderr


def test_a_step_named_by_an_effect_two_steps_have_is_ambiguous(tmp_path):
    look_file(tmp_path, "stars", "name: stars\neffects:\n"
              "  - {effect: streaks, id: star}\n  - {effect: streaks, id: spikes}\n")
    child = look_file(tmp_path, "child", f"name: child\nbase: {tmp_path / 'stars.yaml'}\n"
                      "effects:\n  - effect: halation\n    after: streaks\n")
    r = run("look", "show", child, code=1)
    assert ":5: effects[0].after: 'streaks' is ambiguous: steps star, spikes" in r.stderr
    child.write_text(child.read_text().replace("after: streaks", "after: star"))
    assert [s for s, _ in steps_of(child)] == ["star", "halation", "spikes"]


# -- item 1: the kernel cache ----------------------------------------------------------------
COLD = "clfx: compiling kernels for "


def clfx_cold(cache, *args):
    """``clfx ARGS`` in a subprocess whose kernel cache is ``cache`` (PoCL's work-group
    specialisation as a render has it, not the suite's)."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    env = {k: v for k, v in os.environ.items() if k != "POCL_WORK_GROUP_SPECIALIZATION"}
    env.update(PYTHONPATH=str(root), POCL_CACHE_DIR=str(cache), CLFX_COLD_NOTICE="1")
    proc = subprocess.run([sys.executable, "-m", "clfx.cli", *map(str, args)],
                          capture_output=True, text=True, env=env, timeout=900)
    assert proc.returncode == 0, proc.stderr
    return proc


def kernel_binaries(cache) -> set:
    """PoCL's compiled work-group code in ``cache`` (PROGRAM/KERNEL/VARIANT/KERNEL.so)."""
    return {str(p.relative_to(cache)) for p in cache.rglob("*.so")}


def test_a_cold_kernel_cache_is_said_once_and_a_warm_one_not(rt, tmp_path):
    src = write_exr(tmp_path / "in.exr", rgba())
    cache = tmp_path / "cache"
    cold = clfx_cold(cache, "apply", "vignette", src, tmp_path / "a.exr")
    lines = [ln for ln in cold.stderr.splitlines() if ln.startswith(COLD)]
    assert len(lines) == 1 and f"(cached in {cache})" in lines[0], cold.stderr
    warm = clfx_cold(cache, "apply", "vignette", src, tmp_path / "b.exr")
    assert COLD not in warm.stderr, warm.stderr
    quiet = clfx_cold(tmp_path / "other", "apply", "vignette", src, tmp_path / "c.exr", "-q")
    assert quiet.stderr == ""


def test_prebuild_then_render_at_another_size_compiles_nothing(rt, tmp_path):
    """``clfx prebuild`` fills the kernel cache: a render after it says nothing about
    compiling and adds no program and no work-group code, at another frame size too."""
    look = tmp_path / "vig.yaml"
    look.write_text("name: vig\neffects:\n  - effect: vignette\n    params: {amount: 0.3}\n")
    cache = tmp_path / "cache"
    built = clfx_cold(cache, "prebuild", "--looks", look, "--quality", "final,draft",
                      "--size", "48x32")
    assert "vig" in built.stdout and "final" in built.stdout and "draft" in built.stdout
    assert "program(s) compiled" in built.stdout and COLD not in built.stderr
    before = kernel_binaries(cache)
    for h, w in ((12, 16), (37, 53)):
        src = write_exr(tmp_path / f"in{w}.exr", rgba(h, w))
        r = clfx_cold(cache, "render", src, tmp_path / f"o{w}.exr", "--look", look)
        assert COLD not in r.stderr, r.stderr
    assert kernel_binaries(cache) == before


def test_no_program_is_built_for_a_second_frame_size(rt):
    """A look's programs do not depend on the frame's size: a second size builds none.
    (Some effects pick an algorithm by size class, each its own program: glare's small PSFs
    gather directly, large ones take the FFT; a few such variants, not one per size.)"""
    import clfx

    look = {"effects": [{"effect": "vignette"}, {"effect": "grain"},
                        {"effect": "chromatic_aberration"}]}
    sizes = [(24, 40), (45, 71)]
    counts = []
    for h, w in sizes:
        first = len(rt.builds)
        px = np.random.default_rng(h).uniform(0.0, 8.0, (h, w, 4)).astype(np.float32)
        clfx.render_array(px, look)
        counts.append(rt.builds[first:])
    assert counts[1] == [], counts[1]
