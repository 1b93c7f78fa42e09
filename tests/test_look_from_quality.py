"""``--look-from`` renders the same pixels as the render it reads, at any ``--quality``: the
batch resolves the level once (`clfx.pipeline.options.resolve_quality`) and stamps the look with
every step's level, and ``clfx:quality``."""
import json

import numpy as np
import pytest
from clfx.core.frame import Frame
from clfx.io.probe import header_attribute
from clfx.io.read import read_frame
from clfx.io.write import write_frame
from tests import clirun


@pytest.fixture
def small(tmp_path, monkeypatch):
    rng = np.random.default_rng(3)
    rgba = rng.uniform(0, 1, (48, 64, 4)).astype(np.float32)
    rgba[20:24, 30:34, :3] = 40.0          # highlights: glare and the light effects run
    rgba[..., 3] = 1
    depth = rng.uniform(1, 9, (48, 64)).astype(np.float32)
    write_frame(Frame.from_array(rgba, depth=depth), tmp_path / "in.exr", bit_depth="float")
    monkeypatch.chdir(tmp_path)
    return tmp_path


def run(*args):
    return clirun.run("-q", *args)


def test_look_from_reproduces_every_pixel_at_each_quality(small):
    pixels = {}
    for level in ("draft", "final", "reference"):
        run("render", "in.exr", f"a-{level}.exr", "--look", "default", "--quality", level,
            "--float")
        run("render", "in.exr", f"b-{level}.exr", "--look-from", f"a-{level}.exr", "--float")
        a, b = read_frame(small / f"a-{level}.exr"), read_frame(small / f"b-{level}.exr")
        np.testing.assert_array_equal(b.rgba, a.rgba, err_msg=level)
        assert a.metadata["clfx:quality"] == b.metadata["clfx:quality"] == level
        assert a.metadata["clfx:paramsHash"] == b.metadata["clfx:paramsHash"]
        stamped = json.loads(header_attribute(small / f"a-{level}.exr", "clfx:lookJSON"))
        assert {e.get("quality") for e in stamped["effects"]} == {level}
        pixels[level] = a
    assert len({p.rgba.tobytes() for p in pixels.values()}) > 1   # the levels matter here
    assert len({p.metadata["clfx:paramsHash"] for p in pixels.values()}) == 3


def test_look_from_with_quality_relevels_the_steps_that_took_the_render_level(small):
    run("render", "in.exr", "a-draft.exr", "--look", "default", "--quality", "draft",
        "--set", "grain.quality=reference", "--float")
    run("render", "in.exr", "final.exr", "--look", "default", "--set",
        "grain.quality=reference", "--float")
    run("render", "in.exr", "again.exr", "--look-from", "a-draft.exr", "--quality", "final",
        "--float")
    again = read_frame(small / "again.exr")
    np.testing.assert_array_equal(again.rgba, read_frame(small / "final.exr").rgba)
    stamped = json.loads(again.metadata["clfx:lookJSON"])
    levels = {e["effect"]: e["quality"] for e in stamped["effects"]}
    assert levels.pop("grain") == "reference" and set(levels.values()) == {"final"}
