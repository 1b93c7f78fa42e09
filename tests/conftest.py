"""Shared fixtures: the OpenCL runtime (skipped with a reason if absent), a seeded RNG,
paths to the shared real test data."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("CLFX_SHARED_DATA", ROOT.parent / "shared" / "data"))
EXR_IMAGES = SHARED_DATA / "openexr-images"
NO_EXR_IMAGES = (f"OpenEXR test images not found at {EXR_IMAGES}: put a copy of "
                 f"github.com/AcademySoftwareFoundation/openexr-images there, or set "
                 f"CLFX_SHARED_DATA to the folder that holds openexr-images/")
"""Why tests of the real plates skip: the exact folder looked in and how to point elsewhere."""
needs_exr_images = pytest.mark.skipif(not EXR_IMAGES.is_dir(), reason=NO_EXR_IMAGES)

os.environ.setdefault("CLFX_COLD_NOTICE", "0")
"""The command line's "compiling kernels ... once" line stays out of the in-process CLI tests'
stderr on CI's cold kernel cache (tests/test_first_day.py checks it in subprocesses)."""
os.environ.setdefault("POCL_WORK_GROUP_SPECIALIZATION", "0")
"""PoCL compiles one work-group function per kernel for any local size, not one per local size
and grid class: the suite renders the same kernels at many frame sizes (odd shapes, crops,
windows), and on CI's empty kernel cache those compiles were most of its time (a cold run of
four effects at five sizes: 29.6 -> 17.5 CPU s; warm renders cost the same).  Renders do
the same since issue 33 (`clfx.device.runtime._ensure_generic_work_groups`); set it to 1 to
run the suite with PoCL's specialised build."""


@pytest.fixture(scope="session")
def rt():
    from clfx.core.errors import DeviceError
    from clfx.device.runtime import Runtime

    try:
        return Runtime.get()
    except DeviceError as exc:
        if os.environ.get("CI"):
            raise  # CI must have a device: failing beats a green run that tested nothing
        pytest.skip(f"no OpenCL device: {exc}")


@pytest.fixture
def rng():
    return np.random.default_rng(20261121)


@pytest.fixture(scope="session")
def exr_images():
    if not EXR_IMAGES.is_dir():
        pytest.skip(NO_EXR_IMAGES)
    return EXR_IMAGES


@pytest.fixture
def small(tmp_path):
    """(tests of the command line) A 24x16 EXR ``in.exr`` and a one-effect look ``look.yaml`` in ``tmp_path``."""
    from clfx.core.frame import Frame
    from clfx.io.write import write_frame

    rgba = np.random.default_rng(1).uniform(0, 2, (16, 24, 4)).astype(np.float32)
    rgba[..., 3] = 1
    write_frame(Frame.from_array(rgba), tmp_path / "in.exr")
    (tmp_path / "look.yaml").write_text("name: t\neffects:\n  - effect: vignette\n")
    return tmp_path


def stamped(path, look_json: str):
    """An EXR whose clfx:lookJSON attribute is ``look_json``."""
    import OpenImageIO as oiio

    spec = oiio.ImageSpec(8, 4, 4, "float")
    spec.attribute("clfx:lookJSON", look_json)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec), oiio.geterror()
    assert out.write_image(np.zeros((4, 8, 4), np.float32))
    out.close()


def hard_shapes():
    """Image shapes every kernel must survive (hard-cases.md case 12)."""
    return [(1, 1), (1, 7), (7, 1), (2, 2), (3, 5), (17, 31), (64, 48)]



SPLIT_ACROSS_WORKERS = (
    "tests/test_oclgrind.py",          # one Oclgrind process per test, single-threaded
    "tests/fuzz/test_fuzz.py",         # independent renders of small frames
    "tests/contract/test_values.py",
    "tests/contract/test_regions.py",
    "tests/contract/test_shapes.py",
    "tests/test_damaged.py",
)
"""Modules whose tests share no module-scoped state, so pytest-xdist may spread them over its
workers one test at a time (see ``pytest_xdist_make_scheduler``)."""

BY_EFFECT = ("tests/fuzz/test_fuzz.py", "tests/contract/test_values.py",
             "tests/contract/test_regions.py", "tests/contract/test_shapes.py")
"""Of those, the modules whose test ids start with the effect (or look) they render: their
tests are handed out one effect at a time, so that the tests that build the same programs
(one effect at its levels, values and images) run in one process, one after the other.  One
test at a time, two workers on a cold kernel cache compiled the same programs at once."""


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """``pytest -n N --dist loadscope`` (``make test``): each module runs whole on one worker,
    in its own order (its module-scoped fixtures built once), except ``SPLIT_ACROSS_WORKERS``,
    whose tests are handed out one at a time (``BY_EFFECT``: one effect at a time).  (xdist's
    ``loadgroup`` marks would say the same, but pytest 9.2 ignores the node-id suffix they
    work by: pytest-xdist issue 1386.)"""
    if config.getvalue("dist") != "loadscope":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class ModuleScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            module, _, test = nodeid.partition("::")
            if module in BY_EFFECT and "[" in test:
                return f"{module}::{test.split('[', 1)[1].split('-', 1)[0]}"
            return nodeid if module in SPLIT_ACROSS_WORKERS else module

    return ModuleScheduling(config, log)


CPU_LOG = os.environ.get("CLFX_TEST_CPU_LOG")
"""Opt-in: a file to which every test appends one JSON line, its node id and the CPU seconds
(user + system) it took in this process and in the child processes it waited for, with its
wall time; under xdist, each worker appends its own lines.  Per-module sums say where CI's
time goes (wall time does not, on a shared machine)."""


def _cpu_now() -> tuple[float, float, float]:
    import resource
    import time

    me, kids = (resource.getrusage(w) for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))
    return me.ru_utime + me.ru_stime, kids.ru_utime + kids.ru_stime, time.perf_counter()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    if not CPU_LOG:
        yield
        return
    import json

    before = _cpu_now()
    yield
    after = _cpu_now()
    own, kids, wall = (round(b - a, 3) for a, b in zip(before, after))
    row = {"id": item.nodeid, "cpu_s": own, "children_cpu_s": kids, "wall_s": wall}
    if nextitem is None or nextitem.nodeid.split("::")[0] != item.nodeid.split("::")[0]:
        row["kernel_cache"] = _kernel_cache_entries()
    with open(CPU_LOG, "a") as log:
        log.write(json.dumps(row) + "\n")


def _kernel_cache_entries() -> list[int] | None:
    """Programs and compiled kernels in PoCL's cache (``POCL_CACHE_DIR``: PROGRAM/program.bc
    and PROGRAM/KERNEL/*/KERNEL.so) at the end of a module: differences between modules are
    the compiles each module caused (in a one-worker run; with two, the other's interleave)."""
    root = os.environ.get("POCL_CACHE_DIR")
    if not root or not os.path.isdir(root):
        return None
    programs = kernels = 0
    for shard in os.scandir(root):
        if not shard.is_dir():
            continue
        for prog in os.scandir(shard.path):
            if prog.is_dir():
                programs += 1
                kernels += sum(1 for k in os.scandir(prog.path) if k.is_dir())
    return [programs, kernels]


@pytest.fixture(scope="session")
def small_beachball(exr_images, tmp_path_factory):
    """Beachball's frames decimated by 4, made on first use (`tests.plates.SmallBeachball`)."""
    from tests.plates import SmallBeachball

    if not (exr_images / "Beachball" / "multipart.0008.exr").is_file():
        pytest.skip(f"Beachball sequence not found in {exr_images / 'Beachball'}")
    return SmallBeachball(exr_images / "Beachball", tmp_path_factory.mktemp("small-beachball"))
