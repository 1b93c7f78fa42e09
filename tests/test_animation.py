"""Keyframed parameters and camera values (issue 13): a rack focus in a look file or on the
command line, linear or eased, held outside its keys, checked at every key, shown by
`clfx look show --frame`, stamped into every output."""
import json

import numpy as np
import pytest

import clfx
from clfx.core.errors import PresetError
from clfx.pipeline import animation
from tests.clirun import run

RACK = """\
name: rack
base: default
camera:
  focus_distance: {1001: 2.0, 1040: 5.5}
effects:
  - effect: vignette
    params:
      amount: {interp: smooth, keys: {1001: 0.1, 1011: 0.5}}
"""


def test_linear_smooth_and_held():
    lin = animation.parse({10: 1.0, 20: 3.0}, lambda v, w: float(v), "x")
    assert [lin.at(f) for f in (0, 10, 15, 20, 99)] == [1.0, 1.0, 2.0, 3.0, 3.0]
    ease = animation.parse({"interp": "smooth", "keys": {10: 1.0, 20: 3.0}},
                           lambda v, w: float(v), "x")
    assert ease.at(15) == pytest.approx(2.0)          # symmetric ease: the middle is the middle
    assert 1.0 < ease.at(11) < lin.at(11)             # slow out of the first key...
    assert lin.at(19) < ease.at(19) < 3.0             # ...slow into the last
    steps = animation.parse({1: 3, 4: 6}, lambda v, w: int(v), "blades", integer=True)
    assert [steps.at(f) for f in (1, 2, 3, 4)] == [3, 4, 5, 6]
    vec = animation.parse({0: [0.0, 1.0, 2.0], 10: [1.0, 1.0, 0.0]}, lambda v, w: tuple(v), "t")
    assert vec.at(5) == pytest.approx((0.5, 1.0, 1.0))
    cli_keys = animation.parse_cli("smooth:1001:2.0,1040:5.5", lambda t, w: float(t), "k")
    assert cli_keys.interp == "smooth" and cli_keys.keys == ((1001, 2.0), (1040, 5.5))
    assert animation.looks_keyframed("1001:2,1040:5") and not animation.looks_keyframed("0.5")


def test_rack_focus_in_a_look_file(tmp_path):
    (tmp_path / "rack.yaml").write_text(RACK)
    look = clfx.load_look(str(tmp_path / "rack.yaml"))
    assert look.at(900).camera.focus_distance == 2.0 and look.at(2000).camera.focus_distance == 5.5
    assert look.at(1020).camera.focus_distance == pytest.approx(2.0 + 3.5 * 19 / 39)
    vig = next(s for s in look.at(1006).steps if s.effect == "vignette")
    assert vig.params.amount == pytest.approx(0.3)
    assert look.values_at(1011) == {"camera.focus_distance": pytest.approx(2.0 + 3.5 * 10 / 39),
                                    "vignette.amount": pytest.approx(0.5)}
    # the keyframes survive a round trip through the stamped JSON
    back = clfx.load_look(json.loads(json.dumps(look.document())))
    assert back.values_at(1020) == look.values_at(1020)
    assert back.params_hash() == look.params_hash()


@pytest.mark.parametrize("text, message", [
    ("camera:\n  focus_distance: {1001: 2.0, 1040: -1}\n",
     r"camera.focus_distance at frame 1040: -1 is outside the allowed range"),
    ("camera:\n  shutter_offset: {1: centered}\n", "cannot be keyframed"),
    ("effects:\n  - effect: vignette\n    params:\n      amount: {1001: 0.1, 1020: 5}\n",
     r"vignette.amount at frame 1020: 5.* outside the allowed range"),
    ("effects:\n  - effect: vignette\n    params:\n      amount: {interp: bouncy, keys: {1: 0.1}}\n",
     "interpolation 'bouncy' is not one of linear, smooth"),
    ("effects:\n  - effect: vignette\n    params:\n      amount: {1.5: 0.1}\n",
     "is not a whole frame number"),
    ("effects:\n  - effect: glare\n    params:\n      psf: {1: spencer}\n", "only numbers can be keyframed"),
])
def test_keys_are_checked_at_every_key(tmp_path, text, message):
    (tmp_path / "bad.yaml").write_text("name: bad\n" + text)
    with pytest.raises(PresetError, match=message):
        clfx.load_look(str(tmp_path / "bad.yaml"))


def test_keyframes_from_the_command_line_and_look_show():
    out = run("look", "show", "default", "--set", "camera.focus_distance=1001:2.0,1040:5.5",
              "--set", "vignette.amount=smooth:1001:0.1,1011:0.5", "--frame", "1020").stdout
    assert "at frame 1020: camera.focus_distance=3.70513" in out and "vignette.amount=0.5" in out
    assert "focus_distance=3.7051282" in out          # the camera line shows the resolved value
    shown = json.loads(run("look", "show", "default", "--set",
                           "camera.focus_distance=1001:2.0,1040:5.5", "--json").stdout)
    assert shown["camera"]["focus_distance"] == {"1001": 2.0, "1040": 5.5}
    r = run("look", "show", "default", "--set", "camera.focus_distance=1001:2.0,1040:-3", code=1)
    assert "--set camera.focus_distance at frame 1040" in r.stderr
    r = run("look", "show", "default", "--set", "vignette.amount=1001:0.1,1001:0.2", code=1)
    assert "keyed twice" in r.stderr


def test_outputs_stamp_the_values_used(rt, tmp_path):
    from clfx.core.frame import Frame
    from clfx.io.probe import header_attribute
    from clfx.io.write import write_frame

    img = np.random.default_rng(1).uniform(0.1, 0.9, (24, 32, 4)).astype(np.float32)
    img[..., 3] = 1.0
    for f in (1001, 1002, 1003):
        write_frame(Frame.from_array(img), tmp_path / f"in.{f}.exr", bit_depth="float")
    look = {"name": "anim", "effects": [{"effect": "vignette",
                                         "params": {"natural": 0.0,
                                                    "amount": {1001: 0.0, 1003: 0.8}}}]}
    res = clfx.render_sequence(tmp_path / "in.#.exr", tmp_path / "out.#.exr", look,
                               as_float=True)
    assert [r.values for r in res.reports] == [{"vignette.amount": v} for v in (0.0, 0.4, 0.8)]
    stamped = [json.loads(header_attribute(tmp_path / f"out.{f}.exr", "clfx:values"))
               for f in (1001, 1002, 1003)]
    assert stamped == [{"vignette.amount": v} for v in (0.0, 0.4, 0.8)]
    from clfx.io.read import read_frame

    corner = [read_frame(tmp_path / f"out.{f}.exr").rgba[0, 0, 0] for f in (1001, 1002, 1003)]
    assert corner[0] == pytest.approx(img[0, 0, 0]) and corner[0] > corner[1] > corner[2]
