"""The architecture is checked, not reviewed: the import contracts in pyproject.toml."""
import os
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
    import re

    forbidden = re.compile(r"^\s*(def bench_\w+|(from|import) (cv2|scipy|clfx\.bench)\b)", re.M)
    for path in sorted((ROOT / "clfx" / "plugins").glob("*.py")):
        hits = forbidden.findall(path.read_text())
        assert not hits, f"{path.name}: {hits}"
