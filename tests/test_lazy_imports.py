"""Imports sit at a module's top (issue 36): one inside a function says why it is lazy.

A function-level import is kept only where importing at the top would cost something
measured (start-up of a command that does not need the module: ``clfx --help`` must not load
the device, OpenImageIO or Dask), where the library is optional (bpy, matplotlib) or where a
top import would close a cycle.  It carries a comment ``# lazy: <why>`` on its line, or on the
line(s) just above it (one comment covers a block of consecutive imports).  The standard
library is never imported lazily: it costs nothing worth a hidden import.
"""
from __future__ import annotations

import ast
import io
import sys
import tokenize
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MARK = "# lazy:"

def _comments(source: str) -> dict[int, str]:
    """Line -> the comment on it."""
    return {tok.start[0]: tok.string for tok in
            tokenize.generate_tokens(io.StringIO(source).readline) if tok.type == tokenize.COMMENT}


def function_level_imports():
    """(path, line, modules, reason or None) of every import inside a function in clfx."""
    for path in sorted((ROOT / "clfx").rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        source = path.read_text()
        lines = source.splitlines()
        comments = _comments(source)
        nodes = [n for fn in ast.walk(ast.parse(source))
                 if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef))
                 for n in ast.walk(fn) if isinstance(n, (ast.Import, ast.ImportFrom))]
        in_import = {line for n in nodes for line in range(n.lineno, n.end_lineno + 1)}
        for n in sorted(set(nodes), key=lambda n: n.lineno):
            reason = next((comments[line] for line in range(n.lineno, n.end_lineno + 1)
                           if MARK in comments.get(line, "")), None)
            line = n.lineno - 1           # up through comments and the imports of its block
            while reason is None and line > 0:
                text = lines[line - 1].strip()
                if MARK in comments.get(line, "") and text.startswith("#"):
                    reason = comments[line]
                elif not (line in in_import or text.startswith("#")):
                    break
                line -= 1
            modules = [a.name for a in n.names] if isinstance(n, ast.Import) else [n.module or "."]
            yield rel, n.lineno, modules, reason


def test_every_function_level_import_says_why_it_is_lazy():
    bare = [f"{p}:{line}: {', '.join(m)}" for p, line, m, reason in function_level_imports()
            if reason is None or not reason.split(MARK, 1)[1].strip()]
    assert not bare, (f"import at the module's top, or say why not with '{MARK} <why>' "
                      f"(a measured start-up cost, an optional library, a cycle):\n"
                      + "\n".join(bare))


def test_the_standard_library_is_imported_at_the_top():
    lazy = [f"{p}:{line}: {m}" for p, line, mods, _ in function_level_imports() for m in mods
            if m.split(".")[0] in sys.stdlib_module_names]
    assert not lazy, "the standard library costs nothing worth a lazy import:\n" + "\n".join(lazy)


def test_the_check_sees_an_import_without_its_reason(tmp_path, monkeypatch):
    """The scan finds a bare function-level import, and a reason above a block covers it."""
    pkg = tmp_path / "clfx"
    pkg.mkdir()
    (pkg / "m.py").write_text("def f():\n    import numpy\n\n\n"
                              "def g():\n    # lazy: a reason\n    import numpy\n"
                              "    from clfx import core\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    found = {line: reason for _, line, _, reason in function_level_imports()}
    assert found == {2: None, 7: "# lazy: a reason", 8: "# lazy: a reason"}
