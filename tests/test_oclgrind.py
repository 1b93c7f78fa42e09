"""Every effect's kernels at every quality level, and every built-in look, under Oclgrind
(an OpenCL device simulator that checks each memory access): no invalid access, no data
race, no API error; and no output that depends on uninitialised device memory.

Each group runs in a process of its own (`tests/oclgrind_child.py`; the runtime is one per
process): Oclgrind is the only OpenCL platform there, through a private ICD folder
(``OCL_ICD_VENDORS``, read by ocl-icd, also the copy bundled in the pyopencl wheel), with
``CLFX_DEVICE=oclgrind`` and its checks switched on by ``OCLGRIND_*`` variables.  Kernel
errors go to ``OCLGRIND_LOG``; API errors (``OCLGRIND_CHECK_API``) to stderr.  Both are read.

Frames are tiny (effects: 40x24 at every level, and in bands of 8 rows for an effect that
tiles, at each level that launches a kernel no lower level ran in bands; a 13x7 frame with and without a mask at ``draft``; looks: 48x32 at ``draft``; the
renders of ``EXTRA`` (at most 106x8) reach the paths those frames miss, and the ``FX`` helpers
run on 13x7; see ``tests/oclgrind_child.py``; ``scripts/oclgrind_coverage.py`` fails when a
kernel of kernels/ is in no group).  Programs are built with ``-cl-opt-disable`` (``CLFX_TEST_OPT_DISABLE``):
Oclgrind 21.10 mis-executes some of the ``-Oz`` code it makes itself (grain's and
sensor_noise's polynomial log, ``clfx_log8`` in kernels/lib/fastmath.h, returned 175.3 for
log(0.4676) there, -0.760 unoptimised and on PoCL: NaN noise), and its uninitialised-value
check crashes on optimised vector shuffles.  Unoptimised, every access is checked as the
source writes it.  Oclgrind with race detection is slow and single-threaded: the module is
marked ``slow``, and two groups run at once (``CLFX_OCLGRIND_JOBS``; the ``groups`` fixture).
Run it alone with ``.venv/bin/python -m pytest tests/test_oclgrind.py``; it skips with the
reason where Oclgrind is not installed (Debian: ``apt-get install oclgrind``; ``make
setup`` does).  The last tests ask whether any output depends on uninitialised device
memory on the default device (PoCL), the question Oclgrind 21.10's own check cannot answer
for these kernels.
"""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from clfx.core.plugin import QUALITY_LEVELS
from tests import oclgrind_child as child

ROOT = Path(__file__).resolve().parents[1]
CHILD = Path(__file__).resolve().parent / "oclgrind_child.py"
ICD_LIBS = ("/usr/lib/oclgrind/liboclgrind-rt-icd.so",
            "/usr/lib/x86_64-linux-gnu/oclgrind/liboclgrind-rt-icd.so",
            "/usr/local/lib/oclgrind/liboclgrind-rt-icd.so")
TIMEOUT_S = 600

pytestmark = pytest.mark.slow


def _icd_library() -> str | None:
    for path in ICD_LIBS:
        if os.path.isfile(path):
            return path
    return None


def _builtin(kind: str) -> list[str]:
    if kind == "fx":
        return sorted(child.FX)
    if kind == "effect":
        from clfx.plugins import discover

        return sorted(discover())
    from clfx.pipeline.presets import available_looks

    return sorted(n for n, (origin, _) in available_looks().items() if origin == "built-in")


# -- the log -------------------------------------------------------------------------------
_API_ERROR = re.compile(r"Oclgrind - OpenCL runtime error detected\n\tFunction: (\S+)\n"
                        r"\tError: +(\S+)\n(?:\t([^\n]*)\n)?")

_NOT_A_HEADER = ("First entity", "Second entity", "Oclgrind: ")
"""Continuation lines of a data-race report, and the "N errors generated" summary."""

TOLERATED_API = {
    # pyopencl asks every device for NVIDIA's compute capability
    # (CL_DEVICE_COMPUTE_CAPABILITY_MAJOR_NV, 0x4000) when it builds a program and creates a
    # kernel, and handles the refusal; nothing in clfx asks for an optional parameter.
    ("clGetDeviceInfo", "CL_INVALID_VALUE", "For argument 'param_name'"),
}


_RACE_SIDE = re.compile(r"(First|Second) entity: +Global\([^)]*\) Local\([^)]*\) "
                        r"Group\(([^)]*)\)\n.*?\n\s*At line \d+[^\n]*\n\s*([^\n]*)", re.S)


def is_vkfft_inplace_race(block: str) -> bool:
    """The one report tolerated: VkFFT's in-place r2c kernel (``VkFFT_main``, corona and
    glare through ``clfx.fx.fftconv``) reads ``inputs[i]`` into registers and, after
    barriers that fence only local memory, another work-item of the same work-group writes
    ``outputs[i]``, the same buffer.  Oclgrind orders global accesses only across a
    ``CLK_GLOBAL_MEM_FENCE`` barrier (RaceDetector::workGroupBarrier), so it reports a
    read-write race; the value read has gone through local memory before the barrier, so
    the write cannot overtake it.  A 3x16x16 in-place r2c round trip gives 1000 such reports
    (every one within a work-group, every one this load/store pair) and the out-of-place
    transform none.  A write-write race, a race across work-groups, or any other access
    pair is still reported."""
    if not block.startswith("Read-write data race") or "Kernel: VkFFT_main" not in block:
        return False
    sides = _RACE_SIDE.findall(block)
    if len(sides) != 2 or sides[0][1] != sides[1][1]:
        return False
    code = sorted(s[2] for s in sides)
    return (any(re.search(r"= inputs\[inoutID\];$", c) for c in code)
            and any(re.match(r"outputs\[inoutID\] = ", c) for c in code))


def parse_findings(log: str, stderr: str) -> list[str]:
    """Every error Oclgrind reported: one string per message (kernel, kind, location), the
    tolerated API refusals (``TOLERATED_API``) left out."""
    found = []
    lines = log.splitlines()
    heads = [i for i, line in enumerate(lines)
             if line and not line[0].isspace() and not line.startswith(_NOT_A_HEADER)]
    for i, end in zip(heads, heads[1:] + [len(lines)]):
        block = "\n".join(lines[i:end])
        if is_vkfft_inplace_race(block):
            continue
        kernel = re.search(r"Kernel: (\S+)", block)
        where = re.search(r"At line (\d+)", block)
        found.append(f"{kernel.group(1) if kernel else '?'}: {lines[i].strip()}"
                     + (f" (line {where.group(1)})" if where else ""))
    for m in _API_ERROR.finditer(stderr):
        key = (m.group(1), m.group(2), (m.group(3) or "").strip())
        if key not in TOLERATED_API:
            found.append(f"API: {key[0]} {key[1]} {key[2]}".strip())
    for line in stderr.splitlines():
        if "OCLGRIND FATAL ERROR" in line or line.startswith("Oclgrind - ") and "runtime error" not in line:
            found.append(f"fatal: {line.strip()}")
    return found


def run_group(tmp_path: Path, *args: str, timeout: int = TIMEOUT_S, uninitialized: bool = False):
    """Run ``tests/oclgrind_child.py ARGS`` under Oclgrind; return (records, findings, proc).

    ``uninitialized``: Oclgrind's uninitialised-value check, off for clfx's kernels: in 21.10
    it segfaults (``Uninitialized::instructionExecuted``, a ``memcpy``) on the vector
    shuffles of the first kernel every render runs (``analysis_rows``), optimised or not."""
    lib = _icd_library()
    if lib is None:
        pytest.skip("Oclgrind is not installed (Debian: apt-get install oclgrind; make setup)")
    vendors = tmp_path / "icd"
    vendors.mkdir(exist_ok=True)
    (vendors / "oclgrind.icd").write_text(lib + "\n")
    log = tmp_path / f"oclgrind-{'-'.join(a.replace('/', '_') for a in args)}.log"
    env = dict(os.environ)
    for k in list(env):
        if k.startswith(("OCLGRIND_", "CLFX_")):
            del env[k]
    env.update(
        OCL_ICD_VENDORS=str(vendors), OPENCL_VENDOR_PATH=str(vendors), CLFX_DEVICE="oclgrind",
        OCLGRIND_CHECK_API="1", OCLGRIND_DATA_RACES="1",
        **({"OCLGRIND_UNINITIALIZED": "1"} if uninitialized else {}), OCLGRIND_LOG=str(log),
        OCLGRIND_MAX_ERRORS="1000000", OCLGRIND_NUM_THREADS="1", CLFX_TEST_OPT_DISABLE="1",
        PYTHONPATH=os.pathsep.join(
            [str(ROOT)] + [p for p in [os.environ.get("PYTHONPATH")] if p]),
        XDG_CACHE_HOME=str(tmp_path / "cache"))
    proc = subprocess.run([sys.executable, str(CHILD), *args], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=timeout)
    records = [json.loads(line) for line in proc.stdout.splitlines() if line.startswith("{")]
    text = log.read_text(errors="replace") if log.exists() else ""
    findings = parse_findings(text, proc.stderr)
    if proc.returncode != 0:
        findings.append(f"exit {proc.returncode}: {proc.stderr.strip()[-2000:]}")
    return records, findings, proc


def _check(records, findings, expect_runs):
    assert not findings, "Oclgrind reported:\n" + "\n".join(dict.fromkeys(findings))
    assert len(records) == expect_runs, records
    for r in records:
        assert r["device"].startswith("Oclgrind"), r
        assert r["finite"], r


GROUP_TESTS = {"test_effect_every_level_under_oclgrind": ("effect", ",".join(QUALITY_LEVELS)),
               "test_builtin_looks_under_oclgrind": ("look", "draft"),
               "test_fx_helper_under_oclgrind": ("fx", "draft")}
"""The tests that each run one group: their parameter is the effect or look name."""


def _group_args(item) -> tuple[str, ...] | None:
    kind, levels = GROUP_TESTS.get(getattr(item, "originalname", ""), (None, None))
    if kind is None or item.module.__name__ != __name__:
        return None
    return (kind, item.callspec.params[kind], levels)


@pytest.fixture(scope="module")
def groups(request, tmp_path_factory):
    """Each selected group's run, started ahead: Oclgrind is single-threaded, so up to
    ``CLFX_OCLGRIND_JOBS`` (default 2, at most the cores) groups run at once, each in its own
    process and folder, in the order the tests ask for them.  Under pytest-xdist the workers
    already run tests side by side: there each test runs its own group when it asks."""
    import concurrent.futures

    jobs = int(os.environ.get("CLFX_OCLGRIND_JOBS") or min(2, os.cpu_count() or 1))
    ahead = [] if hasattr(request.config, "workerinput") or _icd_library() is None else [
        a for a in map(_group_args, request.session.items) if a is not None]
    pool = concurrent.futures.ThreadPoolExecutor(max(jobs, 1), thread_name_prefix="oclgrind")
    started = {}

    def result(*args):
        if args not in started:
            started[args] = pool.submit(run_group, tmp_path_factory.mktemp("oclgrind"), *args)
        return started[args].result()

    for args in ahead:
        started[args] = pool.submit(run_group, tmp_path_factory.mktemp("oclgrind"), *args)
    yield result
    pool.shutdown(wait=True, cancel_futures=True)


@pytest.mark.parametrize("effect", _builtin("effect"))
def test_effect_every_level_under_oclgrind(groups, effect):
    records, findings, _ = groups("effect", effect, ",".join(QUALITY_LEVELS))
    tiled = [r for r in records if r["render"].endswith(" tiled")]
    _check(records, findings,
           len(QUALITY_LEVELS) + 2 + len(tiled) + len(child.EXTRA.get(effect, ())))
    for r in records:   # the effect did its work: the test's parameters are not an identity
        if r["size"] == [child.W, child.H]:
            assert r["ran"] == [effect], r
    assert_every_entry_point_ran_in_bands(effect, records)


def assert_every_entry_point_ran_in_bands(effect: str, records: list[dict]) -> None:
    """An effect that tiles renders each level's main frame in bands of 8 rows too, unless
    every entry point (kernel, and whether a float64 build) that level launched already ran
    in bands at a lower level: the band offsets are checked once per entry point and
    precision, not once per level (most levels launch the same kernels)."""
    if not child.tiles(effect):
        assert not any(r["render"].endswith(" tiled") for r in records), records
        return
    banded: set = set()
    for level in QUALITY_LEVELS:
        whole = next(r for r in records if r["render"] == f"{effect}@{level}")
        band = [r for r in records if r["render"] == f"{effect}@{level} tiled"]
        assert whole["entry_points"], whole
        if band:
            banded.update(band[0]["entry_points"])
        missing = set(whole["entry_points"]) - banded
        assert not missing, f"{effect}@{level}: never run in bands: {sorted(missing)}"
    assert any(r["render"] == f"{effect}@draft tiled" for r in records), records


LOOK_GROUPS = 3
"""The built-in looks run in this many child processes (every look in one would serialise
the longest test; one each compiled every shared program again, ~90 s of CI)."""


def _look_groups() -> list[str]:
    looks = _builtin("look")
    return [",".join(looks[i::LOOK_GROUPS]) for i in range(LOOK_GROUPS)]


@pytest.mark.parametrize("look", _look_groups())
def test_builtin_looks_under_oclgrind(groups, look):
    """Every built-in look at draft, a group of them per child (``look`` names them)."""
    records, findings, _ = groups("look", look, "draft")
    _check(records, findings, len(look.split(",")))
    for r in records:
        assert r["ran"], r


@pytest.mark.parametrize("fx", _builtin("fx"))
def test_fx_helper_under_oclgrind(groups, fx):
    """The helpers no render of the test frames reaches (``oclgrind_child.FX``)."""
    records, findings, _ = groups("fx", fx, "draft")
    _check(records, findings, 1)
    assert records[0]["exact"], records


BROKEN = {
    "oob": "kernel void k(global float *x, const int n)"
           "{ x[get_global_id(0) + 1] = 1.0f; }",
    "race": "kernel void k(global float *x, const int n)"
            "{ x[0] += (float)get_global_id(0); }",
    "uninit": "kernel void k(global float *x, const int n)"
              "{ float a[4]; x[get_global_id(0)] = a[get_global_id(0) % 4]; }",
}


@pytest.mark.parametrize("what", sorted(BROKEN))
def test_a_broken_kernel_is_caught(tmp_path, what):
    """The suite can fail: an out-of-bounds write and a race are each reported and parsed; so
    is an uninitialised read where that check can run (a scalar kernel)."""
    src = tmp_path / f"{what}.cl"
    src.write_text(BROKEN[what] + "\n")
    _, findings, _ = run_group(tmp_path, "kernel", str(src), timeout=120,
                               uninitialized=what == "uninit")
    assert findings, f"Oclgrind found nothing wrong with the {what} kernel"
    want = {"oob": "Invalid write", "race": "data race", "uninit": "Uninitialized value"}[what]
    assert any(want in f for f in findings), findings


def test_the_parser_reads_api_errors_and_tolerates_only_pyopencls_probe():
    probe = ("\nOclgrind - OpenCL runtime error detected\n\tFunction: clGetDeviceInfo\n"
             "\tError:    CL_INVALID_VALUE\n\tFor argument 'param_name'\n\n")
    bad = ("\nOclgrind - OpenCL runtime error detected\n\tFunction: clEnqueueReadBuffer\n"
           "\tError:    CL_INVALID_VALUE\n\tFor argument 'offset + cb'\n\n")
    assert parse_findings("", probe) == []
    race = ("Read-write data race at global memory address 0xe000000000004\n\tKernel: VkFFT_main\n"
            "\t\n\tFirst entity:  Global(1,0,0) Local(1,0,0) Group(0,0,0)\n\t  %2 = load\n"
            "\tAt line 92 (column 11) of input.cl:\n\t  loc_0.x = inputs[inoutID];\n\t\n"
            "\tSecond entity: Global(0,0,0) Local(0,0,0) Group({g})\n\t  store\n"
            "\tAt line 890 (column 18) of input.cl:\n\t  outputs[inoutID] = temp_0;\n\t\n")
    assert parse_findings(race.format(g="0,0,0"), "") == []
    assert parse_findings(race.format(g="1,0,0"), "") == [
        "VkFFT_main: Read-write data race at global memory address 0xe000000000004 (line 92)"]
    assert len(parse_findings(race.format(g="0,0,0").replace("VkFFT_main", "glare_mix"), "")) == 1
    assert parse_findings("", probe + bad) == [
        "API: clEnqueueReadBuffer CL_INVALID_VALUE For argument 'offset + cb'"]


# -- uninitialised device memory, on the default device ------------------------------------
POISONS = (0.0, 7.25)
"""Two finite fills for every pooled buffer a render takes (new or reused): an output that
depends on memory no kernel or upload wrote differs between them."""


def _poison_pool(rt, monkeypatch, poison: float) -> None:
    """From now on every buffer the pool hands out (new or reused) holds ``poison``; no cached
    map or spectrum carries an earlier run's memory over."""
    import numpy as np

    take = type(rt.cache).take

    def poisoned(cache, nbytes):
        buf = take(cache, nbytes)
        rt.cl.enqueue_fill_buffer(rt.queue, buf, np.float32(poison), 0,
                                  max(int(nbytes), 16) // 4 * 4)
        return buf

    monkeypatch.setattr(type(rt.cache), "take", poisoned)
    rt.cache.clear()


def _render_poisoned(rt, monkeypatch, look, level, poison):
    from clfx import api

    _poison_pool(rt, monkeypatch, poison)
    try:
        rgba, depth, vel, channels = child.scene(child.W, child.H)
        res = api.render_array(rgba, look, depth=depth, velocity=vel, channels=channels,
                               quality=level, frame=1)
    finally:
        monkeypatch.undo()
        rt.cache.clear()
    return res.rgba


def test_the_poisoned_pool_shows_a_read_of_unwritten_memory(rt, monkeypatch):
    """The check below can fail: an image nobody wrote reads back as each poison in turn."""
    got = []
    for p in POISONS:
        _poison_pool(rt, monkeypatch, p)
        got.append(rt.image((3, 5), 4).download())
        monkeypatch.undo()
    assert (got[0] == POISONS[0]).all() and (got[1] == POISONS[1]).all()


@pytest.mark.parametrize("effect", _builtin("effect"))
def test_no_output_depends_on_uninitialised_device_memory(rt, monkeypatch, effect):
    """Oclgrind 21.10's own uninitialised-value check cannot run on these kernels (see
    ``run_group``), so the same question is asked of the default device: every pooled buffer
    filled with 0, then with 7.25, before each use; every level's output must not change."""
    import numpy as np

    look = child.effect_look(effect, masked=True)
    for level in QUALITY_LEVELS:
        a, b = (_render_poisoned(rt, monkeypatch, look, level, p) for p in POISONS)
        bad = ~((a == b) | (np.isnan(a) & np.isnan(b)))
        assert not bad.any(), (f"{effect}@{level}: {int(bad.sum())} values depend on "
                               f"uninitialised device memory, e.g. at {np.argwhere(bad)[:3].tolist()}")
