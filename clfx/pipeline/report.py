"""What a render says: each frame's report, warnings, notices, failures and the summary.

`clfx.pipeline.stream.render_stream` hands every frame to a sink as a typed `FrameResult`
(in this process, or returned by a Dask task); one `Reporter` turns them into the lines a
user sees, wherever the frame was rendered: warnings on stderr (each text once per batch),
``--json`` lines on stdout, ``--explain`` texts, the ``--log`` file, progress, and the
summary at the end.
"""
from __future__ import annotations

import json
import sys
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Callable

from clfx.core.errors import ClfxError, ImageIOError, option
from clfx.pipeline.look import FrameReport


@dataclass(frozen=True)
class ReportOptions:
    """How a render reports (``--explain``, ``--json``, ``--log``, ``-q``/``-v``).

    Attributes
    ----------
    explain : bool
        Per frame, say on stderr which effects ran and why others were skipped.
    as_json : bool
        One JSON line per frame and a summary on stdout (not when stdout carries frames).
    log_path : str or None
        Also write every frame's report, the warnings and notices and the summary to this
        file (JSON lines when it ends in ``.json``/``.jsonl``, else the ``--explain`` text).
    verbosity : int
        0: nothing on stderr but warnings; 1: notices and a summary line; 2: more.
    """

    explain: bool = False
    as_json: bool = False
    log_path: str | None = None
    verbosity: int = 1


@dataclass
class FrameResult:
    """One frame as the stream hands it on: its report, or the error that failed it.

    Attributes
    ----------
    frame : int
    input, output : str
        The files, as the stream saw them (a worker's absolute paths; `Reporter` names them
        as the user gave them).
    report : FrameReport or None
        None when the frame failed.
    error : str or None
        One line: why the frame failed (a `ClfxError` on a worker that goes on).
    worker : str or None
        ``host:pid`` of the Dask worker that rendered it; None in this process.
    notices : list of (kind, message, key)
        What the reader assumed while reading the frame (``"notice"``: said once per batch
        and key unless ``-q``; ``"warning"``: said once per batch and key whatever ``-q``
        says, e.g. how a depth pass marks "no hit").
    skipped : bool
        Its output appeared meanwhile and ``--skip-existing`` left it (rendered, not written).
    """

    frame: int
    input: str = ""
    output: str = ""
    report: FrameReport | None = None
    error: str | None = None
    worker: str | None = None
    notices: list = field(default_factory=list)
    skipped: bool = False

    @classmethod
    def failure(cls, job, exc: BaseException, worker: str | None = None,
                notices=()) -> FrameResult:
        """The result of ``job`` (a `clfx.pipeline.plan.Job`) that ``exc`` failed."""
        return cls(job.frame, job.input, job.output, error=one_line(exc), worker=worker,
                   notices=list(notices))

    def named(self, input: str, output: str) -> FrameResult:
        """This result naming the files as ``input`` / ``output`` (the user's paths)."""
        self.input, self.output = input, output
        if self.report is not None:
            self.report.input, self.report.output = input, output
        return self


def one_line(exc: BaseException) -> str:
    """Why a frame failed, in one line (a `ClfxError`'s message; else its type too)."""
    message = str(exc) if isinstance(exc, ClfxError) else f"{type(exc).__name__}: {exc}"
    return " ".join(message.split())


@dataclass(frozen=True)
class ClusterInfo:
    """Where a distributed render ran, for its summary."""

    workers: int
    chunk: int
    scheduler: str | None
    startup_s: float


class Reporter:
    """The one consumer of a render's `FrameResult` s: every line a render says, once.

    Parameters
    ----------
    look
        The look rendered (its name, and which passes its steps read: a depth convention
        is not worth a notice when no step reads depth).
    options : ReportOptions
    on_frame : callable(done, total, report), optional
        Progress, after each frame (``report`` None for a failed frame); frames count as they
        finish, wherever they rendered (a cluster's in any order).  If it has them,
        ``on_frame.timing(t0)`` is told when rendering starts (a ``time.perf_counter`` time,
        after a cluster's start-up: the origin of the summary's frames per second) and
        ``on_frame.close()`` is called before the summary is said.
    total : int or None
        Frames to render (None: a raw stream, unknown).
    data_on_stdout : bool
        stdout carries frames (a raw pipe): no ``--json`` lines there.
    """

    def __init__(self, look, options: ReportOptions | None = None, *,
                 on_frame: Callable | None = None, total: int | None = None,
                 data_on_stdout: bool = False):
        self.look = look
        self.options = options or ReportOptions()
        self.on_frame = on_frame
        self.total = total
        self.data_on_stdout = data_on_stdout
        self.reports: list[FrameReport] = []
        self.failed: list[FrameResult] = []
        self.skipped: list[int] = []       # outputs that appeared while rendering
        self._said: set[str] = set()       # warning texts and notice keys said
        self._log = None
        self._t0 = time.perf_counter()
        self._done = 0                     # frames finished (rendered or failed), any order
        self.params_hash: str | None = None    # the stamped clfx:paramsHash (`stamped`)
        self.quality: str | None = None
        self._headed = False

    def stamped(self, params_hash: str, quality: str) -> None:
        """The look's hash as every output is stamped with it (`Look.params_hash`, the
        render's level resolved) and that level: said by ``--explain`` and the summary."""
        self.params_hash, self.quality = params_hash, quality

    def start(self, total: int | None) -> None:
        """The render starts now (its wall time counts from here), ``total`` frames."""
        self._t0, self.total = time.perf_counter(), total
        self.rendering(self._t0)

    def rendering(self, t0: float) -> None:
        """Frames render from ``t0`` on (`start`; after a cluster's start-up): the progress
        display's frames per second count from here, as the summary's do."""
        timing = getattr(self.on_frame, "timing", None)
        if timing is not None:
            timing(t0)

    def finished(self, results) -> None:
        """``results`` (`FrameResult` s) are done: progress counts them now, before they are
        said in frame order (`frame` with ``progress=False``)."""
        results = list(results)
        self._done += len(results)
        if self.on_frame is not None and results:
            self.on_frame(self._done, self.total, results[-1].report)

    @property
    def verbosity(self) -> int:
        return self.options.verbosity

    # -- lines --------------------------------------------------------------------------
    def err(self, msg: str, end: str = "\n") -> None:
        print(msg, end=end, file=sys.stderr, flush=True)

    def notice(self, message: str, key: str) -> None:
        """What the reader assumed (e.g. depth 0 = no hit): one line per batch and key,
        not with ``-q``."""
        if self._moot(key):
            return
        if key not in self._said:
            self._said.add(key)
            self.log({"notice": message}, f"clfx: {message}")
            if self.verbosity > 0:
                self.err(f"clfx: {message}")

    def _moot(self, key: str) -> bool:
        """A depth convention is not worth a line when no step reads the depth."""
        return key.startswith("depth") and "depth" not in self.look.clips_used()

    def assumed(self, message: str, key: str) -> None:
        """What clfx had to assume about an input (a NaN mask, a Cryptomatte without
        manifest, the depth "no hit" convention a pass was read with): one warning line per
        batch and key, whatever ``-q`` says."""
        if self._moot(key):
            return
        if key not in self._said:
            self._said.add(key)
            self.log({"warning": message}, f"clfx: warning: {message}")
            self.err(f"clfx: warning: {message}")

    def warn(self, report: FrameReport) -> None:
        """Say a frame's warnings on stderr, each distinct text once per batch (naming the
        first frame that said it: a pass missing from every frame is one line, not one per
        frame)."""
        for where, text in report.warning_items():
            key = "warning:" + where.removeprefix(f"frame {report.frame}") + text
            if key not in self._said:
                self._said.add(key)
                self.err(f"clfx: warning: {where}: {text}")

    # -- frames -------------------------------------------------------------------------
    def frame(self, result: FrameResult, progress: bool = True) -> None:
        """Everything a finished frame says, in frame order; ``progress``: and count it (not
        when `finished` counted it already)."""
        for kind, message, key in result.notices:
            (self.assumed if kind == "warning" else self.notice)(message, key)
        o = self.options
        if result.error is not None:
            self.failed.append(result)
            record = {"frame": result.frame, "worker": result.worker, "input": result.input,
                      "output": result.output, "error": result.error}
            where = f" on {result.worker}" if result.worker else ""
            line = f"clfx: frame {result.frame} failed{where}: {result.error}"
            if o.as_json and not self.data_on_stdout:
                print(json.dumps(record), flush=True)
            if self.verbosity > 0:
                self.err(line)
            self.log(record, line)
        else:
            report = result.report
            self.warn(report)
            record = report.as_dict()
            if result.worker:
                record["worker"] = result.worker
            if o.as_json and not self.data_on_stdout:
                print(json.dumps(record), flush=True)
            text = report.explain() if o.explain or self._log is not None else ""
            if o.explain:
                if not self._headed and self.params_hash:
                    self._headed = True
                    self.err(f"look {self.look.name!r} at {self.quality}: params hash "
                             f"{self.params_hash}")
                self.err(text)
            self.log(record, text)
            if result.skipped:
                self.skipped.append(result.frame)
                if self.verbosity > 0:
                    self.err(f"clfx: frame {result.frame}: {result.output} appeared "
                             f"meanwhile; skipped")
            self.reports.append(report)
        if progress:
            self.finished([result])

    # -- the end ------------------------------------------------------------------------
    def summary(self, *, skipped_existing: int = 0, cluster: ClusterInfo | None = None,
                raw: bool = False) -> dict:
        """The render's summary (said on stdout with ``--json``, else on stderr unless
        ``-q``; always to ``--log``): frames, time, frames per second (after a cluster's
        start-up), device time per frame, what skipping saved."""
        reports = self.reports
        wall = time.perf_counter() - self._t0
        render_s = wall - (cluster.startup_s if cluster else 0.0)
        n = len(reports)
        summary = {"summary": True, "look": self.look.name, "params_hash": self.params_hash,
                   "quality": self.quality, "frames": n,
                   "skipped_existing": skipped_existing + len(self.skipped),
                   "wall_s": round(wall, 3),
                   "fps": round(n / render_s, 3) if render_s > 0 and n else None,
                   "device_ms_mean": round(sum(r.total_ms + sum(o.total_ms for o in r.other_views)
                                             for r in reports) / n, 2) if n else None,
                   "saved_ms_estimate": round(sum(r.saved_ms or 0.0 for r in reports), 1)}
        views = list(dict.fromkeys(v for r in reports for v in r.views))
        if views:      # a multi-view input: which views each frame rendered
            summary["views"] = views
        what = (f"{n} frame(s) ({len(views)} views each: {', '.join(views)})" if len(views) > 1
                else f"{n} frame(s) (view {views[0]})" if views else f"{n} frame(s)")
        if raw:
            line = f"clfx: {n} raw frame(s) rendered in {wall:.2f} s"
        elif cluster:
            summary.update(failed=[r.frame for r in self.failed],
                           startup_s=round(cluster.startup_s, 3), workers=cluster.workers,
                           chunk=cluster.chunk, scheduler=cluster.scheduler or "local")
            line = (f"clfx: {what} rendered with look {self.look.name!r} on "
                    f"{cluster.workers} worker(s) in {wall:.2f} s"
                    + (f" ({summary['fps']} fps after {cluster.startup_s:.1f} s start-up)"
                       if summary["fps"] else ""))
        else:
            line = (f"clfx: {what} rendered with look {self.look.name!r} in "
                    f"{wall:.2f} s" + (f" ({summary['fps']} fps)" if summary["fps"] else ""))
        self.log(summary, line)
        close = getattr(self.on_frame, "close", None)
        if close is not None:       # the progress display goes first: the summary follows it
            close()
        if not raw:
            if self.options.as_json:
                print(json.dumps(summary), flush=True)
            elif self.verbosity > 0:
                self.err(line)
        return summary

    # -- the log file -------------------------------------------------------------------
    @contextmanager
    def logging(self):
        """The ``--log`` file, open (appended to) while the render runs."""
        path = self.options.log_path
        if not path:
            yield
            return
        try:
            f = open(path, "a", encoding="utf-8")     # noqa: SIM115 (closed below)
        except OSError as exc:
            raise ImageIOError(f"cannot write {option('--log')} {path}: {exc.strerror}") from None
        self._log = f
        try:
            yield
        finally:
            self._log = None
            try:
                f.close()
            except OSError:
                pass        # what failed was reported by the write that failed

    def log(self, record: dict, text: str) -> None:
        """One entry of the --log file: ``record`` as a JSON line, or ``text``.  A failed
        write (a full disk) is a one-line `ImageIOError`."""
        if self._log is None:
            return
        path = self.options.log_path
        as_json = path.lower().endswith((".json", ".jsonl"))
        try:
            self._log.write((json.dumps(record, default=str) if as_json else text) + "\n")
            self._log.flush()
        except OSError as exc:
            log, self._log = self._log, None
            try:
                log.close()
            except OSError:
                pass
            raise ImageIOError(f"cannot write {option('--log')} {path}: {exc.strerror or exc}") from None
