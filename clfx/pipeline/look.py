"""A look: an ordered chain of effects with one camera block, rendered frame by frame.

Rendering a frame uploads its beauty (and depth and velocity passes) once, runs each
effect on the device, and downloads the result once.  Before each effect the host asks
``is_identity``; a skipped effect costs nothing and its reason is reported.  When an effect
grows the beauty's window (light spreading past the frame), the passes are extended to the
new window by edge clamping so later effects always see aligned passes.  The result is
cropped to the display window united with the input's data window (more with
``keep_overscan``).  The frame's windows, and each window an effect would grow it to, are
checked against the pixel limit (``clfx.core.limits``) before anything that size exists.

A :class:`Step` is configuration only; the running costs a sequence accumulates (to estimate
what skipping saved) live in a :class:`RunStats` owned by whoever renders the sequence.
"""
from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass, field, replace
from typing import Mapping

import numpy as np

from clfx._version import __version__
from clfx.core.camera import Camera
from clfx.core.errors import ClfxError, ClipError, ParamError
from clfx.core.frame import Frame
from clfx.core import cancel as cancelling, limits
from clfx.core.limits import check_pixels
from clfx.core.plugin import DEFAULT_QUALITY, QUALITY_LEVELS, Params
from clfx.core.rect import Rect
from clfx.fx import mask as mask_fx
from clfx.device.runtime import release_freed_heap
from clfx.host import Plugin, RenderContext, tile_bands  # noqa: F401 (re-exported)
from clfx.io import lenses as lens_io
from clfx.io.lenses import Lenses
from clfx.kit.warp import canvas_stand_in
from clfx.pipeline.animation import Animated
from clfx.pipeline.masks import FrameMasks, MaskSpec, read_masks
from clfx.plugins import get_plugin

OVERSCAN_KEEP_FRACTION = 0.25
"""With keep_overscan, effects may write up to this fraction of the diagonal past the frame."""


MISSING_PASSES = ("error", "skip")
"""What a step does on a frame without a pass it requires: fail the look, or skip the step."""


@dataclass(frozen=True)
class Step:
    """One effect of a look, as configured: no running state (see :class:`RunStats`).

    Attributes
    ----------
    effect : str
        The registered effect's name.
    params : Params
        Its validated parameters.
    quality : str or None
        This step's quality level; None takes the render's.
    id : str
        Names the step for inheritance and ``--set ID.param=...``; defaults to ``effect``.
    missing_passes : {"error", "skip"}
        On frames without a pass the effect requires: fail before rendering, or skip the step
        (with a reason in the report).
    enabled : bool
        False keeps the step in the look without ever running it.
    mask : MaskSpec or None
        Limits the effect to a mask (`clfx.pipeline.masks`).
    animated : tuple of (str, Animated)
        Keyframed parameters (`clfx.pipeline.animation`); ``params`` holds their value at
        the first key, :meth:`at` the values of a frame.
    plugin : Plugin
        The effect (made from ``effect`` unless given, e.g. an unregistered test plugin).
    origin : str
        The look whose file added the step ("" when built in code); ``changed_in``: the
        looks inheriting it that changed it, in order (``clfx look show`` marks them).
        Neither is part of the step's value (nor of the look's hash).
    """

    effect: str
    params: Params
    quality: str | None = None
    id: str = ""
    missing_passes: str = "error"
    enabled: bool = True
    mask: MaskSpec | None = None
    animated: tuple[tuple[str, Animated], ...] = ()
    plugin: Plugin | None = field(default=None, compare=False, repr=False)
    origin: str = field(default="", compare=False, repr=False)
    changed_in: tuple[str, ...] = field(default=(), compare=False, repr=False)

    def __post_init__(self):
        if self.missing_passes not in MISSING_PASSES:
            raise ValueError(f"missing_passes {self.missing_passes!r} is not one of {MISSING_PASSES}")
        if self.plugin is None:
            object.__setattr__(self, "plugin", get_plugin(self.effect)())
        object.__setattr__(self, "id", self.id or self.effect)

    def describe(self) -> dict:
        """The step as a look file writes it (keyframes included; every parameter given)."""
        d = {"effect": self.effect, "params": self.param_values()}
        if self.id != self.effect:
            d["id"] = self.id
        if self.quality:
            d["quality"] = self.quality
        if self.missing_passes != "error":
            d["missing_passes"] = self.missing_passes
        if not self.enabled:
            d["enabled"] = False
        if self.mask is not None:
            d["mask"] = self.mask.describe()
        return d

    def param_values(self) -> dict:
        """Every parameter's value, keyframed ones as their keyframe mappings."""
        return {**self.params.as_dict(), **{k: a.describe() for k, a in self.animated}}

    def at(self, frame: float) -> "Step":
        """This step with its keyframed parameters resolved at ``frame`` (itself if none)."""
        if not self.animated:
            return self
        values = {**self.params.as_dict(), **{k: a.at(frame) for k, a in self.animated}}
        return replace(self, params=self.plugin.params(**values), animated=())

    def required_clips(self) -> list[str]:
        """Clips (other than the source) the effect cannot run without."""
        return [c.name for c in self.plugin.descriptor.clips
                if c.name != "source" and not c.optional]

    def absent_passes(self, have: dict[str, bool]) -> list[str]:
        """Required clips of this step that the frame does not have."""
        return [name for name in self.required_clips() if not have.get(name, False)]


@dataclass
class StepTiming:
    """A step's running mean cost over the frames it ran on."""

    runs: int = 0
    mean_ms: float | None = None

    def add(self, ms: float) -> None:
        self.runs += 1
        self.mean_ms = ms if self.mean_ms is None else self.mean_ms + (ms - self.mean_ms) / self.runs


@dataclass
class RunStats:
    """Statistics of one run of a look over frames (a batch, a demo), owned by that run:
    each step's mean cost (by its index in ``look.steps``), from which a skipped step's
    saving is estimated."""

    steps: dict[int, StepTiming] = field(default_factory=dict)

    def timing(self, index: int) -> StepTiming:
        return self.steps.setdefault(index, StepTiming())


@dataclass
class Look:
    """A resolved look: camera, seed and ordered steps (inheritance applied).

    ``camera_animated`` holds keyframed camera values (``camera`` their value at the first
    key); :meth:`at` gives the look of one frame, with every keyframed value resolved.
    """

    name: str
    description: str = ""
    camera: Camera = field(default_factory=Camera)
    steps: list[Step] = field(default_factory=list)
    seed: int = 0
    source: str = ""
    base: str | None = None
    camera_animated: tuple[tuple[str, Animated], ...] = ()
    files: tuple[str, ...] = ()
    """The files the look was read from: its YAML and its base looks', or the output whose
    ``clfx:lookJSON`` it is (``--look-from``): inputs of every render with it."""
    lenses: Lenses | None = field(default=None, compare=False, repr=False)
    """The lens data its steps name, read and validated when the look was loaded
    (`clfx.io.lenses.resolve`); None for a look built in code (read on first use)."""

    def camera_values(self) -> dict:
        """Every camera value, keyframed ones as their keyframe mappings."""
        return {**self.camera.as_dict(), **{k: a.describe() for k, a in self.camera_animated}}

    def describe(self) -> dict:
        return {"name": self.name, "description": self.description, "base": self.base,
                "source": self.source, "seed": self.seed, "camera": self.camera_values(),
                "effects": [s.describe() for s in self.steps]}

    def document(self) -> dict:
        """The look as a self-contained look file (schema 1; inheritance applied, every value
        given, keyframes kept): what outputs stamp as ``clfx:lookJSON`` and
        ``clfx.pipeline.presets.look_from_dict`` reads back."""
        return {"name": self.name, "description": self.description, "schema": 1,
                "seed": self.seed, "camera": self.camera_values(),
                "effects": [s.describe() for s in self.steps if s.enabled]}

    @property
    def animated(self) -> bool:
        """Whether any camera value or parameter is keyframed."""
        return bool(self.camera_animated) or any(s.animated for s in self.steps)

    def at(self, frame: float) -> "Look":
        """This look with every keyframed value resolved at ``frame`` (itself if none)."""
        if not self.animated:
            return self
        camera = self.camera.updated(**{k: a.at(frame) for k, a in self.camera_animated})
        return replace(self, camera=camera, camera_animated=(),
                       steps=[s.at(frame) for s in self.steps])

    def values_at(self, frame: float) -> dict:
        """The keyframed values at ``frame``, by ``camera.NAME`` / ``STEP.PARAM``."""
        out = {f"camera.{k}": a.at(frame) for k, a in self.camera_animated}
        for s in self.steps:
            out.update({f"{s.id}.{k}": a.at(frame) for k, a in s.animated})
        return out

    def at_quality(self, quality: str | None) -> "Look":
        """This look with every step's quality level resolved: its own, else ``quality``
        (else ``final``), as a render at ``quality`` runs it."""
        level = quality or DEFAULT_QUALITY
        return replace(self, steps=[s if s.quality else replace(s, quality=level)
                                    for s in self.steps])

    def params_hash(self, quality: str | None = None) -> str:
        """The look's hash: what a TD compares to confirm a render used an approved look.

        One value wherever it is shown: ``clfx look show NAME [--quality LEVEL]``, a
        render's ``--explain`` and ``--json`` summary, and the ``clfx:paramsHash`` stamped
        into every output (and a look read back with ``--look-from`` hashes the same).

        It covers what determines the pixels: the seed, the camera and the enabled steps in
        order, each with every parameter's value (defaults filled in, keyframes and masks
        included) and its quality level resolved as a render at ``quality`` (default
        ``final``) runs it.  Not the look's name, description, file, base or how the file
        is written (order of keys, comments, values left at their defaults or spelt out),
        nor disabled steps.  16 hex digits of the SHA-1 of that, as sorted JSON."""
        doc = self.at_quality(quality).document()
        blob = json.dumps({k: doc[k] for k in ("seed", "camera", "effects")},
                          sort_keys=True, default=str)
        return hashlib.sha1(blob.encode()).hexdigest()[:16]

    def active_steps(self) -> list[tuple[int, Step]]:
        """(index, step) of every enabled step, in order."""
        return [(i, s) for i, s in enumerate(self.steps) if s.enabled]

    def required_clips(self) -> dict[str, list[str]]:
        """Clip name -> effects that cannot run without it (optional clips and steps that
        skip when their passes are missing are not listed)."""
        need: dict[str, list[str]] = {}
        for _, s in self.active_steps():
            if s.missing_passes == "skip":
                continue
            for clip in s.required_clips():
                need.setdefault(clip, []).append(s.effect)
        return need

    def clips_used(self) -> set[str]:
        """Every clip any step reads, required or optional."""
        return {c.name for _, s in self.active_steps() for c in s.plugin.descriptor.clips}

    def masks(self) -> list[tuple[Step, MaskSpec]]:
        """(step, mask) of every enabled masked step."""
        return [(s, s.mask) for _, s in self.active_steps() if s.mask is not None]

    def check_clips(self, frame: Frame) -> None:
        """Raise ClipError if the frame lacks a pass a step requires."""
        have = {"depth": frame.depth is not None, "velocity": frame.velocity is not None}
        for clip, effects in self.required_clips().items():
            if not have.get(clip, False):
                raise ClipError(f"{frame.source or 'frame'}: effect {effects[0]!r} of look "
                                f"{self.name!r} needs a {clip} pass and none was found "
                                f"(see `clfx probe`, or pass --{clip} FILE)")

    def stamp(self, frame: float | None = None, command: str | None = None) -> dict:
        """Attributes written into output headers: the look's name, clfx's version, the
        params hash, the whole resolved look as JSON (``clfx:lookJSON``: ``clfx render
        --look-from FILE`` renders it again), the keyframed values used on ``frame``
        (``clfx:values``, JSON; ``{}`` when nothing is keyframed) and the command line
        (``clfx:commandLine``; "" when not rendered from the command line).  Every key is
        always written, so none is left over from an input clfx rendered before."""
        d = {"clfx:look": self.name, "clfx:version": __version__,
             "clfx:paramsHash": self.params_hash(),
             "clfx:lookJSON": json.dumps(self.document(), sort_keys=True, default=str),
             "clfx:values": json.dumps(self.values_at(frame) if frame is not None else {},
                                       sort_keys=True),
             "clfx:commandLine": command or ""}
        return d


@dataclass
class StepReport:
    effect: str
    ran: bool
    reason: str | None = None
    ms: float = 0.0
    quality: str = DEFAULT_QUALITY
    notes: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    host_ms: float = 0.0    # of ``ms``: planning and enqueueing, host reads included
    cpu_ms: float = 0.0     # process CPU over the step (a CPU device's threads included)

    def as_dict(self) -> dict:
        d = {"effect": self.effect, "ran": self.ran, "quality": self.quality}
        if self.ran:
            d["ms"] = round(self.ms, 2)
            d["host_ms"] = round(self.host_ms, 2)
            d["cpu_ms"] = round(self.cpu_ms, 2)
        else:
            d["reason"] = self.reason
        if self.notes:
            d["notes"] = self.notes
        if self.warnings:
            d["warnings"] = self.warnings
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
    upload_cpu_ms: float = 0.0     # process CPU (time.process_time) of upload, download
    download_cpu_ms: float = 0.0
    read_cpu_ms: float = 0.0       # process CPU while the frame was read / written
    write_cpu_ms: float = 0.0      # (other threads' work at the same time included)
    frame_warnings: list[str] = field(default_factory=list)  # the frame's own (not a step's)
    values: dict = field(default_factory=dict)  # keyframed values used, by camera.K / STEP.P
    view: str | None = None     # the view rendered (multi-view files), None for a plain frame
    other_views: list[FrameReport] = field(default_factory=list)  # the same frame's other views

    def as_dict(self) -> dict:
        d = {"frame": self.frame, "input": self.input, "output": self.output,
             "ran": [s.effect for s in self.steps if s.ran],
             "skipped": {s.effect: s.reason for s in self.steps if not s.ran},
             "ms": {s.effect: round(s.ms, 2) for s in self.steps if s.ran},
             "upload_ms": round(self.upload_ms, 2), "download_ms": round(self.download_ms, 2),
             "analysis_ms": round(self.analysis_ms, 2), "total_ms": round(self.total_ms, 2),
             "read_ms": round(self.read_ms, 2), "write_ms": round(self.write_ms, 2),
             "cpu_ms": {"read": round(self.read_cpu_ms, 2),
                        "upload": round(self.upload_cpu_ms, 2),
                        "download": round(self.download_cpu_ms, 2),
                        "write": round(self.write_cpu_ms, 2),
                        **{s.effect: round(s.cpu_ms, 2) for s in self.steps if s.ran}},
             "steps": [s.as_dict() for s in self.steps]}
        if self.saved_ms is not None:
            d["saved_ms_estimate"] = round(self.saved_ms, 2)
        if self.analysis:
            d["analysis"] = self.analysis
        if self.frame_warnings:
            d["warnings"] = self.frame_warnings
        if self.values:
            d["values"] = self.values
        if self.view is not None:
            d["view"] = self.view
        if self.other_views:      # each view's own steps and times (the hero's are above)
            d["other_views"] = [{k: v for k, v in o.as_dict().items()
                                 if k not in ("frame", "input", "output", "read_ms", "write_ms")}
                                for o in self.other_views]
        return d

    @property
    def views(self) -> list[str]:
        """The views this frame rendered, hero first (empty for a plain frame)."""
        return [r.view for r in (self, *self.other_views) if r.view is not None]

    def warning_items(self) -> list[tuple[str, str]]:
        """(where, text) of every warning of this frame and its other views: ``where`` is
        ``"frame N"`` or ``"frame N (view V)"``."""
        items = []
        for r in (self, *self.other_views):
            where = f"frame {r.frame}" + (f" (view {r.view})" if r.view else "")
            items += [(where, w) for w in r.frame_warnings]
            items += [(where, f"{s.effect}: {w}") for s in r.steps for w in s.warnings]
        return items

    def warnings(self) -> list[str]:
        """The lines this frame must say on stderr whatever the verbosity (a clamp that bit,
        a convention guessed, a request that could not be honoured), each naming the frame
        (and the view, for a multi-view frame)."""
        return [f"clfx: warning: {where}: {w}" for where, w in self.warning_items()]

    def explain(self) -> str:
        """Human-readable lines: what ran, what was skipped and why (per view, for a
        multi-view frame)."""
        own = self._explain_one()
        return "\n".join([own] + [o._explain_one() for o in self.other_views])

    def _explain_one(self) -> str:
        view = f" (view {self.view})" if self.view else ""
        lines = [f"frame {self.frame}{view}: {self.total_ms:.1f} ms on device "
                 f"(upload {self.upload_ms:.1f}, analysis {self.analysis_ms:.1f}, "
                 f"download {self.download_ms:.1f})"]
        if self.values:
            lines.append("  values  " + ", ".join(f"{k}={_short(v)}" for k, v in self.values.items()))
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


def _short(v) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, tuple):
        return "(" + ", ".join(_short(x) for x in v) + ")"
    return str(v)


def read_image_rgba(path: str):
    """An image file a parameter names (a kernel image), as float32 RGBA: the reader the
    pipeline hands effects through their render context."""
    from clfx.io.read import read_frame  # lazy: io pulls in OpenImageIO

    return read_frame(path).rgba


def working_rgb_to_xyz(space: str | None):
    """The working space's RGB -> XYZ matrix from OCIO (`clfx.io.colour.working_rgb_to_xyz`),
    handed to effects as data on the render context (None: Rec.709, the default)."""
    if space in (None, "lin_rec709"):   # frames made in memory: no need for OpenImageIO
        return None
    from clfx.io.colour import working_rgb_to_xyz as matrix  # lazy: io pulls in OpenImageIO

    return matrix(space)


def output_limit(frame: Frame, keep_overscan: bool) -> Rect:
    """The window effects may write to and the result is cropped to."""
    return _limit(frame.data_window, frame.display_window, keep_overscan)


def _limit(data: Rect, display: Rect, keep_overscan: bool) -> Rect:
    limit = data.union(display)
    if keep_overscan:
        grow = int(round(OVERSCAN_KEEP_FRACTION * display.diagonal))
        limit = limit.union(display.grown(grow))
    return limit


def prepare(rt, look: Look, data_window: Rect, display_window: Rect, pixel_aspect: float = 1.0,
            *, frame_number: int = 0, quality: str | None = None,
            keep_overscan: bool = False, cancel=None) -> None:
    """Build the caches of ``look``'s steps that depend only on parameters and geometry
    (`Plugin.prepare`: distortion and chromatic aberration maps) for frames of these windows,
    so the first frame does not wait for them: a batch runs this on a thread while the first
    frame is read and its first steps render.  Each step sees the window the steps before it
    would grow the frame to.  A guess that turns out wrong (a step skipped on the real frame,
    a value that needs pixels) costs only the work: the render builds what it needs under
    its own cache key, so the pixels never depend on this.

    ``cancel`` (a `threading.Event`): once set, the work stops before the next step or the
    next band of a map (`clfx.core.cancel`), e.g. when the first frame is refused.  The
    windows must be within the pixel limit (the caller checks them, as the reader does)."""
    for what, win in (("display window", display_window), ("data window", data_window)):
        check_pixels(win.width, win.height, f"prepared frame: {what}", FrameTooLarge)
    look = look.at(frame_number)
    ctx = RenderContext(rt, canvas_stand_in(data_window), display_window=display_window,
                        pixel_aspect=pixel_aspect, frame=frame_number, seed=look.seed,
                        camera=look.camera, quality=quality or DEFAULT_QUALITY,
                        output_limit=_limit(data_window, display_window, keep_overscan))
    with cancelling.scope(cancel):
        for _, step in look.active_steps():
            if cancel is not None and cancel.is_set():
                return
            step_ctx = ctx.for_step(step.quality or quality or DEFAULT_QUALITY)
            try:
                step.plugin.prepare(rt, step.params, step_ctx)
                window = step.plugin.output_window(step.params, step_ctx)
            except cancelling.Cancelled:
                return
            except Exception:  # noqa: BLE001 - needs pixels after all: the render builds it
                continue
            ctx = ctx.over(source=canvas_stand_in(window))


class FrameTooLarge(ClfxError):
    """A frame, or the window an effect grows it to, exceeds the pixel limit
    (``CLFX_MAX_PIXELS``): checked before anything that size is allocated."""


def render_frame(rt, look: Look, frame: Frame, *, frame_number: int = 0,
                 quality: str | None = None, keep_overscan: bool = False,
                 analysis_summary: bool = False, stats: RunStats | None = None,
                 masks: Mapping[MaskSpec, np.ndarray] | None = None,
                 release_input: bool = False,
                 tile_pixels: int | None = None) -> tuple[Frame, FrameReport]:
    """Render one frame through ``look``; returns the output frame and a report.

    ``quality`` sets the level of every step without its own override.  Keyframed values
    are resolved at ``frame_number``.  The frame is uploaded once and downloaded once; the
    device queue is synchronised after each effect only to time it.  ``stats`` carries the
    steps' running costs across the frames of one run (they estimate what skipping saved);
    without it each frame starts afresh.  ``masks`` holds the frame's masks on the host
    (`clfx.pipeline.masks.read_masks`; read here from the frame's files when None and a
    step is masked), each uploaded once.  ``release_input``: the caller hands ``frame``
    over, and its host beauty (and passes, when the frame has a file layout to copy them
    from) are dropped once on the device, so a frame is not held twice (see "Memory" in
    docs/performance.md).  Device passes are dropped after the last step that reads them.
    ``tile_pixels``: steps that tile render in bands of at most this many pixels, each from
    its region of interest, with the same pixels (`render_tiled`; default
    ``CLFX_TILE_PIXELS``, `clfx.core.limits.tile_pixels`; None there: whole frames).

    Raises
    ------
    ClipError
        The frame lacks a pass a step requires, or a mask cannot be read.
    FrameTooLarge
        The frame's windows, or a window an effect would grow it to, exceed the pixel limit.
    """
    stats = RunStats() if stats is None else stats
    # 0 (a batch's RenderOptions: whole frames) is None: a plan is keyed by its band size
    tiles = (tile_pixels if tile_pixels is not None else limits.tile_pixels()) or None
    report = FrameReport(frame=frame_number, input=frame.source,
                         values=look.values_at(frame_number))
    stamp = look.at_quality(quality).stamp(frame_number)   # the level rendered (one hash)
    reference_camera = look.camera   # keyframed values at their first keys
    look = look.at(frame_number)
    t_start, c_start = time.perf_counter(), time.process_time()
    look.check_clips(frame)
    if masks is None and look.masks():
        masks = read_masks(look, frame, frame_number)
    for what, win in (("display window", frame.display_window), ("data window", frame.data_window)):
        check_pixels(win.width, win.height, f"{frame.source or 'frame'}: {what}", FrameTooLarge)
    ctx = _upload(rt, look, frame, frame_number=frame_number, quality=quality,
                  keep_overscan=keep_overscan, reference_camera=reference_camera)
    report.upload_ms = (time.perf_counter() - t_start) * 1e3
    report.upload_cpu_ms = (time.process_time() - c_start) * 1e3
    report.frame_warnings = list(ctx.warnings)
    have = {"depth": frame.depth is not None, "velocity": frame.velocity is not None}
    if release_input:
        frame.rgba = None
        if frame.layout is not None:     # an output copies the passes from the file
            frame.depth = frame.velocity = None
    frame_masks = FrameMasks(rt, masks or {}, frame.data_window, frame.display_window)
    saved = 0.0
    steps = look.active_steps()
    for n, (index, step) in enumerate(steps):
        if not analysis_summary:          # the summary's analysis may read the passes
            ctx = _drop_unread_passes(ctx, steps[n:])
        timing = stats.timing(index)
        later = {c.name for _, s in steps[n + 1:] for c in s.plugin.descriptor.clips}
        step_report, out, moved = _run_step(rt, step, ctx,
                                            step.quality or quality or DEFAULT_QUALITY, have,
                                            timing, frame_masks, tiles, later)
        report.steps.append(step_report)
        if out is None:
            saved += timing.mean_ms or 0.0
        else:
            ctx = _advance(rt, ctx, out, moved)
    t_dl, c_dl = time.perf_counter(), time.process_time()
    rgba, window = _download(rt, ctx)
    report.download_ms = (time.perf_counter() - t_dl) * 1e3
    report.download_cpu_ms = (time.process_time() - c_dl) * 1e3
    report.total_ms = (time.perf_counter() - t_start) * 1e3
    report.saved_ms = saved if any(not s.ran for s in report.steps) else None
    report.analysis_ms = ctx.analysis_seconds * 1e3
    if analysis_summary and look.steps:
        report.analysis = ctx.analysis.summary()
    out_frame = frame.with_rgba(rgba, window)
    out_frame.metadata.update(stamp)
    return out_frame, report


def _upload(rt, look: Look, frame: Frame, *, frame_number: int, quality: str | None,
            keep_overscan: bool, reference_camera: Camera | None = None) -> RenderContext:
    """The frame on the device (passes no step reads stay on the host) in a new context;
    ``look`` is resolved at the frame, ``reference_camera`` its camera at the first keys."""
    window = frame.data_window
    used = look.clips_used()
    src = rt.upload(frame.rgba, window)
    nonfinite = rt.sanitize(src)  # once for the chain: no effect, run or skipped, sees NaN/Inf
    depth = rt.upload(frame.depth, window) if frame.depth is not None and "depth" in used else None
    velocity = (rt.upload(frame.velocity, window)
                if frame.velocity is not None and "velocity" in used else None)
    back = getattr(frame, "velocity_back", None)
    velocity_back = (rt.upload(back, window)
                     if back is not None and velocity is not None else None)
    rt.finish()
    ctx = RenderContext(rt, src, depth=depth, velocity=velocity, velocity_back=velocity_back,
                        display_window=frame.display_window, pixel_aspect=frame.pixel_aspect,
                        frame=frame_number, seed=look.seed, camera=look.camera,
                        quality=quality or DEFAULT_QUALITY,
                        display_referred=frame.display_referred,
                        output_limit=output_limit(frame, keep_overscan),
                        read_image=read_image_rgba,
                        read_lens=lens_io.read_lens if look.lenses is None else look.lenses.read,
                        reference_camera=reference_camera,
                        rgb_to_xyz=working_rgb_to_xyz(frame.colorspace))
    if nonfinite:
        ctx.warnings.append(f"{nonfinite} pixel(s) with NaN or infinite values set to 0")
    return ctx


def _run_step(rt, step: Step, ctx: RenderContext, level: str, have: dict[str, bool],
              timing: StepTiming, masks: FrameMasks, tile_pixels: int | None = None,
              later: set = frozenset()):
    """Run one step at ``level`` unless it has nothing to do; returns its report, its
    output (None when skipped) and the passes it realigned with its output for the later
    steps, which read the clips ``later`` (`Plugin.passes_after`; none for a masked step,
    whose output is partly its input).  A masked step blends its output with the source by
    its mask, or renders from the masked source (`clfx.pipeline.masks`).  Its time (``ms``)
    runs from here: planning is part of a step's cost (streaks' plan waits for its seeds)."""
    t0, c0 = time.perf_counter(), time.process_time()
    step_ctx = ctx.for_step(level)
    if step.plugin.whole_frame is None and tile_pixels:   # its plan holds what bands read
        step_ctx = step_ctx.over(tile_pixels=tile_pixels)
    missing = step.absent_passes(have)
    reason = f"no {' or '.join(missing)} pass in the input" if missing else None
    if missing:   # the look asked for this step: skipping it is said on stderr, once per batch
        step_ctx.warnings.append(f"skipped: {reason} (missing_passes: skip)")
    mode = masked = mask = None
    if not reason and step.mask is not None:
        if masks.empty(step.mask):
            reason = f"mask ({step.mask.label()}) selects nothing on this frame"
        else:
            mode = step.mask.mode_for(step.plugin.descriptor)
            mask = masks.get(step.mask, ctx.source.window)
            if mode == "sources":
                masked = mask_fx.multiply(rt, ctx.source, mask)
                step_ctx = step_ctx.with_source(masked)
    if not reason:
        reason = step.plugin.is_identity(step.params, step_ctx)
    if reason:
        return StepReport(step.id, False, reason, quality=level,
                          warnings=list(step_ctx.warnings)), None, {}
    step.plugin.planned(step.params, step_ctx)  # once per step: the regions and render read it
    grown = step.plugin.output_window(step.params, step_ctx)
    check_pixels(grown.width, grown.height, f"frame grown by {step.id}", FrameTooLarge)
    out = render_tiled(rt, step.plugin, step.params, step_ctx, grown, tile_pixels)
    if mode == "mix":
        out = mask_fx.mix(rt, ctx.source, out, mask)
    elif mode == "sources":
        out = mask_fx.spread(rt, ctx.source, masked, out)
    moved = {} if mode else step.plugin.passes_after(rt, step.params, step_ctx, out, later)
    host_ms = (time.perf_counter() - t0) * 1e3
    rt.finish()
    ms = (time.perf_counter() - t0) * 1e3
    timing.add(ms)
    notes = list(step_ctx.notes)
    if mode:
        notes.append(f"masked by {step.mask.label()} ({mode})")
    return StepReport(step.id, True, ms=ms, quality=level, notes=notes,
                      warnings=list(step_ctx.warnings), host_ms=host_ms,
                      cpu_ms=(time.process_time() - c0) * 1e3), out, moved


def render_tiled(rt, plugin: Plugin, p: Params, ctx: RenderContext, window: Rect,
                 tile_pixels: int | None):
    """``plugin``'s output over ``window`` (its output window): whole, or, for an effect
    that tiles (``whole_frame`` None) and a window of more than ``tile_pixels`` pixels, band
    by band: each band rendered from its region of interest (`Plugin.region_of_interest`:
    the band and the overlap its light comes from, cut to the source) into one output, so the
    effect's own buffers are band-sized.  The step's plan is the frame's, made for this band
    size (`RenderContext.tile_pixels`) on the whole frame before any band, and every band
    receives it in its :class:`~clfx.host.Band`; the pixels are the whole render's
    (tests/contract/test_tiles.py)."""
    if plugin.whole_frame:
        return plugin.render(rt, p, ctx)
    tile_pixels = tile_pixels or None   # 0 and None: whole, the plan's key (`Plugin.planned`)
    if ctx.tile_pixels != tile_pixels:
        ctx = ctx.over(tile_pixels=tile_pixels)
    bands = ctx.bands(window)
    if len(bands) < 2:
        return plugin.render(rt, p, ctx)
    plan = plugin.planned(p, ctx)
    rois = [plugin.region_of_interest(p, ctx, band).intersect(ctx.source.window)
            for band in bands]
    if any(roi.empty for roi in rois):   # no light reaches a band: whole
        return plugin.render(rt, p, ctx)
    out = rt.image(window, ctx.source.channels)
    name = plugin.descriptor.name
    for band, roi in zip(bands, rois):
        part = plugin.render(rt, p, ctx.tile(roi, band, plan))
        if not part.window.contains(band):
            raise RuntimeError(f"effect {name!r}: a tile's output {part.window} does not "
                               f"cover its band {band}")
        rt.paste(part, out, band)
        del part
        # the band's buffers (sizes no other band may reuse) were freed in pieces glibc keeps:
        # give them back (8K: the process peaked ~1 GB higher than the whole render without)
        rt.finish()
        release_freed_heap()
    for said in (ctx.notes, ctx.warnings):     # a line each band made, said once
        said[:] = list(dict.fromkeys(said))
    return out


def _drop_unread_passes(ctx: RenderContext, steps) -> RenderContext:
    """The context without the device passes no remaining step reads (their memory goes
    back to the pool before the step that could use it)."""
    used = {c.name for _, s in steps for c in s.plugin.descriptor.clips}
    drop = {name: None for name in ("depth", "velocity")
            if name not in used and getattr(ctx, name) is not None}
    if "velocity" not in used and ctx.velocity_back is not None:   # read only beside velocity
        drop["velocity_back"] = None
    return ctx.over(**drop) if drop else ctx


def _advance(rt, ctx: RenderContext, out, moved: dict | None = None) -> RenderContext:
    """The context with a step's output as the current source, and the passes the step
    realigned with it (``moved``, `Plugin.passes_after`); when its window grew, the other
    passes extended to it by edge clamping so later effects see aligned passes."""
    moved = dict(moved or {})
    passes = {}
    if out.window != ctx.source.window:
        passes = {name: rt.reframe(getattr(ctx, name), out.window, "clamp")
                  for name in ("depth", "velocity", "velocity_back")
                  if getattr(ctx, name) is not None and name not in moved}
    return ctx.over(source=out, **passes, **moved)


def _download(rt, ctx: RenderContext):
    """The current source cropped to the output limit, on the host: (rgba, window)."""
    final = ctx.source
    if not ctx.output_limit.contains(final.window):
        final = rt.reframe(final, final.window.intersect(ctx.output_limit))
    return rt.download(final), final.window


def validate_quality(level: str | None, where: str = "--quality") -> str | None:
    if level is not None and level not in QUALITY_LEVELS:
        raise ParamError(f"{where}: {level!r} is not one of {', '.join(QUALITY_LEVELS)}")
    return level

