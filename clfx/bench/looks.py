"""The bench's second and third parts: whole looks (ms per frame, per effect), a sequence
through `clfx render`'s batch pipeline beside its parts alone, and what a scene calls for
(the cinema look on frames that need everything, nothing, or one moving region).

A look's frame is rendered in memory (`bench_look`); the sequence is rendered by
`clfx.pipeline.batch.Batch.run` (`render_stream`), and its parts are timed alone beside it
(`BatchPlan.read` of one frame n times, `render_frame` of it n times, `BatchPlan.write` of
the output n times): the bench runs no read/render/write loop of its own.
"""
from __future__ import annotations

import os
import tempfile
import time

import numpy as np

from clfx.bench.scene import demo_scene, render_sharp
from clfx.bench.timing import stats
from clfx.core.camera import Camera
from clfx.core.frame import Frame
from clfx.io.read import read_frame
from clfx.io.write import write_frame
from clfx.pipeline.batch import Batch
from clfx.pipeline.look import render_frame
from clfx.pipeline.options import RenderOptions
from clfx.pipeline.presets import load_look
from clfx.pipeline.stream import available_cores, codec_threads_for, io_threads, stream_mode


def demo_frame(width: int, height: int, frame: int = 12) -> Frame:
    """Frame ``frame`` of the demo scene, sharp with its passes: the looks' bench input."""
    return render_sharp(demo_scene(frame, width, height))


def bench_look(rt, look_name: str, frame: Frame, repeat: int, quality: str | None = None) -> dict:
    """Milliseconds per frame of a look with a per-effect breakdown (median of runs)."""
    look = load_look(look_name)
    render_frame(rt, look, frame, frame_number=1, quality=quality)  # warm-up
    totals, per_effect = [], {}
    report = None
    for _ in range(repeat):
        _, report = render_frame(rt, look, frame, frame_number=1, quality=quality)
        totals.append(report.total_ms)
        for s in report.steps:
            per_effect.setdefault(s.effect, []).append(s.ms if s.ran else 0.0)
    return {"look": look_name, "quality": quality or "final", **stats(totals),
            "effects": {k: round(float(np.median(v)), 2) for k, v in per_effect.items()},
            "skipped": {s.effect: s.reason for s in report.steps if not s.ran}}


def bench_io(frame: Frame, repeat: int) -> dict:
    """Reading and writing one frame as half-float EXR (zip), the floor of a frame's cost."""
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "io.exr")
        write_frame(frame, path, overwrite=True)
        w, r = [], []
        for _ in range(max(repeat, 1)):
            t0 = time.perf_counter()
            write_frame(frame, path, overwrite=True)
            w.append((time.perf_counter() - t0) * 1e3)
            t0 = time.perf_counter()
            read_frame(path)
            r.append((time.perf_counter() - t0) * 1e3)
    return {"write_ms": float(np.median(w)), "read_ms": float(np.median(r)),
            "io_ms": float(np.median(w) + np.median(r))}


def bench_sequence(rt, look_name: str, width: int, height: int, frames: int,
                   repeat: int = 3) -> dict:
    """A stream as fast as its parts?  The look over ``frames`` EXR frames through `clfx
    render`'s batch pipeline (phased or overlapped, `clfx.pipeline.stream.stream_mode`), beside the same
    parts measured alone in the same run: the look on the first frame (per effect), reading
    the stream's frames in turn and writing the look's output (median of ``repeat`` warm
    runs each, half of them before the stream and half after).  In the stream a write and
    the next read share the codec threads, so their CPU is one figure, ``read + write``
    (``io_cpu_in_stream_ms``): the stream's CPU less its renders'.

    The inputs are the demo scene as a renderer writes it: float RGBA, depth and velocity, in
    the default EXR compression (`clfx.io.write`); outputs keep the input's type and
    compression.  The stream runs after the parts, so set-up (kernels, maps, spectra) is
    already done: this is the steady state.  ``stream_vs_parts`` (stream ms per frame over
    look + read + write alone) and the CPU seconds per frame do not depend on how loaded the
    machine is as much as milliseconds do: below 1 the overlap wins time, above 1 the
    parts slow each other down."""
    def timed(fn):
        c0, t0 = time.process_time(), time.perf_counter()
        out = fn()
        return out, (time.perf_counter() - t0) * 1e3, (time.process_time() - c0) * 1e3

    look = load_look(look_name)
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(1, frames + 1):
            write_frame(render_sharp(demo_scene(i, width, height)),
                        os.path.join(tmp, f"in.{i:04d}.exr"), bit_depth="float")
        batch = Batch(look=look, input_path=os.path.join(tmp, "in.#.exr"),
                      output_path=os.path.join(tmp, "out.#.exr"),
                      options=RenderOptions(overwrite=True), verbosity=0)
        batch.prepare()
        job = batch.jobs[0]
        alone = Batch(look=look, input_path=job.input,
                      output_path=os.path.join(tmp, "alone.exr"),
                      options=RenderOptions(overwrite=True), verbosity=0)
        alone.prepare()
        reads, renders, writes = [], [], []

        def parts(n):   # each part alone, with the codecs as the stream runs them; the reads
            with io_threads(codec_threads_for(rt)):     # of the stream's own frames in turn
                start = len(reads)
                reads.extend([timed(lambda k=start + i: batch.plan.read(
                    batch.jobs[k % len(batch.jobs)])) for i in range(n)])
                renders.extend(timed(lambda: render_frame(rt, look, read.views[0],
                                                          frame_number=job.frame))
                               for _ in range(n))
                out, report = renders[-1][0]
                writes.extend(timed(lambda: alone.plan.write(out, alone.jobs[0], report))
                              for _ in range(n))

        with io_threads(codec_threads_for(rt)):
            read = alone.plan.read(alone.jobs[0])
            render_frame(rt, look, read.views[0], frame_number=job.frame)  # warm-up
        parts(max(1, repeat // 2))     # half the runs before the stream, half after: a
        c0, t0 = time.process_time(), time.perf_counter()   # machine's load drifts
        summary = batch.run(rt)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        parts(max(1, repeat - repeat // 2))
    reports = summary["reports"]
    effects = [s.effect for s in renders[0][0][1].steps]

    def med(values):
        values = [v for v in values if v is not None]
        return float(np.median(values)) if values else None

    def step(rep, effect, key="ms"):
        return next((getattr(s, key) if s.ran else 0.0 for s in rep.steps
                     if s.effect == effect), None)

    alone_reports = [r[0][1] for r in renders]
    rows = [{"part": "read", "alone_ms": med([r[1] for r in reads]),
             "stream_ms": med([r.read_ms for r in reports]),
             "alone_cpu_ms": med([r[2] for r in reads]),
             "stream_cpu_ms": med([r.read_cpu_ms for r in reports])},
            {"part": "upload", "alone_ms": med([r.upload_ms for r in alone_reports]),
             "stream_ms": med([r.upload_ms for r in reports]),
             "alone_cpu_ms": med([r.upload_cpu_ms for r in alone_reports]),
             "stream_cpu_ms": med([r.upload_cpu_ms for r in reports])}]
    rows += [{"part": e, "alone_ms": med([step(r, e) for r in alone_reports]),
              "stream_ms": med([step(r, e) for r in reports]),
              "host_ms": med([step(r, e, "host_ms") for r in reports]),
              "alone_cpu_ms": med([step(r, e, "cpu_ms") for r in alone_reports]),
              "stream_cpu_ms": med([step(r, e, "cpu_ms") for r in reports])} for e in effects]
    rows += [{"part": "download", "alone_ms": med([r.download_ms for r in alone_reports]),
              "stream_ms": med([r.download_ms for r in reports]),
              "alone_cpu_ms": med([r.download_cpu_ms for r in alone_reports]),
              "stream_cpu_ms": med([r.download_cpu_ms for r in reports])},
             {"part": "write", "alone_ms": med([r[1] for r in writes]),
              "stream_ms": med([r.write_ms for r in reports]),
              "alone_cpu_ms": med([r[2] for r in writes]),
              "stream_cpu_ms": med([r.write_cpu_ms for r in reports])},
             {"part": "look (device)", "alone_ms": med([r[1] for r in renders]),
              "stream_ms": med([r.total_ms for r in reports]),
              "alone_cpu_ms": med([r[2] for r in renders])}]
    # the stream's read and write run side by side on shared codec threads: the process CPU
    # each saw holds the other's, so neither is theirs alone.  Theirs together (and the
    # loop's) is the stream's CPU less its renders' (upload, steps, download).
    look_cpu = [r.upload_cpu_ms + r.download_cpu_ms + sum(s.cpu_ms for s in r.steps if s.ran)
                for r in reports]
    rows[-1]["stream_cpu_ms"] = med(look_cpu)
    io_cpu = rows[0]["alone_cpu_ms"] + rows[-2]["alone_cpu_ms"]   # the ratio a load moves less
    io_cpu_stream = (1e3 * cpu - sum(look_cpu)) / max(len(reports), 1)
    rows.insert(-1, {"part": "read + write", "alone_ms": None, "stream_ms": None,
                     "alone_cpu_ms": io_cpu, "stream_cpu_ms": io_cpu_stream})
    for r in rows:
        if r["part"] in ("read", "write"):
            r["stream_cpu_ms"] = None        # in "read + write"
        a, b = r["alone_ms"], r["stream_ms"]
        r["ratio"] = b / a if a and b is not None and a > 0.5 else None
    io_ms = rows[0]["alone_ms"] + rows[-3]["alone_ms"]
    parts_ms = io_ms + rows[-1]["alone_ms"]
    parts_cpu = sum(med([x[2] for x in xs]) for xs in (renders, reads, writes))
    ms_per_frame = 1e3 * wall / max(len(reports), 1)
    return {"look": look_name, "frames": len(reports), "fps": summary["fps"],
            "stream": stream_mode(rt, width * height),
            "ms_per_frame": ms_per_frame, "device_ms_mean": summary["device_ms_mean"],
            "parts_ms": parts_ms, "stream_vs_parts": ms_per_frame / parts_ms if parts_ms else None,
            "io_ms": io_ms, "stream_vs_io": ms_per_frame / io_ms if io_ms else None,
            "io_cpu_ms": io_cpu, "stream_cpu_vs_io": 1e3 * cpu / max(len(reports), 1) / io_cpu
            if io_cpu else None, "io_cpu_in_stream_ms": io_cpu_stream,
            "cpu_ms_per_frame": 1e3 * cpu / max(len(reports), 1), "parts_cpu_ms": parts_cpu,
            "cores": available_cores(),
            "load_avg": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
            "rows": rows}


def analysis_frames(width: int, height: int, camera: Camera) -> dict[str, Frame]:
    """Frames (a) needs everything, (b) static dim all-in-focus, (c) (b) with a moving patch."""
    a = demo_frame(width, height)
    base = np.clip(a.rgba * 0.3, 0.0, 0.4).astype(np.float32)  # below every highlight knee
    base[..., 3] = 1.0
    depth = np.full((height, width), camera.focus_distance, np.float32)
    still = np.zeros((height, width, 2), np.float32)
    b = Frame.from_array(base, depth=depth, velocity=still)
    vel = still.copy()
    ph, pw = max(1, height // 5), max(1, width // 5)
    y0, x0 = height // 3, width // 3
    vel[y0:y0 + ph, x0:x0 + pw] = (12.0 * width / 1920 + 2.0, 0.0)
    c = Frame.from_array(base.copy(), depth=depth, velocity=vel)
    return {"a_needs_everything": a, "b_static_dim_in_focus": b, "c_small_region_moves": c}


def bench_analysis(rt, look_name: str, width: int, height: int, repeat: int) -> dict:
    look = load_look(look_name)
    frames = analysis_frames(width, height, look.camera)
    io = bench_io(frames["a_needs_everything"], repeat)
    out = {"look": look_name, **io, "frames": {}}
    for key, frame in frames.items():
        r = bench_look(rt, look_name, frame, repeat)
        r["vs_io"] = (r["ms"] + io["io_ms"]) / io["io_ms"] if io["io_ms"] > 0 else None
        out["frames"][key] = r
    return out
