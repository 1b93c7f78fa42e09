"""The oracles in tests/reference are written from what each effect claims, never from its
code: they import only the standard library, NumPy, SciPy and each other (a constant or a
function taken from clfx would make the test agree with the implementation by
construction), and no oracle function is a copy of a function in clfx (the same body,
statement for statement)."""
import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
ORACLES = sorted((ROOT / "tests" / "reference").glob("*.py"))
ALLOWED = {"numpy", "scipy"} | set(sys.stdlib_module_names)

KNOWN: dict[tuple[str, str], str] = {
    ("distortion.py", "clfx.fx.resample"):
        "footprint_spread: the host's rule for a footprint's spread (kappa, cap, float16)",
    ("rolling_shutter.py", "clfx.fx.motion"):
        "path: the arc through a point's positions at -1, 0 and +1 frame",
    ("streaks.py", "clfx.fx"):
        "coating_tint: optics.MULTILAYER_DESIGNS and spectral's CIE tables",
}
"""(oracle file, imported module) still to be written out of the oracle, with what it takes:
none may be added (issue 36), each goes when its oracle derives it."""


def imports(tree) -> list[str]:
    """Every module a file imports, at any depth (relative imports are the package's own)."""
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and not node.level:
            out.append(node.module)
    return out


def test_oracles_import_only_numpy_scipy_and_the_standard_library():
    assert len(ORACLES) > 20
    wrong = []
    for path in ORACLES:
        for module in imports(ast.parse(path.read_text())):
            root = module.split(".")[0]
            if root in ALLOWED or module == "tests.reference" or \
                    module.startswith("tests.reference."):
                continue
            if (path.name, module) not in KNOWN:
                wrong.append(f"{path.name}: {module}")
    assert not wrong, wrong


def _bodies(path: Path) -> dict[str, str]:
    """Each function's body (docstring dropped) as an AST dump, by name, when it has at least
    three statements (a one-line helper may well be written the same way twice)."""
    out = {}
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(
                    getattr(body[0], "value", None), ast.Constant):
                body = body[1:]
            if len(body) >= 3:
                out[f"{path.name}:{node.name}"] = ast.dump(ast.Module(body=body,
                                                                      type_ignores=[]))
    return out


def test_no_oracle_function_copies_the_implementation():
    implementation = {}
    for path in sorted((ROOT / "clfx").rglob("*.py")):
        for name, dump in _bodies(path).items():
            implementation.setdefault(dump, name)
    copies = [f"{name} = {implementation[dump]}" for path in ORACLES
              for name, dump in _bodies(path).items() if dump in implementation]
    assert not copies, copies


def test_the_checks_catch_an_import_and_a_copy(tmp_path):
    """The two checks above can fail: an oracle importing clfx, one copying a function."""
    src = (ROOT / "clfx" / "core" / "camera.py").read_text()
    fake = tmp_path / "fake.py"
    fake.write_text("from clfx.core.camera import shutter_interval\n\n" + src)
    assert "clfx.core.camera" in imports(ast.parse(fake.read_text()))
    mine = _bodies(fake)
    theirs = set(_bodies(ROOT / "clfx" / "core" / "camera.py").values())
    assert any(dump in theirs for dump in mine.values())
