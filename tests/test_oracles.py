"""The oracles in tests/reference are written from what each effect claims, never from its
code: they import only the standard library, NumPy, SciPy and each other (a constant or a
function taken from clfx would make the test agree with the implementation by
construction), and no oracle function is a copy of a function in clfx (the same body,
statement for statement).  Published data an oracle needs (CIE tables, coating designs, a
filter's constants) it states itself; a test here checks that clfx uses the same numbers."""
import ast
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
ORACLES = sorted((ROOT / "tests" / "reference").glob("*.py"))
ALLOWED = {"numpy", "scipy"} | set(sys.stdlib_module_names)


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
            if not (root in ALLOWED or module == "tests.reference"
                    or module.startswith("tests.reference.")):
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


def test_the_oracles_published_numbers_are_the_ones_clfx_uses():
    """What an oracle states of published data or of a design's constants, clfx's tables say
    too: the footprint filters' (kappa, cap), the arc's turn limits (kernels/lib/arc.h), the
    coating stacks and their glass, the CIE 1931 fit, the Rec.709 matrix and luminance."""
    from clfx.core import colour
    from clfx.fx import motion, optics, resample, spectral
    from clfx.plugins import streaks
    from tests import reference
    from tests.reference import distortion, rolling_shutter
    from tests.reference import streaks as streaks_oracle

    assert distortion.FOOTPRINT_CONSTANTS == {name: (fp.kappa, fp.cap)
                                              for name, fp in resample.FOOTPRINTS.items()}
    assert (rolling_shutter.MIN_TURN, rolling_shutter.MAX_TURN) == (motion.MIN_TURN,
                                                                    motion.MAX_TURN)
    assert streaks_oracle.COATING_DESIGNS == optics.MULTILAYER_DESIGNS
    assert streaks_oracle.CROWN_GLASS_INDEX == streaks.GLASS_INDEX
    lam = np.linspace(360.0, 830.0, 941)
    np.testing.assert_allclose(reference.cie1931(lam), spectral.cie1931_cmf(lam), rtol=0,
                               atol=1e-15)
    np.testing.assert_array_equal(reference.XYZ_TO_REC709, colour.XYZ_TO_REC709)
    np.testing.assert_array_equal(reference.REC709_Y, colour.REC709_LUMINANCE)
