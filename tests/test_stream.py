"""A stream as fast as its parts: each file decoded once, on a CPU device the render alone
and then the write beside the next read (on a GPU, I/O overlapping the render), geometry-only
caches prepared before the first frame, the EXR compression default; none of it changes a
pixel."""
import ast
import os
import threading
import time
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

from clfx.core.frame import Frame
from clfx.device.cache import DeviceCache
from clfx.io import read as io_read
from clfx.io.read import read_frame
from clfx.io.write import write_frame
from clfx.pipeline import stream as stream_mod
from clfx.pipeline.batch import Batch
from clfx.pipeline.options import RenderOptions
from clfx.pipeline.plan import BatchPlan
from clfx.pipeline.look import prepare, render_frame
from clfx.pipeline.presets import load_look


def _frame(rng, h=24, w=40):
    rgba = rng.uniform(0, 2, (h, w, 4)).astype(np.float32)
    rgba[..., 3] = 1
    depth = rng.uniform(1, 9, (h, w)).astype(np.float32)
    vel = rng.uniform(-3, 3, (h, w, 2)).astype(np.float32)
    return Frame.from_array(rgba, depth=depth, velocity=vel)


def _pixels(path):
    inp = oiio.ImageInput.open(str(path))
    px = inp.read_image(0, 0, 0, inp.spec().nchannels, "float")
    names = tuple(inp.spec().channelnames)
    inp.close()
    return names, px


def test_a_part_is_decoded_once_and_its_passes_copied_from_memory(tmp_path, rng, monkeypatch):
    src = tmp_path / "in.exr"
    write_frame(_frame(rng), src, bit_depth="float")
    reads = []
    real = oiio.ImageInput.read_image
    monkeypatch.setattr(oiio.ImageInput, "read_image",
                        lambda self, *a: reads.append(a) or real(self, *a))
    fr = read_frame(src)
    assert len(reads) == 1                      # beauty, Z and forward.u/v in one read
    assert set(fr.layout.stored[0]) == {"Z", "forward.u", "forward.v"}
    opened = []
    monkeypatch.setattr(oiio.ImageInput, "open",
                        staticmethod(lambda p, *a, _o=oiio.ImageInput.open: opened.append(p) or _o(p, *a)))
    write_frame(fr, tmp_path / "kept.exr")
    assert str(src) not in opened               # the passes came from memory, not the file
    monkeypatch.undo()
    bare = read_frame(src)
    object.__setattr__(bare.layout, "stored", {})
    write_frame(bare, tmp_path / "file.exr")
    assert (tmp_path / "kept.exr").read_bytes() == (tmp_path / "file.exr").read_bytes()


@pytest.mark.parametrize("look, output, passes_mode, decoded, depth, velocity, stored", [
    ("cinema", "out.exr", "keep", 7, True, True, {"Z", "forward.u", "forward.v"}),
    ("macro", "out.exr", "keep", 7, True, False, {"Z", "forward.u", "forward.v"}),
    ("dreamy", "out.exr", "keep", 7, False, False, {"Z", "forward.u", "forward.v"}),
    ("dreamy", "out.png", "keep", 4, False, False, set()),
    ("dreamy", "out.exr", "drop", 4, False, False, set()),
    ("macro", "out.jpg", "keep", 5, True, False, set()),
])
def test_a_batch_reads_the_passes_its_steps_use_and_the_channels_its_output_copies(
        tmp_path, rng, monkeypatch, look, output, passes_mode, decoded, depth, velocity, stored):
    """Issue 37: a look that reads no velocity (macro) or no pass (dreamy) had every pass
    decoded and converted; an output that copies no channel (PNG, JPEG, --passes drop) had
    the beauty part's every channel decoded and kept through the render for nothing."""
    from clfx.pipeline.plan import Job

    src = tmp_path / "in.exr"
    write_frame(_frame(rng), src, bit_depth="float")
    names = []
    real = io_read._read_channels
    monkeypatch.setattr(io_read, "_read_channels",
                        lambda path, part, wanted: names.extend(wanted) or real(path, part, wanted))
    plan = BatchPlan.of(load_look(look), RenderOptions(passes_mode=passes_mode),
                        passes=io_read.PassSpec())
    fr = plan.read(Job(1, str(src), str(tmp_path / output))).views[0]
    assert len(names) == decoded, names
    assert (fr.depth is not None, fr.velocity is not None) == (depth, velocity)
    assert set(fr.layout.stored.get(0, {})) == stored
    whole = read_frame(src)        # what is read is read as before
    assert np.array_equal(fr.rgba, whole.rgba)
    if depth:
        assert np.array_equal(fr.depth, whole.depth)


def test_compression_kept_from_an_exr_only(tmp_path, rng):
    fr = _frame(rng)
    write_frame(fr, tmp_path / "a.exr", compression="piz")
    write_frame(read_frame(tmp_path / "a.exr"), tmp_path / "b.exr", write_passes=False)
    assert read_frame(tmp_path / "b.exr").metadata["compression"] == "piz"
    write_frame(fr, tmp_path / "c.tif", bit_depth="float")          # a TIFF's zip
    write_frame(read_frame(tmp_path / "c.tif"), tmp_path / "d.exr")
    assert read_frame(tmp_path / "d.exr").metadata["compression"] == "zips"
    write_frame(fr, tmp_path / "e.exr")                               # no input at all
    assert read_frame(tmp_path / "e.exr").metadata["compression"] == "zips"


def test_codec_threads_set_and_restored():
    before = oiio.get_int_attribute("exr_threads", 0)
    with io_read.codec_threads(1):
        assert oiio.get_int_attribute("exr_threads", 0) == 1
        assert oiio.get_int_attribute("threads", 0) == 1
    assert oiio.get_int_attribute("exr_threads", 0) == before


@pytest.mark.skipif(not hasattr(os, "setpriority"), reason="per-thread nice is Linux's")
def test_overlapping_io_threads_run_below_a_cpu_device(monkeypatch):
    monkeypatch.setattr(stream_mod, "IO_NICE", 10)
    base = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())

    def nice():
        return os.getpriority(os.PRIO_PROCESS, threading.get_native_id())

    with stream_mod.io_pool("read", lowered=True) as r, stream_mod.io_pool("write", lowered=True) as w:
        got_r, got_w = r.submit(nice).result(), w.submit(nice).result()
    assert got_w == min(19, base + 10) and got_r == min(19, base + 5)
    assert nice() == base                       # the caller keeps its priority
    with stream_mod.io_pool("read") as r, stream_mod.io_pool("write") as w:
        assert r.submit(nice).result() == w.submit(nice).result() == base   # phased


class _Device:
    def __init__(self, cpu):
        self.shares_host_cores = cpu


def test_stream_mode_follows_the_device(monkeypatch):
    monkeypatch.setattr(stream_mod, "STREAM", "auto")
    small, big = 1920 * 1080, stream_mod.OVERLAP_MAX_PIXELS + 1
    assert stream_mod.stream_mode(_Device(True), small) == "phased"
    assert stream_mod.stream_mode(_Device(False), small) == "overlap"
    assert stream_mod.stream_mode(_Device(False), big) == "serial"
    monkeypatch.setattr(stream_mod, "STREAM", "overlap")
    assert stream_mod.stream_mode(_Device(True), small) == "overlap"


def test_unknown_stream_value_is_said_once_and_taken_as_auto(monkeypatch, capsys):
    monkeypatch.setattr(stream_mod, "STREAM", "fast")
    monkeypatch.setattr(stream_mod, "_STREAM_SAID", False)
    assert stream_mod.stream_mode(_Device(True), 1920 * 1080) == "phased"
    assert stream_mod.stream_mode(_Device(False), 1920 * 1080) == "overlap"
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "CLFX_STREAM='fast'" in err[0] and "using auto" in err[0]


def test_codecs_take_every_core_unless_io_overlaps_a_cpu_device(monkeypatch):
    monkeypatch.setattr(stream_mod, "available_cores", lambda: 8)
    monkeypatch.setattr(stream_mod, "STREAM", "auto")
    assert stream_mod.codec_threads_for(_Device(True)) == 8       # phased: I/O has the cores
    assert stream_mod.codec_threads_for(_Device(False)) == 8      # beside a GPU
    monkeypatch.setattr(stream_mod, "STREAM", "overlap")
    assert stream_mod.codec_threads_for(_Device(True)) == stream_mod.IO_CODEC_THREADS == 1


def _timeline(tmp_path, rt, monkeypatch, stream):
    """Run 4 frames with each read, render and write taking at least 0.15 s; return the
    (kind, frame, start, end) intervals."""
    for i in range(1, 5):
        write_frame(_frame(np.random.default_rng(i)), tmp_path / f"in.{i:04d}.exr")
    monkeypatch.setattr(stream_mod, "STREAM", stream)
    b = Batch(look=load_look("cinema"), input_path=str(tmp_path / "in.#.exr"),
              output_path=str(tmp_path / stream / "o.#.exr"),
              options=RenderOptions(), verbosity=0)
    b.prepare()
    spans, lock = [], threading.Lock()

    def timed(kind, fn, frame_of):
        def run(*args):
            t0 = time.perf_counter()
            out = fn(*args)
            time.sleep(0.15)
            with lock:
                spans.append((kind, frame_of(args), t0, time.perf_counter()))
            return out
        return run

    plan = BatchPlan
    monkeypatch.setattr(plan, "read", timed("read", plan.read, lambda a: a[1].frame))
    monkeypatch.setattr(plan, "render", timed("render", plan.render, lambda a: a[2].frame))
    monkeypatch.setattr(plan, "write", timed("write", plan.write, lambda a: a[2].frame))
    assert b.run(rt)["frames"] == 4
    return spans


def _overlap(a, b):
    return min(a[3], b[3]) - max(a[2], b[2]) > 0.02


def test_phased_stream_renders_alone_and_writes_beside_the_next_read(tmp_path, rt, monkeypatch):
    spans = _timeline(tmp_path, rt, monkeypatch, "phased")
    renders = [s for s in spans if s[0] == "render"]
    io = [s for s in spans if s[0] != "render"]
    assert len(renders) == 4 and len(io) == 8
    assert not any(_overlap(r, x) for r in renders for x in io)   # the device has the cores
    for n in (1, 2, 3):                 # frame n's write runs beside frame n+1's read
        w = next(s for s in io if s[:2] == ("write", n))
        r = next(s for s in io if s[:2] == ("read", n + 1))
        assert _overlap(w, r)


def test_overlapping_stream_reads_while_the_device_renders(tmp_path, rt, monkeypatch):
    spans = _timeline(tmp_path, rt, monkeypatch, "overlap")
    renders = [s for s in spans if s[0] == "render"]
    reads = [s for s in spans if s[0] == "read"]
    assert sum(_overlap(r, x) for r in renders for x in reads) >= 3


def test_cache_builds_a_key_once_across_threads(rt):
    cache = DeviceCache(rt.ctx, max_bytes=1 << 20)
    calls = []

    def build():
        calls.append(1)
        time.sleep(0.2)
        return np.zeros(8, np.float32)

    threads = [threading.Thread(target=cache.get, args=(("t.key",), build)) for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(calls) == 1 and cache.peek(("t.key",)) is not None

    def fails():
        raise RuntimeError("no")

    with pytest.raises(RuntimeError):
        cache.get(("t.bad",), fails)
    assert cache.get(("t.bad",), lambda: 3) == 3   # a failed build does not block the key


def test_prepare_builds_what_the_first_frame_uses(rt, rng):
    look = load_look("cinema")
    fr = _frame(rng, 72, 128)
    rt.cache.clear()
    prepare(rt, look, fr.data_window, fr.display_window, fr.pixel_aspect, frame_number=1)
    owners = set(rt.cache.stats()["owners"])
    assert {"distortion.map", "chromatic_aberration.packed"} <= owners
    misses = rt.cache.misses
    render_frame(rt, look, fr, frame_number=1)
    keys = [k for k in rt.cache._lru if k[0] in ("distortion.map", "chromatic_aberration.packed")]
    assert len(keys) == 2                       # the render found them: no second map built
    assert rt.cache.misses >= misses


def test_stream_pixels_match_frames_rendered_alone(tmp_path, rng, rt):
    for i in (1, 2, 3):
        write_frame(_frame(np.random.default_rng(i), 48, 80), tmp_path / f"in.{i:04d}.exr")
    look = load_look("cinema")
    b = Batch(look=look, input_path=str(tmp_path / "in.#.exr"),
              output_path=str(tmp_path / "out" / "o.#.exr"),
              options=RenderOptions(), verbosity=0)
    b.prepare()
    with b.reading():
        b.run(rt)
    rt.cache.clear()
    alone = Batch(look=look, input_path=str(tmp_path / "in.#.exr"),
                  output_path=str(tmp_path / "alone" / "o.#.exr"),
                  options=RenderOptions(frames="2"), verbosity=0)
    alone.prepare()
    alone.run(rt)
    a, b2 = _pixels(tmp_path / "out" / "o.0002.exr"), _pixels(tmp_path / "alone" / "o.0002.exr")
    assert a[0] == b2[0] and np.array_equal(a[1], b2[1], equal_nan=True)


def test_only_io_overlapping_a_cpu_device_runs_lowered(monkeypatch):
    """The default phased stream's read and write threads keep their priority (a lowered
    thread would give way to other processes on a loaded machine); overlapping a CPU device's
    renders, they are lowered; beside a GPU they are not."""
    monkeypatch.setattr(stream_mod, "STREAM", "auto")
    assert not stream_mod.io_overlaps_cpu_device(_Device(True))
    assert not stream_mod.io_overlaps_cpu_device(_Device(False))
    monkeypatch.setattr(stream_mod, "STREAM", "overlap")
    assert stream_mod.io_overlaps_cpu_device(_Device(True))
    assert not stream_mod.io_overlaps_cpu_device(_Device(False))


def test_a_frame_over_4k_keeps_no_channels_for_the_writer(tmp_path, rng, monkeypatch):
    """Issue 23 (memory): above `KEEP_MAX_PIXELS` the reader keeps nothing for the writer (an
    8K frame's passes as float32 would sit through the render: 380 MiB); the writer decodes
    them again, to the same bytes."""
    src = tmp_path / "in.exr"
    write_frame(_frame(rng), src, bit_depth="float")
    write_frame(read_frame(src), tmp_path / "kept.exr")
    monkeypatch.setattr(io_read, "KEEP_MAX_PIXELS", 24 * 40 - 1)
    reads = []
    real = oiio.ImageInput.read_image
    monkeypatch.setattr(oiio.ImageInput, "read_image",
                        lambda self, *a: reads.append(a) or real(self, *a))
    fr = read_frame(src)
    assert fr.layout.stored == {} and len(reads) == 1   # beauty and passes still in one read
    write_frame(fr, tmp_path / "file.exr")
    assert (tmp_path / "kept.exr").read_bytes() == (tmp_path / "file.exr").read_bytes()


# -- render_stream is the one loop -----------------------------------------------------------
RENDERS = {"render_frame", "plan.render"}
WRITES = {"write_frame", "write_raw", "plan.write"}
ONE_LOOP_EXCEPTIONS = {
    "clfx/gallery.py:run_gallery":
        "renders each look on an input resized in memory and writes labelled, tone-mapped "
        "sRGB tiles about the render, never a rendered frame",
    "clfx/bench/looks.py:bench_sequence":
        "times BatchPlan.read, render_frame and BatchPlan.write each alone (n runs of each) "
        "beside the stream it measures, which is Batch.run's render_stream",
}
"""Functions outside `clfx.pipeline` that both render and write, and why that is no
read/render/write loop of their own."""


def _call_name(node) -> str | None:
    f = node.func
    if isinstance(f, ast.Name):
        return f.id
    if isinstance(f, ast.Attribute):   # x.plan.write / plan.write -> plan.write
        owner = f.value.attr if isinstance(f.value, ast.Attribute) else getattr(f.value, "id", "")
        return f"{owner}.{f.attr}"
    return None


def render_write_functions(root) -> dict[str, set]:
    """``{"path:function": calls}`` of the top-level functions and methods (nested functions
    and lambdas included) of the modules under ``root`` outside ``clfx/pipeline`` and
    ``clfx/io`` that call a renderer (`RENDERS`) and a frame writer (`WRITES`)."""
    found = {}
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root.parent).as_posix()
        if rel.startswith(("clfx/pipeline/", "clfx/io/")):
            continue
        tree = ast.parse(path.read_text())
        tops = [n for n in tree.body if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]
        tops += [m for c in tree.body if isinstance(c, ast.ClassDef) for m in c.body
                 if isinstance(m, (ast.FunctionDef, ast.AsyncFunctionDef))]
        for fn in tops:
            calls = {_call_name(n) for n in ast.walk(fn) if isinstance(n, ast.Call)}
            if calls & RENDERS and calls & WRITES:
                found[f"{rel}:{fn.name}"] = calls & (RENDERS | WRITES)
    return found


def test_no_module_outside_the_pipeline_runs_a_read_render_write_loop():
    """`clfx.pipeline.stream.render_stream` is the one loop that reads (or is handed), renders
    and writes frames: a local render, a Dask worker, a raw pipe and `clfx demo` all run it.
    A function elsewhere that calls a renderer and a frame writer is one loop too many,
    unless it is one of the listed exceptions (each says why it is not such a loop)."""
    import clfx

    root = Path(clfx.__file__).resolve().parent
    found = render_write_functions(root)
    extra = sorted(set(found) - set(ONE_LOOP_EXCEPTIONS))
    assert not extra, f"read/render/write outside render_stream: {[(k, found[k]) for k in extra]}"
    assert set(ONE_LOOP_EXCEPTIONS) <= set(found), "an exception no longer renders and writes: drop it"


def test_the_one_loop_check_sees_a_render_and_write_loop(tmp_path):
    """The check above finds a loop like the one `clfx demo` had before it ran render_stream
    (render_frame on each generated frame, then write_frame of the output)."""
    pkg = tmp_path / "clfx"
    pkg.mkdir()
    (pkg / "demo.py").write_text(
        "def run(rt, look, frames, out):\n"
        "    for i, f in enumerate(frames):\n"
        "        img, report = render_frame(rt, look, f)\n"
        "        pool.submit(lambda: write_frame(img, out % i))\n")
    (pkg / "pipeline").mkdir()
    (pkg / "pipeline" / "batch.py").write_text(
        "def render_stream(plan, job):\n    plan.write(plan.render(plan.read(job)), job)\n")
    assert set(render_write_functions(pkg)) == {"clfx/demo.py:run"}
