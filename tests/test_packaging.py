"""Packaging and importing (issue 33): every folder that ships is in pyproject's package list
(setuptools warns about each one left out), an editable install imports from anywhere (also
from the folder above a clone named clfx), the errors are importable from ``clfx`` and API
errors name keywords, not command-line flags."""
import os
import subprocess
import sys
import sysconfig
import tomllib
from pathlib import Path

import numpy as np
import pytest

import clfx
from tests.clirun import run

ROOT = Path(__file__).resolve().parents[1]


def shipped_folders() -> set[str]:
    """Dotted names of the folders under clfx/ (kernels and presets through their links)
    that hold code or data."""
    names = set()
    for base in ("clfx", "clfx/kernels", "clfx/presets"):
        for folder, dirs, files in os.walk(ROOT / base, followlinks=True):
            dirs[:] = [d for d in dirs if d != "__pycache__"]
            if any(not f.endswith(".pyc") for f in files):
                names.add(".".join(Path(folder).relative_to(ROOT).parts))
    return names


def test_every_shipped_folder_is_a_listed_package():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert set(config["packages"]) == shipped_folders()
    assert config["package-dir"] == {"": "."}       # every package where its name says
    data = config["package-data"]
    assert {"clfx.kernels.lib", "clfx.presets.lenses", "clfx.bench.cycles.data"} <= set(data)


def test_kernel_and_preset_folders_resolve_to_the_top_level_ones():
    from clfx.device.runtime import kernel_dir
    from clfx.io.presetfiles import builtin_dir

    assert kernel_dir() == (ROOT / "kernels").resolve()
    assert builtin_dir() == (ROOT / "presets").resolve()


def test_editable_install_imports_from_the_folder_above_a_clone_named_clfx(tmp_path):
    """``pip install -e .`` as a TD runs it, into a throwaway venv; then ``import clfx`` from a
    folder holding the clone as ``clfx/`` (a namespace package ahead of setuptools' import
    hook, before).  Needs no network: the running interpreter's setuptools builds it."""
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    here = sysconfig.get_paths()["purelib"]
    env = {**os.environ, "PYTHONPATH": here, "PIP_NO_INDEX": "1"}
    py = venv / "bin" / "python"
    got = subprocess.run([sys.executable, "-m", "pip", "--python", str(py), "install", "-q",
                          "--no-deps", "--no-build-isolation", "-e", str(ROOT)],
                         env=env, capture_output=True, text=True)
    assert got.returncode == 0, got.stderr
    assert "BuildBackendWarning" not in got.stderr, got.stderr      # nothing left unlisted
    parent = tmp_path / "shows"
    parent.mkdir()
    (parent / "clfx").symlink_to(ROOT, target_is_directory=True)
    code = ("import clfx, sys; from clfx import ClfxError; "
            "print(clfx.__file__); print('render_array' in dir(clfx))")   # no numpy there
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    out = subprocess.run([str(py), "-c", code], cwd=parent, env=env, capture_output=True,
                         text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == [str(ROOT / "clfx" / "__init__.py"), "True"]


def test_errors_are_importable_from_clfx():
    from clfx import ClfxError, ImageIOError, OutputExistsError, ParamError, SequenceError

    assert issubclass(OutputExistsError, ImageIOError) and issubclass(ImageIOError, ClfxError)
    assert issubclass(ParamError, ClfxError) and issubclass(SequenceError, ClfxError)
    assert "ClfxError" in dir(clfx) and "OutputExistsError" in clfx.__all__


def test_api_errors_name_keywords_and_the_cli_flags(tmp_path, rt):
    from clfx.core.frame import Frame
    from clfx.io.write import write_frame

    write_frame(Frame.from_array(np.full((8, 8, 4), 0.5, np.float32)), tmp_path / "in.exr")
    (tmp_path / "out.exr").write_bytes(b"")
    with pytest.raises(clfx.OutputExistsError) as err:
        clfx.render_file(tmp_path / "in.exr", tmp_path / "out.exr", "default")
    assert "overwrite=True" in str(err.value) and "skip_existing=True" in str(err.value)
    assert "--" not in str(err.value)
    r = run("render", tmp_path / "in.exr", tmp_path / "out.exr", code=1)
    assert "use --overwrite" in r.stderr and "--skip-existing" in r.stderr
    with pytest.raises(clfx.ImageIOError, match=r"cannot write log_path"):   # after the CLI
        clfx.render_file(tmp_path / "in.exr", tmp_path / "o2.exr", "default",
                         log_path=str(tmp_path))


def test_missing_test_images_skip_naming_the_folder_and_the_variable(tmp_path):
    """Issue 33: the skip said "openexr-images test data not found" without where it looked
    or how to point elsewhere."""
    env = {**os.environ, "CLFX_SHARED_DATA": str(tmp_path / "nowhere"),
           "PYTHONPATH": str(ROOT)}
    out = subprocess.run([sys.executable, "-m", "pytest", "-q", "-rs", "-p", "no:cacheprovider",
                          "-n", "0", "tests/test_io.py::test_pixel_aspect_files",
                          "tests/test_io_depth.py", "-k", "aspect or beachball"],
                         cwd=ROOT, env=env, capture_output=True, text=True)
    skips = [ln for ln in out.stdout.splitlines() if ln.startswith("SKIPPED")]
    assert skips and out.returncode == 0, out.stdout + out.stderr
    for line in skips:
        assert str(tmp_path / "nowhere" / "openexr-images") in line and "CLFX_SHARED_DATA" in line


def test_setup_says_one_line_per_step(tmp_path):
    """Issue 33: `make demo` printed ~130 lines of setup (pip's and setuptools' output, every
    OpenCL device).  An installed venv (stubs): one line per step, nothing else."""
    import hashlib
    import shutil
    import stat

    venv = tmp_path / "venv"
    (venv / "bin").mkdir(parents=True)
    stubs = {"python": "#!/bin/sh\nexit 0\n",
             "clfx": "#!/bin/sh\necho '  [0:0] other device: not chosen'\n"
                     "echo '* [1:0] pthread-cpu (cpu, OpenCL 3.0): chosen'\n"
                     "echo '  [2:0] another: not chosen'\n"}
    for name, text in stubs.items():
        (venv / "bin" / name).write_text(text)
        (venv / "bin" / name).chmod(stat.S_IRWXU)
    want = hashlib.sha1((ROOT / "pyproject.toml").read_bytes()
                        + (ROOT / "scripts" / "setup.sh").read_bytes()).hexdigest()
    (venv / ".clfx-installed").write_text(want + "\n")
    bin_dir = tmp_path / "bin"          # a PATH without dpkg-query: no system packages step
    bin_dir.mkdir()
    for tool in ("dirname", "cat", "sha1sum", "cut", "mkdir", "sed", "head", "printf", "id"):
        found = shutil.which(tool)
        if found:
            (bin_dir / tool).symlink_to(found)
    out = subprocess.run([shutil.which("bash"), str(ROOT / "scripts" / "setup.sh")],
                         capture_output=True,
                         text=True, env={"PATH": str(bin_dir), "VENV": str(venv),
                                         "HOME": str(tmp_path)})
    assert out.returncode == 0, out.stderr
    lines = out.stderr.splitlines()
    assert out.stdout == "" and all(ln.startswith("clfx setup: ") for ln in lines), lines
    assert lines[-2:] == [f"clfx setup: Python packages in {venv}: up to date",
                          "clfx setup: OpenCL device: [1:0] pthread-cpu (cpu, OpenCL 3.0): chosen"]
