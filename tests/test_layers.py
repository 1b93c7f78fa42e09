"""The architecture is checked, not reviewed: the import contracts in pyproject.toml."""
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _lint_imports() -> str:
    exe = Path(sys.executable).with_name("lint-imports")
    if exe.exists():
        return str(exe)
    found = shutil.which("lint-imports")
    if not found:
        pytest.fail("lint-imports (import-linter) is not installed: it is in the test extras")
    return found


def test_import_contracts_hold():
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    r = subprocess.run([_lint_imports(), "--no-cache"], cwd=ROOT, env=env, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stdout[-4000:] + r.stderr[-2000:]
    assert "0 broken" in r.stdout


def test_plugins_are_only_effects():
    """A plugin module defines an effect: no bench fixtures, no host image libraries."""
    forbidden = re.compile(r"^\s*(def bench_\w+|(from|import) (cv2|scipy|clfx\.bench)\b)", re.M)
    for path in sorted((ROOT / "clfx" / "plugins").glob("*.py")):
        hits = forbidden.findall(path.read_text())
        assert not hits, f"{path.name}: {hits}"


CONTEXT_PARAMS = {"ctx", "context", "plugin"}
CONTEXT_TYPES = re.compile(r"\b(RenderContext|Plugin)\b")


def _defined_callables(module):
    """Every function and method ``module`` defines (not what it imports): top-level
    functions and the methods, static and class methods and property getters of its
    classes, nested classes included."""
    import inspect

    def members(owner, prefix):
        for name, obj in vars(owner).items():
            if isinstance(obj, (staticmethod, classmethod)):
                obj = obj.__func__
            elif isinstance(obj, property):
                obj = obj.fget
            if inspect.isfunction(obj) and obj.__module__ == module.__name__:
                yield prefix + name, obj
            elif inspect.isclass(obj) and obj.__module__ == module.__name__:
                yield from members(obj, f"{prefix}{name}.")

    yield from members(module, "")


def test_fx_is_pure_algorithms():
    """clfx.fx holds algorithms on arrays, maps and the device runtime (``rt``); whatever
    asks a render context or a plugin (the band/tile protocol, plugin mixins) is the kit's
    (clfx.kit): no function or method of clfx.fx takes a parameter named ctx, context or
    plugin, or one annotated RenderContext or Plugin."""
    import importlib
    import inspect
    import pkgutil

    import clfx.fx

    offenders = []
    for info in pkgutil.walk_packages(clfx.fx.__path__, "clfx.fx."):
        module = importlib.import_module(info.name)
        for name, fn in _defined_callables(module):
            for param in inspect.signature(fn).parameters.values():
                if param.name in CONTEXT_PARAMS or CONTEXT_TYPES.search(str(param.annotation)):
                    offenders.append(f"{info.name}.{name}({param.name})")
    assert not offenders, ("clfx.fx takes a render context or plugin (move it to clfx.kit): "
                           + ", ".join(offenders))
