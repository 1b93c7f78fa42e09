"""Issue 10 item 10: bounded memory.  A 1920x1080 frame of the demo scene through the cinema
look, in a fresh process with PoCL's kernel cache warm, peaks below the documented budget
(``clfx.core.limits.memory_budget_mib``: 600 MiB + CLFX_POOL_MB + 72 bytes per pixel); the
peaks at 1080p, 4K UHD and 8K UHD, measured with ``/usr/bin/time -v``, are in the table of
docs/performance.md (8K: under 4 GB)."""
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from clfx.core.limits import memory_budget_mib

ROOT = Path(__file__).resolve().parents[1]

PEAK = """
import sys
from clfx.cli import main
sys.argv = ["clfx"] + sys.argv[1:]
try:
    main()
except SystemExit as exc:
    code = exc.code
else:
    code = 0
# VmHWM: this process image's own peak (ru_maxrss would carry over the parent's peak across
# fork and exec, e.g. a pytest process grown by a whole suite)
hwm = [ln for ln in open("/proc/self/status") if ln.startswith("VmHWM:")][0].split()[1]
print("peak_kib", hwm, file=sys.stderr)
sys.exit(code)
"""


def cinema_frame(path, width, height):
    """The demo scene (HDR lights, depth, velocity) as a half-float EXR with Z and velocity."""
    from clfx.bench.scene import demo_scene, render_sharp
    from clfx.io.write import write_frame

    write_frame(render_sharp(demo_scene(10, width, height), ss=1), path, bit_depth="half")


def peak_mib(args, env) -> float:
    proc = subprocess.run([sys.executable, "-c", PEAK, *map(str, args)], env=env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    line = [ln for ln in proc.stderr.splitlines() if ln.startswith("peak_kib")][-1]
    return int(line.split()[1]) / 1024


@pytest.mark.skipif(not os.path.exists("/proc/self/status"), reason="VmHWM from /proc")
def test_cinema_1080p_peak_memory_stays_below_the_documented_budget(rt, tmp_path):
    w, h, pool = 1920, 1080, 64
    cinema_frame(tmp_path / "in.exr", w, h)
    env = {**os.environ, "CLFX_POOL_MB": str(pool),
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    env.pop("POCL_WORK_GROUP_SPECIALIZATION", None)   # clfx's default build, as it renders
    args = ["-q", "render", tmp_path / "in.exr", tmp_path / "out.exr", "--look", "cinema",
            "--overwrite"]
    peak_mib(args, env)           # the first render on a machine compiles the kernels
    peak = peak_mib(args, env)
    budget = memory_budget_mib(w * h, pool)
    assert (tmp_path / "out.exr").is_file()
    assert peak < budget, f"peak {peak:.0f} MiB over the budget {budget:.0f} MiB"
    assert np.isfinite(peak) and peak > 100     # measured something real
    # (before issue 10: 866 MiB here, over the 806 MiB budget)


@pytest.mark.slow
def test_a_1080p_cinema_sequence_allocates_no_buffer_after_its_first_frames(rt, monkeypatch):
    """Issue 37: with the default pool (``CLFX_POOL_MB``) the 1080p cinema look's buffers,
    maps and spectra stay between frames: a frame takes every buffer from the pool.  At 512
    MiB four frame-sized buffers were freed at each frame's end and made again (~18700 page
    faults, ~100 ms of CPU a frame)."""
    from clfx.bench.looks import demo_frame
    from clfx.device.cache import DEFAULT_BUDGET_BYTES, DeviceCache
    from clfx.pipeline.look import render_frame
    from clfx.pipeline.presets import load_look

    monkeypatch.setattr(rt, "cache", DeviceCache(rt.ctx, DEFAULT_BUDGET_BYTES))
    made = []
    take = rt.cache.take

    def counted(nbytes):
        before = rt.cache.device_bytes
        buf = take(nbytes)
        if rt.cache.device_bytes > before:
            made.append(nbytes)
        return buf

    monkeypatch.setattr(rt.cache, "take", counted)
    frame, look = demo_frame(1920, 1080), load_look("cinema")
    for quality in ("final", "preview"):
        for _ in range(2):            # the first frame builds; the second may find a size new
            render_frame(rt, look, frame, frame_number=1, quality=quality)
        del made[:]
        render_frame(rt, look, frame, frame_number=2, quality=quality)
        assert made == [], f"{quality}: {len(made)} buffers made again ({sum(made) >> 20} MiB)"
    assert rt.cache.nbytes <= rt.cache.max_bytes
