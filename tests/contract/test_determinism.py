"""Determinism: the same inputs, seed and frame give the same bytes

- twice in a row (the second time from warm caches),
- with a fresh plugin instance,
- with other OpenCL work-group sizes (every launch that leaves the size to the runtime),
- with one PoCL thread in a fresh process (and the default thread count here),

for every effect at every quality level.  No float atomics, hashed noise, fixed summation
orders (hard-cases.md case 16); frame N alone equals frame N in a batch: see test_cli.
"""
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.contract import effects as E
from tests.contract.known import param
from tests.effects import render_effect

ROOT = Path(__file__).resolve().parents[2]
ONE_THREAD = {"POCL_MAX_PTHREAD_COUNT": "1", "POCL_CPU_MAX_CU_COUNT": "1"}


def render_all(rt, fresh: bool = False) -> dict[str, np.ndarray]:
    """Every effect at every level on the contract frame: ``{effect-quality: rgba}``."""
    src = E.scene()
    out = {}
    for name in E.EFFECTS:
        plugin = E.discover()[name]() if fresh else E.plugin(name)
        kw = {**E.passes(name, src.shape[:2]), "camera": E.CAMERA}
        for q in E.QUALITIES:
            out[f"{name}-{q}"] = render_effect(rt, plugin, E.params(name), src, quality=q, frame=7,
                                               seed=11, **kw)
    return out


def _divisor(n: int, cap: int) -> int:
    return next(d for d in range(min(n, cap), 0, -1) if n % d == 0)


def local_sizes(rt, monkeypatch, mode: str):
    """Make ``rt.launch`` pick work-group sizes itself where callers leave them to OpenCL:
    ``ones`` (1 x 1) or the largest divisors of the global size up to 8 per dimension (so no
    launch grows)."""
    launch = rt.launch

    def forced(knl, global_size, *args, local=None, **kw):
        if local is None:
            dims = [max(1, int(n)) for n in global_size]
            local = tuple(1 if mode == "ones" else _divisor(n, 8 if len(dims) > 1 else 64)
                          for n in dims)
        return launch(knl, global_size, *args, local=local, **kw)

    monkeypatch.setattr(rt, "launch", forced)


@pytest.fixture(scope="module")
def renders(rt, tmp_path_factory):
    folder = tmp_path_factory.mktemp("determinism")
    code = ("import sys, numpy as np; from clfx.device.runtime import Runtime;"
            "from tests.contract.test_determinism import render_all;"
            "np.savez(sys.argv[1], **render_all(Runtime.get()))")
    env = {**os.environ, **ONE_THREAD,
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    subprocess.run([sys.executable, "-c", code, str(folder / "one.npz")], cwd=ROOT, env=env,
                   check=True, timeout=600)
    runs = {"first": render_all(rt), "second": render_all(rt),
            "fresh instances": render_all(rt, fresh=True)}
    with pytest.MonkeyPatch.context() as mp:
        for mode in ("ones", "divisors"):
            local_sizes(rt, mp, mode)
            runs[f"work-groups {mode}"] = render_all(rt)
            mp.undo()
    runs["one PoCL thread"] = dict(np.load(folder / "one.npz"))
    return runs


@pytest.mark.parametrize("case", [
    param("test_identical_bytes", f"{n}-{q}", id=f"{n}-{q}")
    for n in E.EFFECTS for q in E.QUALITIES])
def test_identical_bytes(renders, case):
    first = renders["first"][case]
    for run, images in renders.items():
        assert images[case].tobytes() == first.tobytes(), f"{case}: {run} differs from first"
