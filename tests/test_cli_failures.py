"""Issue 10 item 8: what used to end in a traceback is one line and the documented exit code
(docs/reliability.md: 0 ok, 1 processing error, 2 usage error, 130 SIGINT, 143 SIGTERM)."""
import os
import subprocess
import sys

import numpy as np
import pytest
from click.testing import CliRunner

from clfx.cli import cli
from tests.conftest import stamped

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
    """A usage error (exit 2, one line; issue 23: was exit 1)."""
    r = CliRunner().invoke(cli, ["render", "-", "-", "--raw", size], input=b"\0" * 64)
    assert r.exit_code == 2, (r.exit_code, r.output)
    one_line(r.stderr, "Invalid value for '--raw'", "is not WxH")


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


def render_small(small, *args, env=None, **kw):
    """``clfx -q render in.exr o.exr --look look.yaml ARGS`` in ``small`` (a subprocess;
    without --look when ARGS give --look-from)."""
    look = [] if "--look-from" in args else ["--look", str(small / "look.yaml")]
    return subprocess.run(CLFX + ["-q", "render", str(small / "in.exr"), str(small / "o.exr"),
                                  *look, *map(str, args)],
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


@pytest.mark.parametrize("look_json,message", [
    ('{"name": "x", "description": "' + "x" * (2 << 20) + '"}', "the limit is 1048576"),
    ("[" * 100000 + "]" * 100000, "nested 100000 levels deep; the limit is 32"),
    ('{"name": "x", "seed": ' + "9" * 5000 + "}", "is not JSON"),
], ids=["2MB", "deep", "5000-digits"])   # short ids: pytest puts the id in PYTEST_CURRENT_TEST,
# which the CLI subprocess inherits; a 2 MB environment string fails exec with E2BIG
def test_look_from_a_hostile_stamp_is_refused_in_one_line(small, look_json, message):
    """A 2 MB lookJSON had no size limit (YAML looks have 1 MiB); deep JSON and a 5000-digit
    integer were tracebacks."""
    stamped(small / "stamp.exr", look_json)
    r = render_small(small, "--look-from", small / "stamp.exr")
    assert r.returncode == 1, r.stderr
    one_line(r.stderr.decode(), "clfx:lookJSON", message)


def test_a_5000_digit_yaml_integer_is_one_line(small):
    (small / "big.yaml").write_text("name: big\nseed: " + "9" * 5000 + "\neffects: []\n")
    r = clfx("look", "show", small / "big.yaml")
    assert r.returncode == 1, r.stderr
    one_line(r.stderr.decode(), "big.yaml:2: an integer of 5000 digits")


@pytest.mark.parametrize("args", [("apply", "dof", "IN", "OUT", "blades=2"),
                                  ("apply", "streaks", "IN", "OUT", "blades=1"),
                                  ("render", "IN", "OUT", "--set", "camera.blades=1")])
def test_one_or_two_blades_are_refused_not_rendered_round(small, args):
    r = CliRunner().invoke(cli, [str(small / "in.exr") if a == "IN" else
                                 str(small / "o.exr") if a == "OUT" else a for a in args])
    assert r.exit_code == 1, r.output
    one_line(r.stderr, "is not allowed (1 or 2 blades make no polygon")
    assert not (small / "o.exr").exists()


@pytest.fixture
def silent_port():
    """A TCP port that accepts connections and never says a word (not a Dask scheduler)."""
    import socket
    import threading

    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(8)
    held = []

    def accept():
        while True:
            try:
                held.append(srv.accept()[0])
            except OSError:
                return

    threading.Thread(target=accept, daemon=True).start()
    yield srv.getsockname()[1]
    srv.close()
    for c in held:
        c.close()


def test_a_port_that_is_not_dask_times_out_in_one_line(silent_port):
    import time

    from clfx.core.errors import ClusterError
    from clfx.pipeline.distributed import check_scheduler

    t0 = time.perf_counter()
    with pytest.raises(ClusterError, match="no Dask scheduler answered within 1 s"):
        check_scheduler(f"tcp://127.0.0.1:{silent_port}", timeout=1.0)
    assert time.perf_counter() - t0 < 10


@pytest.mark.parametrize("address,message", [
    ("foo://x:1", "unknown protocol 'foo'"),
    ("tcp://127.0.0.1:99999", "not an address like tcp://HOST:8786"),
    ("tcp://127.0.0.1:1", "cannot reach scheduler tcp://127.0.0.1:1: Connection refused"),
])
@pytest.mark.parametrize("how", ["option", "env"])
def test_a_bad_scheduler_is_one_line_at_once(small, address, message, how):
    """Was 61 s and then a traceback."""
    args = ("--scheduler", address) if how == "option" else ()
    r = render_small(small, *args, env={"CLFX_SCHEDULER": address} if how == "env" else None)
    assert r.returncode == 1, r.stderr
    one_line(r.stderr.decode(), message)
    assert not (small / "o.exr").exists()


@pytest.mark.parametrize("kw,error,message", [
    ({"quality": "ultra"}, ValueError, "quality: 'ultra' is not one of draft, preview"),
    ({"frame": "x"}, TypeError, "frame: 'x' (str) is not a whole number"),
    ({"look": 5}, TypeError, "look: 5 (int) is not a look name, a file, a dict or a Look"),
    ({"rgba": np.full((4, 6, 4), 255, np.uint8)}, TypeError, "rgba: dtype uint8 is not floating"),
    ({"rgba": np.ones((4, 6, 4), bool)}, TypeError, "rgba: dtype bool is not floating"),
    ({"rgba": np.ones((4, 6, 4), complex)}, TypeError, "rgba: dtype complex128 is not floating"),
    ({"depth": np.ones((4, 6), np.int64)}, TypeError, "depth: dtype int64 is not floating"),
])
def test_api_arguments_of_the_wrong_type_or_value_name_the_argument(kw, error, message):
    import re

    import clfx

    args = {"rgba": np.ones((4, 6, 4), np.float32), "look": {"effects": []}, **kw}
    with pytest.raises(error, match=re.escape(message)):
        clfx.render_array(args.pop("rgba"), args.pop("look"), **args)


def test_api_float_arrays_of_any_width_are_float32(rt):
    import clfx

    for dtype in (np.float16, np.float64):
        out = clfx.render_array(np.full((4, 6, 4), 0.5, dtype), {"effects": []})
        assert out.rgba.dtype == np.float32 and np.all(out.rgba == 0.5)


def test_api_render_names_bad_quality_and_look(small):
    import clfx

    with pytest.raises(ValueError, match="quality: 'ultra'"):
        clfx.render_file(small / "in.exr", small / "o.exr", quality="ultra")
    with pytest.raises(TypeError, match="look: 5"):
        clfx.render_file(small / "in.exr", small / "o.exr", 5)


@pytest.mark.parametrize("pattern", ["o.#.#.exr", "o.%04d.$F4.exr", "o_#_v2.#.exr"])
def test_two_frame_tokens_in_a_pattern_are_refused(small, pattern):
    r = CliRunner().invoke(cli, ["render", str(small / "in.exr"), str(small / pattern),
                                 "--look", str(small / "look.yaml")])
    assert r.exit_code == 1, r.output
    one_line(r.stderr, "2 frame tokens", "give one")
    assert list(small.glob("o*")) == []


@pytest.mark.parametrize("out,args,message", [
    ("o.exr", ("--compression", "bogus"), "compression 'bogus' not supported"),
    ("o.png", ("--compression", "zip"), "compression 'zip' not supported"),
    ("o.png", ("--float",), "bit depth 'float' not supported"),
])
def test_bad_output_options_are_found_before_rendering(small, monkeypatch, out, args, message):
    """Was found only when the first frame was written (after its render)."""
    from clfx.pipeline import look as look_module

    def no_render(*a, **k):
        raise AssertionError("rendered before the output options were checked")

    monkeypatch.setattr(look_module, "render_frame", no_render)
    monkeypatch.setattr("clfx.pipeline.plan.render_frame", no_render)
    r = CliRunner().invoke(cli, ["render", str(small / "in.exr"), str(small / out),
                                 "--look", str(small / "look.yaml"), *args])
    assert r.exit_code == 1, r.output
    one_line(r.stderr, message)


def test_zero_bytes_of_raw_stdin_is_an_error(rt):
    r = clfx("-q", "render", "-", "-", "--look", "wide-angle", "--raw", "8x4", input=b"")
    assert r.returncode == 1, r.stderr
    one_line(r.stderr.decode(), "stdin: no raw frames (0 bytes")
    assert r.stdout == b""


@pytest.mark.parametrize("args,message", [
    (("render", "-", "o.exr"), "'-' as INPUT needs --raw WxH"),
    (("render", "i.exr", "o.exr", "--raw-format", "rgbf32le"), "--raw-format is for raw pipes"),
    (("render", "i.exr", "o.exr", "--raw", "8x4"), "--raw WxH is for raw pipes"),
    (("render", "i.exr", "o.#.exr", "--workers", "2", "--scheduler", "tcp://h:1"),
     "give --workers N (a local cluster) or --scheduler ADDRESS"),
    (("render", "i.exr", "o.exr", "--bogus"), "No such option '--bogus'"),
    (("--bogus",), "No such option '--bogus'"),
    (("nosuchcommand",), "No such command 'nosuchcommand'"),
])
def test_usage_errors_are_one_line_and_exit_2(args, message):
    """Were click's three-line form (--raw, --workers with --scheduler: exit 1)."""
    r = clfx(*args)
    assert r.returncode == 2, r.stderr
    one_line(r.stderr.decode(), message, "--help)")
    r = CliRunner().invoke(cli, list(args))       # the click entry point says the same
    assert r.exit_code == 2, r.output
    one_line(r.stderr, message)
