"""Running a look over a frame sequence (or one file, or a raw stdin/stdout pipe): `Batch`
ties the parts together.  ``prepare`` checks everything before the first frame is read
(`clfx.pipeline.preflight`) and makes the one frozen `clfx.pipeline.plan.BatchPlan`; ``run``
renders it through the one frame loop (`clfx.pipeline.stream.render_stream`: read, render
and write overlapped on I/O threads as its thread policy says), and its `reporter` says
what happened.  What a render is asked to do is in `clfx.pipeline.options`.
"""
from __future__ import annotations

import itertools
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, field

from clfx.core.errors import SequenceError, option
from clfx.io.raw import frame_bytes
from clfx.io.read import PassSpec
from clfx.io.sequence import Pattern, output_path, parse_frames
from clfx.pipeline.look import Look, RunStats
from clfx.pipeline.options import RAW, RenderOptions
from clfx.pipeline.plan import BatchPlan, Job
from clfx.pipeline.preflight import Preflight
from clfx.pipeline.report import Reporter
from clfx.pipeline.stream import codec_threads_for, io_pool, io_threads, render_stream


@dataclass
class Batch(Preflight):
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
            self._reporter = Reporter(self.look, self.options.report_options(self.verbosity),
                                      on_frame=self.on_frame,
                                      data_on_stdout=self.output_path == RAW)
        return self._reporter

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

        pout = Pattern.parse(self.output_path)
        numbers = parse_frames(self.options.frames) if self.options.frames else itertools.count(1)
        return (Job(n, RAW, output_path(pout, n)) for n in numbers)
