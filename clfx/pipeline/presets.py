"""Looks as YAML presets: finding, parsing, inheriting and validating them.

A look file::

    name: cinema
    description: 35 mm, f/2, 180-degree shutter, subtle glare and grain.
    schema: 1
    base: default            # optional: inherit camera, seed and effects from another look
    camera: {focal_length: 35, f_number: 2, focus_distance: 3}
    seed: 0
    effects:
      - effect: dof
        params: {quality_bias: 0}
      - effect: grain
        params: {amount: 0.02}
        quality: preview     # optional per-effect override
        enabled: true        # optional; false removes an inherited effect
        missing_passes: skip # optional: skip (with a reason) on frames lacking the depth or
                             # velocity pass this effect needs; default "error"
      - effect: halation
        before: grain        # optional: where the step goes (or after: STEP)

Inheritance: the base's camera is updated key by key; a step the base already has (same
``id``, which defaults to the effect's name) is updated in place (its params merged), a new
one is appended, ``enabled: false`` drops it.  ``before: STEP`` / ``after: STEP`` place a
new step, or move an inherited one, next to another step of the look so far (named by its
``id``, or by its effect when one step has it; a name that is missing or that several steps
answer to is an error naming the key and line).  Give steps distinct ``id``s to use one
effect twice (e.g. star streaks and aperture spikes); ``--set ID.param=value`` addresses a
step.  ``clfx look show`` marks each step as the look's own or inherited (and from where).

Search order for a name: a path to a file; each folder on ``CLFX_PRESET_PATH`` (os.pathsep
separated); the user folder ``<config>/clfx/looks`` (XDG, ``click.get_app_dir``); the built-in
``presets/`` shipped with clfx.  Every problem is reported before any frame is read, as one
line naming the file, the line and the key, with the closest valid name where one exists.
A look file is at most 1 MiB of UTF-8; YAML aliases, duplicate keys, nesting deeper than 32
levels, integers of more than 20 digits and chains of more than 16 ``base:`` looks are
refused the same way.
"""
from __future__ import annotations

import difflib
from dataclasses import replace
from pathlib import Path

from clfx.core.camera import Camera
from clfx.core.errors import ClfxError, ParamError, PresetError
from clfx.core.plugin import QUALITY_LEVELS, BoolParam, Params, StringParam
from clfx.io import lenses as lens_io
from clfx.io.lenses import available_lenses, find_lens, lens_dirs, read_lens  # noqa: F401 (re-exported)
from clfx.io.presetfiles import (MAX_INT_DIGITS, MAX_LOOK_BYTES, MAX_NESTING,  # noqa: F401
                                 Located as _Located, builtin_dir, find_file, search_dirs,
                                 suggest as _suggest, user_dir, yaml_files)
from clfx.pipeline import animation
from clfx.pipeline.animation import is_keyframed
from clfx.pipeline.look import MISSING_PASSES, Look, Step, validate_quality
from clfx.pipeline.masks import parse_mask
from clfx.plugins import get_plugin

SCHEMA = 1
TOP_KEYS = ("name", "description", "schema", "base", "camera", "seed", "effects")
STEP_KEYS = ("effect", "id", "params", "quality", "enabled", "version", "missing_passes",
             "mask", "before", "after")
ANIMATABLE = ("double", "int", "rgb", "double2d")
"""Parameter kinds that may be keyframed (numbers and vectors of numbers)."""
DEFAULT_LOOK = "default"
MAX_BASE_DEPTH = 16
"""Longest chain of ``base:`` looks."""


def available_looks() -> dict[str, tuple[str, Path]]:
    """Look name -> (origin, path); earlier search folders win."""
    return yaml_files(search_dirs())


def find_look(name_or_path: str) -> Path:
    return find_file(name_or_path, "look", lambda: {k: v[1] for k, v in available_looks().items()},
                     _look_hint)


def _look_hint(name: str, looks: list) -> str:
    close = difflib.get_close_matches(name, looks, n=1)
    return f"; did you mean {close[0]!r}?" if close else f" (known: {', '.join(looks)})"


class _BaseChainTooLong(PresetError):
    """Reported once, as raised at the bottom of the chain (not wrapped at every level)."""


def load_look(name_or_path: str, _chain: tuple = ()) -> Look:
    """Find, parse, inherit and validate a look; raise PresetError naming file and line."""
    path = find_look(name_or_path)
    key = str(path.resolve())
    if key in _chain:
        raise PresetError(f"{path}: base looks form a cycle: {' -> '.join(_chain + (key,))}")
    if len(_chain) >= MAX_BASE_DEPTH:
        raise _BaseChainTooLong(f"{_chain[0]}: base looks nest more than {MAX_BASE_DEPTH} deep "
                                f"(reached {path})")
    return _build(_Located(path), path.stem, str(path), _chain + (key,))


def look_from_dict(data: dict, *, where: str = "look") -> Look:
    """A look from data shaped like a look file (``name``, ``camera``, ``effects``, ...;
    ``base`` names a look to inherit), validated like one; PresetError naming ``where`` and
    the key.  Reads back :meth:`Look.document` (an output's ``clfx:lookJSON``)."""
    return _build(_Located.from_data(data, where), "look", "", ())


def _build(doc: _Located, default_name: str, source: str, chain: tuple) -> Look:
    data = doc.data
    if not isinstance(data, dict):
        doc.fail((), "a look file must be a mapping with name, description and effects")
    for k in data:
        if k not in TOP_KEYS:
            doc.fail((k,), f"unknown key{_suggest(k, TOP_KEYS)}")
    if data.get("schema", SCHEMA) != SCHEMA:
        doc.fail(("schema",), f"unsupported schema {data.get('schema')!r} (this clfx reads {SCHEMA})")
    base = None
    if data.get("base"):
        try:
            base = load_look(str(data["base"]), chain)
        except _BaseChainTooLong:
            raise
        except PresetError as exc:
            doc.fail(("base",), str(exc))
    look = Look(name=str(data.get("name") or default_name),
                description=str(data.get("description") or ""),
                source=source, base=str(data["base"]) if data.get("base") else None,
                files=((source,) if source else ()) + (base.files if base else ()))
    if base:
        look.camera, look.seed = base.camera, base.seed
        look.camera_animated = base.camera_animated
        look.steps = list(base.steps)  # steps are frozen: shared, replaced when updated
        look.description = look.description or base.description
    look.camera, look.camera_animated = _camera(doc, data.get("camera"), look.camera,
                                                look.camera_animated)
    if "seed" in data:
        if isinstance(data["seed"], bool) or not isinstance(data["seed"], int):
            doc.fail(("seed",), f"{data['seed']!r} is not an integer")
        look.seed = data["seed"]
    look.steps = _steps(doc, data.get("effects"), look.steps, look.name, base is not None)
    if len(chain) <= 1:     # the look itself, not a base: its lenses, read and validated now
        try:
            look.lenses = lens_io.resolve(look.steps)
        except PresetError as exc:
            raise PresetError(f"{doc.path}: {exc}") from None
    return look


def _camera(doc: _Located, block, camera: Camera, animated=()):
    """The camera block applied to ``camera``: (camera, keyframed values).  A keyframed value
    is checked at every key; the camera holds its first key's value."""
    if block is None:
        return camera, animated
    if not isinstance(block, dict):
        doc.fail(("camera",), "must be a mapping of camera values")
    names = Camera.field_names()
    values = {}
    keyed = dict(animated)
    for k, v in block.items():
        if k not in names:
            doc.fail(("camera", k), f"unknown camera value{_suggest(k, names)}")
        try:
            _not_cli_keyframes(v)
            if is_keyframed(v):
                if k in Camera.CHOICES:
                    raise ValueError(f"camera.{k} is not numeric; it cannot be keyframed")
                keyed[k] = animation.parse(v, lambda x, w, k=k: _camera_value(k, x, w),
                                           f"camera.{k}", integer=k in Camera.INTEGERS)
                values[k] = keyed[k].keys[0][1]
            else:
                keyed.pop(k, None)
                values[k] = Camera.validate(k, v)
        except (TypeError, ValueError) as exc:
            doc.fail(("camera", k), str(exc))
    try:
        return camera.updated(**values), tuple(keyed.items())
    except (TypeError, ValueError) as exc:
        doc.fail(("camera",), str(exc))


def _not_cli_keyframes(value) -> None:
    """Refuse the command line's keyframe form (``1:2.5,10:4``) in a look file, where YAML
    reads it as text (YAML 1.1 read ``1:2.5`` as the base-60 number 62.5)."""
    if isinstance(value, str) and animation.looks_keyframed(value):
        keys = ", ".join(": ".join(part.strip() for part in item.split(":", 1))
                         for item in value.split(",") if ":" in item)
        raise ValueError(f"{value!r} is not a number; keyframes in a look file are a "
                         f"mapping: {{{keys}}}")


def _camera_value(name: str, value, where: str):
    try:
        return Camera.validate(name, value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None


def _step_params(cls, name: str, merged: dict, fail) -> tuple[Params, tuple]:
    """Validated params and keyframed ones of a step; ``fail(pname, message)`` raises."""
    validated, keyed = {}, {}
    for pname, value in merged.items():
        try:
            param = cls.descriptor.param(pname, name)
            if param.kind in ANIMATABLE:
                _not_cli_keyframes(value)
            if is_keyframed(value):
                if param.kind not in ANIMATABLE:
                    raise ParamError(f"{name}.{pname} is a {param.kind} parameter; only "
                                     "numbers can be keyframed")
                keyed[pname] = animation.parse(value, param.validate, f"{name}.{pname}",
                                               integer=param.kind == "int")
                validated[pname] = keyed[pname].keys[0][1]
            else:
                validated[pname] = param.validate(value, f"{name}.{pname}")
        except (ClfxError, ValueError) as exc:
            fail(pname, str(exc))
    return cls.params(**validated), tuple(keyed.items())


def _place(doc: _Located, at: tuple, entry: dict, steps: list[Step], step: Step) -> list[Step]:
    """``steps`` with ``step`` placed as the entry's ``before:`` / ``after:`` says (moved, if
    it is there already)."""
    keys = [k for k in ("before", "after") if k in entry]
    if len(keys) > 1:
        doc.fail(at + ("after",), "give before: or after:, not both")
    key = keys[0]
    name = entry[key]
    rest = [s for s in steps if s.id != step.id]
    target = [s for s in rest if s.id == name] or [s for s in rest if s.effect == name]
    if not isinstance(name, str) or not target:
        known = ", ".join(s.id for s in rest) or "none"
        doc.fail(at + (key,), f"no step {name!r} in the look to place {step.id!r} {key} "
                 f"(steps: {known})")
    if len(target) > 1:
        doc.fail(at + (key,), f"{name!r} is ambiguous: steps {', '.join(s.id for s in target)} "
                 f"are {name!r} effects; name one by its id")
    i = rest.index(target[0]) + (key == "after")
    return rest[:i] + [step] + rest[i:]


def _steps(doc: _Located, effects, inherited: list[Step], origin: str = "",
           has_base: bool = False) -> list[Step]:
    """The look's steps: ``inherited`` (its base's) with ``effects`` (its file's entries)
    applied; steps it adds or changes are marked with ``origin`` (its name)."""
    steps = list(inherited)
    if effects is None:
        return steps
    if not isinstance(effects, list):
        doc.fail(("effects",), "must be a list of {effect: NAME, params: {...}} entries")
    for i, entry in enumerate(effects):
        at = ("effects", i)
        if not isinstance(entry, dict) or "effect" not in entry:
            doc.fail(at, "each entry needs an 'effect' key naming the effect")
        for k in entry:
            if k not in STEP_KEYS:
                doc.fail(at + (k,), f"unknown key{_suggest(k, STEP_KEYS)}")
        name = entry["effect"]
        try:
            cls = get_plugin(str(name))
        except ClfxError as exc:
            doc.fail(at + ("effect",), str(exc))
        if "version" in entry:
            major = str(entry["version"]).split(".")[0]
            if not (major.isascii() and major.isdigit()):
                doc.fail(at + ("version",), f"{entry['version']!r} is not a version (e.g. 1 or 1.2)")
            if int(major) != cls.descriptor.version[0]:
                doc.fail(at + ("version",), f"look pins major version {entry['version']} of "
                         f"{name!r}; this clfx has {cls.descriptor.version[0]}")
        params = entry.get("params") or {}
        if not isinstance(params, dict):
            doc.fail(at + ("params",), "must be a mapping of parameter names to values")
        when_missing = entry.get("missing_passes", "error")
        if when_missing not in MISSING_PASSES:
            doc.fail(at + ("missing_passes",), f"{when_missing!r} is not 'error' or 'skip'")
        quality = entry.get("quality")
        if quality is not None and quality not in QUALITY_LEVELS:
            doc.fail(at + ("quality",), f"{quality!r} is not a quality level{_suggest(quality, QUALITY_LEVELS)}")
        sid = entry.get("id", name)
        if not isinstance(sid, str) or not sid.replace("_", "").replace("-", "").isalnum():
            doc.fail(at + ("id",), f"{sid!r} is not a name (letters, digits, - and _)")
        existing = next((s for s in steps if s.id == sid), None)
        if existing is not None and existing.effect != name:
            doc.fail(at + ("effect",), f"step id {sid!r} already names a {existing.effect!r} step")
        if entry.get("enabled", True) is False:
            if existing is None and has_base:
                doc.fail(at + ("enabled",), f"enabled: false drops nothing: the base look has "
                         f"no step {sid!r} (steps: {', '.join(s.id for s in steps) or 'none'})")
            steps = [s for s in steps if s is not existing]
            continue
        merged = {**(existing.param_values() if existing else {}), **params}
        p, keyed = _step_params(cls, name, merged,
                                lambda pname, msg: doc.fail(at + ("params", pname), msg))
        if "missing_passes" not in entry and existing:
            when_missing = existing.missing_passes
        mask = existing.mask if existing else None
        if "mask" in entry:
            try:
                mask = None if entry["mask"] is None else parse_mask(entry["mask"], "mask")
            except ValueError as exc:
                doc.fail(at + ("mask",), str(exc))
        step = Step(name, p, quality or (existing.quality if existing else None), id=sid,
                    missing_passes=when_missing, mask=mask, animated=keyed,
                    origin=existing.origin if existing else origin,
                    changed_in=existing.changed_in + (origin,) if existing else ())
        if existing:
            steps[steps.index(existing)] = step
        else:
            steps.append(step)
        if "before" in entry or "after" in entry:
            steps = _place(doc, at, entry, steps, step)
    return steps


STEP_SETTINGS = ("quality", "enabled", "missing_passes")
"""What ``--set STEP.KEY=VALUE`` may set on a step besides its parameters."""


def apply_overrides(look: Look, assignments: list[str]) -> Look:
    """Apply ``--set`` assignments (CLI strings) to ``look`` (changed in place, returned):

    - ``effect.param=value``; ``effect.param=F:V,F:V`` keyframes it (``smooth:F:V,...``
      eases), see `clfx.pipeline.animation`;
    - ``effect.quality=LEVEL``, ``effect.enabled=false`` (drop the step),
      ``effect.missing_passes=skip`` (skip it on frames without its pass);
    - ``camera.key=value`` (keyframes too) and ``seed=N``.

    ``effect`` is a step's id, or its effect's name.
    """
    for text in assignments:
        if "=" not in text:
            raise PresetError(f"--set {text!r}: expected KEY=VALUE, e.g. glare.strength=0.2")
        key, value = text.split("=", 1)
        key = key.strip()
        if key == "seed":
            _ascii_digits(key, value)
            try:
                look.seed = int(value)
            except ValueError:
                raise PresetError(f"--set seed={value!r}: not an integer") from None
            continue
        if "." not in key:
            raise PresetError(f"--set {text!r}: expected EFFECT.PARAM=VALUE or camera.KEY=VALUE")
        target, pname = key.split(".", 1)
        if target == "camera":
            _ascii_digits(key, value)
            look.camera, look.camera_animated = _camera_override(look, pname, value)
            continue
        step = next((s for s in look.steps if s.id == target), None) or \
            next((s for s in look.steps if s.effect == target), None)
        if step is None:
            names = [s.id for s in look.steps]
            raise PresetError(f"--set {text!r}: look {look.name!r} has no effect {target!r}"
                              f"{_suggest(target, names) if names else ''}")
        look.steps[look.steps.index(step)] = _step_override(step, key, pname, value)
    if assignments:
        # a lens named by --set: read and checked now (those read at load are kept)
        look.lenses = lens_io.resolve(look.steps, known=look.lenses)
    return look


def _step_override(step: Step, key: str, pname: str, value: str) -> Step:
    where = f"--set {key}"
    if pname == "quality":
        return replace(step, quality=validate_quality(value, where))
    if pname == "enabled":
        return replace(step, enabled=BoolParam("enabled", True).parse(value, where))
    if pname == "missing_passes":
        if value not in MISSING_PASSES:
            raise PresetError(f"{where}={value!r}: expected {' or '.join(MISSING_PASSES)}")
        return replace(step, missing_passes=value)
    try:
        param = step.plugin.descriptor.param(pname, where)
    except ParamError as exc:
        raise ParamError(f"{exc} (a step also takes {', '.join(STEP_SETTINGS)})") from None
    if not isinstance(param, StringParam):
        _ascii_digits(key, value)
    keyed = dict(step.animated)
    if param.kind in ANIMATABLE and animation.looks_keyframed(value):
        if param.kind in ("rgb", "double2d"):
            raise PresetError(f"{where}: keyframe vector parameters in a look file "
                              f"({pname}: {{1001: [..], 1040: [..]}})")
        try:
            keyed[pname] = animation.parse_cli(value, param.parse, where,
                                               integer=param.kind == "int")
        except ValueError as exc:
            raise PresetError(str(exc)) from None
        parsed = keyed[pname].keys[0][1]
    else:
        keyed.pop(pname, None)
        parsed = param.parse(value, where)
    return replace(step, params=step.plugin.params(**{**step.params.as_dict(), pname: parsed}),
                   animated=tuple(keyed.items()))


def _ascii_digits(key: str, value: str) -> None:
    """Numbers on the command line are written with 0-9: Python's int() and float() would
    also read full-width or other scripts' digits ('３' as 3), which no look file means."""
    bad = next((c for c in value if c.isdecimal() and not c.isascii()), None)
    if bad is not None:
        raise PresetError(f"--set {key}={value!r}: {bad!r} is not an ASCII digit (write numbers "
                          f"with 0-9)")


def _camera_override(look: Look, name: str, value: str):
    """``--set camera.NAME=value`` (or keyframes): (camera, keyframed camera values)."""
    if name not in Camera.field_names():
        raise PresetError(f"--set camera.{name}: unknown camera value{_suggest(name, Camera.field_names())}")
    keyed = dict(look.camera_animated)
    if name not in Camera.CHOICES and animation.looks_keyframed(value):
        try:
            keyed[name] = animation.parse_cli(
                value, lambda text, w: _camera_value(name, _number(name, text), w),
                f"--set camera.{name}", integer=name in Camera.INTEGERS)
        except ValueError as exc:
            raise PresetError(str(exc)) from None
        return look.camera.updated(**{name: keyed[name].keys[0][1]}), tuple(keyed.items())
    keyed.pop(name, None)
    if name not in Camera.CHOICES:
        value = _number(name, value)
    try:
        return look.camera.updated(**{name: Camera.validate(name, value)}), tuple(keyed.items())
    except (TypeError, ValueError) as exc:
        raise PresetError(f"--set camera.{name}: {exc}") from None


def _number(name: str, text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise PresetError(f"--set camera.{name}: {text!r} is not a number") from None


def single_effect_look(effect: str, assignments: list[str]) -> Look:
    """A one-step look for ``clfx apply EFFECT ... param=value``."""
    cls = get_plugin(effect)
    look = Look(name=f"apply:{effect}", steps=[Step(effect, cls.params())])
    return apply_overrides(look, [f"{effect}.{a}" if not a.startswith(("camera.", "seed=")) else a
                                  for a in assignments])
