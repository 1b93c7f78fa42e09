"""Issue 10 item 8: what used to end in a traceback is one line and the documented exit code
(README: 0 ok, 1 processing error, 2 usage error, 130 SIGINT, 143 SIGTERM)."""
import os
import subprocess
import sys

import numpy as np
import pytest
from click.testing import CliRunner

from clfx.cli import cli

CLFX = [sys.executable, "-m", "clfx.cli"]


def one_line(stderr: str, *fragments) -> str:
    err = stderr.strip()
    assert err.startswith("clfx: error:") and "\n" not in err, err
    for f in fragments:
        assert f in err, err
    return err


def clfx(*args, input=b"", stdout=subprocess.PIPE, close_stdout=False, timeout=120):
    """Run the real entry point (``main``: stream guards, exit codes) in a subprocess."""
    return subprocess.run(CLFX + [str(a) for a in args], input=input, stdout=stdout,
                          stderr=subprocess.PIPE, timeout=timeout, check=False,
                          preexec_fn=(lambda: os.close(1)) if close_stdout else None)


@pytest.mark.parametrize("size", ["-64x32", "64x-32", "0x32", "64x", "64x32x2", "\uff16\uff14x32"])
def test_raw_size_must_be_two_positive_whole_numbers(size):
    r = CliRunner().invoke(cli, ["render", "-", "-", "--raw", size], input=b"\0" * 64)
    assert r.exit_code == 1, (r.exit_code, r.output)
    one_line(r.stderr, "is not WxH")


def test_raw_size_over_the_pixel_limit_is_refused_before_reading():
    """A real pipe: reading one 60000x60000 frame would allocate 43 GB (MemoryError)."""
    r = clfx("-q", "render", "-", "-", "--raw", "60000x60000", input=b"\0" * 64)
    assert r.returncode == 1, r.stderr
    one_line(r.stderr.decode(), "--raw frame is 60000x60000; the limit is", "CLFX_MAX_PIXELS")


def test_closed_stdout_is_one_line_and_exit_1(rt):
    w, h = 8, 4
    frame = np.zeros((3, h, w), np.float32).tobytes()
    r = clfx("-q", "render", "-", "-", "--look", "wide-angle", "--raw", f"{w}x{h}", input=frame,
             close_stdout=True)
    assert r.returncode == 1, r.stderr
    one_line(r.stderr.decode(), "stdout is closed")
    r = clfx("plugins", close_stdout=True)
    assert r.returncode == 1, r.stderr
    one_line(r.stderr.decode(), "stdout is closed")


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full")
@pytest.mark.parametrize("args", [("plugins",), ("look", "show", "default", "--json"),
                                  ("-q", "render", "-", "-", "--look", "wide-angle", "--raw", "8x4")])
def test_stdout_on_a_full_device_is_one_line_and_exit_1(rt, args):
    with open("/dev/full", "wb") as full:
        r = clfx(*args, input=np.zeros((3, 4, 8), np.float32).tobytes(), stdout=full)
    assert r.returncode == 1, r.stderr
    one_line(r.stderr.decode(), "cannot write to stdout", "No space left on device")


def test_a_closed_pipe_reader_exits_quietly():
    proc = subprocess.Popen(CLFX + ["describe", "vignette"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    proc.stdout.close()  # the reader went away (`clfx ... | head -0`)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode in (0, 1) and b"Traceback" not in err and b"Exception" not in err, err


# --------------------------------------------------------------------------------------------
# Issue 23, red team: hangs, tracebacks and silent reinterpretation

@pytest.fixture
def small(tmp_path):
    """A 24x16 EXR and a one-effect look in ``tmp_path``."""
    from clfx.core.frame import Frame
    from clfx.io.write import write_frame

    rgba = np.random.default_rng(1).uniform(0, 2, (16, 24, 4)).astype(np.float32)
    rgba[..., 3] = 1
    write_frame(Frame.from_array(rgba), tmp_path / "in.exr")
    (tmp_path / "look.yaml").write_text("name: t\neffects:\n  - effect: vignette\n")
    return tmp_path


def render_small(small, *args, env=None, **kw):
    """``clfx -q render in.exr o.exr --look look.yaml ARGS`` in ``small`` (a subprocess)."""
    return subprocess.run(CLFX + ["-q", "render", str(small / "in.exr"), str(small / "o.exr"),
                                  "--look", str(small / "look.yaml"), *map(str, args)],
                          capture_output=True, timeout=60, env=dict(os.environ, **(env or {})),
                          check=False, **kw)


@pytest.mark.parametrize("kind", ["fifo", "broken"])
def test_ocio_fifo_or_broken_config_is_refused_in_one_line(small, kind):
    """A FIFO blocked the OCIO library for ever (ignoring SIGTERM); a broken config was
    silently replaced by the built-in one."""
    config = small / "config.ocio"
    if kind == "fifo":
        os.mkfifo(config)
    else:
        config.write_text("garbage: [\n")
    r = render_small(small, env={"OCIO": str(config)})
    assert r.returncode == 1, r.stderr
    one_line(r.stderr.decode(), f"$OCIO {config}",
             "not a FIFO" if kind == "fifo" else "not a usable OCIO config")
    assert not (small / "o.exr").exists()


def test_log_on_a_fifo_is_refused_without_blocking(small):
    fifo = small / "log.fifo"
    os.mkfifo(fifo)
    r = render_small(small, "--log", fifo)
    assert r.returncode == 1, r.stderr
    one_line(r.stderr.decode(), f"cannot write --log {fifo}: not a regular file (a FIFO)")
    assert not (small / "o.exr").exists()


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full")
def test_log_on_a_full_disk_is_one_line_and_exit_1(small, rt):
    r = render_small(small, "--log", "/dev/full")
    assert r.returncode == 1, r.stderr
    one_line(r.stderr.decode(), "cannot write --log /dev/full: No space left on device")
