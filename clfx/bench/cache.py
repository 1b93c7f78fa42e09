"""The bench's case cache: cases with a costly ground truth are kept on disk.

A case with a multisample ``truth`` takes minutes to render at 1080p; it is pickled under
``$XDG_CACHE_HOME/clfx/bench`` (else ``~/.cache``), keyed by the case's name, size, seed and
the source of every module that makes it (the case module, :mod:`clfx.bench.scene`,
:mod:`clfx.bench.groundtruth`, the shared case helpers and the module's ``TRUTH_DEPENDS``),
so an edit to any of them rebuilds it.
"""
from __future__ import annotations

import hashlib
import importlib
import inspect
import os
import pickle

import numpy as np

from clfx.bench import groundtruth, scene
from clfx.bench.cases import Case, shared

CACHE_VERSION = 1


def case_cache_path(module, name: str, width: int, height: int, seed: int):
    """A cache file for a case with a costly ground truth, keyed by the sources that make it."""
    h = hashlib.sha1(f"{CACHE_VERSION}:{name}:{width}x{height}:{seed}".encode())
    depends = [importlib.import_module(m) for m in getattr(module, "TRUTH_DEPENDS", ())]
    for mod in (module, scene, groundtruth, shared, *depends):
        h.update(inspect.getsource(mod).encode())
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "clfx", "bench", f"{name}-{width}x{height}-{h.hexdigest()[:12]}.pickle")


def load_case(module, spec: Case, name: str, width: int, height: int, seed: int = 1,
              variant: str | None = None) -> dict:
    """The effect's bench case (or one of its ``variants``); cases with a multisample
    ``truth`` are cached on disk (minutes to render at 1080p) and reused while their sources
    are unchanged."""
    maker = spec.maker(variant)
    if getattr(maker, "cached", True) is False:    # read from files: nothing to cache
        return maker(width, height, np.random.default_rng(seed))
    path = case_cache_path(module, case_label(name, variant), width, height, seed)
    if os.path.exists(path):
        try:
            with open(path, "rb") as f:
                return pickle.load(f)
        except Exception:
            pass  # a damaged cache entry is rebuilt
    case = maker(width, height, np.random.default_rng(seed))
    if case.get("truth") is not None:
        os.makedirs(os.path.dirname(path), exist_ok=True)
        tmp = f"{path}.tmp-{os.getpid()}"
        with open(tmp, "wb") as f:
            pickle.dump(case, f, protocol=pickle.HIGHEST_PROTOCOL)
        os.replace(tmp, path)
    return case


def case_label(effect: str, variant: str | None = None) -> str:
    """``effect`` for the main case, ``effect:variant`` for a variant."""
    return effect if variant is None else f"{effect}:{variant}"
