"""Issue 23, red team: every file a render reads is an input for every output, ``--log``
included.  ``Batch.reads`` is the one list (frames, depth and velocity files, the look's YAML
or the ``--look-from`` source, masks, kernel images, lens prescriptions, the OCIO config);
each test points ``--log`` or the output at one of them and checks the refusal and the bytes.
"""
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from clfx.cli import cli
from clfx.core.frame import Frame
from clfx.io.write import write_frame
from tests.test_io_batch import one_line_error

ROOT = Path(__file__).resolve().parents[1]
LENS = ROOT / "presets" / "lenses" / "double-gauss-50mm.yaml"

OCIO_CONFIG = """\
ocio_profile_version: 1
roles:
  default: raw
  scene_linear: lin_rec709
displays:
  sRGB:
    - !<View> {name: Raw, colorspace: raw}
colorspaces:
  - !<ColorSpace>
    name: raw
    isdata: true
  - !<ColorSpace>
    name: lin_rec709
    isdata: false
"""


@pytest.fixture
def shot(tmp_path, monkeypatch):
    """A frame, a kernel image, a mask, a depth file, a look YAML and a stamped output."""
    rgba = np.random.default_rng(1).uniform(0, 2, (16, 24, 4)).astype(np.float32)
    rgba[..., 3] = 1
    write_frame(Frame.from_array(rgba), tmp_path / "in.exr")
    write_frame(Frame.from_array(np.ones((5, 5, 4), np.float32)), tmp_path / "k.exr")
    write_frame(Frame.from_array(np.full((16, 24, 4), 0.5, np.float32)), tmp_path / "mask.exr")
    write_frame(Frame.from_array(np.full((16, 24, 4), 3.0, np.float32)), tmp_path / "depth.exr")
    (tmp_path / "look.yaml").write_text("name: t\neffects:\n  - effect: vignette\n")
    (tmp_path / "masked.yaml").write_text(
        "name: m\neffects:\n  - effect: vignette\n    mask: {file: mask.exr}\n")
    shutil.copy(LENS, tmp_path / "lens.yaml")
    (tmp_path / "config.ocio").write_text(OCIO_CONFIG)
    monkeypatch.chdir(tmp_path)
    r = CliRunner().invoke(cli, ["-q", "render", "in.exr", "stamped.exr", "--look", "look.yaml"])
    assert r.exit_code == 0, r.output
    return tmp_path


# (the file read, the command reading it, its role in the message)
READERS = {
    "kernel image": ("k.exr", ["apply", "glare", "in.exr", "OUT", "psf=image",
                               "kernel_path=k.exr"], "glare.kernel_path"),
    "mask": ("mask.exr", ["render", "in.exr", "OUT", "--look", "masked.yaml"], "mask"),
    "depth file": ("depth.exr", ["render", "in.exr", "OUT", "--look", "look.yaml",
                                 "--depth", "depth.exr"], "--depth"),
    "look YAML": ("look.yaml", ["render", "in.exr", "OUT", "--look", "look.yaml"], "look"),
    "look-from source": ("stamped.exr", ["render", "in.exr", "OUT", "--look-from",
                                         "stamped.exr"], "look"),
    "lens prescription": ("lens.yaml", ["apply", "lens_flare", "in.exr", "OUT",
                                        "lens=./lens.yaml"], "lens_flare.lens"),
    "OCIO config": ("config.ocio", ["render", "in.exr", "OUT", "--look", "look.yaml"], "$OCIO"),
}


def _invoke(shot, name, args, monkeypatch):
    if name == "OCIO config":
        monkeypatch.setenv("OCIO", str(shot / "config.ocio"))
    return CliRunner().invoke(cli, ["-q", *args])


@pytest.mark.parametrize("name", list(READERS))
def test_log_never_destroys_a_file_the_render_reads(shot, name, monkeypatch):
    path, args, role = READERS[name]
    before = (shot / path).read_bytes()
    r = _invoke(shot, name, [a.replace("OUT", "out.exr") for a in args] + ["--log", path],
                monkeypatch)
    assert r.exit_code == 1, (r.exit_code, r.output)
    one_line_error(r.stderr, f"--log {path} is an input of this render ({role})")
    assert (shot / path).read_bytes() == before
    assert not (shot / "out.exr").exists()


@pytest.mark.parametrize("name", list(READERS))
def test_output_never_replaces_a_file_the_render_reads(shot, name, monkeypatch):
    path, args, role = READERS[name]
    before = (shot / path).read_bytes()
    r = _invoke(shot, name, [a.replace("OUT", path) for a in args] + ["--overwrite"], monkeypatch)
    assert r.exit_code == 1, (r.exit_code, r.output)
    one_line_error(r.stderr, f"output {path} is an input of this render ({role})")
    assert (shot / path).read_bytes() == before


def test_look_from_x_with_output_x_is_refused(shot):
    before = (shot / "stamped.exr").read_bytes()
    r = CliRunner().invoke(cli, ["-q", "render", "in.exr", "stamped.exr", "--look-from",
                                 "stamped.exr", "--overwrite"])
    assert r.exit_code == 1, r.output
    one_line_error(r.stderr, "output stamped.exr is an input of this render (look)")
    assert (shot / "stamped.exr").read_bytes() == before


def test_a_hard_link_to_an_input_is_the_input(shot):
    os.link(shot / "look.yaml", shot / "alias.log")
    r = CliRunner().invoke(cli, ["-q", "render", "in.exr", "out.exr", "--look", "look.yaml",
                                 "--log", "alias.log"])
    assert r.exit_code == 1, r.output
    one_line_error(r.stderr, "--log alias.log is an input of this render (look)")
    assert (shot / "look.yaml").read_text().startswith("name: t")


def test_reads_is_one_list_the_writer_protects_too(shot):
    from clfx.api import load_look
    from clfx.pipeline.batch import Batch
    from clfx.pipeline.options import RenderOptions

    b = Batch(look=load_look("masked.yaml"), input_path="in.exr", output_path="o.exr",
              options=RenderOptions(depth_path="depth.exr"), verbosity=0)
    b.prepare()
    roles = {role for role, _ in b.reads}
    assert {"input", "--depth", "look", "mask"} <= roles, b.reads
    assert b.read_paths() == [p for _, p in b.reads]
