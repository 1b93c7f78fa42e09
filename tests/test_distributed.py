"""Rendering on Dask: a real scheduler and workers on 127.0.0.1 (or a local cluster) give the
same pixels as one process, survive a worker killed mid-frame, and report bad frames."""
from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import signal
import time
from pathlib import Path

import numpy as np
import pytest

from tests.cluster import assert_same_outputs, clfx, clfx_popen, dask_cluster

pytest.importorskip("distributed")


@pytest.fixture(scope="module")
def beachball(small_beachball):
    """Beachball's multipart sequence decimated by 4 (`tests.plates`): every part, view and
    window of the real files, 1/16 of the pixels.  A cluster's frames equal one process's
    at any size; the full-size frames are the killed worker's (`full_beachball`)."""
    return small_beachball.pattern("multipart", range(1, 5))


@pytest.fixture(scope="module")
def full_beachball(exr_images):
    if not (exr_images / "Beachball" / "multipart.0008.exr").is_file():
        pytest.skip(f"Beachball sequence not found in {exr_images / 'Beachball'}")
    return str(exr_images / "Beachball" / "multipart.#.exr")


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """Single-process renders (no flag), made once per (source, look, frames, options)."""
    made = {}

    def render(source, look, frames, *options):
        key = (source, look, frames, options)
        if key not in made:
            out = tmp_path_factory.mktemp("reference")
            clfx("-q", "render", source, out / "out.#.exr", "--look", look,
                 "--frames", frames, *options)
            made[key] = out
        return made[key]
    return render


def json_lines(stdout: str) -> list[dict]:
    return [json.loads(line) for line in stdout.splitlines() if line.startswith("{")]


def test_scheduler_cinema_matches_single_process(beachball, reference, tmp_path):
    want = reference(beachball, "cinema", "1-3", "--quality", "draft")
    out = tmp_path / "out"
    with dask_cluster(tmp_path / "logs") as (address, _):
        proc = clfx("render", beachball, out / "out.#.exr", "--look", "cinema",
                    "--quality", "draft", "--frames", "1-3", "--scheduler", address, "--json")
    lines = json_lines(proc.stdout)
    assert [d["frame"] for d in lines[:-1]] == [1, 2, 3]   # in frame order
    assert lines[-1]["summary"] and lines[-1]["frames"] == 3 and lines[-1]["workers"] == 2
    assert len({d["worker"] for d in lines[:-1]}) == 2        # both workers rendered
    assert_same_outputs(out, want)


def test_worker_killed_mid_frame_batch_completes(full_beachball, reference, tmp_path):
    """Full-size frames: a worker is caught while it writes one (a 2K stereo frame takes
    long enough to write), its chunk goes to the other worker.  Four frames in two chunks:
    each worker starts one, the survivor renders both."""
    want = reference(full_beachball, "wide-angle", "1-4")
    out = tmp_path / "out"
    with dask_cluster(tmp_path / "logs") as (address, workers):
        by_pid = {w.pid: w for w in workers}
        proc = clfx_popen("render", full_beachball, out / "out.#.exr", "--look", "wide-angle",
                          "--frames", "1-4", "--chunk", "2", "--scheduler", address, "--json")
        victim, deadline = None, time.monotonic() + 40
        while victim is None and proc.poll() is None and time.monotonic() < deadline:
            # a worker writing a frame: its temp file .<name>.tmp-<pid>-... is in the folder
            for name in os.listdir(out) if out.is_dir() else ():
                m = re.match(r"\..+\.tmp-(\d+)-", name)
                if m and int(m.group(1)) in by_pid:
                    victim = by_pid[int(m.group(1))]
                    victim.send_signal(signal.SIGKILL)
                    break
            time.sleep(0.002)
        stdout, stderr = proc.communicate(timeout=150)
        assert victim is not None, "no worker was caught writing a frame"
        assert victim.wait(timeout=5) == -signal.SIGKILL
    assert proc.returncode == 0, stderr[-3000:]
    lines = json_lines(stdout)
    assert [d["frame"] for d in lines[:-1]] == list(range(1, 5))
    assert lines[-1]["frames"] == 4 and lines[-1]["failed"] == []
    assert_same_outputs(out, want)   # no partial or temp file either


def test_local_workers_match_no_flag(beachball, reference, tmp_path):
    want = reference(beachball, "film-35mm", "1-4")
    out = tmp_path / "out"
    proc = clfx("render", beachball, out / "out.#.exr", "--look", "film-35mm",
                "--frames", "1-4", "--workers", "2", "--json")
    assert json_lines(proc.stdout)[-1]["workers"] == 2
    assert_same_outputs(out, want)


def test_bad_frame_fails_once_and_others_render(beachball, tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    for f in (1, 3):
        shutil.copy(beachball.replace("#", f"{f:04d}"), src / f"bb.{f:04d}.exr")
    (src / "bb.0002.exr").write_bytes(b"not an exr" * 100)
    with dask_cluster(tmp_path / "logs", workers=1) as (address, _):
        proc = clfx("render", src / "bb.#.exr", tmp_path / "a" / "o.#.exr", "--look",
                    "wide-angle", "--scheduler", address, "--json", check=False)
        assert proc.returncode == 1
        assert "frame 2 failed" in proc.stderr and "bb.0002.exr" in proc.stderr
        lines = json_lines(proc.stdout)
        assert [d["frame"] for d in lines[:-1]] == [1, 2, 3]
        assert "error" in lines[1] and lines[-1]["failed"] == [2]
        assert sorted(os.listdir(tmp_path / "a")) == ["o.0001.exr", "o.0003.exr"]
        # --fail-fast: the chunk stops at the bad frame, frame 3 is never rendered
        proc = clfx("render", src / "bb.#.exr", tmp_path / "b" / "o.#.exr", "--look",
                    "wide-angle", "--scheduler", address, "--chunk", "3", "--fail-fast",
                    check=False)
        assert proc.returncode == 1 and "frame 2 failed" in proc.stderr
        assert sorted(os.listdir(tmp_path / "b")) == ["o.0001.exr"]


def test_unreachable_scheduler_is_one_line_error(beachball, tmp_path):
    from tests.cluster import free_port

    proc = clfx("render", beachball, tmp_path / "o.#.exr", "--frames", "1",
                "--scheduler", f"tcp://127.0.0.1:{free_port()}", check=False,
                DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT="2s")
    assert proc.returncode == 1
    assert proc.stderr.startswith("clfx: error: cannot reach scheduler"), proc.stderr[-2000:]
    assert not Path(tmp_path / "o.0001.exr").exists()


def test_worker_undoes_dasks_malloc_trim_threshold():
    """Dask's nanny starts workers with MALLOC_TRIM_THRESHOLD_=65536, which makes every
    frame-sized buffer a fresh mmap; the worker plugin sets glibc's thresholds back."""
    import platform
    import subprocess
    import sys

    if platform.libc_ver()[0] != "glibc":
        pytest.skip("glibc only")
    code = ("from clfx.pipeline.distributed import malloc_like_one_process as m; "
            "print(m())")
    env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")}
    plain = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                           text=True, check=True)
    under_dask = subprocess.run([sys.executable, "-c", code],
                                env={**env, "MALLOC_TRIM_THRESHOLD_": "65536"},
                                capture_output=True, text=True, check=True)
    assert plain.stdout.split() == ["False"]          # nothing to undo: glibc's own policy
    assert under_dask.stdout.split() == ["True"]


def test_task_threads_take_turns_on_the_device(monkeypatch):
    """Two tasks of one worker overlap their reads and writes, never their renders (both run
    `render_stream`, the loop of a local render)."""
    import threading
    from concurrent.futures import ThreadPoolExecutor

    from clfx.pipeline import stream as stream_mod
    from clfx.pipeline.plan import BatchPlan, Job
    from clfx.pipeline.stream import render_stream
    from clfx.pipeline.presets import load_look

    lock = threading.Lock()
    rendering, overlaps = [0], []

    class Read:
        notices = []

        def pixels(self):
            return 64

    class StubPlan(BatchPlan):
        def read(self, job):
            time.sleep(0.02)
            return Read()

        def render(self, rt, job, read, stats=None):
            assert lock.locked()
            rendering[0] += 1
            overlaps.append(rendering[0])
            time.sleep(0.03)
            rendering[0] -= 1
            return job.frame, job.frame, None

        def write(self, frame, job, report, rest=()):
            time.sleep(0.02)
            return False

    monkeypatch.setattr(stream_mod, "prepare_maps", lambda *a, **k: None)
    plan = StubPlan(look=load_look("default"), quality="final")
    jobs = [[Job(frame=f, input=f"in.{f}", output=f"out.{f}")] for f in range(1, 7)]

    def task(chunk):
        results = []
        render_stream(None, plan, chunk, results.append, keep_going=True, overlap=True,
                      device_lock=lock)
        return results

    with ThreadPoolExecutor(2) as pool:
        results = list(pool.map(task, jobs))
    assert [r[0].frame for r in results] == list(range(1, 7))
    assert all(r[0].report == r[0].frame and r[0].error is None for r in results)
    assert overlaps and max(overlaps) == 1


def test_worker_codecs_take_its_share_of_the_cores(monkeypatch):
    """A local cluster gives each worker its share of the cores as a number (the plugin's
    ``codec_threads``); a farm's worker keeps its own OPENIMAGEIO_OPTIONS, else every core."""
    import OpenImageIO as oiio

    from clfx.pipeline.distributed import ClfxWorker, codec_threads_for_batches, worker_share

    saved = {k: oiio.get_int_attribute(k, 0) for k in ("threads", "exr_threads")}
    try:
        monkeypatch.delenv("OPENIMAGEIO_OPTIONS", raising=False)
        assert worker_share(2, cores=7) == 3 and worker_share(4, cores=2) == 1
        assert ClfxWorker(None, worker_share(2, cores=6)).codec_threads == 3
        assert codec_threads_for_batches(3) == 3 == oiio.get_int_attribute("exr_threads", 0)
        assert codec_threads_for_batches() == len(os.sched_getaffinity(0))   # a user's worker
        monkeypatch.setenv("OPENIMAGEIO_OPTIONS", "threads=2,exr_threads=2")  # set by the user
        assert codec_threads_for_batches() == 2 == oiio.get_int_attribute("exr_threads", 0)
    finally:
        for k, v in saved.items():
            oiio.attribute(k, v)


def test_several_local_workers_do_not_pin_pocl_threads(monkeypatch):
    """The runtime pins PoCL's threads one per core by default (clfx.device.runtime
    ``_ensure_pocl_affinity``); several local workers would pin theirs to the same cores, so
    their environment turns it off, unless the user chose."""
    from clfx.device import runtime
    from clfx.pipeline.distributed import worker_env

    monkeypatch.setattr(runtime, "_AFFINITY_DEFAULTED", True)
    monkeypatch.setenv("POCL_AFFINITY", "1")                      # the runtime's default
    assert worker_env(2, cores=2)["POCL_AFFINITY"] == "0"
    assert "POCL_AFFINITY" not in worker_env(1, cores=2)
    monkeypatch.setattr(runtime, "_AFFINITY_DEFAULTED", False)    # the user's own setting
    assert "POCL_AFFINITY" not in worker_env(2, cores=2)


def masked_batch(folder, mask_file: str, monkeypatch):
    """A prepared one-frame batch in ``folder`` (the working directory from now on): in.exr
    through a look (masked.yaml) whose vignette is masked by the file ``mask_file``, given
    relative to ``folder``."""
    import numpy as np

    from clfx.core.frame import Frame
    from clfx.io.write import write_frame
    from clfx.pipeline.batch import Batch
    from clfx.pipeline.options import RenderOptions
    from clfx.pipeline.presets import load_look

    rgba = np.random.default_rng(1).uniform(0, 2, (16, 24, 4)).astype(np.float32)
    write_frame(Frame.from_array(rgba), folder / "in.exr")
    (folder / mask_file).parent.mkdir(parents=True, exist_ok=True)
    write_frame(Frame.from_array(np.full((16, 24, 4), 0.5, np.float32)), folder / mask_file)
    (folder / "masked.yaml").write_text(
        f"name: m\neffects:\n  - effect: vignette\n    mask: {{file: {mask_file}}}\n")
    monkeypatch.chdir(folder)
    batch = Batch(look=load_look("masked.yaml"), input_path="in.exr", output_path="out.exr",
                  options=RenderOptions(), verbosity=0)
    batch.prepare()
    return batch


def test_workers_protect_mask_files_as_one_process_does(tmp_path, monkeypatch):
    """A worker writes with the plan's list of every file the render reads, mask files
    included: an output that is a mask file is refused on the worker (the client refuses it
    too, before the first frame; here the plan is changed after that check), and the frame
    a worker renders comes back as a typed `FrameResult` with its `FrameReport`."""
    from dataclasses import replace

    from clfx.pipeline.distributed import ShippedPlan, connect, render_chunk
    from clfx.pipeline.look import FrameReport

    plan = masked_batch(tmp_path, "mask.exr", monkeypatch).plan
    assert ("mask", "mask.exr") in plan.reads
    onto_mask = replace(plan, jobs=(replace(plan.jobs[0], output="mask.exr"),),
                        io=replace(plan.io, overwrite=True))
    before = (tmp_path / "mask.exr").read_bytes()
    with connect(workers=1) as client:
        assert client.scheduler.address.startswith("tcp://127.0.0.1:")
        refused = client.submit(render_chunk, ShippedPlan.of(onto_mask), 0, 1, pure=False).result()
        done = client.submit(render_chunk, ShippedPlan.of(plan), 0, 1, pure=False).result()
    assert len(refused) == 1 and refused[0].report is None
    assert "refusing to write" in refused[0].error and "mask.exr" in refused[0].error
    assert (tmp_path / "mask.exr").read_bytes() == before
    assert done[0].error is None and isinstance(done[0].report, FrameReport)
    assert [s.effect for s in done[0].report.steps if s.ran] == ["vignette"]
    assert (tmp_path / "out.exr").is_file()


def test_relative_mask_files_resolve_against_the_submission_folder(tmp_path, monkeypatch, rt):
    """A look's relative ``mask: {file: ...}`` is resolved when the plan is shipped, against
    the folder the render was submitted from (as a render in one process reads it), not the
    worker's working directory: a worker elsewhere reads the same mask."""
    import numpy as np

    from clfx.pipeline.distributed import ShippedPlan

    shot = tmp_path / "shot"
    shot.mkdir()
    batch = masked_batch(shot, "mattes/m.exr", monkeypatch)
    local = batch.plan.render(rt, batch.jobs[0], batch.plan.read(batch.jobs[0]))[0]
    shipped = ShippedPlan.of(batch.plan).plan()
    assert shipped.look.steps[0].mask.file == str(shot / "mattes" / "m.exr")
    assert ("mask", str(shot / "mattes" / "m.exr")) in shipped.reads
    worker_cwd = tmp_path / "worker"
    worker_cwd.mkdir()
    monkeypatch.chdir(worker_cwd)                 # where a worker process runs
    job = shipped.jobs[0]
    remote = shipped.render(rt, job, shipped.read(job))[0]
    np.testing.assert_array_equal(remote.rgba, local.rgba)


def test_quiet_workers_say_nothing_on_a_cold_compiler_cache(rt, tmp_path):
    """``-q --workers``: the workers' OpenCL compiler warnings stay off stderr as in one
    process (a cold PoCL cache made the cinema look print ~1,700 lines).  Each worker builds
    a program that always warns (`tests.compiler_warns`, preloaded) through its runtime
    before its first task, so the test does not depend on whether this machine's compiler
    has anything to say about clfx's own kernels; here, in this process, the same program's
    warning is shown when asked for: there is something to hide."""
    import warnings

    import numpy as np

    from clfx.core.frame import Frame
    from clfx.io.write import write_frame
    from tests import compiler_warns

    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        compiler_warns.build(rt, tmp_path / "here")
    warned = any(compiler_warns.spoke(str(w.message)) for w in seen)
    rgba = np.random.default_rng(2).uniform(0, 4, (36, 64, 4)).astype(np.float32)
    for f in (1, 2):
        write_frame(Frame.from_array(rgba), tmp_path / f"in.{f:04d}.exr")
    (tmp_path / "v.yaml").write_text("name: v\neffects:\n  - effect: vignette\n  - effect: glare\n")
    proc = clfx("-q", "render", tmp_path / "in.#.exr", tmp_path / "out" / "o.#.exr",
                "--look", tmp_path / "v.yaml", "--workers", "1",
                POCL_CACHE_DIR=str(tmp_path / "cold-cache"),
                DASK_DISTRIBUTED__WORKER__PRELOAD=str([compiler_warns.__name__]),
                **{compiler_warns.FOLDER_ENV: str(tmp_path / "worker")})
    assert not compiler_warns.spoke(proc.stderr), proc.stderr
    assert proc.stderr == "" and proc.stdout == ""
    assert sorted(os.listdir(tmp_path / "out")) == ["o.0001.exr", "o.0002.exr"]
    built = list((tmp_path / "worker").glob("*/warns.built"))
    assert len(built) == 1, "the worker built no warning program"
    if not warned:   # a compiler that ignores #warning (none seen yet): nothing leaked either way
        warnings.warn("this OpenCL compiler ignores #warning: the workers had nothing to hide")


def test_sigterm_leaves_no_local_worker_behind(tmp_path):
    """A render on a local cluster (127.0.0.1) ended by SIGTERM: clfx exits 143 within a
    few seconds and no worker process it started outlives it (the signal watcher's forced
    exit skips the cluster's close)."""
    import psutil
    from clfx.core.frame import Frame
    from clfx.io.write import write_frame

    rgba = np.random.default_rng(3).uniform(0, 2, (48, 64, 4)).astype(np.float32)
    for f in range(1, 41):
        write_frame(Frame.from_array(rgba), tmp_path / f"in.{f:04d}.exr")
    proc = clfx_popen("render", tmp_path / "in.#.exr", tmp_path / "out" / "o.#.exr",
                      "--look", "cinema", "--workers", "2")
    me, every = psutil.Process(proc.pid), []
    try:
        workers, deadline = [], time.monotonic() + 90
        while len(workers) < 2 and proc.poll() is None and time.monotonic() < deadline:
            workers = [c for c in me.children(recursive=True)
                       if "multiprocessing" in " ".join(c.cmdline())]
            time.sleep(0.2)
        assert len(workers) >= 2, "no local workers started"
        every = me.children(recursive=True)
        time.sleep(2)                                   # the workers take their frames
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=30)
        assert proc.returncode == 143
        gone, alive = psutil.wait_procs(every, timeout=10)
        assert not alive, [(p.pid, p.cmdline()) for p in alive]
    finally:
        proc.kill()
        for p in every:                                 # none, unless the test failed
            with contextlib.suppress(psutil.Error):
                p.kill()


STUCK_ON_A_CLUSTER = """
import signal, sys, time
import clfx.cli as cli
from clfx.pipeline.distributed import connect
for s in (signal.SIGTERM, signal.SIGINT):         # a main thread that never gets to react
    signal.signal(s, lambda *a: None)
cli._watch_signals()
with connect(workers=2):
    print("ready", flush=True)
    time.sleep(120)
"""


def test_a_forced_exit_leaves_no_local_worker_behind():
    """The signal watcher ends a process whose main thread does not answer with os._exit
    (no cluster close runs): the local workers end with it."""
    import subprocess
    import sys

    import psutil

    from tests.cluster import env

    proc = subprocess.Popen([sys.executable, "-c", STUCK_ON_A_CLUSTER], env=env(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    every = []
    try:
        assert proc.stdout.readline() == b"ready\n"
        every = psutil.Process(proc.pid).children(recursive=True)
        assert len([c for c in every if "multiprocessing" in " ".join(c.cmdline())]) >= 2
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=30)
        assert proc.returncode == 143, err
        _, alive = psutil.wait_procs(every, timeout=10)
        assert not alive, [(p.pid, p.cmdline()) for p in alive]
    finally:
        proc.kill()
        for p in every:
            with contextlib.suppress(psutil.Error):
                p.kill()
