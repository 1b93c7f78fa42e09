"""OpenFX-style descriptors: parameters, clips, quality levels (pure data; the host side,
render context and base class, is ``clfx.host``).

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
import json
import math
from dataclasses import dataclass, field, fields
from types import MappingProxyType
from typing import Any, ClassVar, Mapping

import numpy as np

from clfx.core.errors import ParamError

QUALITY_LEVELS = ("draft", "preview", "final", "reference")
"""Named quality levels, cheapest first.  Every effect maps each to concrete choices
(sample counts, filters, pyramid vs FFT vs direct, float32 vs float64 accumulation);
``reference`` is the accurate level that others are measured against."""

DEFAULT_QUALITY = "final"


@dataclass(frozen=True)
class Level:
    """What one quality level of one effect means, declared once as data.

    ``summary`` is the sentence ``clfx describe`` prints; ``fp64`` asks for float64
    accumulation (``Runtime.kernel(..., fp64=level.fp64)`` builds the program with
    ``CLFX_FP64=1`` where the device has ``cl_khr_fp64``; kernels read it through
    ``kernels/lib/precision.h``).  Effects subclass it (frozen dataclasses) to add their own
    typed settings: sample counts, taps, resolutions; ``describe`` prints every field.
    """

    summary: str
    fp64: bool = False

    def settings(self) -> dict:
        """Every field but the summary, for ``clfx describe``."""
        return {f.name: _jsonable(getattr(self, f.name)) for f in fields(self)
                if f.name != "summary"}


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
    auto: str = ""
    """What the value ``"auto"`` means, for a param that has one (e.g. a metered middle
    grey): ``"auto"`` is stored as 0.0, which the effect reads as auto (so a look file's
    0 means the same); ``describe`` names it."""
    kind: ClassVar[str] = "double"

    def validate(self, value, where=""):
        if self.auto and isinstance(value, str) and value.strip().lower() == "auto":
            return 0.0
        if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
            self._fail(where, value, "a number or 'auto'" if self.auto else "a number")
        value = float(value)
        if math.isnan(value):
            self._fail(where, value, "a number (NaN given)")
        _check_range(self, where, value, self.min, self.max)
        return value

    def parse(self, text, where=""):
        if self.auto and str(text).strip().lower() == "auto":
            return 0.0
        try:
            return self.validate(float(text), where)
        except ValueError:
            self._fail(where, text, "a number or 'auto'" if self.auto else "a number")

    def describe(self):
        d = super().describe()
        d.update(min=_jsonable(self.min), max=_jsonable(self.max))
        if self.auto:
            d["auto"] = self.auto
            if self.default == 0.0:
                d["default"] = "auto"
        if self.display_min is not None:
            d["display_range"] = [self.display_min, self.display_max]
        return d


@dataclass(frozen=True)
class IntParam(Param):
    min: int = -(2 ** 31)
    max: int = 2 ** 31 - 1
    exclude: tuple[int, ...] = ()
    """Values inside the range that mean nothing (``blades`` 1 and 2: no polygon), refused."""
    exclude_why: str = ""
    kind: ClassVar[str] = "int"

    def validate(self, value, where=""):
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            self._fail(where, value, "an integer")
        value = int(value)
        _check_range(self, where, value, self.min, self.max)
        if value in self.exclude:
            raise ParamError(f"{where or self.name}: {value!r} is not allowed ({self.exclude_why})")
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


@dataclass(frozen=True)
class PathParam(StringParam):
    """A file the effect reads (a kernel image, a mask): an input of the render like the
    frames themselves, so the pipeline protects it from being overwritten, requires a regular
    file, and hands its pixels to the effect through ``ctx.read_image``; "" means none."""

    kind: ClassVar[str] = "path"


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
        raise AttributeError(f"{self._plugin} params are immutable: make new ones with the "
                             f"effect's params(**values), e.g. clfx.plugins.discover()"
                             f"[{self._plugin!r}].params({name}=...), which validates them")

    def __eq__(self, other):
        return isinstance(other, Params) and self._values == other._values

    def __hash__(self):
        return hash(self.hash_hex())

    def __repr__(self):
        inner = ", ".join(f"{k}={v!r}" for k, v in self._values.items())
        return f"Params[{self._plugin}]({inner})"

    def __reduce__(self):  # pickle by value (looks travel to distributed workers)
        return (Params, (self._plugin, self._values))

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
    quality: Mapping[str, Level] = field(default_factory=dict)
    version: tuple[int, int] = (1, 0)
    spreads_light: bool = False
    frame_varying: bool = False

    def __post_init__(self):
        bad = [k for k, v in self.quality.items() if not isinstance(v, Level)]
        if bad:
            raise TypeError(f"effect {self.name}: quality levels {bad} must be Level data "
                            f"(clfx.core.plugin.Level or a subclass), declared once")
        object.__setattr__(self, "quality", MappingProxyType(dict(self.quality)))

    def level(self, quality: str) -> Level:
        """The declared meaning of ``quality`` (one of ``QUALITY_LEVELS``)."""
        return self.quality[quality]

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
            "quality": {lvl: self.quality[lvl].summary for lvl in QUALITY_LEVELS
                        if lvl in self.quality},
            "quality_settings": {lvl: self.quality[lvl].settings() for lvl in QUALITY_LEVELS
                                 if lvl in self.quality},
        }
