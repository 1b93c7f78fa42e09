"""Issue 34 (red team v3): hostile names, environment values, scheduler replies, YAML and
stamps through the real command line: one ``clfx: error:`` line (or one warning), never a
traceback, a hang or a silent reinterpretation."""
import os
import socket
import subprocess
import sys
import threading

import numpy as np
import pytest

from tests.conftest import stamped

CLFX = [sys.executable, "-m", "clfx.cli"]


def one_line(stderr, *fragments) -> str:
    err = (stderr.decode(errors="backslashreplace") if isinstance(stderr, bytes) else stderr).strip()
    assert err.startswith("clfx: error:") and "\n" not in err, err
    for f in fragments:
        assert f in err, err
    return err


def clfx(*args, env=None, cwd=None, timeout=120):
    """The real entry point in a subprocess; arguments may be bytes (names that are not
    UTF-8)."""
    return subprocess.run(CLFX + [a if isinstance(a, bytes) else str(a) for a in args],
                          capture_output=True, timeout=timeout, check=False, cwd=cwd,
                          env=dict(os.environ, **(env or {})))



# -- environment values ------------------------------------------------------------------------
@pytest.mark.parametrize("var", ["CLFX_TILE_PIXELS", "CLFX_POOL_MB", "CLFX_MAX_PIXELS",
                                 "CLFX_IO_NICE"])
def test_an_integer_environment_variable_that_is_not_one_is_one_line(small, var):
    """Were ValueError tracebacks."""
    r = clfx("-q", "render", small / "in.exr", small / "o.exr", "--look", small / "look.yaml",
             env={var: "abc"})
    assert r.returncode == 1, r.stderr
    one_line(r.stderr, f"{var}='abc' is not a whole number")
    assert not (small / "o.exr").exists()


def test_env_int_reads_whole_numbers_in_exponent_form(monkeypatch):
    from clfx.core.errors import ClfxError
    from clfx.core.limits import env_int

    monkeypatch.setenv("CLFX_X", "1e3")
    assert env_int("CLFX_X", 5) == 1000
    monkeypatch.setenv("CLFX_X", " ")
    assert env_int("CLFX_X", 5) == 5
    for bad in ("1.5", "inf", "nan", "0x10"):
        monkeypatch.setenv("CLFX_X", bad)
        with pytest.raises(ClfxError, match="is not a whole number"):
            env_int("CLFX_X", 5)
    monkeypatch.setenv("CLFX_X", "-1")
    with pytest.raises(ClfxError, match="is below 0"):
        env_int("CLFX_X", 5, minimum=0)


# -- names that are not UTF-8 --------------------------------------------------------------------
def test_an_input_name_that_is_not_utf8_is_one_line(small):
    os.rename(small / "in.exr", os.fsencode(small) + b"/caf\xe9.exr")
    r = clfx("-q", "apply", "vignette", os.fsencode(small) + b"/caf\xe9.exr", small / "o.exr")
    assert r.returncode == 1, r.stderr
    one_line(r.stderr, "caf\\xe9.exr: the name is not UTF-8 text")


@pytest.mark.parametrize("folder", [False, True])
def test_an_output_name_that_is_not_utf8_is_refused_before_rendering(small, folder):
    out = os.fsencode(small) + (b"/d\xe9/o.exr" if folder else b"/o\xe9.exr")
    r = clfx("-q", "apply", "vignette", small / "in.exr", out)
    assert r.returncode == 1, r.stderr
    one_line(r.stderr, "cannot write", "\\xe9", "the name is not UTF-8 text")
    assert sorted(os.listdir(small)) == ["in.exr", "look.yaml"]


def test_a_log_name_that_is_not_utf8_is_written_and_stamped_escaped(small):
    """The command line was stamped into the output after rendering: RuntimeError."""
    import OpenImageIO as oiio

    log = os.fsencode(small) + b"/l\xe9.txt"
    r = clfx("-q", "render", small / "in.exr", small / "o.exr", "--look", small / "look.yaml",
             "--log", log)
    assert r.returncode == 0, r.stderr
    assert os.path.getsize(log) > 0
    inp = oiio.ImageInput.open(str(small / "o.exr"))
    stamped = " ".join(str(a.value) for a in inp.spec().extra_attribs)
    inp.close()
    assert "l\\xe9.txt" in stamped


def test_a_look_named_with_a_lone_surrogate_is_stamped_escaped(small):
    """Was a RuntimeError after rendering, when its name was stamped."""
    (small / "sur.yaml").write_text('name: "\\ud800"\neffects:\n  - effect: vignette\n')
    r = clfx("-q", "render", small / "in.exr", small / "o.exr", "--look", small / "sur.yaml")
    assert r.returncode == 0, r.stderr
    r = clfx("-q", "render", small / "in.exr", small / "o2.exr", "--look-from", small / "o.exr")
    assert r.returncode == 0, r.stderr


# -- hostile scheduler replies -------------------------------------------------------------------
@pytest.fixture
def banner_port():
    """A TCP port on 127.0.0.1 that greets every connection with an SSH banner (not Dask),
    for at most 60 s."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(8)
    srv.settimeout(60)

    def serve():
        while True:
            try:
                conn = srv.accept()[0]
            except OSError:
                return
            with conn:
                conn.sendall(b"SSH-2.0-OpenSSH_9.6\r\n")
                conn.settimeout(2)
                try:
                    conn.recv(1024)
                except OSError:
                    pass

    threading.Thread(target=serve, daemon=True).start()
    yield srv.getsockname()[1]
    srv.close()


def test_a_port_that_answers_a_banner_is_not_a_scheduler(small, banner_port):
    """Was 20 s, then 'Unable to allocate 3.01 EiB' and a Client timeout traceback."""
    r = clfx("-q", "render", small / "in.exr", small / "o.exr", "--look", small / "look.yaml",
             "--scheduler", f"tcp://127.0.0.1:{banner_port}", timeout=60)
    assert r.returncode == 1, r.stderr
    one_line(r.stderr, "is not a Dask scheduler (it said 'SSH-2.0-OpenSSH_9.6')")
    assert not (small / "o.exr").exists()


# -- bench outputs and sizes ---------------------------------------------------------------------
BENCH = ("bench", "--effects", "vignette", "--looks", "none", "--size", "16x8", "--repeat", "1",
         "--sequence-frames", "0")


@pytest.mark.parametrize("args,message", [
    (("--markdown", "/dev/full"), "cannot write --markdown /dev/full: No space left on device"),
    (("--markdown", "/nonexistent-clfx/t.md"), "cannot write --markdown /nonexistent-clfx/t.md"),
    (("--plot", "x.xyz"), "--plot x.xyz: .xyz is not a format matplotlib writes"),
    (("--size", "70000x70000"), "--size is 70000x70000; the limit is"),
])
def test_bench_refuses_what_it_cannot_do_before_running(tmp_path, args, message):
    """/dev/full and .xyz failed after the whole bench; 70000x70000 printed 'FAILED:
    MemoryError' and exited 0."""
    if args[1] == "/dev/full" and not os.path.exists("/dev/full"):
        pytest.skip("needs /dev/full")
    r = clfx(*BENCH, *args, cwd=tmp_path)
    assert r.returncode == 1, r.stderr
    one_line(r.stderr, message)
    assert not r.stdout


# -- YAML read as YAML 1.2 -----------------------------------------------------------------------
def look_show(path, text):
    path.write_text("name: y\n" + text)
    return clfx("look", "show", path, "--json")


@pytest.mark.parametrize("text,message", [
    ("camera: {focus_distance: 1:2.5}\n",
     "camera.focus_distance: '1:2.5' is not a number; keyframes in a look file are a mapping: "
     "{1: 2.5}"),
    ("seed: 190:20:30\n", "seed: '190:20:30' is not an integer"),
    ("seed: yes\n", "seed: 'yes' is not an integer"),
    ("seed: !!int abc\n", "'abc' is not an integer"),
])
def test_yaml_base60_and_yes_are_not_numbers(tmp_path, text, message):
    """YAML 1.1 read 1:2.5 as 62.5 and 190:20:30 as 685230, without a word."""
    r = look_show(tmp_path / "y.yaml", text)
    assert r.returncode == 1, r.stdout
    one_line(r.stderr, message)


@pytest.mark.parametrize("text,key,value", [
    ("effects: [{effect: glare, params: {size: 1e-3}}]\n", ("effects", 0, "params", "size"), 1e-3),
    ("seed: 0777\n", ("seed",), 777),          # YAML 1.1: octal 511
    ("seed: 0o17\n", ("seed",), 15),
    ("seed: 0x1F\n", ("seed",), 31),
    ("camera: {focus_distance: {1: 2.0, 10: 5.0e+0}}\n", ("camera", "focus_distance", "10"), 5.0),
])
def test_yaml_numbers_read_as_yaml_1_2(tmp_path, text, key, value):
    """1e-3 was 'not a number' (text in YAML 1.1)."""
    import json

    r = look_show(tmp_path / "y.yaml", text)
    assert r.returncode == 0, r.stderr
    got = json.loads(r.stdout)
    for k in key:
        got = got[k]
    assert got == value


# -- keyframes ----------------------------------------------------------------------------------
@pytest.mark.parametrize("how", ["set", "yaml"])
def test_keyframed_blades_may_not_pass_through_refused_counts(small, how):
    """blades 0 -> 6 rendered frames with 1 and 2 blades, which a fixed value refuses."""
    if how == "set":
        r = clfx("-q", "render", small / "in.exr", small / "o.exr", "--look", small / "look.yaml",
                 "--set", "camera.blades=1:0,10:6")
    else:
        (small / "k.yaml").write_text("name: k\ncamera: {blades: {1: 0, 10: 6}}\n"
                                      "effects:\n  - effect: vignette\n")
        r = clfx("-q", "render", small / "in.exr", small / "o.exr", "--look", small / "k.yaml")
    assert r.returncode == 1, r.stderr
    one_line(r.stderr, "blades at frame 2 (between the keys at frames 1 and 10): 1 is not "
                       "allowed")
    assert not (small / "o.exr").exists()


def test_integer_keys_far_apart_are_checked_value_by_value():
    from clfx.core.camera import Camera
    from clfx.pipeline import animation

    def check(v, where):
        try:
            return Camera.validate("blades", v)
        except ValueError as exc:
            raise ValueError(f"{where}: {exc}") from None

    with pytest.raises(ValueError, match="between the keys at frames 1 and 1000000000"):
        animation.parse({1: 0, 10 ** 9: 6}, check, "camera.blades", integer=True)
    assert animation.parse({1: 3, 10 ** 9: 6}, check, "camera.blades", integer=True).at(5) == 3


# -- stamps -------------------------------------------------------------------------------------
def test_a_stamp_with_a_key_twice_is_refused_as_a_look_file_is(small):
    """Last one won in a stamp; a look file refuses it."""
    stamped(small / "stamp.exr", '{"name": "x", "seed": 1, "seed": 2, "effects": []}')
    r = clfx("-q", "render", small / "in.exr", small / "o.exr", "--look-from", small / "stamp.exr")
    assert r.returncode == 1, r.stderr
    one_line(r.stderr, "clfx:lookJSON has the key 'seed' twice")


# -- --skip-existing ----------------------------------------------------------------------------
def test_skip_existing_says_when_it_keeps_frames_of_another_look(small):
    """Frames 1-2 of 'default' and 3-4 of 'cinema' side by side, both exit 0, no word."""
    for f in range(1, 5):
        os.link(small / "in.exr", small / f"in.{f:04d}.exr")
    seq = (small / "in.#.exr", small / "o.#.exr")
    r = clfx("-q", "render", *seq, "--look", small / "look.yaml", "--frames", "1-2")
    assert r.returncode == 0, r.stderr
    (small / "other.yaml").write_text("name: other\neffects:\n  - effect: vignette\n"
                                      "    params: {radius: 0.25}\n")
    r = clfx("-q", "render", *seq, "--look", small / "other.yaml", "--frames", "1-4",
             "--skip-existing")
    assert r.returncode == 0, r.stderr
    warned = [ln for ln in r.stderr.decode().splitlines() if "--skip-existing keeps" in ln]
    assert warned == ["clfx: warning: --skip-existing keeps frame(s) 1-2 rendered with another "
                      "look or other parameters ('t'; this render: 'other'); use --overwrite "
                      "to render them again"], r.stderr
    r = clfx("-q", "render", *seq, "--look", small / "look.yaml", "--frames", "1-2",
             "--skip-existing")
    assert r.returncode == 0 and b"keeps" not in r.stderr, r.stderr


# -- raw pipes ----------------------------------------------------------------------------------
@pytest.mark.parametrize("option", ["--depth", "--velocity"])
def test_passes_with_raw_pipes_are_refused_not_ignored(small, option):
    """'dof skipped: no depth pass' although --depth was given."""
    r = subprocess.run(CLFX + ["-q", "render", "-", "-", "--raw", "8x4", "--look", "cinema",
                               option, str(small / "in.exr")],
                       input=np.zeros((3, 4, 8), np.float32).tobytes(), capture_output=True,
                       timeout=60, check=False)
    assert r.returncode == 1 and not r.stdout, r.stderr
    one_line(r.stderr, f"{option} cannot go with raw frames on stdin")


# -- OpenJD export ------------------------------------------------------------------------------
@pytest.fixture
def shot(small):
    for f in range(1, 4):
        os.link(small / "in.exr", small / f"in.{f:04d}.exr")
    return small / "in.#.exr", small / "o.#.exr"


def test_openjd_keeps_user_text_with_braces_literal(shot, tmp_path):
    """``--log {{Param.ClfxCommand}}.txt`` was expanded by the farm at run time."""
    import yaml

    r = clfx("farm", "openjd", *shot, "--set", "vignette.radius=0.3", "--",
             "--log", "{{Param.ClfxCommand}}.txt")
    assert r.returncode == 0, r.stderr
    template = yaml.safe_load(r.stdout)
    args = template["steps"][0]["script"]["actions"]["onRun"]["args"]
    assert args[-2:] == ["--log", "{{Param.Arg1}}"]
    assert args.count("--skip-existing") == 1 and "vignette.radius=0.3" in args
    arg1 = next(p for p in template["parameterDefinitions"] if p["name"] == "Arg1")
    assert arg1["default"] == "{{Param.ClfxCommand}}.txt"
    (tmp_path / "job.yaml").write_text(r.stdout.decode())
    check = subprocess.run([os.path.join(os.path.dirname(sys.executable), "openjd"), "check",
                            str(tmp_path / "job.yaml")], capture_output=True, timeout=60)
    assert check.returncode == 0, check.stdout + check.stderr


@pytest.mark.parametrize("args,message", [
    (("--name", "a {{bogus}}"), "name: Variable bogus does not exist"),
    (("--name", "x" * 300), "name must be at most 128 characters long"),
])
def test_an_invalid_openjd_template_is_refused_not_printed(shot, args, message):
    """Printed with exit 0; `openjd check` refused it."""
    r = clfx("farm", "openjd", *shot, *args)
    assert r.returncode == 1 and not r.stdout, r.stderr
    one_line(r.stderr, "the OpenJD template would be invalid", message)


def test_a_look_path_with_braces_makes_a_valid_template(shot, small):
    import yaml

    folder = small / "lk{{Param.Look}}"
    folder.mkdir()
    (folder / "l{{Param.Look}}.yaml").write_text("name: l\neffects: []\n")
    r = clfx("farm", "openjd", *shot, "--look", folder / "l{{Param.Look}}.yaml")
    assert r.returncode == 0, r.stderr
    assert "{" not in yaml.safe_load(r.stdout)["name"]


@pytest.mark.parametrize("args,message", [
    (("--bogus-opt", "1"), "No such option '--bogus-opt'"),
    (("--quality", "ultra"), "'ultra' is not one of"),
])
def test_openjd_pass_through_options_are_checked_as_render_options(shot, args, message):
    """``-- --bogus-opt 1`` was copied into every task."""
    r = clfx("farm", "openjd", *shot, "--", *args)
    assert r.returncode == 2 and not r.stdout, r.stderr
    one_line(r.stderr, "after '--' (clfx render options for every task)", message)


# -- Cryptomatte --------------------------------------------------------------------------------
def test_a_manifest_id_no_pixel_carries_is_said(tmp_path, rt, capfd):
    """A manifest mapping a name to a number (read as hex: an id no pixel has) selected
    nothing, said only by --explain."""
    import json

    import clfx
    from tests.test_mask_refusals import _crypto_file, masked

    _crypto_file(tmp_path / "in.exr", json.dumps({"boxA": 12345, "boxB": "0"}))
    clfx.render_file(tmp_path / "in.exr", tmp_path / "o.exr",
                     masked({"cryptomatte": "CryptoObject", "names": ["boxA"]}))
    err = [ln for ln in capfd.readouterr().err.splitlines() if "selects no pixel" in ln]
    assert len(err) == 1 and err[0].startswith("clfx: warning: mask cryptomatte "
                                               "CryptoObject[boxA]: selects no pixel of frame"), err


# -- numbers at the ends of float32 -------------------------------------------------------------
@pytest.mark.parametrize("effect,value,args", [
    ("lens_flare", 3e38, ()),
    ("grain", 1e-40, ()),
    ("sensor_noise", 1e-40, ("middle_grey=0",)),
    ("sensor_noise", 1e-40, ("middle_grey=1e-40",)),
])
def test_extreme_values_leak_no_numpy_warning(tmp_path, effect, value, args):
    """A NaN light centre (3e38) and 1/grey overflowing float32 (denormals) were numpy
    RuntimeWarnings with no clfx message."""
    import OpenImageIO as oiio

    rgba = np.full((16, 24, 4), value, np.float32)
    rgba[..., 3] = 1
    out = oiio.ImageOutput.create(str(tmp_path / "in.exr"))
    out.open(str(tmp_path / "in.exr"), oiio.ImageSpec(24, 16, 4, "float"))
    out.write_image(rgba)
    out.close()
    r = clfx("-q", "apply", effect, tmp_path / "in.exr", tmp_path / "o.exr", *args,
             env={"PYTHONWARNINGS": "error::RuntimeWarning"})
    assert r.returncode == 0 and b"Warning" not in r.stderr, r.stderr


# -- minor --------------------------------------------------------------------------------------
def test_a_gap_in_a_sequence_on_disk_is_one_notice(small):
    for f in (1, 2, 4, 5):
        os.link(small / "in.exr", small / f"in.{f:04d}.exr")
    r = clfx("render", small / "in.#.exr", small / "o.#.exr", "--look", small / "look.yaml")
    assert r.returncode == 0, r.stderr
    said = [ln for ln in r.stderr.decode().splitlines() if "gaps" in ln]
    assert len(said) == 1 and "frame(s) 3 missing between 1 and 5; rendering the 4 there" \
        in said[0], r.stderr
    for f in (1, 3, 5):      # evenly stepped: a sequence, not a gap
        os.link(small / "in.exr", small / f"s.{f:04d}.exr")
    r = clfx("render", small / "s.#.exr", small / "t.#.exr", "--look", small / "look.yaml")
    assert r.returncode == 0 and b"gaps" not in r.stderr, r.stderr


def test_a_truncated_png_is_clfx_line_alone(tmp_path):
    """libpng printed 'libpng error: ...' on stderr before clfx's line."""
    import OpenImageIO as oiio

    out = oiio.ImageOutput.create(str(tmp_path / "p.png"))
    out.open(str(tmp_path / "p.png"), oiio.ImageSpec(64, 64, 3, "uint8"))
    out.write_image(np.random.default_rng(2).random((64, 64, 3), np.float32))
    out.close()
    data = (tmp_path / "p.png").read_bytes()
    (tmp_path / "t.png").write_bytes(data[:len(data) // 2])
    r = clfx("-q", "apply", "vignette", tmp_path / "t.png", tmp_path / "o.exr")
    assert r.returncode == 1, r.stderr
    one_line(r.stderr, "cannot read", "t.png")


@pytest.mark.parametrize("where", ["input", "look-from", "depth"])
def test_a_link_to_a_file_that_is_no_image_is_not_quoted(small, where):
    """OpenEXR's error named the linked file's first 8 bytes (a key, a password file)."""
    (small / "secret.txt").write_text("hunter2-secret\n")
    os.symlink(small / "secret.txt", small / "lnk.exr")
    args = {"input": ("apply", "vignette", small / "lnk.exr", small / "o.exr"),
            "look-from": ("render", small / "in.exr", small / "o.exr", "--look-from",
                          small / "lnk.exr"),
            "depth": ("render", small / "in.exr", small / "o.exr", "--look", "cinema",
                      "--depth", small / "lnk.exr")}[where]
    r = clfx("-q", *args)
    assert r.returncode == 1, r.stderr
    err = one_line(r.stderr, "lnk.exr", "not an OpenEXR file")
    assert "0x" not in err and "magic 0" not in err
    assert not (small / "o.exr").exists()


def test_demo_frames_zero_names_the_value_given():
    """Said "invalid frame range '1-0'"."""
    r = clfx("demo", "--frames", "0")
    assert r.returncode == 2, r.stderr
    one_line(r.stderr, "'--frames': 0 is not in the range x>=1")


# -- signals ------------------------------------------------------------------------------------
STUCK = """
import signal, sys, time
import clfx.cli as cli
from clfx.io import write
for s in (signal.SIGTERM, signal.SIGINT):         # a main thread that never gets to react
    signal.signal(s, lambda *a: None)
cli._watch_signals()
open(sys.argv[1], "w").close()
write._IN_FLIGHT.add(sys.argv[1])                 # a frame being written
print("ready", flush=True)
time.sleep(120)
"""


@pytest.mark.parametrize("sig,code", [("SIGTERM", 143), ("SIGINT", 130)])
def test_a_signal_ends_the_process_while_the_main_thread_is_stuck(tmp_path, sig, code):
    """A 65535x1 frame under a look ignored SIGTERM for minutes: the main thread was inside
    one long call (a PSF build, an FFT plan) and Python's handler never ran."""
    import signal

    tmp = tmp_path / ".o.exr.tmp-1-00000000-00000000.exr"
    proc = subprocess.Popen([sys.executable, "-c", STUCK, str(tmp)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    try:
        assert proc.stdout.readline() == b"ready\n"
        proc.send_signal(getattr(signal, sig))
        _, err = proc.communicate(timeout=60)       # without the watcher: 120 s
    finally:
        proc.kill()
    assert proc.returncode == code, err
    assert err.decode().strip() == ("clfx: terminated" if code == 143 else "clfx: interrupted")
    assert not tmp.exists()


SLOW_EXIT = """
import threading, time
import clfx.cli as cli

class Stuck:                                      # a render that Ctrl-C interrupts...
    @staticmethod
    def main(**kw):
        threading.Thread(target=time.sleep, args=(5,)).start()   # ...while a thread finishes
        print("ready", flush=True)
        time.sleep(60)

cli.cli = Stuck
cli.main(["render"])
"""


def test_an_interrupt_the_main_thread_answers_is_said_once(tmp_path):
    """'clfx: interrupted' twice: the main thread said it, then the watcher as well while
    the process waited for a thread to finish."""
    import signal

    proc = subprocess.Popen([sys.executable, "-c", SLOW_EXIT], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    try:
        assert proc.stdout.readline() == b"ready\n"
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 130, err
    assert err.decode() == "clfx: interrupted\n"
