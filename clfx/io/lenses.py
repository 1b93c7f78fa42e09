"""Lens data, resolved and validated when a look is loaded: lens prescriptions (a shipped
name in ``presets/lenses`` or a YAML file of surfaces, for ``lens_flare``) and lensfun
profiles (for ``lens``).  A step names its lenses (`clfx.host.Plugin.lens_refs`);
:func:`resolve` reads every one of them once, so a bad name fails at look load in one line
naming the key (``STEP.PARAM``), before any frame, and a render reads the resolved data
(:class:`Lenses`), never a file.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from clfx.core.errors import ClfxError, PresetError
from clfx.fx import optics
from clfx.io.presetfiles import (Located, builtin_dir, find_file, search_dirs,
                                 user_dir, yaml_files)

# -- lens prescriptions (presets/lenses) ------------------------------------------------------
LENS_FOLDER = "lenses"


def lens_dirs() -> list[tuple[str, Path]]:
    """Folders of lens prescriptions, searched in order: ``lenses/`` inside each
    ``CLFX_PRESET_PATH`` folder, beside the user's looks, and the built-in ``presets/lenses``."""
    dirs = [(origin, folder / LENS_FOLDER) for origin, folder in search_dirs()[:-2]]
    dirs.append(("user", user_dir().parent / LENS_FOLDER))
    dirs.append(("built-in", builtin_dir() / LENS_FOLDER))
    return dirs


def available_lenses() -> dict[str, Path]:
    """Lens name -> prescription file; earlier folders win."""
    return {name: path for name, (_, path) in yaml_files(lens_dirs()).items()}


def find_lens(name_or_path: str) -> Path:
    """The file of a lens prescription: a path (``.yaml`` or with a separator) or a name."""
    return find_file(name_or_path, "lens", available_lenses)


def read_lens(name_or_path: str) -> dict:
    """A lens prescription as the plain dict ``clfx.fx.optics.Prescription.from_dict`` takes:
    found by :func:`find_lens`, read with the same limits and YAML safety as a look (a regular
    UTF-8 file of at most 1 MiB, no aliases, no duplicate keys); the optics validate it."""
    path = find_lens(name_or_path)
    data = Located(path).data
    if not isinstance(data, dict):
        raise PresetError(f"{path}: a lens prescription is a mapping with name and surfaces")
    return data



def check_lensfun(maker: str, model: str) -> None:
    """Raise ParamError when lensfun's database has no lens ``model`` (by ``maker``)."""
    from clfx.fx import lensdb   # lazy: loads lensfunpy and its database

    lensdb.get_lens(maker, model)


@dataclass(frozen=True)
class Lenses:
    """The lens prescriptions a look's steps name, read when it was loaded (name -> the
    plain dict `clfx.fx.optics.Prescription.from_dict` takes): the render context's
    ``read_lens``.  Plain data: travels with the look to distributed workers."""

    prescriptions: dict = field(default_factory=dict)

    def read(self, name: str) -> dict:
        try:
            return self.prescriptions[name]
        except KeyError:
            raise PresetError(f"lens {name!r} was not resolved when the look was loaded "
                              f"(clfx.io.lenses.resolve)") from None


def resolve(steps, read=None, known: Lenses | None = None) -> Lenses:
    """Read and validate every lens the enabled ``steps`` name (`Plugin.lens_refs`):
    prescriptions are read (``read``: default :func:`read_lens`) and parsed by the optics,
    lensfun names looked up.  Prescriptions in ``known`` (what the look resolved when it was
    loaded, before ``--set``) are taken from it, not read and checked again.  Raises a
    ClfxError of one line naming ``STEP.PARAM``."""
    read = read or read_lens
    done = known.prescriptions if known is not None else {}
    found: dict[str, dict] = {}
    for step in steps:
        if not step.enabled:
            continue
        for param, kind, value in step.plugin.lens_refs(step.params):
            where = f"{step.id}.{param}"
            try:
                if kind == "prescription":
                    if value in done:
                        found[value] = done[value]
                    elif value not in found:
                        data = read(value)
                        optics.Prescription.from_dict(data, value)
                        found[value] = data
                elif kind == "lensfun":
                    check_lensfun(*value)
                else:
                    raise ValueError(f"unknown lens kind {kind!r}")
            except (ClfxError, ValueError, TypeError, KeyError) as exc:
                msg = " ".join(str(exc).split()) or type(exc).__name__
                raise PresetError(f"{where}: {msg}") from None
    return Lenses(found)
