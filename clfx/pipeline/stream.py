"""The frame stream and its I/O thread policy: `render_stream` is the one loop that reads,
renders and writes a batch's frames (`clfx.pipeline.plan.BatchPlan`'s three steps), in this
process, on a Dask worker and for a raw pipe, and hands each frame to a sink as a typed
`clfx.pipeline.report.FrameResult`.  Frames flow through a small pipeline: the next frame is
read and the previous one written on worker threads while the device renders the current
one, so a sequence's throughput approaches the slower of I/O and compute rather than their
sum (frames up to 4K UHD; larger ones one at a time, :data:`OVERLAP_MAX_PIXELS`).

Scheduling: where the device is the CPU (PoCL), the effects and the codecs want the same
cores, so a sequence runs in phases (`STREAM`, "phased"): the device renders frame N with
the cores to itself, then frame N's write and frame N+1's read run side by side (one core
each on two cores, their codecs on every core: `codec_threads_for`), and the next render
starts when both are done.
Nothing runs at a lowered priority, so the stream neither slows the effects down (each
takes its time alone) nor stalls when other processes want the CPU.  Where the device is
not the CPU (a GPU), its kernels leave the cores free: the next frame is read and the
previous one written while it renders ("overlap"), with at most `WRITES_AHEAD` rendered
frames waiting for their write.  Frames above :data:`OVERLAP_MAX_PIXELS` go one step at a
time ("serial"), to bound memory.
"""
from __future__ import annotations

import os
import sys
import threading
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass

from clfx.core.errors import ClfxError
from clfx.core import limits
from clfx.core.limits import OVERLAP_MAX_PIXELS, PREPARE_MAX_PIXELS, available_cores
from clfx.io.read import codec_threads
from clfx.pipeline.look import Look, RunStats, prepare
from clfx.pipeline.options import RAW
from clfx.pipeline.plan import BatchPlan, Job
from clfx.pipeline.preflight import first_frame_geometry
from clfx.pipeline.report import FrameResult

STREAM = os.environ.get("CLFX_STREAM", "auto")
"""How a sequence's I/O and rendering share the machine (``CLFX_STREAM``): "phased" (render,
then write and read side by side), "overlap" (read and write while the device renders) or
"auto": phased where the device is the CPU, overlap elsewhere (`stream_mode`)."""

IO_NICE = limits.env_int("CLFX_IO_NICE", 10, minimum=0)
"""Overlap only: nice increment of the write thread, half of it for the read thread (Linux:
per thread; ``CLFX_IO_NICE``), so that on a CPU device I/O gives way to the effects.  0
leaves the threads alone.  Phased streams do not lower priorities: that stalls when other
processes want the CPU (docs/pipeline.md, "Sequences on one machine")."""


IO_CODEC_THREADS = 1
"""OpenImageIO/OpenEXR threads per read or write where a batch's I/O overlaps a CPU device's
renders (``CLFX_STREAM=overlap``): the codecs stay on their own low-priority thread.  (A Dask
worker sets its own: `clfx.pipeline.distributed.codec_threads_for_batches`.)"""


def codec_threads_for(rt) -> int:
    """Codec threads per read or write during a batch (`clfx.io.read.codec_threads`): every
    core in a phased stream (the I/O phase has the machine: measured on 2 cores, the write
    and the next read side by side took 824-844 ms per frame with 2 threads each, 880-905
    with 1) and beside a GPU; `IO_CODEC_THREADS` where I/O overlaps a CPU device."""
    return IO_CODEC_THREADS if io_overlaps_cpu_device(rt) else available_cores()


def io_overlaps_cpu_device(rt) -> bool:
    """Whether a batch's reads and writes run while a CPU device renders (``CLFX_STREAM=
    overlap`` on PoCL): then, and only then, they run lowered (`io_pool`) on one codec thread
    each (`codec_threads_for`)."""
    return stream_mode(rt, 0) == "overlap" and getattr(rt, "shares_host_cores", True)


WRITES_AHEAD = 2
"""Overlap only: frames rendered but not yet written that a batch holds before it waits
for a write."""


def stream_mode(rt, pixels: int) -> str:
    """"serial" for frames above :data:`OVERLAP_MAX_PIXELS`; otherwise `STREAM`, where
    "auto" is "phased" when ``rt``'s device is the CPU (it shares the cores with the codecs)
    and "overlap" when it is not."""
    global _STREAM_SAID
    if pixels > OVERLAP_MAX_PIXELS:
        return "serial"
    if STREAM in ("phased", "overlap"):
        return STREAM
    if STREAM != "auto" and not _STREAM_SAID:      # never reinterpret silently: once a process
        _STREAM_SAID = True
        print(f"clfx: warning: CLFX_STREAM={STREAM!r} is not auto, phased or overlap; "
              f"using auto", file=sys.stderr, flush=True)
    return "phased" if getattr(rt, "shares_host_cores", True) else "overlap"


_STREAM_SAID = False


def _background(nice: int) -> None:
    """Initialiser of an I/O thread: lower its priority by ``nice`` (where the OS can)."""
    if nice and hasattr(os, "setpriority"):
        try:
            tid = threading.get_native_id()
            os.setpriority(os.PRIO_PROCESS, tid, os.getpriority(os.PRIO_PROCESS, tid) + nice)
        except OSError:
            pass     # not permitted here: the thread keeps its priority


def io_pool(kind: str = "read", lowered: bool = False) -> ThreadPoolExecutor:
    """The thread a batch reads (``"read"``) or writes (``"write"``) on.  ``lowered`` (an
    overlapping stream on a CPU device): at nice ``IO_NICE // 2`` (read) or ``IO_NICE``
    (write), the write lower since the device waits for the next frame's read but only the
    batch's end waits for a write."""
    nice = (IO_NICE // 2 if kind == "read" else IO_NICE) if lowered else 0
    return ThreadPoolExecutor(max_workers=1, thread_name_prefix=f"clfx-{kind}",
                              initializer=_background, initargs=(nice,))


@contextmanager
def io_threads(n: int | None = None):
    """The codecs' threads while a batch runs: ``n``, default every core (the first read,
    while the device is set up: `Batch.reading`)."""
    with codec_threads(n or available_cores()):
        yield


@dataclass
class Preparing:
    """A look's maps being prepared on a thread (`prepare_maps`)."""

    future: Future
    cancelled: threading.Event

    def close(self, cancel: bool = False) -> None:
        """Wait for the thread; ``cancel``: stop it first (before its next step or map band),
        when what it prepares for will not be rendered (a refused frame)."""
        if cancel:
            self.cancelled.set()
        self.future.exception()     # done (its errors are the render's to report)


def prepare_maps(rt, look: Look, jobs, quality: str | None,
                 keep_overscan: bool = False) -> Preparing | None:
    """`clfx.pipeline.look.prepare` for the first job's geometry (from its header), on a
    thread of normal priority: the maps it builds are on the first frame's critical path (a
    Dask worker's later chunks find them in its cache).  Nothing is started for a frame whose
    windows the reader will refuse, nor for one larger than `PREPARE_MAX_PIXELS` (its maps
    would sit beside the first steps' buffers: each is built when its step needs it).  The
    caller closes what it returns, cancelling it when the frame is refused."""
    if not jobs or jobs[0].input == RAW:
        return None

    job = jobs[0]
    try:
        data, display, aspect = first_frame_geometry(job.input)
    except ClfxError:
        return None          # the read says why
    if max(data.width * data.height, display.width * display.height) > PREPARE_MAX_PIXELS:
        return None
    cancelled = threading.Event()

    def run():
        prepare(rt, look, data, display, aspect, frame_number=job.frame,
                quality=quality, keep_overscan=keep_overscan, cancel=cancelled)

    pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="clfx-prepare")
    future = pool.submit(run)
    pool.shutdown(wait=False)
    return Preparing(future, cancelled)


# -- the stream ----------------------------------------------------------------------------
def render_stream(rt, plan: BatchPlan, jobs, sink, *, stats: RunStats | None = None,
                  first: Future | None = None, keep_going: bool = False,
                  fail_fast: bool = False, device_lock=None, overlap: bool = False,
                  worker: str | None = None) -> bool:
    """Read, render and write ``jobs`` (`BatchPlan.read`, ``render``, ``write``): the one
    loop of every render, in this process and on a Dask worker.

    The next frame is read and the previous one written on I/O threads as `stream_mode`
    says: "phased" (the device renders alone, then the write beside the next read),
    "overlap" (read and write while the device renders, at most `WRITES_AHEAD` frames
    waiting for their write; ``overlap`` asks for it where "phased" would run, as workers
    do) or "serial" (large frames).  A raw stream (``plan.raw_size``) reads until its end
    and writes a frame only once the next one has been read whole.

    Parameters
    ----------
    jobs : iterable of Job
        Rendered in order (a raw stream's: frame indices, unbounded).
    sink : callable(FrameResult)
        Called once per job, in order, once its write is done (or it failed).
    stats : RunStats, optional
        The steps' running costs over this render's frames.
    first : Future, optional
        The first job's read, already started (`Batch.reading`).
    keep_going : bool
        A frame that raises a `ClfxError` becomes a result with its error and the others go
        on (a worker's chunk); else the error stops the stream (a local render: frames
        already written stay, so --skip-existing resumes).
    fail_fast : bool
        With ``keep_going``: stop after the first failed frame.
    device_lock : lock, optional
        Held while rendering (task threads of one worker share its device).
    worker : str, optional
        Names the worker in each result.

    Returns
    -------
    bool
        Whether every job was rendered and written.
    """
    jobs = iter(jobs)
    job = next(jobs, None)
    prepared = None
    if job is not None:
        prepared = prepare_maps(rt, plan.look, [job], plan.quality, plan.settings.keep_overscan)
    failed = True
    try:
        failed = _stream(rt, plan, job, jobs, sink, stats, first, keep_going, fail_fast,
                         device_lock, overlap, worker)
    finally:
        if prepared is not None:     # a refused frame: no more work for it
            prepared.close(cancel=failed)
    return not failed


@dataclass
class _Pending:
    """A frame rendered (its write under way) or failed, waiting for its turn to report."""

    job: Job
    write: Future | None
    report: object
    notices: list
    error: BaseException | None = None

    def result(self, keep_going: bool, worker: str | None):
        """The frame's `clfx.pipeline.report.FrameResult` (waiting for its write)."""
        error, skipped = self.error, False
        if error is None:
            try:
                skipped = self.write.result()
            except ClfxError as exc:
                if not keep_going:
                    raise
                error = exc
        if error is not None:
            return FrameResult.failure(self.job, error, worker, self.notices)
        return FrameResult(self.job.frame, self.job.input, self.job.output, report=self.report,
                           worker=worker, notices=self.notices, skipped=skipped)


def _stream(rt, plan, job, jobs, sink, stats, first, keep_going, fail_fast, device_lock,
            overlap, worker) -> bool:
    """`render_stream`'s loop; True when a frame failed."""
    raw = plan.raw_size is not None
    lowered = getattr(rt, "shares_host_cores", True) if overlap else io_overlaps_cpu_device(rt)
    failed = False
    pending: list[_Pending] = []

    def drain(block: bool, count: int | None = None) -> None:
        nonlocal failed
        done = 0
        while pending and (block or pending[0].write is None or pending[0].write.done()) \
                and (count is None or done < count):
            result = pending.pop(0).result(keep_going, worker)
            failed |= result.error is not None
            sink(result)
            done += 1

    with io_pool(lowered=lowered) as pool, io_pool("write", lowered=lowered) as writer:
        next_read = first if first is not None else \
            (pool.submit(plan.read, job) if job is not None else None)
        while job is not None:
            following = next(jobs, None)
            mode, notices = "overlap", []
            try:
                read = next_read.result()
                next_read = None
                if read is None:                 # a raw stream's end
                    break
                notices = read.notices
                mode = stream_mode(rt, read.pixels())
                if mode == "phased" and (overlap or raw):
                    mode = "overlap"
                if mode == "overlap" and following is not None:
                    next_read = pool.submit(plan.read, following)
                elif pending:                    # phased or serial: the device renders alone
                    drain(block=True)
                with device_lock or nullcontext():
                    frame_out, report, rest = plan.render(rt, job, read, stats)
                del read                         # the write holds the output until done
                if raw and next_read is not None:
                    next_read.result()           # a short read raises: nothing written
                pending.append(_Pending(job, writer.submit(plan.write, frame_out, job, report,
                                                           rest), report, notices))
                del frame_out, rest
            except ClfxError as exc:
                if not keep_going:
                    raise
                pending.append(_Pending(job, None, None, notices, error=exc))
                failed = True
                if fail_fast:
                    break
            if mode == "serial":
                drain(block=True)
            drain(block=False)
            while len(pending) > WRITES_AHEAD:
                drain(block=True, count=1)
            if next_read is None and following is not None:   # phased: beside this write
                next_read = pool.submit(plan.read, following)
            job = following
        drain(block=True)
    return failed
