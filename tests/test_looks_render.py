"""Every built-in look renders real frames end to end, and the pass-driven effects run
from the command line on Beachball, the demo scene and the ground-truth renderer's EXRs."""
import json

import numpy as np
import pytest
from click.testing import CliRunner

from clfx.cli import cli
from clfx.presets import available_looks

BUILTIN = sorted(n for n, (origin, _) in available_looks().items() if origin == "built-in")


def run(*args):
    r = CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)
    assert r.exit_code == 0, (r.output, r.stderr)
    return r


@pytest.mark.parametrize("look", BUILTIN)
def test_builtin_look_renders_beachball(rt, exr_images, tmp_path, look):
    from clfx.io import read_frame

    src = exr_images / "Beachball" / "singlepart.0004.exr"
    r = run("render", src, tmp_path / "o.exr", "--look", look, "--quality", "preview", "--json")
    record = json.loads(r.stdout.splitlines()[0])
    assert record["ran"] or record["skipped"]
    out = read_frame(tmp_path / "o.exr")
    assert np.isfinite(out.rgba).all()
    assert out.display_window == read_frame(src).display_window
    assert out.metadata["clfx:look"] == look


@pytest.mark.parametrize("effect", ["dof", "motion_blur", "camera_blur"])
def test_pass_effects_apply_to_beachball_demo_and_ground_truth(rt, exr_images, tmp_path, effect):
    from clfx.camera import Camera
    from clfx.groundtruth import make_case, write_case
    from clfx.io import read_frame, write_frame
    from clfx.scene import demo_scene, render_sharp

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
