"""A look: an ordered chain of effects with one camera block, rendered frame by frame.

Rendering a frame uploads its beauty (and depth and velocity passes) once, runs each
effect on the device, and downloads the result once.  Before each effect the host asks
``is_identity``; a skipped effect costs nothing and its reason is reported.  When an effect
grows the beauty's window (light spreading past the frame), the passes are extended to the
new window by edge clamping so later effects always see aligned passes.  The result is
cropped to the display window united with the input's data window (more with
``keep_overscan``).
"""
from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass, field


from clfx import __version__
from clfx.core.camera import Camera
from clfx.core.errors import ClipError
from clfx.core.frame import Frame
from clfx.core.plugin import DEFAULT_QUALITY, QUALITY_LEVELS, Params
from clfx.host import Plugin, RenderContext
from clfx.plugins import get_plugin
from clfx.core.rect import Rect

OVERSCAN_KEEP_FRACTION = 0.25
"""With keep_overscan, effects may write up to this fraction of the diagonal past the frame."""


@dataclass
class Step:
    """One effect of a look with its validated parameters."""

    effect: str
    params: Params
    quality: str | None = None
    plugin: Plugin | None = None
    typical_ms: float | None = None   # running mean of this step's cost, for "time saved"
    runs: int = 0
    skip_missing_passes: bool = False  # skip (with a reason) on frames without its passes
    id: str = ""                       # names the step; defaults to the effect's name

    def __post_init__(self):
        if self.plugin is None:
            self.plugin = get_plugin(self.effect)()
        self.id = self.id or self.effect

    def describe(self) -> dict:
        d = {"effect": self.effect, "params": self.params.as_dict()}
        if self.id != self.effect:
            d["id"] = self.id
        if self.quality:
            d["quality"] = self.quality
        if self.skip_missing_passes:
            d["missing_passes"] = "skip"
        return d

    def missing_passes(self, have: dict[str, bool]) -> list[str]:
        """Required clips of this step that the frame does not have."""
        return [c.name for c in self.plugin.descriptor.clips
                if c.name != "source" and not c.optional and not have.get(c.name, False)]


@dataclass
class Look:
    name: str
    description: str = ""
    camera: Camera = field(default_factory=Camera)
    steps: list[Step] = field(default_factory=list)
    seed: int = 0
    source: str = ""
    base: str | None = None

    def describe(self) -> dict:
        return {"name": self.name, "description": self.description, "base": self.base,
                "source": self.source, "seed": self.seed, "camera": self.camera.as_dict(),
                "effects": [s.describe() for s in self.steps]}

    def params_hash(self) -> str:
        """A short hash of everything that determines the output (stamped into files)."""
        blob = json.dumps({k: v for k, v in self.describe().items() if k != "source"},
                          sort_keys=True, default=str)
        return hashlib.sha1(blob.encode()).hexdigest()[:16]

    def required_clips(self) -> dict[str, list[str]]:
        """Clip name -> effects that cannot run without it (optional clips and steps that
        skip when their passes are missing are not listed)."""
        need: dict[str, list[str]] = {}
        for s in self.steps:
            if s.skip_missing_passes:
                continue
            for clip in s.plugin.descriptor.clips:
                if clip.name != "source" and not clip.optional:
                    need.setdefault(clip.name, []).append(s.effect)
        return need

    def clips_used(self) -> set[str]:
        """Every clip any step reads, required or optional."""
        return {c.name for s in self.steps for c in s.plugin.descriptor.clips}

    def check_clips(self, frame: Frame) -> None:
        """Raise ClipError if the frame lacks a pass a step requires."""
        have = {"depth": frame.depth is not None, "velocity": frame.velocity is not None}
        for clip, effects in self.required_clips().items():
            if not have.get(clip, False):
                raise ClipError(f"{frame.source or 'frame'}: effect {effects[0]!r} of look "
                                f"{self.name!r} needs a {clip} pass and none was found "
                                f"(see `clfx probe`, or pass --{clip} FILE)")

    def stamp(self) -> dict:
        """Attributes written into output headers."""
        return {"clfx:look": self.name, "clfx:version": __version__,
                "clfx:paramsHash": self.params_hash()}


@dataclass
class StepReport:
    effect: str
    ran: bool
    reason: str | None = None
    ms: float = 0.0
    quality: str = DEFAULT_QUALITY
    notes: list[str] = field(default_factory=list)

    def as_dict(self) -> dict:
        d = {"effect": self.effect, "ran": self.ran, "quality": self.quality}
        if self.ran:
            d["ms"] = round(self.ms, 2)
        else:
            d["reason"] = self.reason
        if self.notes:
            d["notes"] = self.notes
        return d


@dataclass
class FrameReport:
    frame: int
    steps: list[StepReport] = field(default_factory=list)
    upload_ms: float = 0.0
    analysis_ms: float = 0.0
    download_ms: float = 0.0
    total_ms: float = 0.0
    saved_ms: float | None = None
    analysis: dict | None = None
    input: str = ""
    output: str = ""
    read_ms: float = 0.0
    write_ms: float = 0.0

    def as_dict(self) -> dict:
        d = {"frame": self.frame, "input": self.input, "output": self.output,
             "ran": [s.effect for s in self.steps if s.ran],
             "skipped": {s.effect: s.reason for s in self.steps if not s.ran},
             "ms": {s.effect: round(s.ms, 2) for s in self.steps if s.ran},
             "upload_ms": round(self.upload_ms, 2), "download_ms": round(self.download_ms, 2),
             "analysis_ms": round(self.analysis_ms, 2), "total_ms": round(self.total_ms, 2),
             "read_ms": round(self.read_ms, 2), "write_ms": round(self.write_ms, 2),
             "steps": [s.as_dict() for s in self.steps]}
        if self.saved_ms is not None:
            d["saved_ms_estimate"] = round(self.saved_ms, 2)
        if self.analysis:
            d["analysis"] = self.analysis
        return d

    def explain(self) -> str:
        """Human-readable lines: what ran, what was skipped and why."""
        lines = [f"frame {self.frame}: {self.total_ms:.1f} ms on device "
                 f"(upload {self.upload_ms:.1f}, analysis {self.analysis_ms:.1f}, "
                 f"download {self.download_ms:.1f})"]
        for s in self.steps:
            if s.ran:
                extra = f" [{'; '.join(s.notes)}]" if s.notes else ""
                lines.append(f"  ran     {s.effect:<22} {s.ms:8.1f} ms  ({s.quality}){extra}")
            else:
                lines.append(f"  skipped {s.effect:<22} {'':8}     {s.reason}")
        if self.saved_ms:
            lines.append(f"  skipping saved ~{self.saved_ms:.0f} ms (estimated from this "
                         f"sequence's runs of the skipped effects)")
        return "\n".join(lines)


def read_image_rgba(path: str):
    """An image file a parameter names (a kernel image), as float32 RGBA: the reader the
    pipeline hands effects through their render context."""
    from clfx.io.read import read_frame  # lazy: io pulls in OpenImageIO

    return read_frame(path).rgba


def output_limit(frame: Frame, keep_overscan: bool) -> Rect:
    """The window effects may write to and the result is cropped to."""
    limit = frame.data_window.union(frame.display_window)
    if keep_overscan:
        grow = int(round(OVERSCAN_KEEP_FRACTION * frame.display_window.diagonal))
        limit = limit.union(frame.display_window.grown(grow))
    return limit


def render_frame(rt, look: Look, frame: Frame, *, frame_number: int = 0,
                 quality: str | None = None, keep_overscan: bool = False,
                 analysis_summary: bool = False) -> tuple[Frame, FrameReport]:
    """Render one frame through ``look``; returns the output frame and a report.

    ``quality`` sets the level of every step without its own override.  The frame is
    uploaded once and downloaded once; the device queue is synchronised after each effect
    only to time it.
    """
    report = FrameReport(frame=frame_number, input=frame.source)
    t_start = time.perf_counter()
    look.check_clips(frame)
    window = frame.data_window
    used = look.clips_used()  # passes no step reads stay on the host
    src = rt.upload(frame.rgba, window)
    depth = rt.upload(frame.depth, window) if frame.depth is not None and "depth" in used else None
    velocity = (rt.upload(frame.velocity, window)
                if frame.velocity is not None and "velocity" in used else None)
    rt.finish()
    t_up = time.perf_counter()
    report.upload_ms = (t_up - t_start) * 1e3
    ctx = RenderContext(rt, src, depth=depth, velocity=velocity,
                        display_window=frame.display_window, pixel_aspect=frame.pixel_aspect,
                        frame=frame_number, seed=look.seed, camera=look.camera,
                        quality=quality or DEFAULT_QUALITY,
                        display_referred=frame.display_referred,
                        output_limit=output_limit(frame, keep_overscan),
                        read_image=read_image_rgba)
    analyses = {}  # the analysis is computed on first use (again if the window changes)
    saved = 0.0
    have = {"depth": frame.depth is not None, "velocity": frame.velocity is not None}
    for step in look.steps:
        level = step.quality or quality or DEFAULT_QUALITY
        step_ctx = ctx.with_quality(level)
        step_ctx.notes = []
        missing = step.missing_passes(have)
        reason = (f"no {' or '.join(missing)} pass in the input" if missing
                  else step.plugin.is_identity(step.params, step_ctx))
        ctx._analysis = step_ctx._analysis  # share an analysis the step computed
        if ctx._analysis is not None:
            analyses[id(ctx._analysis)] = ctx._analysis.seconds
        if reason:
            report.steps.append(StepReport(step.id, False, reason, quality=level))
            saved += step.typical_ms or 0.0
            continue
        t0 = time.perf_counter()
        out = step.plugin.render(rt, step.params, step_ctx)
        rt.finish()
        ms = (time.perf_counter() - t0) * 1e3
        step.runs += 1
        step.typical_ms = ms if step.typical_ms is None else step.typical_ms + (ms - step.typical_ms) / step.runs
        report.steps.append(StepReport(step.id, True, ms=ms, quality=level,
                                       notes=list(step_ctx.notes)))
        ctx._analysis = step_ctx._analysis
        if ctx._analysis is not None:
            analyses[id(ctx._analysis)] = ctx._analysis.seconds
        if out.window != ctx.source.window:
            ctx.depth = rt.reframe(ctx.depth, out.window, "clamp") if ctx.depth is not None else None
            ctx.velocity = rt.reframe(ctx.velocity, out.window, "clamp") if ctx.velocity is not None else None
        ctx.source = out
    t_dl = time.perf_counter()
    final = ctx.source
    keep = ctx.output_limit
    if not keep.contains(final.window):
        final = rt.reframe(final, final.window.intersect(keep))
    rgba = rt.download(final)
    report.download_ms = (time.perf_counter() - t_dl) * 1e3
    report.total_ms = (time.perf_counter() - t_start) * 1e3
    report.saved_ms = saved if any(not s.ran for s in report.steps) else None
    report.analysis_ms = sum(analyses.values()) * 1e3
    if analysis_summary and look.steps:
        report.analysis = ctx.analysis.summary()
    out_frame = frame.with_rgba(rgba, final.window)
    out_frame.metadata.update(look.stamp())
    return out_frame, report


def validate_quality(level: str | None, where: str = "--quality") -> str | None:
    from clfx.core.errors import ParamError

    if level is not None and level not in QUALITY_LEVELS:
        raise ParamError(f"{where}: {level!r} is not one of {', '.join(QUALITY_LEVELS)}")
    return level

