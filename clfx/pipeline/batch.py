"""Running a look over a frame sequence (or one file, or a raw stdin/stdout pipe).

Everything that can be checked is checked before the first frame is read (`Batch.prepare`):
the look, the input frames (missing ones named), the output folder, existing outputs, inputs
that would be overwritten.  What the render then needs is one frozen `BatchPlan` (the look
with every step's quality level resolved, the jobs, how passes are read, every file read),
the one thing sent to Dask workers; `render_stream` is the one loop that reads, renders and
writes its frames, in this process, on a worker and for a raw pipe, and hands each frame to
a sink as a typed `clfx.pipeline.report.FrameResult` (a `Reporter` says them).  Frames flow
through a small pipeline: the next frame is read and the
previous one written on worker threads while the device renders the current one, so a
sequence's throughput approaches the slower of I/O and compute rather than their sum
(frames up to 4K UHD; larger ones one at a time, :data:`OVERLAP_MAX_PIXELS`).
Output is deterministic per frame: rendering frame N alone or inside a batch gives the
same bytes.

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

import hashlib
import itertools
import os
import sys
import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass, field, fields, replace
from typing import TYPE_CHECKING

from clfx.core.errors import ClfxError, ImageIOError, SequenceError, option
from clfx.core.frame import Frame
from clfx.core import limits
from clfx.core.limits import OVERLAP_MAX_PIXELS, PREPARE_MAX_PIXELS
from clfx.pipeline.look import Look, RunStats, render_frame

if TYPE_CHECKING:
    from clfx.io.read import PassSpec

RAW = "-"

STREAM = os.environ.get("CLFX_STREAM", "auto")
"""How a sequence's I/O and rendering share the machine (``CLFX_STREAM``): "phased" (render,
then write and read side by side), "overlap" (read and write while the device renders) or
"auto": phased where the device is the CPU, overlap elsewhere (`stream_mode`)."""

IO_NICE = limits.env_int("CLFX_IO_NICE", 10, minimum=0)
"""Overlap only: nice increment of the write thread, half of it for the read thread (Linux:
per thread; ``CLFX_IO_NICE``), so that on a CPU device I/O gives way to the effects.  0
leaves the threads alone.  Phased streams do not lower priorities: that stalls when other
processes want the CPU (docs/pipeline.md, "Sequences on one machine")."""


def available_cores() -> int:
    """The cores this process may run on (its CPU affinity where the OS has one)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


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
    import threading

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
    from clfx.io.read import codec_threads

    with codec_threads(n or available_cores()):
        yield


@dataclass(frozen=True)
class PassOptions:
    """How depth and velocity passes are found and read (``--depth-channel`` ...).

    The fields of :class:`clfx.io.read.PassSpec` that the command line sets; ``spec`` makes
    the PassSpec once the focal length for radial depth is known.

    Attributes
    ----------
    depth_channel : str or None
        Exact depth channel name; None: the documented search order.
    depth_mode : {"auto", "z", "inverse", "distance", "normalized"}
        How depth is stored.
    depth_scale : float
        Multiplies depth (scene-unit conversion, e.g. 0.01 for cm to m).
    focal_length_px : float or None
        Focal length in pixels for ``depth_mode="distance"``; None: from the look's camera
        block and the first frame's width.
    velocity_channels : (str, str) or None
        Exact (u, v) channel names; None: the search order.
    velocity_y_up : bool or None
        Whether stored +v points up; None: from the detected convention.
    velocity_scale : float
        Multiplies velocity.
    depth_zero : {"auto", "far", "invalid"}
        Depth 0: no hit (infinitely far), invalid (in focus), or decided from its share and
        alpha (said on stderr once per sequence).
    depth_far_threshold : float
        Depths of at least this magnitude are no hit.
    """

    depth_channel: str | None = None
    depth_mode: str = "auto"
    depth_scale: float = 1.0
    focal_length_px: float | None = None
    velocity_channels: tuple[str, ...] | None = None
    velocity_y_up: bool | None = None
    velocity_scale: float = 1.0
    depth_zero: str = "auto"
    depth_far_threshold: float = 1e9

    @classmethod
    def names(cls) -> tuple[str, ...]:
        return tuple(f.name for f in fields(cls))

    def spec(self, focal_length_px: float | None = None):
        """The :class:`~clfx.io.read.PassSpec` (``focal_length_px`` fills in a missing one)."""
        from clfx.io.read import PassSpec

        return PassSpec(depth_channel=self.depth_channel, depth_mode=self.depth_mode,
                        depth_scale=self.depth_scale, velocity_channels=self.velocity_channels,
                        velocity_y_up=self.velocity_y_up, velocity_scale=self.velocity_scale,
                        focal_length_px=self.focal_length_px or focal_length_px,
                        depth_zero=self.depth_zero, depth_far_threshold=self.depth_far_threshold)


@dataclass(frozen=True)
class RenderSettings:
    """What the device does with each frame besides the quality level (resolved once against
    the look: `BatchPlan.quality`): whether light spread past the display window is kept,
    and the band size of tiled steps (``CLFX_TILE_PIXELS``, read once when the plan is made
    and shipped with it; 0: whole frames)."""

    keep_overscan: bool = False
    tile_pixels: int = 0


@dataclass(frozen=True)
class IOOptions:
    """What a render reads and writes, and how (the fields of `RenderOptions` of the same
    names: frames, passes, colour spaces, the output's encoding, overwrites)."""

    frames: str | None = None
    depth_path: str | None = None
    velocity_path: str | None = None
    passes: PassOptions = field(default_factory=PassOptions)
    colorspace: str | None = None
    out_colorspace: str | None = None
    working_space: str | None = None
    view: str | None = None
    passes_mode: str = "keep"
    as_float: bool = False
    bit_depth: str | None = None
    compression: str | None = None
    overwrite: bool = False
    skip_existing: bool = False
    skip_missing: bool = False
    raw_size: str | None = None
    raw_format: str = "gbrpf32le"
    command: str | None = None

    def out_bit_depth(self) -> str | None:
        """The output beauty's bit depth: float with ``as_float``, else ``bit_depth``
        (None: the input's type)."""
        return "float" if self.as_float else self.bit_depth


@dataclass(frozen=True)
class RenderOptions(IOOptions):
    """Everything ``clfx render`` and ``clfx apply`` set besides the look (the CLI builds it),
    as keywords: the `IOOptions`, the ``quality`` a plan resolves against the look
    (`BatchPlan.of`), and the fields a render splits off into its `RenderSettings`
    (``keep_overscan``) and its `clfx.pipeline.report.ReportOptions` (``explain``,
    ``as_json``, ``log_path``).

    Attributes
    ----------
    frames : str or None
        Frame spec (``1-100``, ``1-100x2``, ``1,5,10-20``, ``a-b:n``); None: all on disk.
    quality : str or None
        Quality level of every step without its own; None: ``final``.
    depth_path, velocity_path : str or None
        Passes from separate files (a pattern like the input, or one file for all frames).
    passes : PassOptions
        How the passes are found and read.
    colorspace, out_colorspace : str or None
        Colour space of the input (None: the file's tag or chromaticities, else its type's
        default) / to write the output in (None: the input's).
    working_space : str or None
        Linear space effects work in (None: lin_rec709).
    view : str or None
        Multi-view input: render this view only (None: every view an EXR output can hold).
    passes_mode : {"keep", "drop"}
        keep: every other channel and part of the input written through unchanged (EXR).
    as_float : bool
        Write the EXR beauty as 32-bit float (default: the input's type).
    bit_depth : str or None
        The output beauty's bit depth when not ``as_float`` (``"half"``: what `clfx demo`
        writes from its float scene); None: the input's type.
    compression : str or None
        EXR compression; None: an EXR input's, else zips (`clfx.io.write`).
    overwrite : bool
        Replace existing outputs.
    skip_existing : bool
        Skip frames whose output exists (resume a batch).
    skip_missing : bool
        Skip missing input frames instead of failing.
    keep_overscan : bool
        Keep light spread past the display window.
    raw_size : str or None
        ``WxH`` of the raw frames on stdin when INPUT is ``-``; with only OUTPUT ``-``
        (files to a raw stream), optional: the display window every frame must have.
    raw_format : str
        Layout of raw frames (ffmpeg's ``-pix_fmt``, `clfx.io.raw.FORMATS`): gbrpf32le
        (planar G, B, R), gbrapf32le (planar G, B, R, A), rgbf32le (packed R, G, B),
        rgbaf32le (packed R, G, B, A).
    explain : bool
        Per frame, say on stderr which effects ran and why others were skipped.
    as_json : bool
        One JSON line per frame and a summary on stdout.
    log_path : str or None
        Also write every frame's report, the warnings and notices and the summary to this
        file (JSON lines when it ends in ``.json``/``.jsonl``, else the ``--explain`` text).
    command : str or None
        The command line, stamped into outputs as ``clfx:commandLine``.
    """

    quality: str | None = None
    keep_overscan: bool = False
    explain: bool = False
    as_json: bool = False
    log_path: str | None = None

    def render_settings(self) -> RenderSettings:
        """What the device does with each frame (the quality level resolved apart, once,
        against the look: `BatchPlan.of`); ``CLFX_TILE_PIXELS`` read here, once."""
        return RenderSettings(keep_overscan=self.keep_overscan,
                              tile_pixels=limits.tile_pixels() or 0)

    def io_options(self) -> IOOptions:
        """What is read and written, and how."""
        return IOOptions(**{f.name: getattr(self, f.name) for f in fields(IOOptions)})

    def report_options(self, verbosity: int = 1):
        """What the render says (`clfx.pipeline.report.ReportOptions`)."""
        from clfx.pipeline.report import ReportOptions

        return ReportOptions(explain=self.explain, as_json=self.as_json,
                             log_path=self.log_path, verbosity=verbosity)


@dataclass(frozen=True)
class ClusterOptions:
    """Where a render runs when not in this process (``--workers``, ``--scheduler``).

    Attributes
    ----------
    workers : int or None
        A local Dask cluster of this many processes.
    scheduler : str or None
        An existing Dask cluster's scheduler address (``tcp://host:8786``).
    chunk : int
        Frames per task.
    fail_fast : bool
        Stop at the first failed frame (default: the other frames go on).
    """

    workers: int | None = None
    scheduler: str | None = None
    chunk: int = 1
    fail_fast: bool = False

    @classmethod
    def of(cls, value) -> ClusterOptions:
        """``value`` as ClusterOptions (a mapping of its fields is accepted)."""
        if isinstance(value, cls):
            return value
        try:
            return cls(**dict(value))
        except TypeError as exc:
            raise TypeError(f"distributed: {exc} (see clfx.pipeline.batch.ClusterOptions)") from None


def look_files(look: Look) -> list[tuple[str, str]]:
    """(``effect.param``, path) of every file a step reads (a PathParam): inputs of the render."""
    return [(f"{s.id}.{p.name}", getattr(s.params, p.name)) for s in look.steps
            for p in s.plugin.descriptor.params if p.kind == "path" and getattr(s.params, p.name)]


def lens_files(look: Look) -> list[tuple[str, str]]:
    """(``effect.param``, file) of every lens prescription an enabled step reads (its
    plugin's `clfx.host.Plugin.lens_refs`, the lenses `clfx.io.lenses.resolve` reads)."""
    from clfx.pipeline.presets import find_lens

    return [(f"{s.id}.{param}", str(find_lens(value))) for s in look.steps if s.enabled
            for param, kind, value in s.plugin.lens_refs(s.params) if kind == "prescription"]


def _inode(path: str) -> tuple[int, int] | None:
    """(device, inode) of the file at ``path``, None if there is none."""
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        return None
    return st.st_dev, st.st_ino


def first_frame_geometry(path: str):
    """The data window, display window and pixel aspect of the frame `read_frame` would take
    from ``path``, from its headers; refused (`ImageIOError`, the reader's message) when a
    window exceeds the limits of `clfx.core.limits`.  A render checks its first frame so
    before anything is set up for it (the device, the first read, the maps)."""
    from clfx.io.read import beauty_geometry

    return beauty_geometry(path, check=True)


def check_first_frame(input_path: str, options: RenderOptions) -> None:
    """Refuse the first frame of ``input_path`` (a file or a sequence, ``options.frames``)
    whose windows exceed the pixel limits, from its header: ``clfx render`` calls this before
    it starts setting up the device.  Missing frames and everything else are left to
    `Batch.prepare`, which checks the first frame it will render again."""
    if input_path == RAW:
        return
    from clfx.io.sequence import Pattern, parse_frames, resolve_inputs

    try:
        frames = parse_frames(options.frames) if options.frames else None
        inputs = resolve_inputs(Pattern.parse(input_path), frames, skip_missing=True)
    except SequenceError:
        return              # said by Batch.prepare, in its order of checks
    if inputs and not options.skip_existing:   # with --skip-existing: the first one rendered
        first_frame_geometry(inputs[0][1])


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


@dataclass
class FrameRead:
    """One job's input, read (on an I/O thread): every view's frame (hero first), each
    view's masks (`clfx.pipeline.masks.read_masks`), the milliseconds reading took and what
    the reader assumed (`clfx.pipeline.report.FrameResult.notices`)."""

    views: list[Frame]
    masks: list[dict | None]
    read_ms: float
    notices: list = field(default_factory=list)
    read_cpu_ms: float = 0.0     # process CPU meanwhile (a concurrent write's included)

    def pixels(self) -> int:
        """Pixels of the largest view's data window."""
        return max((f.data_window.width * f.data_window.height for f in self.views), default=0)


@dataclass(frozen=True)
class Job:
    """One frame to render: its number, input, output and pass files."""

    frame: int
    input: str
    output: str
    depth: str | None = None
    velocity: str | None = None

    def absolute(self) -> Job:
        """This job with absolute paths (what a worker in another folder needs)."""
        return replace(self, **{k: os.path.abspath(v) for k in ("input", "output", "depth",
                                                                 "velocity")
                                if (v := getattr(self, k)) and v != RAW})


def resolve_quality(look: Look, quality: str | None) -> tuple[Look, str]:
    """The render's quality level (``quality``, else ``final``) and ``look`` with every
    step's level resolved (its own override, else the render's): the one place a batch
    resolves it, so the stamped look (``clfx:lookJSON``) renders the same pixels again."""
    from clfx.pipeline.look import DEFAULT_QUALITY

    level = quality or DEFAULT_QUALITY
    return look.at_quality(level), level


@dataclass(frozen=True)
class BatchPlan:
    """Everything a render needs, resolved and checked: the one thing sent to Dask workers.

    Attributes
    ----------
    look : Look
        Every step's quality level resolved (`resolve_quality`); stamped into outputs.
    quality : str
        The render's level (steps without their own override take it).
    jobs : tuple of Job
    passes : PassSpec or None
        How depth and velocity are read.
    reads : tuple of (role, path)
        Every file the render reads (frames, pass files, the look's files, mask files,
        files effects read, the OCIO config): outputs never replace one (`write`).
    settings : RenderSettings
    io : IOOptions
    analysis : bool
        Reports carry the frame analysis summary (``--json``).
    raw_size : (int, int) or None
        Frames are read raw from stdin, of this size (``io.raw_format``).
    raw_out : (int, int) or None
        Frames are written raw to stdout, of this size (a raw input's, or the first input
        file's display window).
    """

    look: Look
    quality: str
    jobs: tuple[Job, ...] = ()
    passes: PassSpec | None = None
    reads: tuple[tuple[str, str], ...] = ()
    settings: RenderSettings = field(default_factory=RenderSettings)
    io: IOOptions = field(default_factory=IOOptions)
    analysis: bool = False
    raw_size: tuple[int, int] | None = None
    raw_out: tuple[int, int] | None = None

    @classmethod
    def of(cls, look: Look, options: RenderOptions, *, jobs=(), passes=None, reads=(),
           raw_size=None, raw_out=None) -> BatchPlan:
        """The plan of rendering ``jobs`` through ``look`` with ``options``."""
        resolved, level = resolve_quality(look, options.quality)
        return cls(look=resolved, quality=level, jobs=tuple(jobs), passes=passes,
                   reads=tuple(reads), settings=options.render_settings(),
                   io=options.io_options(), analysis=options.as_json and raw_out is None,
                   raw_size=raw_size, raw_out=raw_out)

    def for_workers(self) -> BatchPlan:
        """This plan with absolute paths (workers need not share the client's folder): the
        jobs, the files read and the look's mask files, resolved against this process's
        folder (the submission's) as a render here resolves them, not the worker's."""
        steps = [replace(s, mask=replace(s.mask, file=os.path.abspath(s.mask.file)))
                 if s.mask is not None and s.mask.file else s for s in self.look.steps]
        return replace(self, look=replace(self.look, steps=steps),
                       jobs=tuple(j.absolute() for j in self.jobs),
                       reads=tuple((role, os.path.abspath(p)) for role, p in self.reads))

    def key(self, blob: bytes) -> str:
        """Identifies the plan in a worker's cache: the look's params hash and a hash of the
        whole plan (``blob``: the plan pickled, as it is shipped)."""
        return f"{self.look.params_hash()}-{hashlib.sha1(blob).hexdigest()[:12]}"

    def read_paths(self) -> list[str]:
        """The paths of `reads` (what the writer protects)."""
        return [p for _, p in self.reads]

    def stamp(self, frame: int) -> dict:
        """The attributes an output of ``frame`` is stamped with (`Look.stamp`, the look
        with its levels resolved, and ``clfx:quality``)."""
        return {**self.look.stamp(frame, self.io.command), "clfx:quality": self.quality}

    # -- the three steps of a frame -------------------------------------------------------
    def read(self, job: Job) -> FrameRead | None:
        """The job's frame (every view of a multi-view file when the output can hold them,
        hero first) with each view's masks; None at the end of a raw stream."""
        from clfx.pipeline.masks import read_masks

        t0, c0 = time.perf_counter(), time.process_time()
        io, notes = self.io, []
        if self.raw_size is not None:
            from clfx.io.raw import read_raw

            frame = read_raw(sys.stdin.buffer, self.raw_size, job.frame,
                             colorspace=io.colorspace, working_space=io.working_space,
                             pix_fmt=io.raw_format)
            if frame is None:
                return None
            frames = [frame]
        else:
            from clfx.io.read import read_views

            frames = read_views(job.input, view=io.view, passes=self.passes,
                                all_views=job.output.lower().endswith(".exr")
                                and io.passes_mode != "drop",
                                colorspace=io.colorspace, working_space=io.working_space,
                                depth_path=job.depth, velocity_path=job.velocity,
                                notify=lambda m, k: notes.append(("warning", m, k)))
        masks = [read_masks(self.look, f, job.frame,
                            notify=lambda m, k: notes.append(("warning", m, k)))
                 if self.look.masks() or self.raw_size is None else None for f in frames]
        return FrameRead(frames, masks, (time.perf_counter() - t0) * 1e3, notes,
                         (time.process_time() - c0) * 1e3)

    def render(self, rt, job: Job, read: FrameRead, stats: RunStats | None = None):
        """Render one job's frames (already read) through the look: the hero's output frame
        and report, and what its write needs besides (the other views' output frames; a raw
        frame's input window).  The one place a batch renders, in this process or on a
        worker."""
        raw = self.raw_size is not None
        outs = []
        for frame_in, masks in zip(read.views, read.masks):
            outs.append(render_frame(
                rt, self.look, frame_in, frame_number=job.frame, quality=self.quality,
                keep_overscan=self.settings.keep_overscan and self.raw_out is None,
                analysis_summary=self.analysis, stats=stats, masks=masks,
                release_input=not raw, tile_pixels=self.settings.tile_pixels))
        for (_, r), frame_in in zip(outs, read.views):
            r.view = frame_in.layout.view if frame_in.layout is not None else None
        frame_out, report = outs[0]
        report.other_views = [r for _, r in outs[1:]]
        if not (raw and self.raw_out is not None):
            report.input, report.output = job.input, job.output
        report.read_ms, report.read_cpu_ms = read.read_ms, read.read_cpu_ms
        if self.raw_out is not None:    # the window a raw frame holds: the input's frame
            rest = read.views[0].data_window if raw else read.views[0].display_window
        else:
            rest = [f for f, _ in outs[1:]]
        return frame_out, report, rest

    def write(self, frame: Frame, job: Job, report, rest=()) -> bool:
        """Write a rendered frame (atomically; never over one of `reads`); True when
        ``--skip-existing`` left an output another writer published meanwhile."""
        t0, c0 = time.perf_counter(), time.process_time()
        io, skipped = self.io, False
        if self.raw_out is not None:
            from clfx.io.raw import write_raw

            if (rest.width, rest.height) != self.raw_out:
                w, h = self.raw_out
                raise ImageIOError(f"{job.input}: display window {rest.width}x{rest.height}, "
                                   f"but the raw frames on stdout are {w}x{h} (one size for "
                                   f"every frame of a raw stream)")
            write_raw(sys.stdout.buffer, frame, rest, colorspace=io.out_colorspace,
                      pix_fmt=io.raw_format)
        else:
            from clfx.io.write import OutputExistsError, write_frame

            try:   # not overwrite: an output published meanwhile is never replaced
                write_frame(frame, job.output, bit_depth=io.out_bit_depth(),
                            compression=io.compression, colorspace=io.out_colorspace,
                            overwrite=io.overwrite, attributes=self.stamp(job.frame),
                            protect=[p for p in (job.input, job.depth, job.velocity)
                                     if p and p != RAW]
                            + self.read_paths(),
                            write_passes=io.passes_mode != "drop", views=rest)
            except OutputExistsError:
                if not io.skip_existing:
                    raise
                skipped = True
        report.write_ms = (time.perf_counter() - t0) * 1e3
        report.write_cpu_ms = (time.process_time() - c0) * 1e3
        return skipped


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
    from clfx.core.errors import ClfxError
    from clfx.pipeline.look import prepare

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
        from clfx.pipeline.report import FrameResult

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


def _check_output_folder(output: str) -> None:
    """The folder of ``output`` exists (created now if need be) and can be written."""
    folder = os.path.dirname(os.path.abspath(output))
    if not os.path.isdir(folder):
        try:
            os.makedirs(folder, exist_ok=True)
        except OSError as exc:
            raise ImageIOError(f"cannot create output folder {folder}: {exc.strerror}") from exc
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ImageIOError(f"output folder {folder} is not writable")


@dataclass
class Batch:
    """A look over INPUT to OUTPUT: ``prepare`` checks everything and makes the `plan`,
    ``run`` renders it (`render_stream`), its `reporter` says what happened.

    ``skipped_existing`` and ``plan`` are filled by ``prepare`` (``jobs``, ``passes``,
    ``raw_size`` and ``reads`` are the plan's); ``stats`` holds the steps' running costs over
    this batch's frames.
    """

    look: Look
    input_path: str
    output_path: str
    options: RenderOptions = field(default_factory=RenderOptions)
    verbosity: int = 1
    skipped_existing: list[int] = field(default_factory=list, init=False)
    kept_other: list[tuple[int, str | None]] = field(default_factory=list, init=False)
    stats: RunStats = field(default_factory=RunStats, init=False)
    look_files: list[str] = field(default_factory=list, init=False)  # files effects read (PathParam)
    mask_files: list[str] = field(default_factory=list, init=False)  # mask sequences' files
    plan: BatchPlan | None = field(default=None, init=False)
    _read_index: tuple | None = field(default=None, init=False, repr=False)
    on_frame: object = field(default=None, repr=False)  # callable(done, total, report): progress
    _reporter: object = field(default=None, init=False, repr=False)
    _pool: ThreadPoolExecutor | None = field(default=None, init=False, repr=False)
    _first_read: Future | None = field(default=None, init=False, repr=False)

    @property
    def jobs(self) -> tuple[Job, ...]:
        """The frames to render (the plan's; none before `prepare`)."""
        return self.plan.jobs if self.plan is not None else ()

    @property
    def passes(self) -> PassSpec | None:
        """What frames are read with (the plan's)."""
        return self.plan.passes if self.plan is not None else None

    @property
    def raw_size(self) -> tuple[int, int] | None:
        """The size of raw pipe frames (the plan's)."""
        return self.plan.raw_size if self.plan is not None else None

    @property
    def reads(self) -> tuple[tuple[str, str], ...]:
        """(role, path) of every file the render reads (the plan's: `_reads`)."""
        return self.plan.reads if self.plan is not None else ()

    @property
    def reporter(self):
        """The `clfx.pipeline.report.Reporter` of this batch (warnings said while checking
        count for the render: each once)."""
        if self._reporter is None:
            from clfx.pipeline.report import Reporter

            self._reporter = Reporter(self.look, self.options.report_options(self.verbosity),
                                      on_frame=self.on_frame,
                                      data_on_stdout=self.output_path == RAW)
        return self._reporter

    # -- checks -------------------------------------------------------------------------
    def prepare(self) -> None:
        """Resolve frames and outputs; raise before any pixel is read if anything is wrong;
        make the `plan`."""
        from clfx.io.sequence import Pattern, output_path, parse_frames, resolve_inputs

        from clfx.io.colour import check_config

        o = self.options
        check_config()      # a FIFO or broken $OCIO: refused before anything reads a frame
        if self.input_path == RAW:
            given = [option(f"--{n}") for n in ("depth", "velocity") if getattr(o, f"{n}_path")]
            if given:       # raw frames on stdin are RGB only: no pass, no frame name to match
                raise ClfxError(f"{' and '.join(given)} cannot go with raw frames on stdin ('-': "
                                f"RGB only); render EXR files with "
                                f"{'those passes' if len(given) > 1 else 'that pass'} instead")
            self._prepare_raw()
            return
        raw_out = self.output_path == RAW        # files to a raw stream on stdout
        frames = parse_frames(o.frames) if o.frames else None
        pin = Pattern.parse(self.input_path)
        pout = Pattern.parse(self.output_path)
        if pin.is_sequence and not pout.is_sequence and not raw_out:
            raise SequenceError(f"input {self.input_path} is a sequence but output "
                                f"{self.output_path} has no frame token (use e.g. out.#.exr)")
        self._say_padding(pin, pout, *(Pattern.parse(p) for p in (o.depth_path, o.velocity_path)
                                       if p))
        inputs = resolve_inputs(pin, frames, skip_missing=o.skip_missing)
        if not inputs:
            raise SequenceError(f"no input frames found for {self.input_path}")
        if frames is None and pin.is_sequence:
            self._say_gaps([f for f, _ in inputs])
        aux = {}
        for name in ("depth", "velocity"):
            path = getattr(o, f"{name}_path")
            if path:
                pat = Pattern.parse(path)
                found = dict(resolve_inputs(pat, [f for f, _ in inputs] if pat.is_sequence else None,
                                            skip_missing=False))
                aux[name] = (pat, found)
        jobs = []
        for frame, path in inputs:
            out = output_path(pout, frame) if pout.is_sequence and not raw_out else \
                self.output_path
            passes = {name: found[frame] if pat.is_sequence else next(iter(found.values()))
                      for name, (pat, found) in aux.items()}
            jobs.append(Job(frame, path, out, **passes))
        from clfx.io.sequence import check_input_file
        self.look_files = [check_input_file(p, what) for what, p in look_files(self.look)]
        self._check_masks(jobs)
        self.plan = BatchPlan.of(self.look, o, reads=self._reads(jobs))   # what is read: checked
        self.reporter.stamped(self.plan.look.params_hash(), self.plan.quality)
        if raw_out:
            from clfx.io.raw import check_format

            check_format(o.raw_format)
            self._say_no_overscan()
        else:
            self._check_outputs(jobs)
        self._check_log(jobs)
        jobs = tuple(j for j in jobs if j.frame not in self.skipped_existing)
        size = None
        if jobs:   # before anything is set up for it (device, first read, maps)
            _, display, _ = first_frame_geometry(jobs[0].input)
            size = (display.width, display.height)
        if raw_out:
            size = self._raw_out_size(jobs[0].input, size)
        self.plan = replace(self.plan, jobs=jobs, raw_out=size if raw_out else None,
                            passes=o.passes.spec(self._radial_depth_focal_px(jobs)))

    def _say_padding(self, *patterns) -> None:
        """One line for each pattern whose ``#`` count differs from Nuke's meaning
        (`clfx.io.sequence.hash_notice`: ``shot.####.exr`` is 16 digits here)."""
        from clfx.io.sequence import hash_notice

        for pattern in patterns:
            message = hash_notice(pattern)
            if message:
                self.reporter.assumed(message, f"padding:{pattern.text}")

    def _say_no_overscan(self) -> None:
        """One line when ``--keep-overscan`` cannot hold: raw frames on stdout are the
        frame's size (a raw input's, a file's display window)."""
        if self.options.keep_overscan:
            self.reporter.assumed(f"{option('--keep-overscan')} ignored: raw frames on stdout "
                                  f"hold the frame only (light spread past it is cropped)",
                                  "overscan")

    def _raw_out_size(self, first: str, size: tuple[int, int]) -> tuple[int, int]:
        """The size of the raw frames written to stdout: the first input's display window,
        which ``--raw WxH``, when given, must match; said once on stderr (ffmpeg's ``-s``)."""
        from clfx.io.raw import parse_size

        if self.options.raw_size:
            want = parse_size(self.options.raw_size)
            if want != size:
                raise SequenceError(f"{option('--raw', self.options.raw_size)}: {first} has a "
                                    f"{size[0]}x{size[1]} display window (the raw frames' size)")
        fmt = self.options.raw_format
        self.reporter.notice(f"writing raw {fmt} frames of {size[0]}x{size[1]} to stdout "
                             f"(ffmpeg -f rawvideo -pix_fmt {fmt} -s {size[0]}x{size[1]} -i -)",
                             "raw")
        return size

    def _radial_depth_focal_px(self, jobs) -> float | None:
        """Focal length in pixels for --depth-mode distance, from the look's camera block and
        the first input's display width (square pixels assumed, as the camera block does)."""
        p = self.options.passes
        if p.depth_mode != "distance" or p.focal_length_px or not jobs:
            return None
        from clfx.io.probe import probe as probe_file

        info = probe_file(jobs[0].input)
        part = info["beauty"]["part"] if info["beauty"] else 0   # pass-only: read refuses it
        width = info["parts"][part]["display_window"]["width"]
        return self.look.camera.focal_length_px(width)

    def _say_gaps(self, found: list[int]) -> None:
        """One notice when the frames found on disk (no --frames) skip some: a missing frame
        is not rendered, and the output has the same hole.  Evenly stepped frames (every
        other frame on disk) are a sequence, not a gap."""
        steps = {b - a for a, b in zip(found, found[1:])}
        if len(steps) < 2:
            return
        step = min(steps)
        gaps = [(a + step, b - step) for a, b in zip(found, found[1:]) if b - a > step]
        shown = ", ".join(str(a) if a == b else f"{a}-{b}" for a, b in gaps[:5])
        more = f" and {len(gaps) - 5} more" if len(gaps) > 5 else ""
        self.reporter.notice(f"{self.input_path} has gaps on disk: frame(s) {shown}{more} "
                             f"missing between {found[0]} and {found[-1]}; rendering the "
                             f"{len(found)} there (--frames {found[0]}-{found[-1]} would "
                             f"refuse)", "gaps")

    def _check_masks(self, jobs: list[Job]) -> None:
        """Every masked step's mask can be made: its files exist, its channel, layer and
        names are in the first frame's header (`clfx.pipeline.masks.check_mask`)."""
        from clfx.pipeline.masks import check_mask

        files: set[str] = set()
        for step, mask in self.look.masks():
            files.update(check_mask(mask, jobs[0].input, [j.frame for j in jobs],
                                    f"effect {step.id!r}", notify=self.reporter.assumed))
        self.mask_files = sorted(files)

    def _reads(self, jobs: list[Job]) -> list[tuple[str, str]]:
        """(role, path) of every file this render reads: the frames and their depth and
        velocity files, the files the look was read from (its YAML and its base looks', or
        the output of ``--look-from``), mask files, files effects read (kernel images, lens
        prescriptions) and the OCIO config.  The one list every output and ``--log`` is
        checked against (`_check_outputs`, `_check_log`, the writer's ``protect``)."""
        from clfx.io.colour import config_file

        reads = [(role, p) for j in jobs for role, p in
                 (("input", j.input), ("--depth", j.depth), ("--velocity", j.velocity)) if p]
        reads += [("look", p) for p in self.look.files]
        reads += [("mask", p) for p in self.mask_files]
        reads += look_files(self.look) + lens_files(self.look)
        ocio = config_file()
        if ocio:
            reads.append(("$OCIO", ocio))
        return reads

    def read_paths(self) -> list[str]:
        """The paths of `reads` (what the writer protects)."""
        return [p for _, p in self.reads]

    def _read_by(self, path: str) -> str | None:
        """The role of the file ``path`` (the same file, through a symbolic or hard link) if
        the render reads it, else None."""
        if self._read_index is None or self._read_index[0] is not self.reads:
            by_path, by_inode = {}, {}
            for role, p in reversed(self.reads):     # the first role given wins
                by_path[os.path.realpath(p)] = role
                key = _inode(p)
                if key is not None:
                    by_inode[key] = role
            self._read_index = (self.reads, by_path, by_inode)
        _, by_path, by_inode = self._read_index
        role = by_path.get(os.path.realpath(path))
        key = _inode(path)
        return role if role is not None or key is None else by_inode.get(key)

    def _check_log(self, jobs: list[Job] | None = None) -> None:
        """The --log file is none of the render's inputs or outputs, is a regular file (or a
        device such as /dev/null; a FIFO would block), and can be written (created now,
        empty)."""
        import stat

        path = self.options.log_path
        if not path:
            return
        role = self._read_by(path)
        if role is not None:
            raise ImageIOError(f"{option('--log')} {path} is an input of this render ({role}); "
                               f"clfx never overwrites its inputs")
        real = os.path.realpath(path)
        if any(os.path.realpath(j.output) == real for j in (jobs or [])):
            raise ImageIOError(f"{option('--log')} {path} is an output of this render")
        try:
            mode = os.stat(path).st_mode
        except FileNotFoundError:
            mode = None
        except OSError as exc:
            raise ImageIOError(f"cannot write {option('--log')} {path}: {exc.strerror}") from None
        if mode is not None and not (stat.S_ISREG(mode) or stat.S_ISCHR(mode)):
            kind = "a folder" if stat.S_ISDIR(mode) else \
                "not a regular file (a FIFO)" if stat.S_ISFIFO(mode) else "not a regular file"
            raise ImageIOError(f"cannot write {option('--log')} {path}: {kind}")
        try:
            with open(path, "w", encoding="utf-8"):
                pass
        except OSError as exc:
            raise ImageIOError(f"cannot write {option('--log')} {path}: {exc.strerror}") from None

    def _check_kept(self, job: Job) -> None:
        """Note a frame --skip-existing keeps that another look or other parameters rendered
        (its stamped ``clfx:paramsHash`` differs from this look's, or it has none)."""
        from clfx.io.probe import header_attribute

        try:
            stamped = header_attribute(job.output, "clfx:paramsHash")
            name = header_attribute(job.output, "clfx:look") if stamped else None
        except ClfxError:
            stamped = name = None               # unreadable: its render failed half-way?
        if stamped != self.reporter.params_hash:    # the one this render stamps (`prepare`)
            self.kept_other.append((job.frame, name))

    def _kept_other_warning(self) -> str | None:
        """One line for the frames kept from another look (`_check_kept`), or None."""
        if not self.kept_other:
            return None
        from clfx.io.sequence import compact

        names = sorted({n or "no clfx stamp" for _, n in self.kept_other})
        return (f"clfx: warning: --skip-existing keeps frame(s) "
                f"{compact(f for f, _ in self.kept_other)} rendered with another look or other "
                f"parameters ({', '.join(map(repr, names))}; this render: {self.look.name!r}); "
                f"use --overwrite to render them again")

    def _check_outputs(self, jobs: list[Job]) -> None:
        from clfx.io.write import check_output_format

        outs = [j.output for j in jobs]
        if len(set(outs)) != len(outs):
            raise SequenceError(f"several frames would write the same output {outs[0]} "
                                f"(add a frame token such as # to the output)")
        for j in jobs:          # first: an output that names a file the render reads
            role = self._read_by(j.output)
            if role is not None:
                what = "" if role == "input" else f" ({role})"
                raise ImageIOError(f"output {j.output} is an input of this render{what}; clfx "
                                   f"never overwrites its inputs")
        check_output_format(outs[0], self.options.out_bit_depth(),
                            self.options.compression)    # not after the first render
        _check_output_folder(outs[0])
        if self.options.skip_existing:
            from clfx.io.write import sweep_stale_temps
            sweep_stale_temps(outs)   # temp files of killed runs (their process is gone)
        for j in jobs:
            if os.path.lexists(j.output):   # a dangling symlink counts
                if self.options.skip_existing:
                    self.skipped_existing.append(j.frame)
                    self._check_kept(j)
                elif not self.options.overwrite:
                    from clfx.io.write import OutputExistsError

                    raise OutputExistsError(f"output {j.output} exists (use {option('--overwrite')} "
                                            f"to replace it, or {option('--skip-existing')} to "
                                            f"resume)")

    # -- running ------------------------------------------------------------------------
    @contextmanager
    def reading(self):
        """Start reading the first frame now (on an I/O thread); ``run`` picks it up."""
        with io_threads():
            self._pool = io_pool()
            try:
                if self.jobs and self.input_path != RAW:
                    self._first_read = self._pool.submit(self.plan.read, self.jobs[0])
                yield self
            finally:
                self._pool.shutdown(wait=True)
                self._pool = None

    def run(self, rt) -> dict:
        """Render every job (`render_stream`); return the summary (with ``reports``: each
        frame's `FrameReport`).  The first failing frame stops the batch (its output is not
        written; frames already written stay, so --skip-existing resumes)."""
        raw = self.input_path == RAW
        reporter = self.reporter
        reporter.start(None if raw else len(self.jobs))
        with reporter.logging(), io_threads(codec_threads_for(rt)):
            if raw:
                jobs = self._raw_jobs()
            else:
                jobs = self.jobs
                if self.skipped_existing and self.verbosity > 0:
                    reporter.err(f"clfx: skipping {len(self.skipped_existing)} frame(s) whose "
                                 f"output exists")
                if self._kept_other_warning():
                    reporter.err(self._kept_other_warning())
            first, self._first_read = self._first_read, None
            render_stream(rt, self.plan, jobs, reporter.frame, stats=self.stats, first=first)
            if raw and not reporter.reports and not reporter.failed:   # an empty stream is an
                from clfx.io.raw import frame_bytes                     # error, not 0 frames

                w, h = self.raw_size
                fmt = self.options.raw_format
                raise SequenceError(f"stdin: no raw frames (0 bytes; {option('--raw', f'{w}x{h}')} "
                                    f"{fmt} frames are {frame_bytes((w, h), fmt)} bytes each)")
            summary = reporter.summary(skipped_existing=len(self.skipped_existing),
                                       raw=self.output_path == RAW)
        self.skipped_existing += reporter.skipped
        return {**summary, "reports": reporter.reports}

    # -- raw pipes (ffmpeg -f rawvideo: clfx.io.raw) -------------------------------------
    def _raw_jobs(self):
        """A raw input's jobs, unbounded (the stream's end stops them): to stdout, frame
        indices 0, 1, ...; to files, the frames of ``--frames`` in order (default 1, 2, ...),
        each with its output."""
        if self.output_path == RAW:
            return (Job(i, RAW, RAW) for i in itertools.count())
        from clfx.io.sequence import Pattern, output_path, parse_frames

        pout = Pattern.parse(self.output_path)
        numbers = parse_frames(self.options.frames) if self.options.frames else itertools.count(1)
        return (Job(n, RAW, output_path(pout, n)) for n in numbers)

    def _prepare_raw(self) -> None:
        """Raw frames on stdin, to stdout or to a file sequence: checked as far as a stream
        of unknown length can be before it is read."""
        o = self.options
        from clfx.io.raw import check_format, check_stream_size, parse_size

        check_format(o.raw_format)
        if not o.raw_size:
            raise SequenceError(f"'-' as INPUT needs {option('--raw', 'WxH')}, the size of the "
                                f"raw frames on stdin ({o.raw_format}, as ffmpeg's -f rawvideo "
                                f"-pix_fmt {o.raw_format})")
        raw_size = parse_size(o.raw_size)  # two positive whole numbers within the pixel limit
        for clip, effects in self.look.required_clips().items():
            raise SequenceError(f"effect {effects[0]!r} needs a {clip} pass, which raw pipes "
                                f"do not carry ({option('--set', f'{effects[0]}.enabled=false')} drops it, "
                                f"{option('--set', f'{effects[0]}.missing_passes=skip')} skips it)")
        for step, mask in self.look.masks():
            if not mask.file:
                raise SequenceError(f"effect {step.id!r} is masked by a channel of the frame "
                                    "and raw pipes carry colour only (use a mask file:)")
        check_stream_size(sys.stdin.buffer, raw_size, o.raw_format)
        self.look_files = [p for _, p in look_files(self.look)]
        self.mask_files = sorted({f for _, m in self.look.masks() for f in [m.file] if f})
        self.plan = BatchPlan.of(self.look, o, reads=self._reads([]), raw_size=raw_size,
                                 raw_out=raw_size if self.output_path == RAW else None)
        if self.output_path != RAW:
            self._check_raw_outputs()
        else:
            self._say_no_overscan()
        self.reporter.stamped(self.plan.look.params_hash(), self.plan.quality)
        self._check_log()

    def _check_raw_outputs(self) -> None:
        """A raw input's file outputs: a sequence pattern (a stream holds any number of
        frames) in a writable folder and format; outputs already on disk (of ``--frames``,
        else any frame of the pattern) are refused unless overwritten or skipped, and none
        is a file the render reads."""
        from clfx.io.sequence import Pattern, parse_frames, resolve_inputs
        from clfx.io.write import OutputExistsError, check_output_format

        o = self.options
        pout = Pattern.parse(self.output_path)
        if not pout.is_sequence:
            raise SequenceError(f"output {self.output_path} has no frame token: raw frames on "
                                f"stdin are a sequence (use e.g. out.#.exr)")
        self._say_padding(pout)
        _check_output_folder(self.output_path)
        check_output_format(self.output_path, o.out_bit_depth(), o.compression)
        frames = parse_frames(o.frames) if o.frames else None
        there = resolve_inputs(pout, frames, skip_missing=True)
        for _, path in there:
            role = self._read_by(path)
            if role is not None:
                raise ImageIOError(f"output {path} is an input of this render ({role}); clfx "
                                   f"never overwrites its inputs")
        if there and not (o.overwrite or o.skip_existing):
            more = f" (and {len(there) - 1} more)" if len(there) > 1 else ""
            raise OutputExistsError(f"output {there[0][1]} exists{more} (use "
                                    f"{option('--overwrite')} to replace it, or "
                                    f"{option('--skip-existing')} to keep it)")
