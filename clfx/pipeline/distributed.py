"""Rendering a sequence on a Dask cluster: a local one (``--workers N``) or an existing one
(``--scheduler ADDRESS``, env ``CLFX_SCHEDULER``).

Frames, or chunks of ``--chunk N`` consecutive frames, are Dask tasks.  A task carries only its
jobs (paths and frame numbers) and a small pickled spec of the render (look, options, pass
overrides); the worker reads its inputs and writes its outputs itself (shared storage) with the
same atomic writes as a single-process render, and sends back one small report per frame.

Each worker process holds a `ClfxWorker` plugin: the OpenCL runtime, built once when the
worker joins (a process-wide `Runtime`), and the renders it has unpacked, by key, so a task
pays neither device set-up nor look loading; effects keep their one-off set-up in the
runtime's cache as in one process.  Inside a task the next frame is read and the previous one
written on I/O threads while the device renders (at nice 10/5 on a CPU device: the overlapped
stream of `clfx.pipeline.batch`; workers keep it, measured faster for them than the single
process's phases, README "Scaling out"); across tasks, a worker runs `TASK_THREADS` of them
at once and a per-process device lock lets one render while the others read or write, so
single-frame tasks overlap their I/O too.

Faults: a worker that dies mid-frame leaves at most a temp file (removed when the batch
ends); Dask reruns its task on another worker (``distributed.scheduler.allowed-failures``
times) and the frame is rendered again from its inputs, so the output is the same pixels.
A frame that fails for a data reason (any `ClfxError`: bad file, missing pass) is not retried:
it is reported with its error and the other frames go on, unless ``fail_fast``.

Output is deterministic per frame: a frame rendered on any worker, alone or in a chunk, is the
same as in one process (the look's seed and the frame number decide the noise).
"""
from __future__ import annotations

import glob
import hashlib
import json
import logging
import os
import pickle
import socket
import threading
import time
import uuid
from collections import OrderedDict
from contextlib import ExitStack, contextmanager, nullcontext, suppress
from dataclasses import dataclass, replace

from distributed import Client, LocalCluster, as_completed, get_worker
from distributed.diagnostics.plugin import WorkerPlugin

from clfx.core.errors import ClfxError, ClusterError, SequenceError
from clfx.device.runtime import user_set_pocl_affinity
from clfx.pipeline.batch import RAW, Batch, Job, available_cores, io_pool

PLUGIN_NAME = "clfx"
TASK_THREADS = 2
"""Task threads of a local cluster's workers (``dask worker --nthreads``): one task renders
on the device (`ClfxWorker.device_lock`) while the other reads its input or writes its output.
More only hold more frames in memory: renders take turns on the one device."""
SPECS_KEPT = 4
"""Renders (look + options) a worker keeps unpacked; a long-lived cluster serves many."""


# -- what travels to the workers -----------------------------------------------------------
@dataclass(frozen=True)
class RenderSpec:
    """A batch's look, paths, options and pass overrides, pickled once on the client.

    ``key`` starts with the look's params hash and identifies the render in each worker's
    cache, so the look is unpacked once per worker process, not once per task.
    """

    key: str
    blob: bytes

    @classmethod
    def of(cls, batch: Batch) -> RenderSpec:
        reads = [(role, os.path.abspath(p)) for role, p in batch.reads]  # what writes protect
        blob = pickle.dumps((batch.look, batch.input_path, batch.output_path, batch.options,
                             batch.passes, batch.look_files, reads),
                            protocol=pickle.HIGHEST_PROTOCOL)
        return cls(f"{batch.look.params_hash()}-{hashlib.sha1(blob).hexdigest()[:12]}", blob)

    def batch(self) -> Batch:
        look, input_path, output_path, options, passes, look_files, reads = pickle.loads(self.blob)
        batch = Batch(look=look, input_path=input_path, output_path=output_path,
                      options=options, verbosity=0)
        batch.passes, batch.look_files, batch.reads = passes, look_files, reads  # from the client
        return batch


class ClfxWorker(WorkerPlugin):
    """State of one worker process: the runtime (built when the worker joins), the renders
    it has unpacked (`SPECS_KEPT` most recent, by `RenderSpec.key`) and the lock its task
    threads take to render (kernels share their argument slots, so one render at a time)."""

    idempotent = True   # a second client on the same cluster keeps the warm state

    def __init__(self, device: str | None = None):
        self.device = device

    def setup(self, worker=None):
        malloc_like_one_process()
        codec_threads_for_batches()
        self.device_lock = threading.Lock()
        self._lock = threading.Lock()
        self._batches: OrderedDict[str, Batch] = OrderedDict()
        self._rt = None
        self._rt_error: ClfxError | None = None
        self.runtime_s = 0.0
        t0 = time.perf_counter()
        try:
            from clfx.device.runtime import Runtime

            self._rt = Runtime.get(self.device)
        except ClfxError as exc:   # reported by every task of this worker, not at join time
            self._rt_error = exc
        self.runtime_s = time.perf_counter() - t0

    def runtime(self):
        if self._rt is None:
            raise self._rt_error or ClusterError("clfx worker plugin was not set up")
        return self._rt

    def batch(self, spec: RenderSpec) -> Batch:
        with self._lock:      # task threads
            if spec.key in self._batches:
                self._batches.move_to_end(spec.key)
            else:
                self._batches[spec.key] = spec.batch()
                while len(self._batches) > SPECS_KEPT:
                    self._batches.popitem(last=False)
            return self._batches[spec.key]


MMAP_THRESHOLD = 32 << 20
"""glibc's largest automatic mmap threshold (64-bit): blocks below it are reused from the heap."""
TRIM_THRESHOLD = 256 << 20
"""Free memory at the heap's top kept for the next frame instead of returned to the OS."""


def malloc_like_one_process() -> bool:
    """Undo Dask's ``MALLOC_TRIM_THRESHOLD_`` in a worker process (glibc only).

    Dask's nanny starts workers with ``MALLOC_TRIM_THRESHOLD_=65536`` (config
    ``distributed.nanny.pre-spawn-environ``) so that freed memory goes back to the OS at once.
    That also switches off glibc's adaptive mmap threshold: every buffer above 128 KiB is then
    a fresh mmap whose pages fault in again on first touch.  A render frees and reallocates
    the same tens of MB per frame, so a worker spent 3x the system time of one process and
    its effects ran 1.3-1.6x slower (8 frames of 1080p ``cinema``: 6.1 vs 1.9 s system time).
    Setting both thresholds explicitly restores what a long-lived process converges to.
    Returns True when the thresholds were set.
    """
    if not any(k in os.environ for k in ("MALLOC_TRIM_THRESHOLD_", "MALLOC_MMAP_THRESHOLD_")):
        return False
    import ctypes
    import ctypes.util
    import platform

    if platform.libc_ver()[0] != "glibc":
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        m_trim_threshold, m_mmap_threshold = -1, -3       # <malloc.h>
        return bool(libc.mallopt(m_mmap_threshold, MMAP_THRESHOLD)
                    and libc.mallopt(m_trim_threshold, TRIM_THRESHOLD))
    except (OSError, AttributeError):
        return False


def codec_threads_for_batches() -> int:
    """Set, once for the process, the codec threads of a worker's reads and writes: its share
    of the cores (``OPENIMAGEIO_OPTIONS``'s ``exr_threads``, which a local cluster sets to
    cores / N), else every core.  Measured with `--workers 1` on 2 cores, 24 frames of 1080p
    ``cinema``: 1.113 and 1.082 fps with 2 threads, 1.075 and 1.034 with 1 (the I/O runs on
    its own thread at nice 10/5 beside the renders).  Once for the process, since its task
    threads would undo each other's `clfx.io.read.codec_threads`."""
    import OpenImageIO as oiio

    from clfx.io.read import set_codec_threads

    n = 0
    options = os.environ.get("OPENIMAGEIO_OPTIONS")
    if options:                          # OpenImageIO's own parser of its variable
        oiio.attribute("options", options)
        n = oiio.get_int_attribute("exr_threads", 0)
    n = n or available_cores()
    set_codec_threads(n)
    return n


def _worker_state() -> ClfxWorker:
    worker = get_worker()
    state = worker.plugins.get(PLUGIN_NAME)
    if state is None:   # a task landed on a worker that never got the plugin
        raise ClusterError(f"worker {worker.address} has no {PLUGIN_NAME!r} plugin")
    return state


def _where() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


# -- the task ------------------------------------------------------------------------------
def render_chunk(spec: RenderSpec, jobs: list[Job], fail_fast: bool = False) -> list[dict]:
    """The Dask task: render ``jobs`` on this worker; one small result per frame.

    Each result has ``frame``, ``worker`` and either ``report`` (`FrameReport.as_dict`) and
    ``explain``, or ``error`` (the message of the `ClfxError` that failed the frame).
    """
    state = _worker_state()
    batch = state.batch(spec)
    try:
        rt = state.runtime()
    except ClfxError as exc:
        return [_failed(job, exc) for job in jobs]
    return render_jobs(batch, rt, jobs, fail_fast=fail_fast, device_lock=state.device_lock)


def render_jobs(batch: Batch, rt, jobs: list[Job], *, fail_fast: bool = False,
                device_lock=None) -> list[dict]:
    """Read, render and write ``jobs`` with `Batch`'s own steps, reading the next frame and
    writing the previous one on I/O threads while the device renders (holding
    ``device_lock`` if given); a frame that raises a `ClfxError` is reported and the others
    go on (all stop after it with ``fail_fast``)."""
    prepared = batch._prepare_look(rt, jobs)
    try:
        results = _render_jobs(batch, rt, jobs, fail_fast, device_lock)
    except BaseException:
        if prepared is not None:
            prepared.close(cancel=True)
        raise
    if prepared is not None:      # a frame failed or was not rendered: stop preparing for it
        prepared.close(cancel=any(r is None or "error" in r for r in results))
    return [r for r in results if r is not None]


def _render_jobs(batch: Batch, rt, jobs: list[Job], fail_fast: bool,
                 device_lock) -> list[dict | None]:
    """`render_jobs` without the maps' thread: a result per job (None: not rendered)."""
    results: list[dict | None] = [None] * len(jobs)
    writes = []
    lowered = getattr(rt, "shares_host_cores", True)   # I/O gives way to a CPU device
    with io_pool(lowered=lowered) as pool, io_pool("write", lowered=lowered) as writer:
        next_read = pool.submit(batch._read, jobs[0]) if jobs else None
        for i, job in enumerate(jobs):
            read, next_read = next_read, (pool.submit(batch._read, jobs[i + 1])
                                          if i + 1 < len(jobs) else None)
            try:
                frame_in = read.result()
                with device_lock or nullcontext():
                    frame_out, report, views = batch.render(rt, job, frame_in)
            except ClfxError as exc:
                results[i] = _failed(job, exc)
                if fail_fast:
                    break
                continue
            writes.append((i, report, writer.submit(batch._write, frame_out, job, report, views)))
        for i, report, done in writes:
            try:
                done.result()
            except ClfxError as exc:
                results[i] = _failed(jobs[i], exc)
                continue
            results[i] = {"frame": jobs[i].frame, "worker": _where(),
                          "report": report.as_dict(), "explain": report.explain()}
    return results


def _failed(job: Job, exc: BaseException) -> dict:
    message = str(exc) if isinstance(exc, ClfxError) else f"{type(exc).__name__}: {exc}"
    return {"frame": job.frame, "worker": _where(), "input": job.input, "output": job.output,
            "error": " ".join(message.split())}


# -- the cluster ---------------------------------------------------------------------------
def worker_env(workers: int, cores: int | None = None) -> dict[str, str]:
    """Environment for ``workers`` local worker processes sharing ``cores``: each gets an
    equal share of threads for PoCL (its OpenCL CPU device) and OpenImageIO (EXR
    decode/encode), so renders and I/O do not oversubscribe the cores.  Variables already set
    in the environment win."""
    if cores is None:
        cores = available_cores()
    share = str(max(1, (cores or 1) // max(1, workers)))
    env = {"POCL_MAX_PTHREAD_COUNT": share,         # PoCL <= 4 pthread device
           "POCL_CPU_MAX_CU_NUM": share,            # PoCL >= 4 cpu device
           "OPENIMAGEIO_OPTIONS": f"threads={share},exr_threads={share}",
           "OMP_NUM_THREADS": share}
    env = {k: v for k, v in env.items() if k not in os.environ}
    if workers > 1 and not user_set_pocl_affinity():
        env["POCL_AFFINITY"] = "0"   # each would pin its PoCL thread i to core i: all on
    return env                       # the same cores (clfx.device.runtime's default)


CONNECT_TIMEOUT_S = 10.0
"""Seconds to reach a ``--scheduler`` and hear its Dask handshake (a scheduler sends one at
once); a port where something else listens is refused after this, not waited on."""


def check_scheduler(address: str, timeout: float = CONNECT_TIMEOUT_S) -> None:
    """Raise `ClusterError` in one line unless a Dask scheduler answers at ``address``
    within ``timeout`` seconds: an unknown protocol, a bad port or host, nothing listening,
    or (``tcp://``) a listener that never sends Dask's handshake."""
    from distributed.comm import registry
    from distributed.comm.addressing import parse_address, parse_host_port

    what = f"--scheduler {address!r}"
    try:
        scheme, loc = parse_address(address.strip(), strict=False)
    except (ValueError, TypeError) as exc:
        raise ClusterError(f"{what}: not an address like tcp://HOST:8786 ({exc})") from None
    if scheme not in registry.backends:
        raise ClusterError(f"{what}: unknown protocol {scheme!r} (expected "
                           f"{', '.join(sorted(registry.backends))}; e.g. tcp://HOST:8786)")
    if scheme != "tcp":
        return
    try:
        host, port = parse_host_port(loc, 8786)
        port = int(port)
        if not host or not 0 < port < 65536:
            raise ValueError(f"host {host!r}, port {port}")
    except (ValueError, TypeError) as exc:
        raise ClusterError(f"{what}: not an address like tcp://HOST:8786 ({exc})") from None
    try:
        with socket.create_connection((host, port), timeout=timeout) as sock:
            sock.settimeout(timeout)
            if not sock.recv(1):
                raise ClusterError(f"cannot reach scheduler {address}: it closed the "
                                   f"connection (not a Dask scheduler?)")
    except socket.timeout:
        raise ClusterError(f"cannot reach scheduler {address}: no Dask scheduler answered "
                           f"within {timeout:g} s") from None
    except OSError as exc:
        raise ClusterError(f"cannot reach scheduler {address}: "
                           f"{exc.strerror or exc}") from None


@contextmanager
def connect(*, workers: int | None = None, scheduler: str | None = None,
            device: str | None = None, quiet: bool = True):
    """A Dask client on a fresh local cluster of ``workers`` processes (`TASK_THREADS` task
    threads each) or on the cluster at ``scheduler``; the `ClfxWorker` plugin is registered on every
    worker, present and future."""
    if scheduler and workers:
        raise ClusterError("give --workers N (a local cluster) or --scheduler ADDRESS "
                           "(an existing one), not both")
    level = logging.ERROR if quiet else logging.WARNING
    with ExitStack() as stack:
        try:
            if scheduler:
                check_scheduler(scheduler)
                client = stack.enter_context(Client(scheduler, set_as_default=False,
                                                    timeout=CONNECT_TIMEOUT_S))
            else:
                if workers < 1:
                    raise ClusterError(f"--workers {workers}: expected 1 or more")
                cluster = stack.enter_context(LocalCluster(
                    n_workers=workers, threads_per_worker=TASK_THREADS, processes=True,
                    dashboard_address=None, silence_logs=level, env=worker_env(workers)))
                client = stack.enter_context(Client(cluster, set_as_default=False))
        except (OSError, TimeoutError) as exc:
            where = f"scheduler {scheduler}" if scheduler else f"a local cluster of {workers}"
            raise ClusterError(f"cannot reach {where}: {exc}") from exc
        client.register_plugin(ClfxWorker(device), name=PLUGIN_NAME)
        yield client


# -- the client ----------------------------------------------------------------------------
def render_distributed(batch: Batch, *, workers: int | None = None, scheduler: str | None = None,
                       chunk: int = 1, fail_fast: bool = False, device: str | None = None) -> dict:
    """Render a prepared batch (``batch.prepare()`` done, passes set) on a Dask cluster.

    Prints what `Batch.run` prints (JSON lines in frame order and a summary with ``--json``,
    ``--explain`` texts), plus progress with frames per second and ETA on a terminal.

    Returns
    -------
    dict
        The summary (as `Batch.run`'s, plus ``workers``, ``chunk``, ``failed`` frames and
        ``startup_s``, the time to start or reach the cluster; ``fps`` leaves it out).

    Raises
    ------
    ClusterError
        The cluster cannot be started or reached.
    ClfxError
        Some frames failed, each reported first (JSON line, stderr): a data error, or a task
        that could not complete (e.g. its workers died ``allowed-failures`` times).  The other
        frames are rendered unless ``fail_fast``.
    """
    if batch.input_path == RAW or batch.output_path == RAW:
        raise SequenceError("raw pipes ('-') render in one process; --workers and "
                            "--scheduler render files")
    if chunk < 1:
        raise SequenceError(f"--chunk {chunk}: expected 1 or more frames per task")
    o = batch.options
    as_json, explain = o.as_json, o.explain
    jobs = batch.jobs
    if batch.skipped_existing and batch.verbosity > 0:
        batch._err(f"clfx: skipping {len(batch.skipped_existing)} frame(s) whose output exists")
    spec = RenderSpec.of(batch)
    remote = [_absolute(j) for j in jobs]   # workers need not share the client's folder
    chunks = [remote[i:i + chunk] for i in range(0, len(remote), chunk)]
    t0 = time.perf_counter()
    reports, failed = [], []
    ended = False   # every task has ended (none is still writing a temp file)
    startup = 0.0
    try:
        with connect(workers=workers, scheduler=scheduler, device=device,
                     quiet=batch.verbosity < 2) as client:
            nworkers = len(client.scheduler_info()["workers"]) if scheduler else workers
            startup = time.perf_counter() - t0
            ended = _collect(batch, client, spec, chunks, fail_fast, as_json, explain,
                             reports, failed, {j.frame: j for j in jobs})
    finally:
        if ended or not scheduler:   # a local cluster's workers are gone by now
            _remove_orphan_temps(jobs)
    wall = time.perf_counter() - t0
    render_s = wall - startup
    device_ms = [r["report"]["total_ms"] for r in reports]
    summary = {"summary": True, "look": batch.look.name, "frames": len(reports),
               "failed": [r["frame"] for r in failed],
               "skipped_existing": len(batch.skipped_existing), "wall_s": round(wall, 3),
               "startup_s": round(startup, 3),
               "fps": round(len(reports) / render_s, 3) if render_s > 0 and reports else None,
               "device_ms_mean": round(sum(device_ms) / len(device_ms), 2) if device_ms else None,
               "workers": nworkers, "chunk": chunk,
               "scheduler": scheduler or "local"}
    if as_json:
        print(json.dumps(summary), flush=True)
    elif batch.verbosity > 0:
        batch._err(f"clfx: {len(reports)} frame(s) rendered with look {batch.look.name!r} on "
                   f"{nworkers} worker(s) in {wall:.2f} s"
                   + (f" ({summary['fps']} fps after {startup:.1f} s start-up)"
                      if summary["fps"] else ""))
    if failed:
        first = failed[0]
        more = f" (and {len(failed) - 1} more: frames {_frames_text(failed[1:])})" if len(failed) > 1 else ""
        raise ClfxError(f"frame {first['frame']} failed: {first['error']}{more}")
    return summary


def _collect(batch: Batch, client, spec: RenderSpec, chunks: list[list[Job]], fail_fast: bool,
             as_json: bool, explain: bool, reports: list, failed: list,
             given: dict[int, Job]) -> bool:
    """Submit one task per chunk, emit results in frame order as tasks finish; True when
    every task ended (False when ``fail_fast`` cancelled the rest).  Reports name the
    files as ``given`` (the client's jobs by frame)."""
    progress = _Progress(batch, sum(map(len, chunks))) if batch.progress else None
    run = uuid.uuid4().hex[:8]
    futures = {client.submit(render_chunk, spec, c, fail_fast, pure=False, retries=0,
                             key=f"clfx-render-{c[0].frame}-{c[-1].frame}-{run}"): i
               for i, c in enumerate(chunks)}
    results: dict[int, list[dict]] = {}
    emitted = 0
    try:
        for future in as_completed(futures, loop=client.loop):
            i = futures[future]
            if future.status == "error":
                exc = future.exception()
                results[i] = [_failed(job, exc) for job in chunks[i]]
            else:
                results[i] = future.result()
            future.release()
            while emitted in results:   # frame order
                for r in results.pop(emitted):
                    _as_given(r, given[r["frame"]])
                    _emit(batch, r, as_json, explain)
                    (failed if "error" in r else reports).append(r)
                    if progress:
                        progress.update(r)
                emitted += 1
            if fail_fast and failed:
                client.cancel(list(futures))
                return False
    finally:
        if progress:
            progress.close()
    return True


def _absolute(job: Job) -> Job:
    return replace(job, **{k: os.path.abspath(v) for k in ("input", "output", "depth", "velocity")
                           if (v := getattr(job, k))})


def _as_given(result: dict, job: Job) -> None:
    """Name the files in a result as the user gave them (tasks saw absolute paths)."""
    for d in (result, result.get("report")):
        if d is not None and "input" in d:
            d["input"], d["output"] = job.input, job.output


def _emit(batch: Batch, result: dict, as_json: bool, explain: bool) -> None:
    if "error" in result:
        if as_json:
            print(json.dumps(result), flush=True)
        if batch.verbosity > 0:
            batch._err(f"clfx: frame {result['frame']} failed on {result['worker']}: "
                       f"{result['error']}")
        return
    if as_json:
        print(json.dumps({**result["report"], "worker": result["worker"]}), flush=True)
    rep = result["report"]  # the same lines as a local render
    said = rep.get("warnings", []) + [f"{s['effect']}: {w}" for s in rep.get("steps", [])
                                      for w in s.get("warnings", [])]
    for w in said:   # each text once per batch, as a local render says it
        if w not in batch._warned:
            batch._warned.add(w)
            batch._err(f"clfx: warning: frame {result['frame']}: {w}")
    if explain:
        batch._err(result["explain"])


def _frames_text(results: list[dict]) -> str:
    from clfx.io.sequence import compact

    return compact(r["frame"] for r in results)


class _Progress:
    """One stderr line: frames done, frames per second and time left (rate measured from the
    first finished frame, so cluster start-up does not count)."""

    def __init__(self, batch: Batch, total: int):
        self.batch, self.total, self.done, self.failed = batch, total, 0, 0
        self.t_first: float | None = None

    def update(self, result: dict) -> None:
        now = time.perf_counter()
        self.done += 1
        self.failed += "error" in result
        if self.t_first is None:
            self.t_first = now
        rate = (self.done - 1) / (now - self.t_first) if self.done > 1 and now > self.t_first else None
        eta = f"ETA {_duration((self.total - self.done) / rate)}" if rate else "ETA --"
        fps = f"{rate:.2f} fps" if rate else "-- fps"
        bad = f", {self.failed} failed" if self.failed else ""
        self.batch._err(f"\rclfx: {self.done}/{self.total} frames{bad}  {fps}  {eta}   ", end="")

    def close(self) -> None:
        if self.done:
            self.batch._err("")


def _duration(seconds: float) -> str:
    s = round(seconds)
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"


def _remove_orphan_temps(jobs: list[Job]) -> None:
    """Remove the temp files of this batch's outputs (``.<name>.tmp-<pid>-<rand>-<host><ext>``, see
    `clfx.io.write.write_frame`) that a killed worker left; every task has ended, so none is
    still being written."""
    for job in jobs:
        folder, name = os.path.split(os.path.abspath(job.output))
        for tmp in glob.glob(os.path.join(glob.escape(folder), f".{glob.escape(name)}.tmp-*")):
            with suppress(OSError):
                os.remove(tmp)
