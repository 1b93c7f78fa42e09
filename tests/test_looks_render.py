"""Every built-in look renders real frames end to end, and the pass-driven effects run
from the command line on Beachball, the demo scene and the ground-truth renderer's EXRs."""
import json

import numpy as np
import pytest
from click.testing import CliRunner

from clfx.cli import cli
from clfx.plugins import discover
from clfx.pipeline.presets import available_looks

BUILTIN = sorted(n for n, (origin, _) in available_looks().items() if origin == "built-in")


def run(*args):
    r = CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)
    assert r.exit_code == 0, (r.output, r.stderr)
    return r


@pytest.mark.parametrize("look", BUILTIN)
def test_builtin_look_renders_beachball(rt, small_beachball, tmp_path, look):
    """Every look on a real stereo frame with depth and motion (Beachball decimated by 4,
    tests/plates.py: its views, passes and windows; sizes are fractions of the frame, so a
    look does at 512x389 what it does at 2K; the pass effects below run on a 2K frame)."""
    from clfx.io.read import read_frame

    src = small_beachball.path("singlepart", 4)
    r = run("render", src, tmp_path / "o.exr", "--look", look, "--quality", "preview", "--json")
    record = json.loads(r.stdout.splitlines()[0])
    assert record["ran"] or record["skipped"]
    out = read_frame(tmp_path / "o.exr")
    assert np.isfinite(out.rgba).all()
    assert out.display_window == read_frame(src).display_window
    assert out.metadata["clfx:look"] == look


@pytest.mark.parametrize("effect", ["dof", "motion_blur", "camera_blur"])
def test_pass_effects_apply_to_beachball_demo_and_ground_truth(rt, exr_images, tmp_path, effect):
    from clfx.core.camera import Camera
    from clfx.bench.groundtruth import make_case, write_case
    from clfx.io.read import read_frame
    from clfx.io.write import write_frame
    from clfx.bench.scene import demo_scene, render_sharp

    demo = tmp_path / "demo.exr"
    write_frame(render_sharp(demo_scene(5, 160, 90)), demo, bit_depth="float")
    case = make_case(demo_scene(5, 160, 90), Camera(focal_length=50, f_number=2, focus_distance=3),
                     samples=16, dof=True, motion=True)
    truth = write_case(case, tmp_path, name="gt")
    params = {"dof": ["max_coc=0.03", "camera.focus_distance=3"], "motion_blur": [],
              "camera_blur": ["length=0.01", "roll=1"]}[effect]
    for i, src in enumerate([exr_images / "Beachball" / "singlepart.0002.exr", demo, truth["sharp"]]):
        out = tmp_path / f"{effect}-{i}.exr"
        run("apply", effect, src, out, *params)
        got = read_frame(out)
        assert np.isfinite(got.rgba).all()
        assert not np.array_equal(got.rgba, read_frame(src).rgba), f"{effect} changed nothing in {src.name}"


@pytest.fixture(scope="module")
def small_inputs(tmp_path_factory):
    """A demo-scene EXR (with depth and velocity) and the same frame as an 8-bit PNG."""
    from clfx.core.frame import Frame
    from clfx.io.write import write_frame
    from clfx.bench.scene import demo_scene, render_sharp

    folder = tmp_path_factory.mktemp("apply")
    sharp = render_sharp(demo_scene(3, 128, 72))
    write_frame(sharp, folder / "in.exr", bit_depth="float")
    write_frame(Frame.from_array(np.clip(sharp.rgba, 0, 1)), folder / "in.png")
    return folder


@pytest.mark.parametrize("fmt", ["exr", "png"])
@pytest.mark.parametrize("effect", sorted(discover()))
def test_every_effect_applies_to_exr_and_png(rt, small_inputs, effect, fmt):
    from clfx.io.read import read_frame
    from clfx.plugins import get_plugin

    src = small_inputs / f"in.{fmt}"
    needs = [c.name for c in get_plugin(effect).descriptor.clips
             if c.name != "source" and not c.optional]
    out = small_inputs / f"{effect}.{fmt}"
    args = ["apply", effect, src, out, "--overwrite"]
    if effect == "lens":  # a real lens must be named; the real-lens look's one
        from clfx.pipeline.presets import load_look

        lens = next(s for s in load_look("real-lens").steps if s.effect == "lens").params
        args += [f"maker={lens.maker}", f"model={lens.model}"]
    if fmt == "png":  # 8-bit files carry no passes: supply them from the EXR
        for clip in needs:
            args += [f"--{clip}", small_inputs / "in.exr"]
    run(*args)
    got = read_frame(out)
    assert np.isfinite(got.rgba).all() and got.rgba.shape == read_frame(src).rgba.shape
