"""Contract and fuzz cases that fail today because of real bugs (issue 10 item 6).

Each is marked ``xfail(strict=True)``: when its fix lands the case passes, strict turns that
into an XPASS failure, and its entry here is deleted.  The assertions are never weakened.
Keys are case ids as the tests build them (``effect-quality-value``,
``effect-setting-quality-image``, ``look-image``, ``effect``); ``*`` matches any run of
characters, everything else literally.
"""
from __future__ import annotations

import re

import pytest

# Every case found by the red-team pass and by these suites is fixed (issue 10 item 6); a
# new known bug goes here with its issue, never by weakening an assertion.
KNOWN: dict[str, dict[str, str]] = {}
"""test name -> {case id pattern: reason}."""


def _matches(pattern: str, case_id: str) -> bool:
    return re.fullmatch(".*".join(map(re.escape, pattern.split("*"))), case_id) is not None


def marks(test: str, case_id: str) -> list:
    """The strict xfail mark of ``case_id`` of ``test`` if a known bug fails it, else []."""
    for pattern, reason in KNOWN.get(test, {}).items():
        if _matches(pattern, case_id):
            return [pytest.mark.xfail(strict=True, reason=reason)]
    return []


def param(test: str, *values, id: str):
    """``pytest.param(*values, id=id)`` carrying ``marks(test, id)``."""
    return pytest.param(*values, id=id, marks=marks(test, id))
