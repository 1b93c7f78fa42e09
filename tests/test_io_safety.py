"""Issue 10 at the I/O layer: nothing lost, nothing hung, nothing overwritten.

Each test reproduces one red-team finding: a full disk (items 1), hostile windows (3), FIFOs
(5), concurrent writers and symlinks (7), leftovers and determinism (9).  Every failure must be
one line naming the file, leave nothing at the output path or under a temp name, and touch no
input.
"""
import errno
import json
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

from clfx.core.errors import ImageIOError
from clfx.core.frame import Frame
from clfx.core.limits import MAX_PIXELS
from clfx.io import write as io_write
from clfx.io.probe import probe
from clfx.io.read import read_frame
from clfx.io.write import OutputExistsError, sweep_stale_temps, write_frame
from clfx.pipeline.look import read_image_rgba
from tests.test_damaged import run_with_timeout

ROOT = Path(__file__).resolve().parents[1]
FORMATS = ("exr", "png", "jpg", "tif", "dpx", "hdr")


def noisy(w=300, h=200, seed=1):
    """Incompressible pixels: every format needs ~w*h*3 bytes or more."""
    rgba = np.random.default_rng(seed).uniform(0, 1, (h, w, 4)).astype(np.float32)
    rgba[..., 3] = 1.0
    return Frame.from_array(rgba)


def nothing_left(folder, name):
    """No output and no temp file of ``name`` in ``folder``."""
    names = [p.name for p in Path(folder).iterdir()]
    return name not in names and not [n for n in names if ".tmp-" in n]


def one_line(exc, *fragments):
    msg = str(exc)
    assert "\n" not in msg, msg
    for f in fragments:
        assert f in msg, msg
    return msg


def run_python(code, *args, timeout=120, env=None):
    """Run ``code`` in a fresh interpreter with this worktree first on the path."""
    e = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    e.update(env or {})
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code), *map(str, args)],
                          capture_output=True, text=True, timeout=timeout, env=e,
                          check=False)


# --------------------------------------------------------------------------------------------
# Item 1: a full disk is an error, never a silent truncation or an exit

FULL_DISK_CHILD = """
    import json, os, resource, sys
    import numpy as np
    from clfx.core.frame import Frame
    from clfx.io.write import write_frame
    limit = int(sys.argv[2])
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))  # Python ignores SIGXFSZ: EFBIG
    rgba = np.random.default_rng(1).uniform(0, 1, (200, 300, 4)).astype(np.float32)
    try:
        write_frame(Frame.from_array(rgba), sys.argv[1])
        print(json.dumps({"ok": True}))
    except Exception as e:
        print(json.dumps({"ok": False, "type": type(e).__name__, "msg": str(e)}))
"""


@pytest.mark.parametrize("ext", ["png", "exr", "tif", "dpx", "hdr"])
def test_full_disk_is_one_clean_error(tmp_path, ext):
    """RLIMIT_FSIZE makes every write past 20 kB fail, as a full disk does (EFBIG instead
    of ENOSPC).  libpng ignores it and used to leave a truncated PNG that exited 0."""
    out = tmp_path / f"x.{ext}"
    r = run_python(FULL_DISK_CHILD, out, 20000)
    assert r.returncode == 0, r.stderr
    got = json.loads(r.stdout.strip().splitlines()[-1])
    assert got["ok"] is False and got["type"] == "ImageIOError", got
    assert got["msg"].startswith(f"cannot write {out}") and "\n" not in got["msg"], got
    assert ".tmp-" not in got["msg"], got              # names the output, not the temp
    assert nothing_left(tmp_path, out.name)


@pytest.mark.parametrize("ext", ["jpg", "png"])
def test_copy_of_in_memory_encoding_fails_cleanly(tmp_path, monkeypatch, ext):
    """JPEG is encoded in memory (libjpeg exit()s on a write error) and copied with checked
    writes: the copy failing like a full disk is an ImageIOError.  PNG: a silent short
    write is caught by the missing end-of-image marker."""
    out = tmp_path / f"x.{ext}"
    if ext == "jpg":
        def full(fd, data):
            raise OSError(errno.ENOSPC, "No space left on device")
        monkeypatch.setattr(io_write.os, "write", full)
        want = "No space left on device"
    else:
        encode = io_write._encode_file

        def short_write(tmp, *args):
            encode(tmp, *args)
            os.truncate(tmp, os.path.getsize(tmp) // 2)   # what a full disk did to libpng
        monkeypatch.setattr(io_write, "_encode_file", short_write)
        want = "truncated"
    with pytest.raises(ImageIOError) as info:
        write_frame(noisy(), out)
    monkeypatch.undo()
    one_line(info.value, f"cannot write {out}", want)
    assert nothing_left(tmp_path, out.name)


def test_oiio_write_failure_midway_leaves_nothing(tmp_path, monkeypatch):
    calls = {"n": 0}
    blocks = io_write._write_blocks

    def fail_midway(out, part):
        calls["n"] += 1
        return False if calls["n"] == 1 else blocks(out, part)
    monkeypatch.setattr(io_write, "_write_blocks", fail_midway)
    with pytest.raises(ImageIOError) as info:
        write_frame(noisy(), tmp_path / "x.exr")
    one_line(info.value, "cannot write")
    assert nothing_left(tmp_path, "x.exr")


@pytest.fixture
def tiny_tmpfs(tmp_path):
    """A 256 kB tmpfs (root only; skipped elsewhere)."""
    if os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root; the RLIMIT_FSIZE tests cover full disks")
    mnt = tmp_path / "full"
    mnt.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(mnt)],
                       capture_output=True, text=True, check=False)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {r.stderr.strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


@pytest.mark.parametrize("ext", FORMATS)
def test_really_full_tmpfs(tiny_tmpfs, ext):
    out = tiny_tmpfs / f"x.{ext}"
    with pytest.raises(ImageIOError) as info:
        write_frame(noisy(600, 400), out)      # > 256 kB in every format
    one_line(info.value, f"cannot write {out}")
    assert nothing_left(tiny_tmpfs, out.name)
    write_frame(noisy(8, 8), tiny_tmpfs / f"small.{ext}")     # the disk still works
    assert read_frame(tiny_tmpfs / f"small.{ext}").rgba.shape == (8, 8, 4)


# --------------------------------------------------------------------------------------------
# Item 3: windows are checked from the header, before any allocation

def test_huge_display_window_refused_before_allocating(tmp_path):
    """A 1x1 data window in a 60000x60000 display window: a few hundred bytes on disk."""
    path = tmp_path / "tiny_in_huge.exr"
    spec = oiio.ImageSpec(1, 1, 3, "half")
    spec.full_width = spec.full_height = 60000
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec) and out.write_image(np.ones((1, 1, 3), np.float32))
    assert out.close()
    assert path.stat().st_size < 1000
    t0 = time.perf_counter()
    with pytest.raises(ImageIOError) as info:
        read_frame(path)
    assert time.perf_counter() - t0 < 5.0
    one_line(info.value, str(path), "display window is 60000x60000",
             f"the limit is {MAX_PIXELS} pixels", "CLFX_MAX_PIXELS")
    assert probe(path)["parts"][0]["display_window"]["width"] == 60000   # probe still says why


TILED_CHILD = """
    import resource, sys, time
    from clfx.core.errors import ImageIOError
    from clfx.io.read import read_frame
    t0 = time.perf_counter()
    try:
        read_frame(sys.argv[1])
        print("READ")
    except ImageIOError as e:
        print("ERROR", e)
    # VmHWM: this process's own peak (getrusage's ru_maxrss keeps the parent's across exec)
    hwm = [l for l in open("/proc/self/status") if l.startswith("VmHWM:")]
    print("RSS_MB", int(hwm[0].split()[1]) // 1024 if hwm
          else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024)
    print("SECONDS", time.perf_counter() - t0)
"""


def test_tiled_exr_claiming_16k_refused_before_allocating(tmp_path):
    """A 16384^2 tiled EXR with one tile written (500 kB) opens fine in OpenImageIO; reading
    it used to allocate 3 GB before failing on the missing tiles."""
    path = tmp_path / "claims16k.exr"
    spec = oiio.ImageSpec(16384, 16384, 3, "half")
    spec.tile_width = spec.tile_height = 64
    spec.attribute("compression", "zip")
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec)
    assert out.write_tile(0, 0, 0, np.zeros((64, 64, 3), np.float32))
    out.close()
    assert path.stat().st_size < 2_000_000
    r = run_python(TILED_CHILD, path)
    lines = dict(line.split(" ", 1) for line in r.stdout.strip().splitlines())
    assert "ERROR" in lines, r.stdout + r.stderr
    assert "data window is 16384x16384" in lines["ERROR"] and "CLFX_MAX_PIXELS" in lines["ERROR"]
    assert int(lines["RSS_MB"]) < 400, lines          # not the 3 GB of pixels
    assert float(lines["SECONDS"]) < 10.0


# --------------------------------------------------------------------------------------------
# Item 5: inputs must be regular files; a FIFO never blocks

def test_fifo_inputs_refused_without_blocking(tmp_path):
    fifo = tmp_path / "pipe.exr"
    os.mkfifo(fifo)
    good = tmp_path / "good.exr"
    write_frame(noisy(8, 8), good)
    for call in (lambda: read_frame(fifo), lambda: read_frame(good, depth_path=fifo),
                 lambda: read_frame(good, velocity_path=fifo), lambda: probe(fifo),
                 lambda: read_image_rgba(str(fifo))):      # what effects get as ctx.read_image
        err = run_with_timeout(call, timeout=20)
        assert isinstance(err, ImageIOError), err
        one_line(err, str(fifo), "not a regular file (a FIFO)")


# --------------------------------------------------------------------------------------------
# Item 7: outputs are created exclusively

def appear_while_writing(monkeypatch, make):
    """Run ``make(path)`` between encoding and publishing (another writer finishing first)."""
    verify = io_write._verify

    def racing(tmp, path, *args):
        verify(tmp, path, *args)
        make(Path(path))
    monkeypatch.setattr(io_write, "_verify", racing)


def test_output_appearing_meanwhile_is_not_replaced(tmp_path, monkeypatch):
    out = tmp_path / "x.exr"
    appear_while_writing(monkeypatch, lambda p: p.write_bytes(b"the other writer's frame"))
    with pytest.raises(OutputExistsError) as info:
        write_frame(noisy(8, 8), out)
    one_line(info.value, str(out), "appeared while it was being written")
    assert out.read_bytes() == b"the other writer's frame"
    assert not [p for p in tmp_path.iterdir() if ".tmp-" in p.name]
    write_frame(noisy(8, 8), out, overwrite=True)          # overwrite: replaced
    assert read_frame(out).rgba.shape == (8, 8, 4)


def test_dangling_symlink_counts_as_existing(tmp_path, monkeypatch):
    out = tmp_path / "x.exr"
    target = tmp_path / "elsewhere" / "never.exr"
    out.symlink_to(target)
    with pytest.raises(OutputExistsError, match="exists"):
        write_frame(noisy(8, 8), out)
    assert out.is_symlink() and not target.exists()
    out.unlink()
    appear_while_writing(monkeypatch, lambda p: p.symlink_to(target))   # appears meanwhile
    with pytest.raises(OutputExistsError):
        write_frame(noisy(8, 8), out)
    assert out.is_symlink() and not target.exists()
    assert not [p for p in tmp_path.iterdir() if ".tmp-" in p.name]


def test_publish_without_hard_links_is_still_exclusive(tmp_path, monkeypatch):
    def no_links(src, dst):
        raise OSError(errno.EPERM, "Operation not permitted")
    monkeypatch.setattr(io_write.os, "link", no_links)
    write_frame(noisy(8, 8), tmp_path / "a.exr")
    assert read_frame(tmp_path / "a.exr").rgba.shape == (8, 8, 4)
    appear_while_writing(monkeypatch, lambda p: p.write_bytes(b"other"))
    with pytest.raises(OutputExistsError):
        write_frame(noisy(8, 8), tmp_path / "b.exr")
    assert (tmp_path / "b.exr").read_bytes() == b"other"
    assert not [p for p in tmp_path.iterdir() if ".tmp-" in p.name]


WRITER_CHILD = """
    import json, os, sys, time
    import numpy as np
    from clfx.core.frame import Frame
    from clfx.io.write import OutputExistsError, write_frame
    folder, writer, count, go = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
    while not os.path.exists(go):          # both start together
        time.sleep(0.001)
    won, lost, raced = [], [], 0
    for f in range(count):
        rgba = np.random.default_rng(f).uniform(0, 1, (256, 256, 4)).astype(np.float32)
        rgba[0, 0] = writer
        try:
            write_frame(Frame.from_array(rgba), f"{folder}/o.{f:04d}.exr", bit_depth="float",
                        attributes={"clfx:writer": writer})
            won.append(f)
        except OutputExistsError as e:
            assert "\\n" not in str(e)
            lost.append(f)
            raced += "appeared" in str(e)
    print(json.dumps({"won": won, "lost": lost, "raced": raced}))
"""


def test_two_processes_writing_the_same_outputs(tmp_path):
    """Each frame is published by exactly one writer, whole; the other is refused cleanly."""
    count = 24
    out_dir, go = tmp_path / "out", tmp_path / "go"
    out_dir.mkdir()
    procs = [subprocess.Popen([sys.executable, "-c", textwrap.dedent(WRITER_CHILD),
                               str(out_dir), str(w), str(count), str(go)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                              env=dict(os.environ, PYTHONPATH=str(ROOT)))
             for w in (1, 2)]
    time.sleep(0.5)
    go.touch()
    results = []
    for p in procs:
        out, err = p.communicate(timeout=120)
        assert p.returncode == 0, err
        results.append(json.loads(out.strip().splitlines()[-1]))
    for f in range(count):
        winners = [w for w, r in zip((1, 2), results) if f in r["won"]]
        assert len(winners) == 1, (f, results)
        fr = read_frame(out_dir / f"o.{f:04d}.exr")      # whole, and the winner's
        assert fr.metadata["clfx:writer"] == winners[0] == fr.rgba[0, 0, 0]
    assert sorted(p.name for p in out_dir.iterdir()) == [f"o.{f:04d}.exr" for f in range(count)]


# --------------------------------------------------------------------------------------------
# Item 9: leftovers, determinism, what was read

def test_sweep_removes_only_temps_of_dead_processes(tmp_path):
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True).stdout.strip()
    names = {
        f".o.0001.exr.tmp-{dead}-0123abcd.exr": False,          # killed writer: swept
        f".o.0002.exr.tmp-{dead}-89abcdef.exr": False,
        f".o.0001.exr.tmp-{os.getpid()}-0123abcd.exr": True,    # live writer: kept
        f".o.0001.exr.tmp-{dead}-0123abcd.png": True,           # not our extension
        f".other.exr.tmp-{dead}-0123abcd.exr": True,            # not one of the outputs
        ".o.0001.exr.tmp-99999999999999-0123abcd.exr": False,  # impossible pid: gone
        "o.0003.exr": True,
    }
    for n in names:
        (tmp_path / n).write_bytes(b"partial")
    (tmp_path / f".o.0002.exr.tmp-{dead}-0123abcd.exr.d").mkdir()    # not a temp file
    outputs = [tmp_path / f"o.{f:04d}.exr" for f in (1, 2, 3)]
    removed = sweep_stale_temps(outputs)
    assert sorted(Path(p).name for p in removed) == sorted(n for n, keep in names.items()
                                                           if not keep)
    left = {p.name for p in tmp_path.iterdir()}
    assert left == {n for n, keep in names.items() if keep} | {
        f".o.0002.exr.tmp-{dead}-0123abcd.exr.d"}


def test_temps_of_another_host_are_swept_only_when_old(tmp_path):
    """On shared storage a retried farm task runs elsewhere: a PID of another host says
    nothing, so its temps go only once they have not been written to for an hour."""
    from clfx.io import write

    here = write._host_token()
    other = "0" * 8 if here != "0" * 8 else "1" * 8
    fresh = tmp_path / f".o.0001.exr.tmp-{os.getpid()}-0123abcd-{other}.exr"
    old = tmp_path / f".o.0002.exr.tmp-{os.getpid()}-0123abcd-{other}.exr"
    mine = tmp_path / f".o.0003.exr.tmp-99999999999999-0123abcd-{here}.exr"
    for p in (fresh, old, mine):
        p.write_bytes(b"partial")
    stale = time.time() - write.REMOTE_TEMP_STALE_S - 60
    os.utime(old, (stale, stale))
    removed = sweep_stale_temps([tmp_path / f"o.{f:04d}.exr" for f in (1, 2, 3)])
    assert sorted(Path(p).name for p in removed) == sorted([old.name, mine.name])
    assert fresh.exists()
    assert here in Path(write._temp_path(str(tmp_path / "o.exr"), str(tmp_path))).name


def test_same_frame_gives_identical_bytes(tmp_path):
    """OpenImageIO stamped DateTime (EXR, TIFF) and DPX stored the temp file's name."""
    fr = noisy(40, 30)
    attrs = {"clfx:look": "cinema", "clfx:paramsHash": "0123456789abcdef"}
    for ext in FORMATS:
        write_frame(fr, tmp_path / f"a.{ext}", attributes=attrs)
    time.sleep(1.05 - time.time() % 1.0)                   # the next second on the clock
    for ext in FORMATS:
        (tmp_path / "b").mkdir(exist_ok=True)
        write_frame(fr, tmp_path / "b" / f"a.{ext}", attributes=attrs)
        assert (tmp_path / f"a.{ext}").read_bytes() == (tmp_path / "b" / f"a.{ext}").read_bytes(), ext
    assert "DateTime" not in read_frame(tmp_path / "a.exr").metadata
    assert (tmp_path / "a.dpx").read_bytes()[36:41] == b"a.dpx"
    carried = Frame.from_array(fr.rgba)
    carried.metadata["DateTime"] = "2020:01:02 03:04:05"    # an input's DateTime is kept
    write_frame(carried, tmp_path / "c.exr")
    assert read_frame(tmp_path / "c.exr").metadata["DateTime"] == "2020:01:02 03:04:05"


def test_depth_only_exr_is_refused_naming_its_channels(tmp_path):
    path = tmp_path / "z_only.exr"
    spec = oiio.ImageSpec(16, 8, 1, "float")
    spec.channelnames = ("Z",)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec) and out.write_image(np.full((8, 16, 1), 5.0, np.float32))
    assert out.close()
    with pytest.raises(ImageIOError) as info:
        read_frame(path)
    one_line(info.value, "no beauty channels", str(path), "channels: Z", "depth pass only")
    beauty = tmp_path / "beauty.exr"
    write_frame(noisy(16, 8), beauty)
    assert np.all(read_frame(beauty, depth_path=path).depth == 5.0)   # fine as a depth file


def test_write_text_never_follows_a_link_and_is_exclusive(tmp_path, monkeypatch):
    """Issue 34: `clfx gallery` wrote index.json with open(..., "w") through a link to a file
    outside its folder.  `write_text` is the frames' atomic, exclusive publish for text."""
    from clfx.io.write import output_folder, write_text

    outside = tmp_path / "outside.txt"
    outside.write_text("keep")
    link = tmp_path / "index.json"
    link.symlink_to(outside)
    with pytest.raises(OutputExistsError, match="index.json"):
        write_text("{}", link)
    write_text("{}\n", link, overwrite=True)
    assert outside.read_text() == "keep" and not link.is_symlink()
    assert link.read_text() == "{}\n"
    # a failed write leaves nothing at the path nor under a temp name
    monkeypatch.setattr(io_write.os, "write", lambda fd, data: (_ for _ in ()).throw(
        OSError(errno.ENOSPC, "No space left on device")))
    with pytest.raises(ImageIOError, match=r"new\.json: No space left"):
        write_text("x", tmp_path / "new.json")
    monkeypatch.undo()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["index.json", "outside.txt"]
    with pytest.raises(ImageIOError, match="not a folder"):
        output_folder(outside)
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "sub").symlink_to(tmp_path / "elsewhere")
    with pytest.raises(ImageIOError, match="symbolic link"):
        output_folder(tmp_path / "sub", inside=tmp_path)
    assert output_folder(tmp_path / "sub") == str(tmp_path / "sub")   # no `inside`: allowed
