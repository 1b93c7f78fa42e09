"""One module per effect; each registers a Plugin subclass (see clfx.core.plugin).

A plugin module imports only ``clfx.core``, ``clfx.device`` and ``clfx.fx`` (never another
plugin, the bench, io or the pipeline): the import contracts in ``pyproject.toml`` check it.
"""
from __future__ import annotations

import difflib
import importlib
import pkgutil

from clfx.core.errors import ParamError
from clfx.host import Plugin, registry

_DISCOVERED = False


def discover() -> dict[str, type[Plugin]]:
    """Import every module of ``clfx.plugins`` once; return the registry."""
    global _DISCOVERED
    if not _DISCOVERED:
        for mod in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
            if not mod.name.startswith("_"):
                importlib.import_module(f"clfx.plugins.{mod.name}")
        _DISCOVERED = True
    return registry()


def get_plugin(name: str, where: str = "") -> type[Plugin]:
    """The plugin class called ``name``; ParamError suggesting the closest name otherwise."""
    reg = discover()
    if name in reg:
        return reg[name]
    close = difflib.get_close_matches(str(name), list(reg), n=1)
    hint = f"; did you mean {close[0]!r}?" if close else f" (known: {', '.join(reg)})"
    raise ParamError(f"{where + ': ' if where else ''}unknown effect {name!r}{hint}")
