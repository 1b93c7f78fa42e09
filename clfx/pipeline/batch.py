"""Running a look over a frame sequence (or one file, or a raw stdin/stdout pipe).

Everything that can be checked is checked before the first frame is read: the look, the
input frames (missing ones named), the output folder, existing outputs, inputs that would be
overwritten.  Then frames flow through a small pipeline: the next frame is read and the
previous one written on worker threads while the device renders the current one, so a
sequence's throughput approaches the slower of I/O and compute rather than their sum.
Output is deterministic per frame: rendering frame N alone or inside a batch gives the
same bytes.
"""
from __future__ import annotations

import json
import os
import sys
import time
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass, field

import numpy as np

from clfx.core.errors import ImageIOError, SequenceError
from clfx.core.frame import Frame
from clfx.pipeline.look import Look, render_frame

RAW = "-"


def look_files(look: Look) -> list[tuple[str, str]]:
    """(``effect.param``, path) of every file a step reads (a PathParam): inputs of the render."""
    return [(f"{s.id}.{p.name}", getattr(s.params, p.name)) for s in look.steps
            for p in s.plugin.descriptor.params if p.kind == "path" and getattr(s.params, p.name)]


@dataclass
class Job:
    frame: int
    input: str
    output: str
    depth: str | None = None
    velocity: str | None = None


@dataclass
class Batch:
    look: Look
    input_path: str
    output_path: str
    options: dict
    passes: object
    verbosity: int = 1
    progress: bool = False
    jobs: list[Job] = field(default_factory=list)
    skipped_existing: list[int] = field(default_factory=list)
    look_files: list[str] = field(default_factory=list)   # files effects read (PathParam)
    noticed: set[str] = field(default_factory=set)        # reader notices said (once each)

    # -- checks -------------------------------------------------------------------------
    def prepare(self) -> None:
        """Resolve frames and outputs; raise before any pixel is read if anything is wrong."""
        from clfx.io.sequence import Pattern, output_path, parse_frames, resolve_inputs

        o = self.options
        if self.input_path == RAW or self.output_path == RAW:
            self._prepare_raw()
            return
        frames = parse_frames(o["frames"]) if o.get("frames") else None
        pin = Pattern.parse(self.input_path)
        pout = Pattern.parse(self.output_path)
        if pin.is_sequence and not pout.is_sequence:
            raise SequenceError(f"input {self.input_path} is a sequence but output "
                                f"{self.output_path} has no frame token (use e.g. out.####.exr)")
        inputs = resolve_inputs(pin, frames, skip_missing=o.get("skip_missing", False))
        if not inputs:
            raise SequenceError(f"no input frames found for {self.input_path}")
        aux = {}
        for name in ("depth", "velocity"):
            path = o.get(f"{name}_path")
            if path:
                pat = Pattern.parse(path)
                found = dict(resolve_inputs(pat, [f for f, _ in inputs] if pat.is_sequence else None,
                                            skip_missing=False))
                aux[name] = (pat, found)
        jobs = []
        for frame, path in inputs:
            out = output_path(pout, frame) if pout.is_sequence else self.output_path
            job = Job(frame, path, out)
            for name, (pat, found) in aux.items():
                setattr(job, name, found[frame] if pat.is_sequence else next(iter(found.values())))
            jobs.append(job)
        from clfx.io.sequence import check_input_file
        self.look_files = [check_input_file(p, what) for what, p in look_files(self.look)]
        self._check_outputs(jobs)
        self.jobs = [j for j in jobs if j.frame not in self.skipped_existing]

    def _check_outputs(self, jobs: list[Job]) -> None:
        o = self.options
        inputs = {os.path.realpath(p) for j in jobs for p in (j.input, j.depth, j.velocity) if p}
        inputs |= {os.path.realpath(p) for p in self.look_files}
        outs = [j.output for j in jobs]
        if len(set(outs)) != len(outs):
            raise SequenceError(f"several frames would write the same output {outs[0]} "
                                f"(add a frame token such as #### to the output)")
        folder = os.path.dirname(os.path.abspath(outs[0]))
        if not os.path.isdir(folder):
            try:
                os.makedirs(folder, exist_ok=True)
            except OSError as exc:
                raise ImageIOError(f"cannot create output folder {folder}: {exc.strerror}") from exc
        if not os.access(folder, os.W_OK | os.X_OK):
            raise ImageIOError(f"output folder {folder} is not writable")
        if o.get("skip_existing"):
            from clfx.io.write import sweep_stale_temps
            sweep_stale_temps(outs)   # temp files of killed runs (their process is gone)
        for j in jobs:
            real = os.path.realpath(j.output)
            if real in inputs:
                raise ImageIOError(f"output {j.output} is an input of this render; clfx never "
                                   f"overwrites its inputs")
            if os.path.lexists(j.output):   # a dangling symlink counts
                if o.get("skip_existing"):
                    self.skipped_existing.append(j.frame)
                elif not o.get("overwrite"):
                    raise ImageIOError(f"output {j.output} exists (use --overwrite to replace it, "
                                       f"or --skip-existing to resume)")

    # -- running ------------------------------------------------------------------------
    @contextmanager
    def reading(self):
        """Start reading the first frame now (on an I/O thread); ``run`` picks it up."""
        self._pool = ThreadPoolExecutor(max_workers=2, thread_name_prefix="clfx-io")
        try:
            if self.jobs and self.input_path != RAW:
                self._first_read = self._pool.submit(self._read, self.jobs[0])
            yield self
        finally:
            self._pool.shutdown(wait=True)
            self._pool = None

    def run(self, rt) -> dict:
        """Render every job; return a summary.  The first failing frame stops the batch
        (its output is not written; frames already written stay, so --skip-existing resumes)."""
        if self.input_path == RAW or self.output_path == RAW:
            return self._run_raw(rt)
        t0 = time.perf_counter()
        reports = []
        total = len(self.jobs)
        if self.skipped_existing and self.verbosity > 0:
            self._err(f"clfx: skipping {len(self.skipped_existing)} frame(s) whose output exists")
        own_pool = getattr(self, "_pool", None) is None
        pool = ThreadPoolExecutor(max_workers=2, thread_name_prefix="clfx-io") if own_pool else self._pool
        first, self._first_read = getattr(self, "_first_read", None), None
        with (pool if own_pool else nullcontext()):
            next_read: Future | None = first or (pool.submit(self._read, self.jobs[0]) if self.jobs else None)
            writes: list[tuple[Future, object]] = []
            for i, job in enumerate(self.jobs):
                views_in, read_ms = next_read.result()   # multi-view files: hero first
                next_read = pool.submit(self._read, self.jobs[i + 1]) if i + 1 < total else None
                frame_out, report = render_frame(
                    rt, self.look, views_in[0], frame_number=job.frame,
                    quality=self.options.get("quality"),
                    keep_overscan=self.options.get("keep_overscan", False),
                    analysis_summary=bool(self.options.get("as_json")))
                views_out = [render_frame(rt, self.look, v, frame_number=job.frame,
                                          quality=self.options.get("quality"),
                                          keep_overscan=self.options.get("keep_overscan", False))[0]
                             for v in views_in[1:]]
                report.input, report.output = job.input, job.output
                report.read_ms = read_ms
                writes.append((pool.submit(self._write, frame_out, job, report, views_out), report))
                writes = self._drain(writes, block=False)
                reports.append(report)
                if self.progress:
                    self._err(f"\rclfx: frame {job.frame} ({i + 1}/{total})", end="")
            self._drain(writes, block=True)
        if self.progress:
            self._err("")
        wall = time.perf_counter() - t0
        summary = {"summary": True, "look": self.look.name, "frames": len(reports),
                   "skipped_existing": len(self.skipped_existing), "wall_s": round(wall, 3),
                   "fps": round(len(reports) / wall, 3) if wall > 0 and reports else None,
                   "device_ms_mean": round(float(np.mean([r.total_ms for r in reports])), 2) if reports else None,
                   "saved_ms_estimate": round(sum(r.saved_ms or 0.0 for r in reports), 1)}
        if self.options.get("as_json"):
            print(json.dumps(summary), flush=True)
        elif self.verbosity > 0:
            self._err(f"clfx: {len(reports)} frame(s) rendered with look {self.look.name!r} in "
                      f"{wall:.2f} s" + (f" ({summary['fps']} fps)" if summary["fps"] else ""))
        return summary

    def _drain(self, writes, *, block: bool):
        """Report finished writes in frame order (re-raising a write's error)."""
        while writes and (block or writes[0][0].done()):
            future, report = writes.pop(0)
            future.result()
            if self.options.get("as_json"):
                print(json.dumps(report.as_dict()), flush=True)
            if self.options.get("explain"):
                self._err(report.explain())
        return writes

    def _read(self, job: Job) -> tuple[list[Frame], float]:
        """The job's frame (every view of a multi-view file when the output can hold them,
        hero first) and the milliseconds it took to read."""
        from clfx.io.read import read_views

        t0 = time.perf_counter()
        o = self.options
        frames = read_views(job.input, view=o.get("view"), passes=self.passes,
                            all_views=job.output.lower().endswith(".exr") and o.get("passes") != "drop",
                            colorspace=o.get("colorspace"), working_space=o.get("working_space"),
                            depth_path=job.depth, velocity_path=job.velocity, notify=self._notice)
        return frames, (time.perf_counter() - t0) * 1e3

    def _notice(self, message: str, key: str) -> None:
        """What the reader assumed (e.g. depth 0 = no hit): one line per sequence and key."""
        if key.startswith("depth") and "depth" not in self.look.clips_used():
            return                       # no step reads the depth: its conventions are moot
        if key not in self.noticed:
            self.noticed.add(key)
            if self.verbosity > 0:
                self._err(f"clfx: {message}")

    def _write(self, frame: Frame, job: Job, report, views=()) -> None:
        from clfx.io.write import OutputExistsError, write_frame

        t0 = time.perf_counter()
        o = self.options
        try:   # not overwrite: an output another writer published meanwhile is never replaced
            write_frame(frame, job.output, bit_depth="float" if o.get("as_float") else None,
                        compression=o.get("compression"), colorspace=o.get("out_colorspace"),
                        overwrite=bool(o.get("overwrite")), attributes=self.look.stamp(),
                        protect=[p for p in (job.input, job.depth, job.velocity) if p] + self.look_files,
                        write_passes=o.get("passes") != "drop", views=views)
        except OutputExistsError:
            if not o.get("skip_existing"):
                raise
            self.skipped_existing.append(job.frame)
            if self.verbosity > 0:
                self._err(f"clfx: frame {job.frame}: {job.output} appeared meanwhile; skipped")
        report.write_ms = (time.perf_counter() - t0) * 1e3

    def _err(self, msg: str, end: str = "\n") -> None:
        print(msg, end=end, file=sys.stderr, flush=True)

    # -- raw pipes (ffmpeg gbrpf32le) ---------------------------------------------------
    def _prepare_raw(self) -> None:
        size = self.options.get("raw_size")
        if not size:
            raise SequenceError("'-' as INPUT or OUTPUT needs --raw WxH (raw gbrpf32le frames, "
                                "as ffmpeg's -f rawvideo -pix_fmt gbrpf32le)")
        from clfx.io.raw import parse_size

        self.raw_size = parse_size(size)
        if self.input_path != RAW or self.output_path != RAW:
            raise SequenceError("raw pipes need '-' for both INPUT and OUTPUT")
        for clip, effects in self.look.required_clips().items():
            raise SequenceError(f"effect {effects[0]!r} needs a {clip} pass, which raw pipes do not carry")

    def _run_raw(self, rt) -> dict:
        """Read gbrpf32le frames from stdin until EOF; write them to stdout."""
        from clfx.io.raw import read_raw, write_raw

        stdin, stdout = sys.stdin.buffer, sys.stdout.buffer
        count = 0
        t0 = time.perf_counter()
        o = self.options
        while (frame := read_raw(stdin, self.raw_size, count, colorspace=o.get("colorspace"),
                                 working_space=o.get("working_space"))) is not None:
            out, report = render_frame(rt, self.look, frame, frame_number=count,
                                       quality=self.options.get("quality"))
            write_raw(stdout, out, frame.data_window, colorspace=o.get("out_colorspace"))
            if self.options.get("explain"):
                self._err(report.explain())
            count += 1
        wall = time.perf_counter() - t0
        return {"frames": count, "wall_s": wall}
