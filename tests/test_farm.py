"""`clfx farm openjd`: the Open Job Description template passes `openjd check`, and
`openjd run` renders its chunks with `clfx render` (same pixels as one process)."""
from __future__ import annotations

import subprocess

import pytest
import yaml
from click.testing import CliRunner

from clfx.cli import cli
from clfx.farm import chunk_ranges, farm_range
from tests.cluster import VENV_BIN, assert_same_outputs, clfx, env

OPENJD = VENV_BIN / "openjd"
CLFX = VENV_BIN / "clfx"


@pytest.fixture(scope="module")
def beachball(exr_images):
    if not (exr_images / "Beachball" / "multipart.0004.exr").is_file():
        pytest.skip(f"Beachball sequence not found in {exr_images / 'Beachball'}")
    return str(exr_images / "Beachball" / "multipart.#.exr")


def template(*args) -> str:
    result = CliRunner().invoke(cli, ["farm", "openjd", *map(str, args)])
    assert result.exit_code == 0, result.output
    return result.output


def openjd(*args, timeout=50) -> subprocess.CompletedProcess:
    if not OPENJD.exists():
        pytest.skip("openjd-cli is not installed (pip install openjd-cli)")
    return subprocess.run([str(OPENJD), *map(str, args)], check=False, env=env(),
                          capture_output=True, text=True, timeout=timeout)


def test_farm_ranges():
    assert farm_range([1, 2, 3, 4]) == "1-4"
    assert farm_range([7, 1, 4, 10]) == "1-10:3"        # sorted, fileseq x-step as a-b:n
    assert chunk_ranges(range(1, 11), 4) == ["1-4", "5-8", "9-10"]
    assert chunk_ranges([1, 3, 5, 7, 9], 3) == ["1-5:2", "7,9"]


@pytest.mark.parametrize("options", [(), ("--explicit-chunks",), ("--path-params",),
                                     ("--explicit-chunks", "--path-params")])
def test_openjd_template_passes_check(beachball, tmp_path, options):
    text = template(beachball, tmp_path / "out.#.exr", "--look", "cinema", "--frames",
                    "1-8", "--chunk", "3", "--set", "grain.amount=0.01", *options)
    doc = yaml.safe_load(text)
    assert doc["specificationVersion"] == "jobtemplate-2023-09"
    frames = doc["steps"][0]["parameterSpace"]["taskParameterDefinitions"][0]
    if "--explicit-chunks" in options:
        assert frames["type"] == "STRING" and frames["range"] == ["1-3", "4-6", "7-8"]
    else:
        assert doc["extensions"] == ["TASK_CHUNKING"] and frames["type"] == "CHUNK[INT]"
        assert frames["chunks"]["rangeConstraint"] == "CONTIGUOUS"
    args = doc["steps"][0]["script"]["actions"]["onRun"]["args"]
    assert args[:2] == ["render", "{{Param.InputDir}}/{{Param.InputName}}"]
    assert "--skip-existing" in args and "{{Task.Param.Frames}}" in args
    (tmp_path / "job.yaml").write_text(text)
    proc = openjd("check", tmp_path / "job.yaml")
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_openjd_template_refuses_bad_look(beachball, tmp_path):
    result = CliRunner().invoke(cli, ["farm", "openjd", beachball, str(tmp_path / "o.#.exr"),
                                      "--look", "no-such-look", "--frames", "1-2"])
    assert result.exit_code == 1 and "no-such-look" in result.output


def test_openjd_run_renders_two_chunks(beachball, tmp_path):
    if not CLFX.exists():
        pytest.skip(f"no clfx console script at {CLFX}")
    out = tmp_path / "farm"
    (tmp_path / "job.yaml").write_text(template(
        beachball, out / "out.#.exr", "--look", "wide-angle", "--frames", "1-4",
        "--chunk", "2", "--clfx", CLFX))
    proc = openjd("run", tmp_path / "job.yaml")
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert "Chunks run: 2" in proc.stdout
    assert "Frames(CHUNK[INT]) = 1-2" in proc.stdout and "Frames(CHUNK[INT]) = 3-4" in proc.stdout
    want = tmp_path / "want"
    clfx("-q", "render", beachball, want / "out.#.exr", "--look", "wide-angle",
         "--frames", "1-4")
    assert_same_outputs(out, want)


def test_openjd_nuke_style_pattern(tmp_path):
    """A Nuke user's ``shot.####.exr`` is 16 digits here (oiiotool's #): a farm job of it is
    said on stderr (the template on stdout stays YAML), and a pattern with no frame on disk
    says so in the error instead of only asking for --frames."""
    for f in (1, 2):
        (tmp_path / f"in.{f:04d}.exr").write_bytes(b"x")
    result = CliRunner().invoke(cli, ["farm", "openjd", str(tmp_path / "in.#.exr"),
                                      str(tmp_path / "o.####.exr"), "--frames", "1-2"])
    assert result.exit_code == 0, result.output
    assert "o.####.exr: each # is 4 digits" in result.stderr, result.stderr
    assert yaml.safe_load(result.stdout)["specificationVersion"] == "jobtemplate-2023-09"
    result = CliRunner().invoke(cli, ["farm", "openjd", str(tmp_path / "in.####.exr"),
                                      str(tmp_path / "o.#.exr")])
    assert result.exit_code == 1
    assert "in.0000000000000001.exr" in result.stderr and "@@@@ or %04d" in result.stderr, \
        result.stderr
