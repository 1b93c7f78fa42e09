"""Preset files: the folders clfx's YAML lives in (looks, lens prescriptions) and the policy
every such file is read with (a regular UTF-8 file of at most 1 MiB; no aliases, duplicate
keys, deep nesting or huge integers), with the line of every key for one-line errors.

`clfx.pipeline.presets` builds looks from these documents; `clfx.io.lenses` reads lens
prescriptions with them.
"""
from __future__ import annotations

import difflib
import os
import re
import stat
from pathlib import Path

import yaml

from clfx.core.errors import PresetError

MAX_LOOK_BYTES = 1 << 20
"""A look file is a page of YAML; anything bigger is refused before it is parsed."""
MAX_NESTING = 32
"""Deepest nesting of YAML mappings and lists a look may use (a look needs 4)."""
MAX_INT_DIGITS = 20
"""Most digits of an integer in a look (a 64-bit seed has 20)."""

def builtin_dir() -> Path:
    """The built-in looks: ``clfx/presets`` in a wheel, or the repository's ``presets/``
    (``clfx/presets`` links to it in a checkout, resolved: one spelling of the path)."""
    here = Path(__file__).resolve().parent.parent  # the clfx package
    for path in (here / "presets", here.parent / "presets"):
        if path.is_dir() and any(path.glob("*.yaml")):
            return path.resolve()
    return here.parent / "presets"


def user_dir() -> Path:
    import click   # lazy: 25 ms, for its app-dir rule only: API users do not load click

    return Path(click.get_app_dir("clfx")) / "looks"


def search_dirs() -> list[tuple[str, Path]]:
    dirs = [("CLFX_PRESET_PATH", Path(p)) for p in
            os.environ.get("CLFX_PRESET_PATH", "").split(os.pathsep) if p]
    dirs.append(("user", user_dir()))
    dirs.append(("built-in", builtin_dir()))
    return dirs


class Refused(yaml.YAMLError):
    """YAML a look may not use (aliases, duplicate keys, deep nesting), at a mark."""

    def __init__(self, problem: str, mark):
        super().__init__(problem)
        self.problem, self.problem_mark = problem, mark


class LookLoader(yaml.SafeLoader):
    """SafeLoader refusing what a look never needs: aliases (an alias bomb expands without
    bound), duplicate keys (YAML would keep the last one silently) and nesting deeper than
    ``MAX_NESTING`` (the composer recurses once per level)."""

    def __init__(self, stream):
        super().__init__(stream)
        self._depth = 0

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise Refused(f"YAML aliases (*{event.anchor}) are not allowed in a look",
                           event.start_mark)
        if self._depth >= MAX_NESTING:
            raise Refused(f"nested deeper than {MAX_NESTING} levels", self.peek_event().start_mark)
        self._depth += 1
        try:
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_yaml_int(self, node):
        digits = sum(c.isalnum() for c in str(node.value))
        if digits > MAX_INT_DIGITS:      # Python refuses > 4300 digits with a ValueError
            raise Refused(f"an integer of {digits} digits (a look needs at most "
                           f"{MAX_INT_DIGITS})", node.start_mark)
        text = str(self.construct_scalar(node))
        sign, body = (-1, text[1:]) if text[:1] == "-" else (1, text.lstrip("+"))
        base = {"0o": 8, "0x": 16}.get(body[:2], 10)
        try:                                        # YAML 1.2: 0777 is 777, not octal
            return sign * int(body[2:] if base != 10 else body, base)
        except ValueError:                          # an explicit !!int on text
            raise Refused(f"{text!r} is not an integer", node.start_mark) from None

    def construct_mapping(self, node, deep=False):
        if isinstance(node, yaml.MappingNode):
            first: dict = {}
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue
                key = self.construct_object(key_node, deep=True)
                try:
                    seen = first.setdefault(key, key_node)
                except TypeError:  # an unhashable key: the base class reports it
                    continue
                if seen is not key_node:
                    raise Refused(f"duplicate key {key!r} (first on line "
                                   f"{seen.start_mark.line + 1})", key_node.start_mark)
        return super().construct_mapping(node, deep=deep)


def read_text(path: Path) -> str:
    """A look file's text: a regular file of at most MAX_LOOK_BYTES of UTF-8."""
    try:
        st = path.stat()
        if not stat.S_ISREG(st.st_mode):
            raise PresetError(f"{path}: a look must be a regular file")
        if st.st_size > MAX_LOOK_BYTES:
            raise PresetError(f"{path}: look file is {st.st_size} bytes; the limit is "
                              f"{MAX_LOOK_BYTES} (1 MiB)")
        with open(path, "rb") as f:
            data = f.read(MAX_LOOK_BYTES + 1)
    except OSError as exc:
        raise PresetError(f"{path}: cannot read look file: {exc.strerror}") from exc
    if len(data) > MAX_LOOK_BYTES:
        raise PresetError(f"{path}: look file is over the limit of {MAX_LOOK_BYTES} bytes (1 MiB)")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[:exc.start].count(b"\n") + 1
        raise PresetError(f"{path}:{line}: not UTF-8 text (byte 0x{data[exc.start]:02x}); "
                          f"save the look as UTF-8") from None


LookLoader.add_constructor("tag:yaml.org,2002:int", LookLoader.construct_yaml_int)

# YAML 1.2 core schema for plain scalars (PyYAML resolves YAML 1.1): ``1:2.5`` is text, not
# the base-60 number 62.5; ``0777`` is 777, not octal 511 (octal is ``0o777``); ``1e-3`` is a
# number; only true/false (any case) are booleans, not yes/no/on/off/y/n; no ``1_000``.
LookLoader.yaml_implicit_resolvers = {
    first: [(tag, regexp) for tag, regexp in resolvers
            if tag not in ("tag:yaml.org,2002:bool", "tag:yaml.org,2002:int",
                           "tag:yaml.org,2002:float")]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()}
LookLoader.add_implicit_resolver(
    "tag:yaml.org,2002:bool", re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$"),
    list("tTfF"))
LookLoader.add_implicit_resolver(
    "tag:yaml.org,2002:int", re.compile(r"^(?:[-+]?[0-9]+|0o[0-7]+|0x[0-9a-fA-F]+)$"),
    list("-+0123456789"))
LookLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^(?:[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?"
               r"|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$"),
    list("-+.0123456789"))


class Located:
    """YAML data with the line of every key path, for error messages."""

    @classmethod
    def from_data(cls, data, where: str) -> "Located":
        """A look given as data (a dict: the Python API, an output's ``clfx:lookJSON``):
        errors name ``where`` and the key."""
        doc = cls.__new__(cls)
        doc.path, doc.data, doc.lines = where, data, {}
        return doc

    def __init__(self, path: Path):
        self.path = path
        text = read_text(path)
        loader = None
        try:
            loader = LookLoader(text)  # the reader refuses control characters at once
            node = loader.get_single_node()
            self.data = loader.construct_document(node) if node is not None else None
        except Refused as exc:
            raise PresetError(f"{path}:{exc.problem_mark.line + 1}: {exc.problem}") from None
        except yaml.YAMLError as exc:
            mark = getattr(exc, "problem_mark", None)
            where = f"{path}:{mark.line + 1}" if mark else str(path)
            problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
            raise PresetError(f"{where}: malformed YAML: {problem}") from exc
        finally:
            if loader is not None:
                loader.dispose()
        self.lines: dict[tuple, int] = {}
        if node is not None:
            self._index(node, ())

    def _index(self, node, path):
        self.lines.setdefault(path, node.start_mark.line + 1)
        if isinstance(node, yaml.MappingNode):
            for k, v in node.value:
                key = k.value
                self.lines[path + (key,)] = k.start_mark.line + 1
                self._index(v, path + (key,))
        elif isinstance(node, yaml.SequenceNode):
            for i, v in enumerate(node.value):
                self._index(v, path + (i,))

    def where(self, *path) -> str:
        for n in range(len(path), -1, -1):
            if path[:n] in self.lines:
                return f"{self.path}:{self.lines[path[:n]]}"
        return str(self.path)

    def fail(self, path: tuple, message: str):
        key = ".".join(f"[{p}]" if isinstance(p, int) else str(p) for p in path).replace(".[", "[")
        raise PresetError(f"{self.where(*path)}: {key + ': ' if key else ''}{message}")


def suggest(name, options) -> str:
    close = difflib.get_close_matches(str(name), list(options), n=1)
    return f"; did you mean {close[0]!r}?" if close else f" (expected one of: {', '.join(options)})"


def find_file(name_or_path: str, what: str, available, hint=None) -> Path:
    """The file ``name_or_path`` names: itself when it is a path (``.yaml``/``.yml``, or
    with a separator), else the name's in ``available()`` (name -> path); PresetError when
    there is none (``hint(name, names)``: what to say after it; default :func:`suggest`)."""
    p = Path(name_or_path)
    if p.suffix.lower() in (".yaml", ".yml") or os.sep in name_or_path:
        if p.is_file():
            return p
        raise PresetError(f"{what} file {name_or_path} does not exist")
    known = available()
    if name_or_path in known:
        return known[name_or_path]
    raise PresetError(f"unknown {what} {name_or_path!r}{(hint or suggest)(name_or_path, list(known))}")


def yaml_files(dirs) -> dict[str, tuple[str, Path]]:
    """Name (file stem) -> (origin, path) of the YAML files in ``dirs`` ((origin, folder)
    pairs, searched in order: earlier folders win)."""
    found: dict[str, tuple[str, Path]] = {}
    for origin, folder in dirs:
        if folder.is_dir():
            for path in sorted(folder.glob("*.y*ml")):
                found.setdefault(path.stem, (origin, path))
    return found
