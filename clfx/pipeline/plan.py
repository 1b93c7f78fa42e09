"""The plan of a batch: one frozen `BatchPlan` holds everything a render needs, resolved and
checked (the look with every step's quality level resolved, the jobs, how passes are read,
every file read): the one thing sent to Dask workers.  Its three steps of a frame (`read`,
`render`, `write`) are the only place a batch reads, renders and writes a frame; the stream
(`clfx.pipeline.stream.render_stream`) runs them.  Output is deterministic per frame:
rendering frame N alone or inside a batch gives the same bytes."""
from __future__ import annotations

import hashlib
import os
import sys
import time
from dataclasses import dataclass, field, replace

from clfx.core.errors import ImageIOError
from clfx.core.frame import Frame
from clfx.io.raw import read_raw, write_raw
from clfx.io.read import PassSpec, read_views
from clfx.io.write import OutputExistsError, write_frame
from clfx.pipeline.look import Look, RunStats, render_frame
from clfx.pipeline.masks import read_masks
from clfx.pipeline.options import RAW, IOOptions, RenderOptions, RenderSettings, resolve_quality


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
        t0, c0 = time.perf_counter(), time.process_time()
        io, notes = self.io, []
        if self.raw_size is not None:
            frame = read_raw(sys.stdin.buffer, self.raw_size, job.frame,
                             colorspace=io.colorspace, working_space=io.working_space,
                             pix_fmt=io.raw_format)
            if frame is None:
                return None
            frames = [frame]
        else:
            # the passes the steps read, and the channels the output copies, nothing more
            copies = job.output.lower().endswith(".exr") and io.passes_mode != "drop"
            frames = read_views(job.input, view=io.view, passes=self.passes,
                                all_views=copies, keep=copies,
                                needs=self.look.clips_used() & {"depth", "velocity"},
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
            if (rest.width, rest.height) != self.raw_out:
                w, h = self.raw_out
                raise ImageIOError(f"{job.input}: display window {rest.width}x{rest.height}, "
                                   f"but the raw frames on stdout are {w}x{h} (one size for "
                                   f"every frame of a raw stream)")
            write_raw(sys.stdout.buffer, frame, rest, colorspace=io.out_colorspace,
                      pix_fmt=io.raw_format)
        else:
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
