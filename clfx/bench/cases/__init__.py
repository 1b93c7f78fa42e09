"""One bench case module per effect: ``clfx/bench/cases/<effect>.py`` defines ``CASE``.

A case is what ``clfx bench`` measures an effect on (its representative hard case), the
peers doing the same operation (OpenCV, SciPy, a naive method), and, for effects whose
levels draw different random samples, the statistics to compare instead of pixels.  Effect
modules know nothing of the bench: everything here may import scenes, ground truth, OpenCV
and SciPy, which no plugin may.

``make(width, height, rng) -> dict`` returns:

- ``source`` (h, w, 4) float32, and optionally ``depth`` (h, w), ``velocity`` (h, w, 2),
  ``data_window``, ``display_window``, ``pixel_aspect``, ``frame``, ``seed``, ``camera``,
  ``display_referred``;
- ``params``: the effect's parameters for the case;
- ``truth``: a multisample ground truth, when the reference is not the effect's own
  ``reference`` level (cases with a truth are cached on disk, keyed by their sources);
- ``edge_mask``: where the edge-band error is measured (else derived from depth/velocity).

``peers(case, params, ctx) -> {label: fn | (fn, level)}``: host callables returning RGBA,
compared with the clfx ``level`` doing the same work (``final`` when not given).

``metrics(out, ref, case) -> dict``: replaces the pixel error metrics (noise effects).
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass
from types import ModuleType
from typing import Callable


@dataclass(frozen=True)
class Case:
    make: Callable[..., dict]
    peers: Callable[..., dict] | None = None
    metrics: Callable[..., dict] | None = None


def module_for(effect: str) -> ModuleType | None:
    """The case module of ``effect``, or None when it has none."""
    try:
        return importlib.import_module(f"{__name__}.{effect}")
    except ModuleNotFoundError as exc:
        if exc.name != f"{__name__}.{effect}":
            raise
        return None


def for_effect(effect: str) -> Case | None:
    """The declared bench case of ``effect`` (its module's ``CASE``), or None."""
    module = module_for(effect)
    return None if module is None else module.CASE
