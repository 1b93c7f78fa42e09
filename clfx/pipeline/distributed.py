"""Rendering a sequence on a Dask cluster: a local one (``--workers N``) or an existing one
(``--scheduler ADDRESS``, env ``CLFX_SCHEDULER``).

Frames, or chunks of ``--chunk N`` consecutive frames, are Dask tasks.  A task carries the
batch's `BatchPlan` (pickled once on the client) and the range of its jobs it renders; the
worker runs the same `render_stream` as a single-process render (it reads its inputs and
writes its outputs itself, shared storage, with the same atomic writes and the same files
protected) and sends back one typed `FrameResult` per frame, which the client's `Reporter`
says as a local render would.

Each worker process holds a `ClfxWorker` plugin: the OpenCL runtime, built once when the
worker joins (a process-wide `Runtime`), and the plans it has unpacked, by key, so a task
pays neither device set-up nor look loading; effects keep their one-off set-up in the
runtime's cache as in one process.  Inside a task the next frame is read and the previous one
written on I/O threads while the device renders (at nice 10/5 on a CPU device: the overlapped
stream of `clfx.pipeline.stream`; workers keep it, measured faster for them than the single
process's phases, docs/scaling.md); across tasks, a worker runs `TASK_THREADS` of them
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

import ctypes
import ctypes.util
import glob
import logging
import os
import pickle
import platform
import socket
import struct
import threading
import time
import uuid
import warnings
from collections import OrderedDict
from contextlib import ExitStack, contextmanager, suppress
from dataclasses import dataclass

import OpenImageIO as oiio
from distributed import Client, LocalCluster, as_completed, get_worker
from distributed.comm import registry
from distributed.comm.addressing import parse_address, parse_host_port
from distributed.diagnostics.plugin import WorkerPlugin

from clfx.core.errors import ClfxError, ClusterError, SequenceError, option
from clfx.device.runtime import KernelBuildWarning, Runtime, user_set_pocl_affinity
from clfx.io.read import set_codec_threads
from clfx.io.sequence import compact
from clfx.pipeline.batch import Batch
from clfx.pipeline.options import RAW, ClusterOptions
from clfx.pipeline.plan import BatchPlan, Job
from clfx.pipeline.stream import available_cores, render_stream
from clfx.pipeline.look import RunStats
from clfx.pipeline.report import ClusterInfo, FrameResult, Reporter

PLUGIN_NAME = "clfx"
TASK_THREADS = 2
"""Task threads of a local cluster's workers (``dask worker --nthreads``): one task renders
on the device (`ClfxWorker.device_lock`) while the other reads its input or writes its output.
More only hold more frames in memory: renders take turns on the one device."""
SPECS_KEPT = 4
"""Renders (look + options) a worker keeps unpacked; a long-lived cluster serves many."""


# -- what travels to the workers -----------------------------------------------------------
@dataclass(frozen=True)
class ShippedPlan:
    """A batch's `BatchPlan` (absolute paths), pickled once on the client: the one thing a
    task carries besides the frames it renders.

    ``key`` starts with the look's params hash and identifies the plan in each worker's
    cache, so it is unpacked once per worker process, not once per task.
    """

    key: str
    blob: bytes

    @classmethod
    def of(cls, plan: BatchPlan) -> ShippedPlan:
        plan = plan.for_workers()
        blob = pickle.dumps(plan, protocol=pickle.HIGHEST_PROTOCOL)
        return cls(plan.key(blob), blob)

    def plan(self) -> BatchPlan:
        return pickle.loads(self.blob)


class ClfxWorker(WorkerPlugin):
    """State of one worker process: the runtime (built when the worker joins), the plans
    it has unpacked with their running statistics (`SPECS_KEPT` most recent, by
    `ShippedPlan.key`) and the lock its task threads take to render (kernels share their
    argument slots, so one render at a time).

    ``codec_threads``: OpenImageIO threads per read or write (a local cluster gives each
    worker its share of the cores; None: every core)."""

    idempotent = True   # a second client on the same cluster keeps the warm state

    def __init__(self, device: str | None = None, codec_threads: int | None = None):
        self.device = device
        self.codec_threads = codec_threads

    def setup(self, worker=None):
        warnings.filterwarnings("ignore", category=KernelBuildWarning)   # -v shows them
        malloc_like_one_process()
        codec_threads_for_batches(self.codec_threads)
        self.device_lock = threading.Lock()
        self._lock = threading.Lock()
        self._plans: OrderedDict[str, tuple[BatchPlan, RunStats]] = OrderedDict()
        self._rt = None
        self._rt_error: ClfxError | None = None
        self.runtime_s = 0.0
        t0 = time.perf_counter()
        try:
            self._rt = Runtime.get(self.device)
        except ClfxError as exc:   # reported by every task of this worker, not at join time
            self._rt_error = exc
        self.runtime_s = time.perf_counter() - t0

    def runtime(self):
        if self._rt is None:
            raise self._rt_error or ClusterError("clfx worker plugin was not set up")
        return self._rt

    def plan(self, shipped: ShippedPlan) -> tuple[BatchPlan, RunStats]:
        """The plan and its statistics on this worker (unpacked once)."""
        with self._lock:      # task threads
            if shipped.key in self._plans:
                self._plans.move_to_end(shipped.key)
            else:
                self._plans[shipped.key] = (shipped.plan(), RunStats())
                while len(self._plans) > SPECS_KEPT:
                    self._plans.popitem(last=False)
            return self._plans[shipped.key]


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

    if platform.libc_ver()[0] != "glibc":
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        m_trim_threshold, m_mmap_threshold = -1, -3       # <malloc.h>
        return bool(libc.mallopt(m_mmap_threshold, MMAP_THRESHOLD)
                    and libc.mallopt(m_trim_threshold, TRIM_THRESHOLD))
    except (OSError, AttributeError):
        return False


def codec_threads_for_batches(n: int | None = None) -> int:
    """Set, once for the process, the codec threads of a worker's reads and writes: ``n``
    (a local cluster's share of the cores per worker), else every core.  Measured with
    `--workers 1` on 2 cores, 24 frames of 1080p ``cinema``: 1.113 and 1.082 fps with 2
    threads, 1.075 and 1.034 with 1 (the I/O runs on its own thread at nice 10/5 beside the
    renders).  Once for the process, since its task threads would undo each other's
    `clfx.io.read.codec_threads`."""
    if not n and os.environ.get("OPENIMAGEIO_OPTIONS"):   # a farm worker's own setting

        oiio.attribute("options", os.environ["OPENIMAGEIO_OPTIONS"])
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
def render_chunk(shipped: ShippedPlan, start: int, stop: int,
                 fail_fast: bool = False) -> list[FrameResult]:
    """The Dask task: render the plan's jobs ``start:stop`` on this worker (`render_stream`,
    I/O overlapping the renders, one render at a time per worker); one `FrameResult` per
    frame rendered or failed (a `ClfxError` fails its frame, the others go on unless
    ``fail_fast``)."""
    state = _worker_state()
    plan, stats = state.plan(shipped)
    jobs = plan.jobs[start:stop]
    try:
        rt = state.runtime()
    except ClfxError as exc:
        return [_failed(job, exc) for job in jobs]
    results: list[FrameResult] = []
    render_stream(rt, plan, jobs, results.append, stats=stats, keep_going=True,
                  fail_fast=fail_fast, device_lock=state.device_lock, overlap=True,
                  worker=_where())
    return results


def _failed(job: Job, exc: BaseException) -> FrameResult:
    return FrameResult.failure(job, exc, _where())


# -- the cluster ---------------------------------------------------------------------------
def worker_share(workers: int, cores: int | None = None) -> int:
    """Threads each of ``workers`` local worker processes sharing ``cores`` gets."""
    if cores is None:
        cores = available_cores()
    return max(1, (cores or 1) // max(1, workers))


def worker_env(workers: int, cores: int | None = None) -> dict[str, str]:
    """Environment for ``workers`` local worker processes sharing ``cores``: PoCL (its
    OpenCL CPU device, which reads its thread count from the environment only) gets each
    worker's share (`worker_share`; OpenImageIO's is the `ClfxWorker` plugin's
    ``codec_threads``), so renders and I/O do not oversubscribe the cores.  Variables
    already set in the environment win."""
    share = str(worker_share(workers, cores))
    env = {"POCL_MAX_PTHREAD_COUNT": share,         # PoCL <= 4 pthread device
           "POCL_CPU_MAX_CU_NUM": share,            # PoCL >= 4 cpu device
           "OMP_NUM_THREADS": share}
    env = {k: v for k, v in env.items() if k not in os.environ}
    if workers > 1 and not user_set_pocl_affinity():
        env["POCL_AFFINITY"] = "0"   # each would pin its PoCL thread i to core i: all on
    return env                       # the same cores (clfx.device.runtime's default)


CONNECT_TIMEOUT_S = 10.0
"""Seconds to reach a ``--scheduler`` and hear its Dask handshake (a scheduler sends one at
once); a port where something else listens is refused after this, not waited on."""


HANDSHAKE_MAX_BYTES = 1 << 20
"""A Dask scheduler's first message (its handshake: versions and options) is a few hundred
bytes, announced by its length in 8 little-endian bytes; a listener whose first 8 bytes
announce more is something else (an SSH or SMTP banner read as a length is exabytes)."""


def _check_handshake(sock: socket.socket, address: str) -> None:
    """Read the first 8 bytes a scheduler sends and refuse what cannot be Dask's handshake."""
    head = b""
    while len(head) < 8:
        got = sock.recv(8 - len(head))
        if not got:
            raise ClusterError(f"cannot reach scheduler {address}: it closed the connection"
                               f"{' after ' + repr(head) if head else ''} (not a Dask "
                               f"scheduler?)")
        head += got
    (size,) = struct.unpack("<Q", head)
    if not 0 < size <= HANDSHAKE_MAX_BYTES:
        try:
            sock.settimeout(0.2)
            head += sock.recv(64)
        except OSError:
            pass
        said = head.split(b"\n")[0].decode("ascii", "backslashreplace").strip()[:60]
        raise ClusterError(f"cannot reach scheduler {address}: it is not a Dask scheduler "
                           f"(it said {said!r})")


def check_scheduler(address: str, timeout: float = CONNECT_TIMEOUT_S) -> None:
    """Raise `ClusterError` in one line unless a Dask scheduler answers at ``address``
    within ``timeout`` seconds: an unknown protocol, a bad port or host, nothing listening,
    or (``tcp://``) a listener that never sends Dask's handshake."""
    what = option("--scheduler", address)
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
            _check_handshake(sock, address)
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
        raise ClusterError(f"give {option('--workers', 'N')} (a local cluster) or "
                           f"{option('--scheduler', 'ADDRESS')} (an existing one), not both")
    level = logging.ERROR if quiet else logging.WARNING
    with ExitStack() as stack:
        try:
            if scheduler:
                check_scheduler(scheduler)
                client = stack.enter_context(Client(scheduler, set_as_default=False,
                                                    timeout=CONNECT_TIMEOUT_S))
            else:
                if workers < 1:
                    raise ClusterError(f"{option('--workers', workers)}: expected 1 or more")
                cluster = stack.enter_context(LocalCluster(
                    n_workers=workers, threads_per_worker=TASK_THREADS, processes=True,
                    dashboard_address=None, silence_logs=level, env=worker_env(workers)))
                client = stack.enter_context(Client(cluster, set_as_default=False))
        except (OSError, TimeoutError) as exc:
            where = f"scheduler {scheduler}" if scheduler else f"a local cluster of {workers}"
            raise ClusterError(f"cannot reach {where}: {exc}") from exc
        client.register_plugin(ClfxWorker(device, None if scheduler else worker_share(workers)),
                               name=PLUGIN_NAME)
        yield client


# -- the client ----------------------------------------------------------------------------
def render_distributed(batch: Batch, cluster: ClusterOptions, *,
                       device: str | None = None) -> dict:
    """Render a prepared batch (``batch.prepare()`` done) on a Dask cluster.

    Says what `Batch.run` says, through the batch's `Reporter` (JSON lines in frame order
    and a summary with ``--json``, ``--explain`` texts, warnings once, ``--log``, progress).

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
        raise SequenceError(f"raw pipes ('-') render in one process; {option('--workers')} "
                            f"and {option('--scheduler')} render files")
    if cluster.chunk < 1:
        raise SequenceError(f"{option('--chunk', cluster.chunk)}: expected 1 or more frames per task")
    reporter = batch.reporter
    jobs = batch.jobs
    reporter.start(len(jobs))
    if batch.skipped_existing and batch.verbosity > 0:
        reporter.err(f"clfx: skipping {len(batch.skipped_existing)} frame(s) whose output exists")
    shipped = ShippedPlan.of(batch.plan)
    chunks = [(i, min(i + cluster.chunk, len(jobs))) for i in range(0, len(jobs), cluster.chunk)]
    t0 = time.perf_counter()
    ended = False   # every task has ended (none is still writing a temp file)
    startup, nworkers = 0.0, cluster.workers
    with reporter.logging():
        try:
            with connect(workers=cluster.workers, scheduler=cluster.scheduler, device=device,
                         quiet=batch.verbosity < 2) as client:
                if cluster.scheduler:
                    nworkers = len(client.scheduler_info()["workers"])
                startup = time.perf_counter() - t0
                reporter.rendering(t0 + startup)
                ended = _collect(reporter, client, shipped, jobs, chunks, cluster.fail_fast)
        finally:
            if ended or not cluster.scheduler:   # a local cluster's workers are gone by now
                _remove_orphan_temps(jobs)
        summary = reporter.summary(skipped_existing=len(batch.skipped_existing),
                                   cluster=ClusterInfo(nworkers, cluster.chunk,
                                                       cluster.scheduler, startup))
    failed = reporter.failed
    if failed:
        first = failed[0]
        more = f" (and {len(failed) - 1} more: frames {_frames_text(failed[1:])})" if len(failed) > 1 else ""
        raise ClfxError(f"frame {first.frame} failed: {first.error}{more}")
    return summary


def _collect(reporter: Reporter, client, shipped: ShippedPlan, jobs: list[Job],
             chunks: list[tuple[int, int]], fail_fast: bool) -> bool:
    """Submit one task per chunk, count its frames as it finishes (progress) and report
    results in frame order; True when every task ended (False when ``fail_fast`` cancelled
    the rest).  Results name the files as ``jobs`` do (tasks saw absolute paths)."""
    run = uuid.uuid4().hex[:8]
    futures = {client.submit(render_chunk, shipped, a, b, fail_fast, pure=False, retries=0,
                             key=f"clfx-render-{jobs[a].frame}-{jobs[b - 1].frame}-{run}"): i
               for i, (a, b) in enumerate(chunks)}
    given = {j.frame: j for j in jobs}
    results: dict[int, list[FrameResult]] = {}
    emitted = 0
    for future in as_completed(futures, loop=client.loop):
        i = futures[future]
        if future.status == "error":
            exc = future.exception()
            a, b = chunks[i]
            results[i] = [_failed(job, exc) for job in jobs[a:b]]
        else:
            results[i] = future.result()
        future.release()
        reporter.finished(results[i])   # progress: as tasks finish, in any order
        while emitted in results:   # frame order
            for r in results.pop(emitted):
                job = given[r.frame]
                reporter.frame(r.named(job.input, job.output), progress=False)
            emitted += 1
        if fail_fast and reporter.failed:
            client.cancel(list(futures))
            return False
    return True


def _frames_text(results: list[FrameResult]) -> str:
    return compact(r.frame for r in results)


def _remove_orphan_temps(jobs: list[Job]) -> None:
    """Remove the temp files of this batch's outputs (``.<name>.tmp-<pid>-<rand>-<host><ext>``, see
    `clfx.io.write.write_frame`) that a killed worker left; every task has ended, so none is
    still being written."""
    for job in jobs:
        folder, name = os.path.split(os.path.abspath(job.output))
        for tmp in glob.glob(os.path.join(glob.escape(folder), f".{glob.escape(name)}.tmp-*")):
            with suppress(OSError):
                os.remove(tmp)
