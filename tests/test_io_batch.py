"""Issue 10 where the batch calls io: files effects read are inputs (item 2), FIFOs as any input
(5), concurrent renders into one folder (7), ``--skip-existing`` sweeping killed runs' temp files
(9).  Checks that run before the first frame need no device; renders use the tiny vignette."""
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from clfx.cli import cli
from clfx.core.errors import ImageIOError
from clfx.core.frame import Frame
from clfx.core.plugin import Descriptor, PathParam
from clfx.host import Plugin
from clfx.io.read import read_frame
from clfx.io.write import write_frame
from clfx.pipeline.batch import Batch
from clfx.pipeline.preflight import look_files
from clfx.pipeline.look import Look, Step
from clfx.pipeline.presets import single_effect_look
from tests.test_damaged import run_with_timeout

ROOT = Path(__file__).resolve().parents[1]


class ReadsAFile(Plugin):
    """A step with a file parameter, as glare's kernel image (never rendered here)."""

    descriptor = Descriptor(name="reads_a_file", label="Reads a file", group="Test",
                            summary="test only", kernel="",
                            params=(PathParam("kernel_path", "", hint="A kernel image."),))


def look_reading(path) -> Look:
    return Look(name="reads", steps=[Step("reads_a_file", ReadsAFile.params(kernel_path=str(path)),
                                          plugin=ReadsAFile())])


def frames(folder: Path, count=4, w=48, h=32, name="in.{:04d}.exr"):
    rng = np.random.default_rng(7)
    for f in range(1, count + 1):
        write_frame(Frame.from_array(rng.uniform(0, 2, (h, w, 4)).astype(np.float32)),
                    folder / name.format(f))
    return str(folder / name.replace("{:04d}", "#"))


def batch(look, inp, out, **options) -> Batch:
    from clfx.pipeline.options import RenderOptions

    return Batch(look=look, input_path=str(inp), output_path=str(out),
                 options=RenderOptions(**options), verbosity=0)


def cli_run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)


def one_line_error(stderr, *fragments):
    err = stderr.strip()
    assert err.startswith("clfx: error:") and "\n" not in err, err
    for f in fragments:
        assert f in err, err
    return err


# --------------------------------------------------------------------------------------------
# Item 2: every file an effect reads is an input

def test_path_params_are_inputs(tmp_path):
    kernel = tmp_path / "k.exr"
    write_frame(Frame.from_array(np.ones((5, 5, 4), np.float32)), kernel)
    before = kernel.read_bytes()
    src = tmp_path / "in.exr"
    write_frame(Frame.from_array(np.ones((8, 8, 4), np.float32)), src)
    look = look_reading(kernel)
    assert look_files(look) == [("reads_a_file.kernel_path", str(kernel))]
    for out in (kernel, tmp_path / "sub" / ".." / "k.exr"):
        (tmp_path / "sub").mkdir(exist_ok=True)
        with pytest.raises(ImageIOError, match="is an input") as info:
            batch(look, src, out, overwrite=True).prepare()
        assert "\n" not in str(info.value)
    link = tmp_path / "link.exr"
    link.symlink_to(kernel)
    with pytest.raises(ImageIOError, match="is an input"):
        batch(look, src, link, overwrite=True).prepare()
    assert kernel.read_bytes() == before


def test_glare_kernel_image_never_overwritten(tmp_path, rt):
    """The red-team command: glare psf=image kernel_path=k.exr with --overwrite onto k.exr."""
    from clfx.plugins import get_plugin

    if get_plugin("glare").descriptor.param("kernel_path", "glare").kind != "path":
        pytest.skip("glare.kernel_path is not a PathParam in this tree yet")
    kernel = tmp_path / "k.exr"
    write_frame(Frame.from_array(np.ones((5, 5, 4), np.float32)), kernel)
    before = kernel.read_bytes()
    src = tmp_path / "in.exr"
    write_frame(Frame.from_array(np.ones((16, 16, 4), np.float32)), src)
    r = cli_run("apply", "glare", src, kernel, "psf=image", f"kernel_path={kernel}", "--overwrite")
    assert r.exit_code == 1
    one_line_error(r.stderr, "k.exr", "input")
    assert kernel.read_bytes() == before


# --------------------------------------------------------------------------------------------
# Item 5: a FIFO as any input is refused at once

def test_fifo_as_a_file_parameter_refused_before_any_frame(tmp_path):
    fifo = tmp_path / "k.exr"
    os.mkfifo(fifo)
    inp = frames(tmp_path, 1)
    err = run_with_timeout(batch(look_reading(fifo), inp, tmp_path / "o.#.exr").prepare,
                           timeout=20)
    assert isinstance(err, ImageIOError), err
    msg = str(err)
    assert "reads_a_file.kernel_path" in msg and "not a regular file (a FIFO)" in msg, msg


@pytest.mark.parametrize("where", ["input", "--depth", "--velocity"])
def test_fifo_on_the_command_line_refused(tmp_path, where):
    fifo = tmp_path / "pipe.0001.exr"
    os.mkfifo(fifo)
    good = frames(tmp_path, 1)
    args = ["apply", "vignette", fifo if where == "input" else good, tmp_path / "o.#.exr"]
    if where != "input":
        args += [where, fifo]
    proc = subprocess.run([sys.executable, "-m", "clfx.cli", *map(str, args)], timeout=120,
                          capture_output=True, text=True, check=False,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert proc.returncode == 1, proc.stderr
    one_line_error(proc.stderr, "pipe.0001.exr", "not a regular file (a FIFO)")
    assert not list(tmp_path.glob("o.*"))


# --------------------------------------------------------------------------------------------
# Item 7: concurrent writers

def test_output_appearing_during_a_batch(tmp_path, rt):
    inp = frames(tmp_path, 3)
    out = tmp_path / "out" / "o.#.exr"
    look = single_effect_look("vignette", ["amount=0.5"])
    b = batch(look, inp, out)
    b.prepare()                                       # nothing there yet
    other = tmp_path / "out" / "o.0002.exr"
    other.write_bytes(b"another render's frame 2")    # another writer publishes meanwhile
    with pytest.raises(ImageIOError, match="o.0002.exr") as info:
        b.run(rt)
    assert "\n" not in str(info.value)
    assert other.read_bytes() == b"another render's frame 2"
    assert read_frame(tmp_path / "out" / "o.0001.exr").rgba.shape == (32, 48, 4)
    assert not [p for p in (tmp_path / "out").iterdir() if ".tmp-" in p.name]
    for f in (1, 3):                                 # frame 3 may have been written too
        (tmp_path / "out" / f"o.000{f}.exr").unlink(missing_ok=True)
    b = batch(look, inp, out, skip_existing=True)
    b.prepare()
    assert [j.frame for j in b.jobs] == [1, 3]
    (tmp_path / "out" / "o.0003.exr").write_bytes(b"frame 3 from elsewhere")
    b.run(rt)                                        # skips frame 3 cleanly
    assert b.skipped_existing == [2, 3]
    assert (tmp_path / "out" / "o.0003.exr").read_bytes() == b"frame 3 from elsewhere"
    assert read_frame(tmp_path / "out" / "o.0001.exr").rgba.shape == (32, 48, 4)


def test_dangling_symlink_output_refused_before_rendering(tmp_path):
    inp = frames(tmp_path, 1)
    out = tmp_path / "o.0001.exr"
    out.symlink_to(tmp_path / "nowhere" / "x.exr")
    with pytest.raises(ImageIOError, match="exists"):
        batch(single_effect_look("vignette", []), inp, tmp_path / "o.#.exr").prepare()
    assert out.is_symlink() and not (tmp_path / "nowhere").exists()


def test_two_renders_into_one_folder(tmp_path, rt):
    """Two `clfx apply` processes, same inputs and outputs, no --overwrite: every output is
    whole, each process either finishes or stops with one line saying the output exists."""
    inp = frames(tmp_path, 6, 96, 64)
    out_dir = tmp_path / "out"
    out = out_dir / "o.#.exr"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    for extra in ([], ["--skip-existing"]):
        procs = [subprocess.Popen([sys.executable, "-m", "clfx.cli", "-q", "apply", "vignette",
                                   inp, str(out), "amount=0.5", *extra],
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                  env=env) for _ in range(2)]
        results = [(p.wait(timeout=300), p.stderr.read()) for p in procs]
        for rc, err in results:
            if extra:
                assert rc == 0, err
            else:
                assert rc in (0, 1), err
                if rc == 1:
                    one_line_error(err, "o.0")
                    assert "exists" in err or "appeared" in err, err
        names = sorted(p.name for p in out_dir.iterdir())
        assert not [n for n in names if ".tmp-" in n], names
        want = single_effect_look("vignette", ["amount=0.5"])
        from clfx.pipeline.look import render_frame

        for n in names:                                  # whole and right, whoever won
            f = int(n.split(".")[1])
            ref, _ = render_frame(rt, want, read_frame(tmp_path / f"in.{f:04d}.exr"))
            np.testing.assert_array_equal(read_frame(out_dir / n).rgba,
                                          ref.rgba.astype(np.float16).astype(np.float32))
        if extra:
            assert names == [f"o.{f:04d}.exr" for f in range(1, 7)]
        else:
            for n in names:
                (out_dir / n).unlink()


# --------------------------------------------------------------------------------------------
# Item 9: --skip-existing sweeps what killed runs left

def test_skip_existing_sweeps_stale_temps(tmp_path):
    inp = frames(tmp_path, 2)
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True).stdout.strip()
    stale = out_dir / f".o.0002.exr.tmp-{dead}-0badc0de.exr"
    live = out_dir / f".o.0002.exr.tmp-{os.getppid()}-0badc0de.exr"     # a live process
    stale.write_bytes(b"half a frame")
    live.write_bytes(b"being written")
    b = batch(single_effect_look("vignette", []), inp, out_dir / "o.#.exr", skip_existing=True)
    b.prepare()
    assert not stale.exists() and live.exists()
    b = batch(single_effect_look("vignette", []), inp, out_dir / "o.#.exr")
    stale.write_bytes(b"half a frame")
    b.prepare()                                       # only --skip-existing sweeps
    assert stale.exists()
