"""Issue 10 item 3 (pipeline half): a frame's windows, and every window an effect grows it
to, are checked against the pixel limit before anything that size is allocated.  Issue 23:
a first frame over the limits is refused from its header before anything is set up for it
(device, first read, the look's maps), and maps prepared ahead of need stop when cancelled."""
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from clfx.core import limits
from clfx.cli import cli
from clfx.core.errors import ClfxError
from clfx.core.frame import Frame
from clfx.core.rect import Rect
from clfx.pipeline.look import FrameTooLarge, Look, Step, render_frame
from clfx.plugins import get_plugin
from tests.test_memory import PEAK

ROOT = Path(__file__).resolve().parents[1]


def hot_frame(size=40):
    rgba = np.zeros((size, size, 4), np.float32)
    rgba[..., 3] = 1.0
    rgba[size // 2, size // 2, :3] = 1e4
    return Frame.from_array(rgba)


def glare_look():
    return Look("g", steps=[Step("glare", get_plugin("glare").params())])


def test_a_huge_display_window_is_refused_before_upload(rt, monkeypatch):
    frame = Frame(np.ones((1, 1, 4), np.float32), Rect(0, 0, 1, 1), Rect(0, 0, 60000, 60000),
                  source="tiny.exr")
    monkeypatch.setattr(rt, "upload", lambda *a, **k: pytest.fail("uploaded before the check"))
    with pytest.raises(FrameTooLarge) as err:
        render_frame(rt, glare_look(), frame)
    msg = str(err.value)
    assert isinstance(err.value, ClfxError) and "\n" not in msg
    assert msg.startswith("tiny.exr: display window is 60000x60000; the limit is")
    assert "(CLFX_MAX_PIXELS)" in msg


def test_a_window_grown_past_the_limit_is_refused_before_rendering(rt, monkeypatch):
    frame = hot_frame(40)
    _, report = render_frame(rt, glare_look(), frame, keep_overscan=True)
    assert report.steps[0].ran  # glare runs and spreads light past the frame
    monkeypatch.setattr(limits, "MAX_PIXELS", 40 * 40 + 1)  # the frame fits, growth does not
    glare = get_plugin("glare")
    render = glare.render
    monkeypatch.setattr(glare, "render", lambda *a, **k: pytest.fail("rendered past the limit"))
    with pytest.raises(FrameTooLarge, match=r"^frame grown by glare is \d+x\d+; the limit is 1601 "
                                            r"pixels and 65536 a side \(CLFX_MAX_PIXELS\)$"):
        render_frame(rt, glare_look(), frame, keep_overscan=True)
    monkeypatch.setattr(glare, "render", render)
    _, report = render_frame(rt, glare_look(), frame)  # cropped to the frame: within the limit
    assert report.steps[0].ran


def test_tiny_data_window_in_a_huge_display_window_from_the_cli(rt, tmp_path):
    """A few hundred bytes claiming a 60000x60000 frame: one line, exit 1, nothing written."""
    from clfx.io.write import write_frame

    src = tmp_path / "tiny.exr"
    write_frame(Frame(np.ones((1, 1, 4), np.float32), Rect(0, 0, 1, 1), Rect(0, 0, 60000, 60000)),
                src, bit_depth="float")
    assert src.stat().st_size < 2000
    r = CliRunner().invoke(cli, ["render", str(src), str(tmp_path / "o.exr"), "--look", "wide-angle"])
    err = r.stderr.strip()
    assert r.exit_code == 1, (r.exit_code, r.output)
    assert err.startswith("clfx: error:") and "\n" not in err and "60000" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tiny.exr"]


# -- issue 23: nothing is set up for a frame that will be refused ----------------------------

def tiny_exr(path, width, height):
    """A 1x1 half RGBA pixel claiming a ``width`` x ``height`` display window (~400 bytes)."""
    import OpenImageIO as oiio

    spec = oiio.ImageSpec(1, 1, 4, "half")
    spec.full_width, spec.full_height = width, height
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec)
    out.write_image(np.ones((1, 1, 4), np.float16))
    out.close()
    assert path.stat().st_size < 1000
    return path


def _no_set_up(monkeypatch):
    """Record any set-up (the device, the first read, the look's maps) instead of doing it."""
    import clfx.api
    from clfx.device.runtime import Runtime
    from clfx.pipeline import plan as plan_mod, stream as stream_mod

    started = []
    monkeypatch.setattr(clfx.api, "runtime_soon", lambda *a, **k: started.append("device"))
    monkeypatch.setattr(Runtime, "get", classmethod(lambda cls, *a: started.append("device")))
    monkeypatch.setattr(stream_mod, "prepare", lambda *a, **k: started.append("maps"))
    monkeypatch.setattr(plan_mod.BatchPlan, "read", lambda *a: started.append("read"))
    return started


def _clfx_threads():
    import threading

    return [t.name for t in threading.enumerate() if t.name.startswith("clfx-")]


@pytest.mark.parametrize("side", [60000, 8193])
def test_refused_from_the_header_before_any_set_up(tmp_path, monkeypatch, side):
    """A few hundred bytes claiming a 60000^2 or 8193^2 display window under cinema: one line,
    exit 1, nothing written, and no device, read or map thread started (the maps went on
    building for minutes after the refusal: 2.2 GB at 120 s; 8193^2 took 21 s, 640 MB)."""
    src = tiny_exr(tmp_path / "tiny.exr", side, side)
    started = _no_set_up(monkeypatch)
    r = CliRunner().invoke(cli, ["render", str(src), str(tmp_path / "o.exr"), "--look", "cinema"])
    err = r.stderr.strip()
    assert r.exit_code == 1, (r.exit_code, r.output)
    assert err == (f"clfx: error: cannot read {src}: display window is {side}x{side}; the limit "
                   f"is {limits.MAX_PIXELS} pixels and 65536 a side (CLFX_MAX_PIXELS)"), err
    assert started == [] and _clfx_threads() == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tiny.exr"]
    from clfx.api import render

    with pytest.raises(ClfxError, match=f"display window is {side}x{side}"):
        render(src, tmp_path / "o.exr", "cinema")
    assert started == [] and _clfx_threads() == []


@pytest.mark.skipif(not os.path.exists("/proc/self/status"), reason="VmHWM from /proc")
def test_a_refused_frame_costs_no_memory_in_a_fresh_process(tmp_path):
    """The same file in a fresh ``clfx render`` process: it exits 1 well within the timeout
    and its peak stays that of a process that only imported clfx (75 MiB measured; before:
    640 MB for 8193^2, 2.2 GB and rising for 60000^2)."""
    src = tiny_exr(tmp_path / "tiny.exr", 8193, 8193)
    env = {**os.environ,
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, "-c", PEAK, "render", str(src),
                           str(tmp_path / "o.exr"), "--look", "cinema"],
                          env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 1, proc.stderr
    assert "display window is 8193x8193" in proc.stderr
    peak_mib = int(proc.stderr.split("peak_kib")[-1].split()[0]) / 1024
    assert 20 < peak_mib < 300, peak_mib


def test_maps_are_prepared_only_for_frames_that_will_render_and_fit(rt, tmp_path, monkeypatch):
    """`prepare_maps` (what `render_stream` starts for its first job) starts nothing for a frame the reader will refuse nor for one
    above `PREPARE_MAX_PIXELS` (at 8K the maps sat beside the first steps: 3794 MiB, budget
    3390); for a small frame it starts, and closing it with ``cancel`` stops it."""
    from clfx.pipeline import stream as stream_mod
    from clfx.pipeline.options import resolve_quality
    from clfx.pipeline.plan import Job
    from clfx.pipeline.stream import prepare_maps
    from clfx.pipeline.presets import load_look

    prepared = []
    monkeypatch.setattr(stream_mod, "prepare", lambda *a, **k: prepared.append(k["cancel"]))
    look, level = resolve_quality(load_look("cinema"), None)
    side = int((limits.PREPARE_MAX_PIXELS) ** 0.5) + 1
    for name, w in (("refused", 60000), ("large", side)):
        job = Job(1, str(tiny_exr(tmp_path / f"{name}.exr", w, w)), str(tmp_path / "o.exr"))
        assert prepare_maps(rt, look, [job], level) is None
    assert prepared == []
    job = Job(1, str(tiny_exr(tmp_path / "small.exr", 64, 48)), str(tmp_path / "o.exr"))
    handle = prepare_maps(rt, look, [job], level)
    handle.close(cancel=True)
    assert len(prepared) == 1 and prepared[0] is handle.cancelled and handle.cancelled.is_set()


def test_cancelled_preparation_stops_between_map_bands(rt, monkeypatch):
    """A cancelled `prepare` stops before the next band of a map and keeps nothing (a frame
    of 4 bands: one built)."""
    import threading

    from clfx.fx import resample
    from clfx.pipeline.look import prepare

    bands = []
    upload = resample._upload_bands
    cancel = threading.Event()

    def counting(rt_, spans, make, records):
        def band(y0, y1):
            bands.append((y0, y1))
            cancel.set()                 # e.g. the first frame was refused meanwhile
            return make(y0, y1)
        return upload(rt_, spans, band, records)

    monkeypatch.setattr(resample, "_upload_bands", counting)
    look = Look("d", steps=[Step("distortion", get_plugin("distortion").params(k1=-0.05))])
    win = Rect(0, 0, 1024, 1024)
    assert len(resample.map_bands(win.height, win.width)) == 4
    rt.cache.clear("distortion.map")
    prepare(rt, look, win, win, cancel=cancel)
    assert len(bands) == 1
    assert "distortion.map" not in rt.cache.stats()["owners"]
    bands.clear()
    prepare(rt, look, win, win, cancel=threading.Event())     # not cancelled: every band
    assert len(bands) == 4 and "distortion.map" in rt.cache.stats()["owners"]
