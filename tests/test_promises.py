"""The reliability promises (docs/reliability.md) and the tests that check them stay together:
every promise cites tests, and every cited test exists (issue 10: "the README's reliability
promises match what the tests check"; issue 36 moved them from the README to docs/)."""
import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CITE = re.compile(r"`(tests/[\w/]+\.py)::(\w+)`")


def promises() -> list[tuple[str, str]]:
    """(promise title, its text) for every bullet of docs/reliability.md."""
    section = (ROOT / "docs" / "reliability.md").read_text().split("\n## ", 1)[0]
    bullets = re.split(r"\n- ", "\n" + section.split("\n- ", 1)[1])
    out = []
    for b in bullets:
        if b.strip():
            title = re.match(r"\s*\*\*(.+?)\*\*", b)
            assert title, f"a promise without a bold title: {b[:60]!r}"
            out.append((title.group(1), b))
    return out


def test_every_promise_cites_tests_that_exist():
    found = promises()
    titles = [t for t, _ in found]
    for needed in ("Exit codes", "Atomic, checked writes", "Deterministic",
                   "Bounded memory and time"):
        assert any(t.startswith(needed) for t in titles), (needed, titles)
    defined: dict[str, set[str]] = {}
    for title, text in found:
        cited = CITE.findall(text)
        assert cited, f"promise {title!r} cites no test"
        for path, name in cited:
            if path not in defined:
                tree = ast.parse((ROOT / path).read_text())
                defined[path] = {n.name for n in ast.walk(tree)
                                 if isinstance(n, ast.FunctionDef)}
            assert name in defined[path], f"promise {title!r} cites {path}::{name}, not found"
