"""Hostile look files and --set values (issue 10, items 4, 8 and 9): each is refused with one
line naming the file and line (or the option), in bounded time and memory, never a traceback."""
import time

import pytest
from click.testing import CliRunner

from clfx.cli import cli
from clfx.core.errors import PresetError
from clfx.pipeline.presets import (MAX_BASE_DEPTH, MAX_LOOK_BYTES, MAX_NESTING, apply_overrides,
                                   load_look, single_effect_look)


def refused(path, *fragments):
    with pytest.raises(PresetError) as err:
        load_look(str(path))
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(str(path)), msg
    for f in fragments:
        assert f in msg, msg
    return msg


# -- item 4: alias bombs, huge files, duplicate keys ------------------------------------------
def test_yaml_alias_bomb_is_refused_at_once(tmp_path):
    lines = ["a0: &a0 [x, x, x, x, x, x, x, x, x, x]"]
    lines += [f"a{i}: &a{i} [*a{i - 1}, *a{i - 1}, *a{i - 1}, *a{i - 1}, *a{i - 1}, *a{i - 1}, "
              f"*a{i - 1}, *a{i - 1}, *a{i - 1}, *a{i - 1}]" for i in range(1, 20)]
    bomb = tmp_path / "bomb.yaml"
    bomb.write_text("name: bomb\n" + "\n".join(lines) + "\neffects: *a19\n")
    t0 = time.perf_counter()
    refused(bomb, f"{bomb}:3:", "aliases (*a0) are not allowed")
    assert time.perf_counter() - t0 < 1.0


def test_look_file_over_the_size_limit_is_refused_before_parsing(tmp_path):
    big = tmp_path / "big.yaml"
    big.write_text("name: big\ndescription: " + "x" * MAX_LOOK_BYTES + "\n")
    t0 = time.perf_counter()
    refused(big, "the limit is 1048576", "1 MiB")
    assert time.perf_counter() - t0 < 1.0


def test_duplicate_keys_name_file_and_line(tmp_path):
    dup = tmp_path / "dup.yaml"
    dup.write_text("name: dup\neffects:\n  - effect: vignette\n    params:\n"
                   "      amount: 0.2\n      amount: 0.9\n")
    refused(dup, f"{dup}:6:", "duplicate key 'amount' (first on line 5)")
    top = tmp_path / "top.yaml"
    top.write_text("name: a\nseed: 1\nname: b\n")
    refused(top, f"{top}:3:", "duplicate key 'name'")


# -- item 8: non-UTF-8, deep nesting, long base chains ----------------------------------------
def test_non_utf8_look_file_is_one_line(tmp_path):
    bad = tmp_path / "latin1.yaml"
    bad.write_bytes("name: caf\xe9\ndescription: x\n".encode("latin-1") + b"effects: []\n")
    refused(bad, f"{bad}:1:", "not UTF-8", "0xe9")


@pytest.mark.parametrize("nested", [
    "effects: " + "[" * 3000 + "]" * 3000,
    "effects:\n" + "".join(" " * i + "- \n" for i in range(0, 2 * 700, 2)),  # < 1 MiB
    "camera: " + "{a: " * 3000 + "1" + "}" * 3000,
])
def test_deeply_nested_yaml_is_refused(tmp_path, nested):
    deep = tmp_path / "deep.yaml"
    deep.write_text("name: deep\n" + nested + "\n")
    refused(deep, f"nested deeper than {MAX_NESTING} levels")


def test_long_base_chain_is_refused_without_recursion(tmp_path, monkeypatch):
    monkeypatch.setenv("CLFX_PRESET_PATH", str(tmp_path))
    for i in range(2000):
        (tmp_path / f"l{i}.yaml").write_text(f"name: l{i}\nbase: l{i + 1}\n")
    (tmp_path / "l2000.yaml").write_text("name: l2000\neffects: []\n")
    msg = refused(tmp_path / "l0.yaml", f"more than {MAX_BASE_DEPTH} deep")
    assert len(msg) < 500, msg
    # a chain within the limit still inherits
    (tmp_path / f"l{MAX_BASE_DEPTH - 1}.yaml").write_text("name: end\neffects: [{effect: vignette}]\n")
    assert [s.effect for s in load_look(str(tmp_path / "l0.yaml")).steps] == ["vignette"]


def test_hostile_looks_from_the_cli_exit_1_with_one_line(tmp_path):
    bad = tmp_path / "bad.yaml"
    for content in ("name: caf\xe9\n".encode("latin-1"), ("effects: " + "[" * 3000).encode(),
                    b"name: x\x01\n"):
        bad.write_bytes(content)
        r = CliRunner().invoke(cli, ["look", "show", str(bad)])
        assert r.exit_code == 1, r.output
        err = r.stderr.strip()
        assert err.startswith("clfx: error:") and "\n" not in err and str(bad) in err, err


def test_a_non_integer_version_pin_is_refused(tmp_path):
    bad = tmp_path / "ver.yaml"
    bad.write_text("name: v\neffects:\n  - {effect: vignette, version: x1}\n")
    refused(bad, f"{bad}:3:", "'x1' is not a version")


# -- item 9: whole-number camera values, ASCII digits -----------------------------------------
def test_camera_blades_must_be_a_whole_number(tmp_path):
    bad = tmp_path / "blades.yaml"
    bad.write_text("name: b\ncamera: {blades: 3.5}\n")
    refused(bad, f"{bad}:2:", "camera.blades: 3.5 is not a whole number")
    bad.write_text("name: b\ncamera: {blades: 6.0}\n")
    assert load_look(str(bad)).camera.blades == 6
    with pytest.raises(PresetError, match=r"--set camera.blades: 3.5 is not a whole number"):
        apply_overrides(load_look("default"), ["camera.blades=3.5"])
    assert apply_overrides(load_look("default"), ["camera.blades=7"]).camera.blades == 7


@pytest.mark.parametrize("assignment", ["camera.blades=\uff16", "camera.f_number=\uff12.8",
                                        "vignette.amount=0.\uff15", "seed=\uff17",
                                        "vignette.amount=0.\u0665"])
def test_set_values_with_non_ascii_digits_are_refused(assignment):
    with pytest.raises(PresetError, match="is not an ASCII digit"):
        apply_overrides(load_look("default"), [assignment])


def test_non_ascii_digits_from_the_cli_exit_1(tmp_path):
    r = CliRunner().invoke(cli, ["look", "show", "default", "--set", "camera.blades=\uff16"])
    assert r.exit_code == 1 and "not an ASCII digit" in r.stderr, r.output
    with pytest.raises(PresetError, match="not an ASCII digit"):
        single_effect_look("vignette", ["amount=\uff10.5"])
