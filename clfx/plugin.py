"""OpenFX-style plugins: parameter and clip descriptors, the Plugin base class, the registry.

Each effect is one module in ``clfx/plugins/`` and one kernel file in ``kernels/``.  A module
defines a :class:`Plugin` subclass decorated with :func:`register`; the registry discovers
every module in the package, so adding an effect touches nothing else.

The descriptor is pure data (OpenFX ``describe``): identifier, version, label, group,
parameters with default, hard range, hint and units, input clips, and what each quality level
means.  The class answers cheap questions (``is_identity`` with a reason, regions of
definition and interest) and renders on the device.

Spatial sizes are resolution-independent: fractions of the frame diagonal (the display
window's), or physical units through the look's camera block, so a half-size preview looks
like the full-size render.
"""
from __future__ import annotations

import difflib
import hashlib
import importlib
import json
import math
import pkgutil
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from clfx.camera import Camera
from clfx.errors import ClipError, ParamError
from clfx.rect import Rect

QUALITY_LEVELS = ("draft", "preview", "final", "reference")
"""Named quality levels, cheapest first.  Every effect maps each to concrete choices
(sample counts, filters, pyramid vs FFT vs direct, float32 vs float64 accumulation);
``reference`` is the accurate level that others are measured against."""

DEFAULT_QUALITY = "final"


# -- parameters ----------------------------------------------------------------------------
@dataclass(frozen=True)
class Param:
    """Base of every parameter descriptor."""

    name: str
    default: Any
    hint: str = ""
    units: str = ""
    label: str = ""
    kind: ClassVar[str] = "param"

    def validate(self, value, where: str = ""):
        """Return ``value`` coerced to this parameter's type, or raise ParamError."""
        return value

    def parse(self, text: str, where: str = ""):
        """Parse a command-line string (``--set effect.name=text``)."""
        return self.validate(text, where)

    def describe(self) -> dict:
        d = {"name": self.name, "type": self.kind, "default": _jsonable(self.default),
             "hint": self.hint}
        if self.units:
            d["units"] = self.units
        return d

    def _fail(self, where, value, expected):
        raise ParamError(f"{where or self.name}: {value!r} is not {expected}")


def _jsonable(v):
    if isinstance(v, tuple):
        return [_jsonable(x) for x in v]
    if isinstance(v, float) and not math.isfinite(v):
        return str(v)
    return v


def _check_range(param, where, value, lo, hi):
    if not (lo <= value <= hi):
        raise ParamError(f"{where or param.name}: {value!r} is outside the allowed range "
                         f"[{lo:g}, {hi:g}]{' ' + param.units if param.units else ''}")


@dataclass(frozen=True)
class FloatParam(Param):
    min: float = -math.inf
    max: float = math.inf
    display_min: float | None = None
    display_max: float | None = None
    kind: ClassVar[str] = "double"

    def validate(self, value, where=""):
        if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
            self._fail(where, value, "a number")
        value = float(value)
        if math.isnan(value):
            self._fail(where, value, "a number (NaN given)")
        _check_range(self, where, value, self.min, self.max)
        return value

    def parse(self, text, where=""):
        try:
            return self.validate(float(text), where)
        except ValueError:
            self._fail(where, text, "a number")

    def describe(self):
        d = super().describe()
        d.update(min=_jsonable(self.min), max=_jsonable(self.max))
        if self.display_min is not None:
            d["display_range"] = [self.display_min, self.display_max]
        return d


@dataclass(frozen=True)
class IntParam(Param):
    min: int = -(2 ** 31)
    max: int = 2 ** 31 - 1
    kind: ClassVar[str] = "int"

    def validate(self, value, where=""):
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            self._fail(where, value, "an integer")
        value = int(value)
        _check_range(self, where, value, self.min, self.max)
        return value

    def parse(self, text, where=""):
        try:
            return self.validate(int(text), where)
        except ValueError:
            self._fail(where, text, "an integer")

    def describe(self):
        d = super().describe()
        d.update(min=self.min, max=self.max)
        return d


@dataclass(frozen=True)
class BoolParam(Param):
    kind: ClassVar[str] = "bool"

    def validate(self, value, where=""):
        if isinstance(value, (bool, np.bool_)):
            return bool(value)
        self._fail(where, value, "true or false")

    def parse(self, text, where=""):
        t = str(text).strip().lower()
        if t in ("1", "true", "yes", "on"):
            return True
        if t in ("0", "false", "no", "off"):
            return False
        self._fail(where, text, "true or false")


@dataclass(frozen=True)
class ChoiceParam(Param):
    choices: tuple[str, ...] = ()
    kind: ClassVar[str] = "choice"

    def validate(self, value, where=""):
        if isinstance(value, str) and value in self.choices:
            return value
        close = difflib.get_close_matches(str(value), self.choices, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ParamError(f"{where or self.name}: {value!r} is not one of "
                         f"{', '.join(self.choices)}{hint}")

    def describe(self):
        d = super().describe()
        d["choices"] = list(self.choices)
        return d


@dataclass(frozen=True)
class _VectorParam(Param):
    min: float = -math.inf
    max: float = math.inf
    size: ClassVar[int] = 2

    def validate(self, value, where=""):
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            value = (value,) * self.size
        if not isinstance(value, (list, tuple, np.ndarray)) or len(value) != self.size:
            self._fail(where, value, f"a list of {self.size} numbers")
        out = []
        for i, v in enumerate(value):
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) \
                    or math.isnan(float(v)):
                self._fail(where, value, f"a list of {self.size} numbers")
            _check_range(self, f"{where or self.name}[{i}]", float(v), self.min, self.max)
            out.append(float(v))
        return tuple(out)

    def parse(self, text, where=""):
        try:
            parts = [float(t) for t in str(text).replace(" ", "").strip("[]()").split(",")]
        except ValueError:
            self._fail(where, text, f"{self.size} comma-separated numbers")
        return self.validate(parts[0] if len(parts) == 1 else parts, where)

    def describe(self):
        d = super().describe()
        d.update(min=_jsonable(self.min), max=_jsonable(self.max))
        return d


@dataclass(frozen=True)
class RGBParam(_VectorParam):
    min: float = 0.0
    kind: ClassVar[str] = "rgb"
    size: ClassVar[int] = 3


@dataclass(frozen=True)
class Vec2Param(_VectorParam):
    kind: ClassVar[str] = "double2d"
    size: ClassVar[int] = 2


@dataclass(frozen=True)
class StringParam(Param):
    kind: ClassVar[str] = "string"

    def validate(self, value, where=""):
        if not isinstance(value, str):
            self._fail(where, value, "a string")
        return value


class Params:
    """Validated, immutable parameter values with attribute access (``p.strength``)."""

    __slots__ = ("_values", "_plugin")

    def __init__(self, plugin: str, values: dict):
        object.__setattr__(self, "_values", dict(values))
        object.__setattr__(self, "_plugin", plugin)

    def __getattr__(self, name):
        try:
            return self._values[name]
        except KeyError:
            raise AttributeError(f"{self._plugin} has no parameter {name!r}") from None

    def __setattr__(self, name, value):
        raise AttributeError("Params are immutable; use .replace(...)")

    def __eq__(self, other):
        return isinstance(other, Params) and self._values == other._values

    def __hash__(self):
        return hash(self.hash_hex())

    def __repr__(self):
        inner = ", ".join(f"{k}={v!r}" for k, v in self._values.items())
        return f"Params[{self._plugin}]({inner})"

    def as_dict(self) -> dict:
        return dict(self._values)

    def hash_hex(self) -> str:
        blob = json.dumps([self._plugin, self._values], sort_keys=True, default=str)
        return hashlib.sha1(blob.encode()).hexdigest()[:16]


# -- clips and descriptors -----------------------------------------------------------------
@dataclass(frozen=True)
class Clip:
    """An input clip: ``source`` (RGBA), ``depth`` (1 channel), ``velocity`` (2 channels)."""

    name: str
    optional: bool = False
    channels: int = 4
    hint: str = ""


@dataclass(frozen=True)
class Descriptor:
    name: str
    label: str
    group: str
    summary: str
    kernel: str
    params: tuple[Param, ...] = ()
    clips: tuple[Clip, ...] = (Clip("source"),)
    quality: dict = field(default_factory=dict)
    version: tuple[int, int] = (1, 0)
    spreads_light: bool = False
    frame_varying: bool = False

    def param(self, name: str, where: str = "") -> Param:
        for p in self.params:
            if p.name == name:
                return p
        close = difflib.get_close_matches(name, [p.name for p in self.params], n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise ParamError(f"{where or self.name}: unknown parameter {name!r} for effect "
                         f"{self.name!r}{hint}")

    def clip(self, name: str) -> Clip | None:
        return next((c for c in self.clips if c.name == name), None)

    def describe(self) -> dict:
        return {
            "name": self.name, "label": self.label, "group": self.group,
            "version": f"{self.version[0]}.{self.version[1]}", "summary": self.summary,
            "kernel": self.kernel, "spreads_light": self.spreads_light,
            "frame_varying": self.frame_varying,
            "clips": [{"name": c.name, "optional": c.optional, "channels": c.channels,
                       "hint": c.hint} for c in self.clips],
            "params": [p.describe() for p in self.params],
            "quality": {lvl: self.quality.get(lvl, "") for lvl in QUALITY_LEVELS},
        }


# -- render context ------------------------------------------------------------------------
class RenderContext:
    """Everything an effect may read while rendering one frame.

    Attributes
    ----------
    runtime : Runtime
    source : DeviceImage
        The current RGBA image (the previous effect's output), scene-linear.
    depth, velocity : DeviceImage or None
        Passes in clfx's conventions (planar z in scene units; forward px/frame, +y down),
        covering ``source.window`` (the look re-frames them when an effect grows the window).
    display_window : Rect
        The frame's display window; resolution-independent sizes refer to its diagonal.
    pixel_aspect : float
        Pixel width / height.
    frame : int
        Frame number (drives noise; effects are deterministic per frame).
    seed : int
        The look's seed.
    camera : Camera
    quality : str
        One of ``QUALITY_LEVELS``.
    display_referred : bool
        The input was an 8/16-bit display-referred file (linearised on read).
    """

    def __init__(self, runtime, source, *, depth=None, velocity=None, display_window=None,
                 pixel_aspect=1.0, frame=0, seed=0, camera=None, quality=DEFAULT_QUALITY,
                 display_referred=False, analysis=None, output_limit=None):
        self.runtime = runtime
        self.source = source
        self.depth = depth
        self.velocity = velocity
        self.display_window = display_window or source.window
        self.pixel_aspect = float(pixel_aspect)
        self.frame = int(frame)
        self.seed = int(seed)
        self.camera = camera or Camera()
        self.quality = quality
        self.display_referred = display_referred
        self._analysis = analysis
        self.output_limit = output_limit or source.window.union(self.display_window)
        self.notes: list[str] = []

    @property
    def analysis(self):
        """The frame's shared scene analysis of the current source: computed on first use,
        and again only if an effect has since changed the source's window (its tiles are
        always those of ``source.window``)."""
        if self._analysis is None or self._analysis.window != self.source.window:
            from clfx.analysis import analyse

            self._analysis = analyse(self.runtime, self.source, depth=self.depth,
                                     velocity=self.velocity, camera=self.camera,
                                     display_window=self.display_window)
        return self._analysis

    @property
    def diagonal_px(self) -> float:
        return self.display_window.diagonal

    @property
    def width_px(self) -> int:
        return self.display_window.width

    def size_px(self, fraction_of_diagonal: float) -> float:
        """A resolution-independent size (fraction of the frame diagonal) in pixels."""
        return fraction_of_diagonal * self.diagonal_px

    def with_quality(self, quality: str) -> "RenderContext":
        ctx = RenderContext.__new__(RenderContext)
        ctx.__dict__.update(self.__dict__)
        ctx.quality = quality
        return ctx


# -- plugins -------------------------------------------------------------------------------
class Plugin:
    """Base of every effect.  Subclasses set ``descriptor`` and implement ``render``."""

    descriptor: ClassVar[Descriptor]

    @classmethod
    def params(cls, _where: str = "", **values) -> Params:
        """Validated parameters: defaults overridden by ``values``; raises ParamError."""
        d = cls.descriptor
        out = {p.name: p.default for p in d.params}
        for name, value in values.items():
            where = f"{_where or d.name}.{name}"
            out[name] = d.param(name, _where or d.name).validate(value, where)
        return Params(d.name, out)

    # cheap questions ------------------------------------------------------------------
    def is_identity(self, p: Params, ctx: RenderContext) -> str | None:
        """A reason (e.g. "amount is 0") if this frame needs nothing from the effect."""
        return None

    def region_of_definition(self, p: Params, ctx: RenderContext) -> Rect:
        """Where the output can be non-zero: the source window grown by the light spread."""
        return ctx.source.window

    def region_of_interest(self, p: Params, ctx: RenderContext, window: Rect) -> Rect:
        """The input area needed to render ``window``."""
        return window

    def output_window(self, p: Params, ctx: RenderContext) -> Rect:
        """The window to render: the source window, grown to the region of definition as far
        as anything will be kept (``ctx.output_limit``: display and data windows, or more with
        --keep-overscan)."""
        rod = self.region_of_definition(p, ctx).intersect(ctx.output_limit)
        return ctx.source.window.union(rod)

    def render(self, rt, p: Params, ctx: RenderContext):
        """Enqueue the effect; return a DeviceImage (the source itself must not be changed)."""
        raise NotImplementedError

    # conveniences ---------------------------------------------------------------------
    def check_clips(self, ctx: RenderContext) -> None:
        for clip in self.descriptor.clips:
            if clip.name != "source" and not clip.optional and getattr(ctx, clip.name) is None:
                raise ClipError(f"effect {self.descriptor.name!r} needs a {clip.name} pass "
                                f"and the frame has none (see `clfx probe`, --depth/--velocity)")

    def apply(self, rt, p: Params, source: np.ndarray, *, depth=None, velocity=None,
              quality: str = DEFAULT_QUALITY, frame: int = 0, seed: int = 0, camera=None,
              data_window: Rect | None = None, display_window: Rect | None = None,
              pixel_aspect: float = 1.0, display_referred: bool = False,
              keep_rod: bool = False):
        """Run the effect on host arrays: upload, identity check, render, download.

        Returns the output cropped to the source window, or ``(array, window)`` with
        ``keep_rod=True``.  An identity returns a copy of ``source``.
        """
        src = np.asarray(source, np.float32)
        if src.ndim == 2:
            src = np.stack([src, src, src, np.ones_like(src)], axis=2)
        window = data_window or Rect.from_size(src.shape[1], src.shape[0])
        ctx = RenderContext(
            rt, rt.upload(src, window),
            depth=None if depth is None else rt.upload(np.asarray(depth, np.float32), window),
            velocity=None if velocity is None else rt.upload(np.asarray(velocity, np.float32), window),
            display_window=display_window or window, pixel_aspect=pixel_aspect, frame=frame,
            seed=seed, camera=camera, quality=quality, display_referred=display_referred)
        self.check_clips(ctx)
        if self.is_identity(p, ctx):
            out, out_window = src.copy(), window
        else:
            img = self.render(rt, p, ctx)
            out, out_window = rt.download(img), img.window
        if keep_rod:
            return out, out_window
        return crop_to(out, out_window, window)


def crop_to(array: np.ndarray, window: Rect, target: Rect, fill: float = 0.0) -> np.ndarray:
    """``array`` (covering ``window``) cut or padded with ``fill`` to cover ``target``."""
    if window == target:
        return array
    shape = (target.height, target.width) + array.shape[2:]
    out = np.full(shape, fill, array.dtype)
    common = window.intersect(target)
    if not common.empty:
        sx, sy = common.offset_in(window)
        tx, ty = common.offset_in(target)
        out[ty:ty + common.height, tx:tx + common.width] = \
            array[sy:sy + common.height, sx:sx + common.width]
    return out


_REGISTRY: dict[str, type[Plugin]] = {}
_DISCOVERED = False


def register(cls: type[Plugin]) -> type[Plugin]:
    """Class decorator: add a plugin to the registry (checks its descriptor)."""
    d = cls.descriptor
    missing = [lvl for lvl in QUALITY_LEVELS if lvl not in d.quality]
    if missing:
        raise TypeError(f"plugin {d.name} does not say what quality levels {missing} mean")
    names = [p.name for p in d.params]
    if len(set(names)) != len(names):
        raise TypeError(f"plugin {d.name} has duplicate parameter names")
    for p in d.params:
        p.validate(p.default, f"{d.name}.{p.name} (default)")
    _REGISTRY[d.name] = cls
    return cls


def discover() -> dict[str, type[Plugin]]:
    """Import every module of ``clfx.plugins`` once; return the registry."""
    global _DISCOVERED
    if not _DISCOVERED:
        import clfx.plugins as pkg

        for mod in sorted(pkgutil.iter_modules(pkg.__path__), key=lambda m: m.name):
            if not mod.name.startswith("_"):
                importlib.import_module(f"clfx.plugins.{mod.name}")
        _DISCOVERED = True
    return dict(sorted(_REGISTRY.items()))


def get_plugin(name: str, where: str = "") -> type[Plugin]:
    """The plugin class called ``name``; ParamError suggesting the closest name otherwise."""
    reg = discover()
    if name in reg:
        return reg[name]
    close = difflib.get_close_matches(str(name), list(reg), n=1)
    hint = f"; did you mean {close[0]!r}?" if close else f" (known: {', '.join(reg)})"
    raise ParamError(f"{where + ': ' if where else ''}unknown effect {name!r}{hint}")
