"""Keyframed (animated) parameter and camera values.

Any numeric effect parameter (float, int, RGB, 2-D vector) or numeric camera value of a look
may be keyframed by frame number instead of given one value::

    camera:
      focus_distance: {1001: 2.0, 1040: 5.5}          # linear between the keys
    effects:
      - effect: dof
        params:
          max_coc: {interp: smooth, keys: {1001: 0.02, 1040: 0.05}}   # ease in and out

- Keys are whole frame numbers; values are validated against the parameter's hard range at
  every key (a typo at frame 1040 is an error before any frame is read).
- ``linear`` interpolates straight between neighbouring keys; ``smooth`` eases in and out of
  every key (smoothstep ``3t^2 - 2t^3`` between neighbours: zero slope at each key, no
  overshoot).  Both stay between the neighbouring keys' values.
- Before the first key the first value holds; after the last, the last (held outside).
- Integer values (``blades``, sample counts) are rounded to the nearest whole number;
  vectors and colours are interpolated per component.  The whole numbers an integer value
  passes through between keys are checked too (``blades`` keyed 0 then 6 would pass 1 and
  2, which no blade count allows): one that is refused is an error naming its frame.
- On the command line: ``--set camera.focus_distance=1001:2.0,1040:5.5`` (linear) or
  ``--set camera.focus_distance=smooth:1001:2.0,1040:5.5``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

INTERPOLATIONS = ("linear", "smooth")
MAX_KEYS = 10_000
MAX_FRAMES_CHECKED = 100_000
"""Integer values between keys further apart than this are checked value by value (every
whole number between the keys' values), not frame by frame."""
"""More keys than frames in any shot: a look that needs more is a baked curve, not a look."""


@dataclass(frozen=True)
class Animated:
    """A keyframed value: ``keys`` sorted by frame, each ``(frame, value)``; ``value`` is a
    float, an int (``integer``) or a tuple of floats (vectors, colours)."""

    keys: tuple[tuple[int, Any], ...]
    interp: str = "linear"
    integer: bool = False

    def at(self, frame: float):
        """The value at ``frame`` (held before the first key and after the last)."""
        keys = self.keys
        if frame <= keys[0][0]:
            return keys[0][1]
        if frame >= keys[-1][0]:
            return keys[-1][1]
        for (f0, v0), (f1, v1) in zip(keys, keys[1:]):
            if f0 <= frame <= f1:
                t = (frame - f0) / (f1 - f0)
                if self.interp == "smooth":
                    t = t * t * (3.0 - 2.0 * t)
                return self._lerp(v0, v1, t)
        return keys[-1][1]  # pragma: no cover (keys are sorted)

    def _lerp(self, a, b, t: float):
        if isinstance(a, tuple):
            return tuple(x + (y - x) * t for x, y in zip(a, b))
        v = a + (b - a) * t
        return int(math.floor(v + 0.5)) if self.integer else float(v)

    def describe(self):
        """The JSON/YAML form: ``{frame: value}`` (linear) or ``{interp, keys}``."""
        keys = {int(f): list(v) if isinstance(v, tuple) else v for f, v in self.keys}
        return keys if self.interp == "linear" else {"interp": self.interp, "keys": keys}


def is_keyframed(value) -> bool:
    """Whether a look's value is a keyframe mapping rather than one value."""
    return isinstance(value, dict)


def _frame(key, where: str) -> int:
    if isinstance(key, bool):
        raise ValueError(f"{where}: keyframe {key!r} is not a frame number")
    if isinstance(key, int):
        return key
    if isinstance(key, float) and key.is_integer():
        return int(key)
    if isinstance(key, str):
        text = key.strip()
        body = text[1:] if text[:1] in "+-" else text
        if body.isascii() and body.isdigit():
            return int(text)
    raise ValueError(f"{where}: keyframe {key!r} is not a whole frame number")


def parse(value: dict, validate: Callable[[Any, str], Any], where: str, *,
          integer: bool = False) -> Animated:
    """An :class:`Animated` from a look's mapping (``{frame: value}`` or
    ``{interp: linear|smooth, keys: {frame: value}}``), each value checked by
    ``validate(value, where)`` (the parameter's own validation, range included).

    Raises
    ------
    ValueError
        Not a keyframe mapping, no keys, a key that is not a whole frame number, an unknown
        interpolation (the parameter's own errors pass through as raised by ``validate``).
    """
    if not isinstance(value, dict):
        raise ValueError(f"{where}: {value!r} is not a keyframe mapping")
    interp = "linear"
    keys = value
    if "keys" in value or "interp" in value:
        extra = set(value) - {"keys", "interp"}
        if extra:
            raise ValueError(f"{where}: unknown key {sorted(extra, key=str)[0]!r} in an animated "
                             "value (expected interp and keys)")
        interp = value.get("interp", "linear")
        if interp not in INTERPOLATIONS:
            raise ValueError(f"{where}: interpolation {interp!r} is not one of "
                             f"{', '.join(INTERPOLATIONS)}")
        keys = value.get("keys")
        if not isinstance(keys, dict):
            raise ValueError(f"{where}: keys must be a mapping of frame numbers to values")
    if not keys:
        raise ValueError(f"{where}: an animated value needs at least one keyframe")
    if len(keys) > MAX_KEYS:
        raise ValueError(f"{where}: {len(keys)} keyframes; the limit is {MAX_KEYS}")
    parsed: dict[int, Any] = {}
    for k, v in keys.items():
        frame = _frame(k, where)
        if frame in parsed:
            raise ValueError(f"{where}: frame {frame} is keyed twice")
        if isinstance(v, (dict, bool, str)) or v is None:
            raise ValueError(f"{where} at frame {frame}: {v!r} is not a number")
        parsed[frame] = validate(v, f"{where} at frame {frame}")
    return _checked(Animated(tuple(sorted(parsed.items())), interp, integer), validate, where)


def parse_cli(text: str, parse_value: Callable[[str, str], Any], where: str, *,
              integer: bool = False) -> Animated:
    """``[linear:|smooth:]F:V,F:V,...`` (``--set``) as an :class:`Animated`; each value parsed
    by ``parse_value(text, where)`` (the parameter's own parser and range check)."""
    body = text.strip()
    interp = "linear"
    for name in INTERPOLATIONS:
        if body.startswith(name + ":"):
            interp, body = name, body[len(name) + 1:]
    keys: dict[int, Any] = {}
    for item in body.split(","):
        if ":" not in item:
            raise ValueError(f"{where}={text!r}: keyframe {item!r} is not FRAME:VALUE")
        f, v = item.split(":", 1)
        frame = _frame(f, f"{where}={text!r}")
        if frame in keys:
            raise ValueError(f"{where}={text!r}: frame {frame} is keyed twice")
        keys[frame] = parse_value(v.strip(), f"{where} at frame {frame}")
    return _checked(Animated(tuple(sorted(keys.items())), interp, integer),
                    lambda v, w: parse_value(str(v), w), where)


def _checked(anim: Animated, check: Callable[[Any, str], Any], where: str) -> Animated:
    """``anim``, once every whole number an integer value reaches between its keys has
    passed ``check(value, where)`` (the parameter's own validation)."""
    if not anim.integer:
        return anim
    for (f0, v0), (f1, v1) in zip(anim.keys, anim.keys[1:]):
        if abs(v1 - v0) < 2:
            continue
        between = f"between the keys at frames {f0} and {f1}"
        if f1 - f0 <= MAX_FRAMES_CHECKED:
            reached: dict[int, int] = {}
            for frame in range(f0 + 1, f1):
                reached.setdefault(anim.at(frame), frame)
            for value, frame in reached.items():
                check(value, f"{where} at frame {frame} ({between})")
        else:
            for value in range(min(v0, v1) + 1, max(v0, v1)):
                check(value, f"{where} {between}")
    return anim


def looks_keyframed(text: str) -> bool:
    """Whether a ``--set`` value is written as keyframes (``F:V,...``, optionally prefixed)."""
    body = text.strip()
    for name in INTERPOLATIONS:
        if body.startswith(name + ":"):
            return True
    head = body.split(":", 1)[0].strip()
    head = head[1:] if head[:1] in "+-" else head
    return ":" in body and head.isascii() and head.isdigit()
