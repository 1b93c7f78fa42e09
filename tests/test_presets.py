"""Looks: finding, inheritance, overrides, and errors naming file, line and key."""
import textwrap

import pytest

from clfx.core.errors import PresetError
from clfx.pipeline.presets import apply_overrides, available_looks, load_look, single_effect_look


def write(tmp_path, name, text):
    path = tmp_path / f"{name}.yaml"
    path.write_text(textwrap.dedent(text))
    return path


def test_builtin_looks_all_load():
    looks = available_looks()
    assert "default" in looks and len(looks) >= 2
    for name, (origin, path) in looks.items():
        if origin == "built-in":
            look = load_look(str(path))
            assert look.steps, f"{name} has no effects"
            assert look.description


def test_inheritance_merges_camera_and_effects(tmp_path, monkeypatch):
    monkeypatch.setenv("CLFX_PRESET_PATH", str(tmp_path))
    write(tmp_path, "parent", """
        name: parent
        description: base look
        camera: {focal_length: 50, f_number: 2}
        effects:
          - effect: vignette
            params: {amount: 0.3, radius: 0.4}
    """)
    path = write(tmp_path, "child", """
        name: child
        base: parent
        camera: {f_number: 8}
        effects:
          - effect: vignette
            params: {amount: 0.5}
    """)
    look = load_look(str(path))
    assert look.camera.focal_length == 50 and look.camera.f_number == 8
    assert len(look.steps) == 1
    assert look.steps[0].params.amount == 0.5 and look.steps[0].params.radius == 0.4
    assert look.description == "base look"


def test_enabled_false_removes_inherited_effect(tmp_path, monkeypatch):
    monkeypatch.setenv("CLFX_PRESET_PATH", str(tmp_path))
    write(tmp_path, "parent", "name: parent\neffects:\n  - effect: vignette\n")
    path = write(tmp_path, "child", "name: child\nbase: parent\neffects:\n  - {effect: vignette, enabled: false}\n")
    assert load_look(str(path)).steps == []


def test_user_preset_path_wins_over_builtin(tmp_path, monkeypatch):
    monkeypatch.setenv("CLFX_PRESET_PATH", str(tmp_path))
    write(tmp_path, "default", "name: default\ndescription: mine\neffects: []\n")
    assert load_look("default").description == "mine"


@pytest.mark.parametrize("text, line, pattern", [
    ("name: x\neffects:\n  - effect: vignete\n", 3, r"effects\[0\]\.effect: unknown effect 'vignete'; did you mean 'vignette'"),
    ("name: x\neffects:\n  - effect: vignette\n    params:\n      amout: 0.2\n", 5, r"amout.*did you mean 'amount'"),
    ("name: x\neffects:\n  - effect: vignette\n    params: {amount: 7}\n", 4, r"params\.amount: .*outside the allowed range"),
    ("name: x\neffects:\n  - effect: vignette\n    params: {amount: lots}\n", 4, r"params\.amount: .*not a number"),
    ("name: x\ncamera: {focal_lenght: 50}\n", 2, r"camera\.focal_lenght: unknown camera value; did you mean 'focal_length'"),
    ("name: x\ncamera: {f_number: 0}\n", 2, r"camera\.f_number: 0 is outside"),
    ("name: x\neffect:\n  - effect: vignette\n", 2, r"effect: unknown key; did you mean 'effects'"),
    ("name: x\neffects:\n  - effect: vignette\n    quality: best\n", 4, r"quality: 'best' is not a quality level"),
    ("name: x\neffects: [\n  - effect\n", 3, r"malformed YAML"),
    ("name: x\nbase: nonexistent-look\n", 2, r"base: unknown look 'nonexistent-look'"),
])
def test_bad_looks_name_file_line_and_key(tmp_path, text, line, pattern):
    path = write(tmp_path, "bad", text)
    with pytest.raises(PresetError, match=pattern) as err:
        load_look(str(path))
    msg = str(err.value)
    assert msg.startswith(f"{path}:{line}:"), msg
    assert "\n" not in msg


def test_base_cycle_is_an_error(tmp_path, monkeypatch):
    monkeypatch.setenv("CLFX_PRESET_PATH", str(tmp_path))
    write(tmp_path, "a", "name: a\nbase: b\n")
    write(tmp_path, "b", "name: b\nbase: a\n")
    with pytest.raises(PresetError, match="cycle"):
        load_look("a")


def test_unknown_look_name_suggests():
    with pytest.raises(PresetError, match="did you mean 'default'"):
        load_look("defualt")


def test_overrides():
    look = apply_overrides(load_look("default"), ["vignette.amount=0.5", "camera.focal_length=85",
                                                  "seed=3", "vignette.quality=draft"])
    vignette = next(s for s in look.steps if s.effect == "vignette")
    assert vignette.params.amount == 0.5 and look.camera.focal_length == 85
    assert look.seed == 3 and vignette.quality == "draft"
    with pytest.raises(PresetError, match="has no effect 'glaree'"):
        apply_overrides(load_look("default"), ["glaree.strength=1"])
    with pytest.raises(Exception, match="outside the allowed range"):
        apply_overrides(load_look("default"), ["vignette.amount=9"])
    with pytest.raises(PresetError, match="outside the allowed range"):
        apply_overrides(load_look("default"), ["camera.f_number=0"])


def test_single_effect_look():
    look = single_effect_look("vignette", ["amount=0.25", "center=0.1,0.2", "camera.focal_length=24"])
    assert look.steps[0].params.amount == 0.25 and look.steps[0].params.center == (0.1, 0.2)
    assert look.camera.focal_length == 24


def test_missing_passes_skip_is_inherited_and_validated(tmp_path, monkeypatch):
    monkeypatch.setenv("CLFX_PRESET_PATH", str(tmp_path))
    write(tmp_path, "parent", "name: parent\neffects:\n  - {effect: dof, missing_passes: skip}\n")
    child = load_look(str(write(tmp_path, "child", "name: child\nbase: parent\neffects:\n"
                                                   "  - {effect: dof, params: {max_coc: 0.02}}\n")))
    assert child.steps[0].missing_passes == "skip" and child.required_clips() == {}
    bad = write(tmp_path, "bad", "name: bad\neffects:\n  - {effect: dof, missing_passes: maybe}\n")
    with pytest.raises(PresetError, match=r"bad.yaml:3: effects\[0\]\.missing_passes"):
        load_look(str(bad))


def test_one_effect_twice_with_step_ids(tmp_path):
    path = write(tmp_path, "twice", """
        name: twice
        effects:
          - effect: vignette
            params: {amount: 0.2}
          - effect: vignette
            id: corners
            params: {amount: 0.5}
    """)
    look = apply_overrides(load_look(str(path)), ["corners.amount=0.7"])
    assert [(s.id, s.params.amount) for s in look.steps] == [("vignette", 0.2), ("corners", 0.7)]
    clash = write(tmp_path, "clash", "name: c\neffects:\n  - {effect: vignette, id: x}\n  - {effect: grain, id: x}\n")
    with pytest.raises(PresetError, match=r"clash.yaml:4: .*step id 'x' already names a 'vignette' step"):
        load_look(str(clash))
