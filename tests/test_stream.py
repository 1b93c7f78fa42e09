"""A stream as fast as its parts: each file decoded once, I/O threads at low priority with the
codecs on them, geometry-only caches prepared before the first frame, the EXR compression
default; none of it changes a pixel."""
import os
import threading
import time

import numpy as np
import OpenImageIO as oiio
import pytest

from clfx.core.frame import Frame
from clfx.device.cache import DeviceCache
from clfx.io import read as io_read
from clfx.io.read import read_frame
from clfx.io.write import write_frame
from clfx.pipeline import batch as batch_mod
from clfx.pipeline.batch import Batch, RenderOptions
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
def test_io_threads_run_below_the_device(monkeypatch):
    monkeypatch.setattr(batch_mod, "IO_NICE", 10)
    base = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())

    def nice():
        return os.getpriority(os.PRIO_PROCESS, threading.get_native_id())

    with batch_mod.io_pool("read") as r, batch_mod.io_pool("write") as w:
        got_r, got_w = r.submit(nice).result(), w.submit(nice).result()
    assert got_w == min(19, base + 10) and got_r == min(19, base + 5)
    assert nice() == base                       # the caller keeps its priority


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
    b = Batch(look=look, input_path=str(tmp_path / "in.####.exr"),
              output_path=str(tmp_path / "out" / "o.####.exr"),
              options=RenderOptions(), verbosity=0)
    b.prepare()
    with b.reading():
        b.run(rt)
    rt.cache.clear()
    alone = Batch(look=look, input_path=str(tmp_path / "in.####.exr"),
                  output_path=str(tmp_path / "alone" / "o.####.exr"),
                  options=RenderOptions(frames="2"), verbosity=0)
    alone.prepare()
    alone.run(rt)
    a, b2 = _pixels(tmp_path / "out" / "o.0002.exr"), _pixels(tmp_path / "alone" / "o.0002.exr")
    assert a[0] == b2[0] and np.array_equal(a[1], b2[1], equal_nan=True)
