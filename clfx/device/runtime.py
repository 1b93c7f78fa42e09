"""The OpenCL runtime: device choice, programs, device images, and the one cache
(``clfx.device.cache``: pooled buffers and every cached value under one byte cap).

Only this module creates OpenCL contexts.  Effects receive a :class:`Runtime` and work on
:class:`DeviceImage` objects, so a frame is uploaded once, stays on the device across a
look's chain of effects, and is downloaded once.

Device choice: every platform and device is tried in turn; a device is usable only if a tiny
kernel builds and runs on it and returns the right answer.  A CPU PoCL device is preferred
(it is what these machines have, and it supports double precision).  ``CLFX_DEVICE`` (or the
CLI's ``--device``) selects explicitly, as ``P:D`` (platform and device index) or a
case-insensitive substring of "platform name / device name".

Build options are pinned (``BUILD_OPTIONS``): no fast-math, because ``-cl-finite-math-only``
may fold the NaN guards away (notes/hard-cases.md case 4) and ``-cl-fast-relaxed-math``
relaxes ``pow``.  Kernels that can afford it opt into ``-cl-mad-enable`` via their own
defines.  PoCL caches compiled binaries under ``POCL_CACHE_DIR``; clfx points it at a
persistent folder (``$XDG_CACHE_HOME/clfx/pocl``) unless the user set it, pins its
worker threads one per core (``POCL_AFFINITY=1``, ``_ensure_pocl_affinity``) unless the user
set that or the process may not use every core, and has it compile each kernel's work-group
code once for every launch size (``POCL_WORK_GROUP_SPECIALIZATION=0``,
``_ensure_generic_work_groups``), so a new frame size compiles nothing.

Kernel cache: a program this machine never built is compiled (seconds; a look's first
render was 2-9x its warm time), then loaded from the cache (milliseconds).  The runtime
knows which (a marker per program beside PoCL's cache, `Runtime._built_marker`), lists its
builds (`Runtime.builds`) and, once per process before the first compile, calls
`cold_build_notice` (the command line's "compiling kernels ... once" line).
"""
from __future__ import annotations

import contextlib
import ctypes
import hashlib
import json
import os
import re
import sys
import tempfile
import threading
import time
import warnings
import weakref
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from clfx.core.errors import DeviceError, KernelBuildError
from clfx.core.rect import Rect
from clfx.device.cache import DeviceCache
from clfx.device.kernel_args import KernelArgs, KernelArgumentError, declaration

BUILD_OPTIONS = ("-cl-std=CL1.2", "-cl-mad-enable")
"""Pinned for every program.  ``-cl-mad-enable`` only allows fused multiply-add (more
accurate, not less, on CPUs with FMA); nothing here allows finite-math or relaxed maths."""

ALIGN_PX = 4
"""Rows of device images are padded to a multiple of this many pixels, so a work-item can
process 4 RGBA pixels (one ``float16``) without tail code."""

INSTALL_HINT = ("install PoCL, the CPU OpenCL driver: `sudo apt-get install pocl-opencl-icd "
                "ocl-icd-opencl-dev` (or run `make setup`); do not use PyPI's "
                "pocl-binary-distribution, which fails on these CPUs")

class KernelBuildWarning(UserWarning):
    """An OpenCL program built, and the compiler had something to say (its warnings, from the
    build log).  The command line shows these only with ``-v``."""


warnings.filterwarnings("ignore", category=KernelBuildWarning, append=True)
"""The OpenCL compiler's warnings (hundreds of lines on a cold PoCL cache) stay quiet wherever
clfx is used from, as on the command line without -v; appended, so a filter of the caller's
own (``-W``, ``warnings.simplefilter``) still shows them."""


_COMPILER_SUMMARY = re.compile(r"^\s*\d+ (warning|error)s?( and \d+ (warning|error)s?)? generated\.\s*$")


@contextlib.contextmanager
def _compiler_quiet(caught: list):
    """While a program builds, keep the compiler's own chatter off the terminal: PoCL's
    clang writes "N warnings generated." straight to file descriptor 2, and pyopencl warns
    (``CompilerWarning``).  Both land in ``caught``; anything else written to stderr
    meanwhile (another thread's messages) is passed on afterwards, and other warnings are
    re-issued."""
    # lazy: pyopencl is ~0.2 s; `clfx render --help` and `import clfx.api` load this module
    import pyopencl as cl

    with contextlib.suppress(Exception):
        sys.stderr.flush()
    try:
        saved = os.dup(2)
    except OSError:          # no descriptor 2 (a closed stderr): nothing to keep quiet
        saved = None
    with tempfile.TemporaryFile() as tmp, warnings.catch_warnings(record=True) as records:
        warnings.simplefilter("always")
        if saved is not None:
            os.dup2(tmp.fileno(), 2)
        try:
            yield
        finally:
            with contextlib.suppress(Exception):
                sys.stderr.flush()
            if saved is not None:
                os.dup2(saved, 2)
                os.close(saved)
        tmp.seek(0)
        text = tmp.read().decode("utf-8", "replace")
    other = []
    for line in text.splitlines():
        (caught if _COMPILER_SUMMARY.match(line) else other).append(line)
    if other:
        with contextlib.suppress(OSError):
            os.write(2, ("\n".join(other) + "\n").encode())
    for r in records:
        if issubclass(r.category, cl.CompilerWarning):
            caught.append(str(r.message))
        else:
            warnings.warn_explicit(r.message, r.category, r.filename, r.lineno)


_PROBE_SRC = """
kernel void clfx_probe(global float *x) {
    const int i = get_global_id(0);
    x[i] = x[i] * 2.0f + 1.0f;
}
"""


def default_cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "clfx" / "pocl"


def _ensure_pocl_cache() -> None:
    if "POCL_CACHE_DIR" not in os.environ:
        path = default_cache_dir()
        try:
            path.mkdir(parents=True, exist_ok=True)
            os.environ["POCL_CACHE_DIR"] = str(path)
        except OSError:
            pass  # PoCL falls back to its own default


def _ensure_generic_work_groups() -> None:
    """Have PoCL compile one work-group function per kernel for every launch size
    (``POCL_WORK_GROUP_SPECIALIZATION=0``) unless the user chose: specialised (PoCL's
    default), each kernel was compiled again for each local size a frame size led to, so
    every new frame size paid a cold compile (cinema on a 960x540 demo frame, kernel
    programs cached: first render 113 s specialised, 47.5 s generic; warm renders the same
    within the noise of a loaded machine: medians 3.24 and 3.32 s, fastest 3.16 and 3.10 s)."""
    os.environ.setdefault("POCL_WORK_GROUP_SPECIALIZATION", "0")


def _malloc_trim():
    """glibc's ``malloc_trim``, or None (another C library, another system)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        trim = ctypes.CDLL(None).malloc_trim
    except (OSError, AttributeError):
        return None
    trim.argtypes, trim.restype = [ctypes.c_size_t], ctypes.c_int
    return trim


_TRIM = _malloc_trim()


def release_freed_heap() -> None:
    """Give the pages of freed heap memory back to the system (glibc: ``malloc_trim``; a
    no-op elsewhere).  After a kernel build: the OpenCL compiler (PoCL's LLVM, in-process on
    a cold kernel cache) frees most of what it took, in pieces glibc keeps; they stayed
    resident through the render (a cold 1080p cinema frame peaked 250 MiB above a warm one,
    and 110 MiB with this)."""
    if _TRIM is not None:
        _TRIM(0)


def kernel_dir() -> Path:
    """Folder holding the ``.cl`` files: ``clfx/kernels`` in an installed wheel, or the
    repository's top-level ``kernels/`` in a source checkout (editable install; there
    ``clfx/kernels`` links to it, resolved: one spelling of the path)."""
    here = Path(__file__).resolve().parent.parent  # the clfx package
    for path in (here / "kernels", here.parent / "kernels"):
        if (path / "lib" / "common.h").is_file():
            return path.resolve()
    raise KernelBuildError(f"cannot find clfx's kernels folder next to {here} "
                           f"(is the package installed correctly?)")


@dataclass
class DeviceReport:
    """One platform/device pair and why it was chosen or rejected."""

    index: str
    platform: str
    device: str
    kind: str
    version: str
    usable: bool
    reason: str
    chosen: bool = False
    fp64: bool = False

    @property
    def label(self) -> str:
        return f"{self.platform} / {self.device}"


def _device_kind(dev) -> str:
    # lazy: pyopencl is ~0.2 s; `clfx render --help` and `import clfx.api` load this module
    import pyopencl as cl

    t = dev.type
    if t & cl.device_type.CPU:
        return "CPU"
    if t & cl.device_type.GPU:
        return "GPU"
    if t & cl.device_type.ACCELERATOR:
        return "accelerator"
    return "other"


def _test_device(dev) -> str | None:
    """None if a tiny kernel builds and computes correctly on ``dev``, else the reason."""
    # lazy: pyopencl is ~0.2 s; `clfx render --help` and `import clfx.api` load this module
    import pyopencl as cl

    try:
        ctx = cl.Context([dev])
        queue = cl.CommandQueue(ctx)
        prg = cl.Program(ctx, _PROBE_SRC).build(options=list(BUILD_OPTIONS))
        host = np.arange(16, dtype=np.float32)
        buf = cl.Buffer(ctx, cl.mem_flags.READ_WRITE | cl.mem_flags.COPY_HOST_PTR, hostbuf=host)
        prg.clfx_probe(queue, (16,), None, buf)
        out = np.empty_like(host)
        cl.enqueue_copy(queue, out, buf)
        queue.finish()
        if not np.array_equal(out, host * 2 + 1):
            return "test kernel returned wrong values"
    except Exception as exc:  # any driver failure means: not usable
        msg = " ".join(str(exc).split())
        return f"test kernel failed: {msg[:200]}"
    return None


BUILD_LOG = os.environ.get("CLFX_BUILD_LOG")
"""Opt-in: a file to which every program build appends one JSON line (kernel file, defines,
seconds, and the test running it, from ``PYTEST_CURRENT_TEST``).  The distinct (file, defines)
pairs are the programs a cold kernel cache compiles; ``scripts/test_cpu_table.py --builds``
sums them per test module.  VkFFT's plans (``clfx.fx.fftconv``) are logged as file ``vkfft``:
each builds a program of its own, a compile on a cold kernel cache."""


def log_build(file: str, defines, seconds: float) -> None:
    test = os.environ.get("PYTEST_CURRENT_TEST", "").rsplit(" (", 1)[0]
    with contextlib.suppress(OSError), open(BUILD_LOG, "a") as log:
        log.write(json.dumps({"file": file, "defines": [list(d) for d in defines],
                              "s": round(seconds, 3), "pid": os.getpid(), "test": test}) + "\n")


cold_build_notice = None
"""Process-wide: called once, as ``cold_build_notice(runtime)``, just before the first program
this process builds that was never built on this machine with this cache (its kernel cache
is cold for it: a compile of seconds, not a load of milliseconds).  None: say nothing (the
API, ``-q``).  The command line sets it to print ``clfx: compiling kernels for ... once``."""


@dataclass(frozen=True)
class BuildRecord:
    """A program this runtime built: kernel file, defines, seconds, and whether the kernel
    cache was cold for it (`Runtime.builds`)."""

    file: str
    defines: tuple
    seconds: float
    cold: bool


def _headers_digest(folder: Path) -> str:
    """A digest of the shared kernel sources (``kernels/lib``): a program includes them."""
    h = hashlib.sha1()
    for path in sorted(folder.rglob("*")):
        if path.is_file() and path.suffix in (".h", ".cl"):
            h.update(path.name.encode() + b"\0" + path.read_bytes())
    return h.hexdigest()


def _matches(selector: str, index: str, label: str) -> bool:
    s = selector.strip().lower()
    return s == index or s in label.lower()


def _ensure_pocl_affinity() -> None:
    """Pin PoCL's worker threads one per core (``POCL_AFFINITY=1``) where this process may use
    every core and the user has not chosen.  Unpinned, a few-millisecond kernel at times ran
    on one of the two threads while the other sat idle (distortion draft at 1080p, 300 runs
    per round: p90 3.1-4.0 ms and p95 up to 6 in spells, against 2.6-2.7 pinned; medians
    alike; the cinema look's sequence 1.25 against 1.24 fps).  Not where the process is
    confined to some cores (PoCL pins thread i to core i), nor for several local workers
    (``clfx.pipeline.distributed.worker_env`` turns it off there)."""
    global _AFFINITY_DEFAULTED
    if "POCL_AFFINITY" in os.environ or not hasattr(os, "sched_getaffinity"):
        return
    if os.sched_getaffinity(0) == set(range(os.cpu_count() or 0)):
        os.environ["POCL_AFFINITY"] = "1"
        _AFFINITY_DEFAULTED = True


_AFFINITY_DEFAULTED = False


def user_set_pocl_affinity() -> bool:
    """Whether ``POCL_AFFINITY`` is the user's (not ``_ensure_pocl_affinity``'s default)."""
    return "POCL_AFFINITY" in os.environ and not _AFFINITY_DEFAULTED


def is_pocl(platform_name: str) -> bool:
    """Whether an OpenCL platform is PoCL ("Portable Computing Language")."""
    name = platform_name.lower()
    return "portable computing language" in name or "pocl" in name


def survey_devices(selector: str | None = None) -> tuple[list[DeviceReport], object | None]:
    """Try every platform and device; return the reports and the chosen ``cl.Device``.

    Preference without a selector: usable CPU devices of a PoCL platform, then other usable
    CPU devices, then anything usable.  With a selector only matching devices are eligible.
    """
    _ensure_pocl_cache()
    _ensure_pocl_affinity()
    _ensure_generic_work_groups()
    try:
        # lazy: pyopencl is ~0.2 s; `clfx render --help` and `import clfx.api` load this module
        import pyopencl as cl
    except ImportError as exc:  # pragma: no cover - dependency missing
        raise DeviceError(f"pyopencl is not installed ({exc}); run `make setup`") from exc
    reports: list[DeviceReport] = []
    devices = {}
    try:
        platforms = cl.get_platforms()
    except Exception as exc:  # no ICD at all
        platforms = []
        reports.append(DeviceReport("-", "(none)", "(none)", "-", "-", False,
                                    f"no OpenCL platform: {' '.join(str(exc).split())[:160]}"))
    for pi, plat in enumerate(platforms):
        try:
            devs = plat.get_devices()
        except Exception as exc:
            reports.append(DeviceReport(f"{pi}:-", plat.name.strip(), "(no devices)", "-",
                                        plat.version, False, f"cannot list devices: {exc}"))
            continue
        for di, dev in enumerate(devs):
            index = f"{pi}:{di}"
            rep = DeviceReport(index, plat.name.strip(), dev.name.strip(), _device_kind(dev),
                               dev.version.strip(), False, "",
                               fp64="cl_khr_fp64" in dev.extensions)
            if selector and not _matches(selector, index, rep.label):
                rep.reason = f"not selected by CLFX_DEVICE/--device={selector!r}"
            else:
                failure = _test_device(dev)
                rep.usable = failure is None
                rep.reason = failure or "usable"
                devices[index] = dev
            reports.append(rep)

    def rank(r: DeviceReport):
        pocl = is_pocl(r.platform)
        return (0 if r.kind == "CPU" and pocl else 1 if r.kind == "CPU" else 2, r.index)

    usable = sorted((r for r in reports if r.usable), key=rank)
    chosen = None
    if usable:
        usable[0].chosen = True
        usable[0].reason = "in use"
        chosen = devices[usable[0].index]
        for r in usable[1:]:
            r.reason = f"usable, but {usable[0].label} is preferred (PoCL CPU first)"
    return reports, chosen


@dataclass(eq=False)
class DeviceImage:
    """An image on the device: float32, ``channels`` per pixel, rows padded to ``pitch``.

    Layout: pixel (x, y) channel c of the window lives at float index
    ``(y * pitch + x) * channels + c``.  ``window`` places the image in the frame's full
    coordinate system (a data window).  Padding pixels (``x >= width``) hold finite values and
    are never meaningful.  The buffer returns to the runtime's pool when the image is dropped.
    """

    buffer: object
    window: Rect
    channels: int
    pitch: int
    runtime: "Runtime" = field(repr=False)

    @property
    def width(self) -> int:
        return self.window.width

    @property
    def height(self) -> int:
        return self.window.height

    @property
    def shape(self) -> tuple[int, ...]:
        h, w = self.window.shape
        return (h, w) if self.channels == 1 else (h, w, self.channels)

    @property
    def nbytes(self) -> int:
        return max(self.window.height, 1) * self.pitch * self.channels * 4

    def download(self) -> np.ndarray:
        return self.runtime.download(self)

    def like(self, window: Rect | None = None, channels: int | None = None) -> "DeviceImage":
        """A new, uninitialised image with this one's window and channels unless given."""
        return self.runtime.image(window or self.window, channels or self.channels)


GROUPS_PER_UNIT = 4
""":func:`row_groups` leaves at least this many work-groups per compute unit where the grid
allows, so no core idles behind another's last group."""

GROUP_ITEMS = 64
"""Rows narrower than this are stacked into one work-group (:func:`row_groups`) up to this
many work-items."""


def _divisor_at_most(n: int, cap: int) -> int:
    """The largest divisor of ``n`` that is at most ``cap`` (1 at least)."""
    for d in range(max(1, min(n, cap)), 0, -1):
        if n % d == 0:
            return d
    return 1


def row_groups(global_size: tuple, max_items: int, max_sizes: tuple,
               units: int) -> tuple | None:
    """The work-group size for a launch of ``global_size`` (x first) that names none, on a CPU
    device: whole rows (x) per group, rows narrower than ``GROUP_ITEMS`` stacked, at least
    ``GROUPS_PER_UNIT`` groups per compute unit where the grid has them; always an exact
    divisor of the global size, so the grid is unchanged.  None (the device chooses) for
    3-D grids.

    A CPU device runs a group's work-items in a loop on one thread: a group along a row walks
    memory in order, and every core gets groups.  PoCL 3.1's own choice
    (``pocl_default_local_size_optimizer``) keeps a dimension's size a multiple of
    gcd(global, 8), and where that is 1 (an odd width) it sets the group's width to 1: the
    cinema look's grain_noise at 1080p, (241, 1088), ran in groups of (1, 136), one column
    each (24.0 ms of CPU; whole rows 21.0); dof_prepare at (493, 1128) in (1, 1128), 2.5x
    slower than at 496 wide.  Where the whole grid fits one group (dof_tile_cap, (60, 34))
    it ran on one thread (wall 5.0 ms; in rows 2.0)."""
    if len(global_size) not in (1, 2):
        return None
    gx = int(global_size[0])
    gy = int(global_size[1]) if len(global_size) == 2 else 1
    want = GROUPS_PER_UNIT * max(1, int(units))
    cap_x = max(1, min(max_items, int(max_sizes[0])))
    # a row's worth, or its largest part that leaves `want` groups when rows are few
    lx = _divisor_at_most(gx, min(cap_x, max(1, gx * gy // want)))
    if len(global_size) == 1:
        return (lx,)
    ly = 1
    if lx == gx and lx < GROUP_ITEMS:
        cap_y = min(GROUP_ITEMS // lx, max(1, gy // want), int(max_sizes[1]), max_items // lx)
        ly = _divisor_at_most(gy, max(1, cap_y))
    return (lx, ly)


class Runtime:
    """An OpenCL context, queue, program cache and buffer pool for one process.

    Use :meth:`Runtime.get` for the process-wide instance.  Programs are built once per
    (file, defines) and ``Kernel`` objects are reused.
    """

    _instance: "Runtime | None" = None
    _instance_lock = threading.Lock()

    def __init__(self, device=None, selector: str | None = None):
        # lazy: pyopencl is ~0.2 s; `clfx render --help` and `import clfx.api` load this module
        import pyopencl as cl

        if device is None:
            reports, device = survey_devices(selector)
            if device is None:
                raise DeviceError(no_device_message(reports, selector))
        self.cl = cl
        self.device = device
        self.ctx = cl.Context([device])
        self.queue = cl.CommandQueue(self.ctx)
        self.has_fp64 = "cl_khr_fp64" in device.extensions
        self._fp64_said = False
        self.cache = DeviceCache(self.ctx)
        self._programs: dict = {}
        self._kernels: dict = {}
        self._signatures: dict = {}
        """Each kernel's declaration and dtypes, by its handle (``Kernel.int_ptr``)."""
        self._groups: dict = {}
        """:meth:`_row_groups`'s answers, by kernel handle and global size."""
        self._lock = threading.RLock()
        self.kernel_dir = kernel_dir()
        self.builds: list[BuildRecord] = []
        """Every program built by this runtime, in order (``clfx prebuild`` reports them)."""
        self._headers: str | None = None
        self._cold_said = False

    @classmethod
    def get(cls, selector: str | None = None) -> "Runtime":
        """The process-wide runtime (created on first use)."""
        with cls._instance_lock:
            if cls._instance is None:
                cls._instance = cls(selector=selector or os.environ.get("CLFX_DEVICE"))
            return cls._instance

    @property
    def description(self) -> str:
        return f"{self.device.platform.name.strip()} / {self.device.name.strip()}"

    @property
    def shares_host_cores(self) -> bool:
        """Whether the device is the host's CPU (PoCL): its kernels and the host's threads
        (EXR codecs) take turns on the same cores (`clfx.pipeline.stream.stream_mode`)."""
        return bool(self.device.type & self.cl.device_type.CPU)

    @property
    def host_cpu_kernels(self) -> bool:
        """Whether kernels may use the CPU-only paths (``CLFX_HOST_CPU``, kernels/lib/common.h:
        ``__builtin_prefetch``, x86 streaming stores and ``sfence``, out-of-line cold paths):
        on PoCL's CPU device only.  Not on any device that reports the CPU type: Oclgrind
        reports every type and cannot build a prefetch (``llvm.prefetch`` is an undefined
        external function there), and another CPU implementation's compiler may not take
        the x86 builtins."""
        return self.shares_host_cores and is_pocl(self.device.platform.name)

    def streams_stores(self, nbytes: int) -> bool:
        """Whether a kernel writing ``nbytes`` of output should stream it past the cache
        (``CLFX_STREAM_STORES``, kernels/lib/common.h): on PoCL's CPU device
        (:attr:`host_cpu_kernels`), for an output of at
        least half its global memory cache, which would not stay cached beside its source
        anyway; the store then skips reading each line in first.  The kernels store whole
        64-byte lines, so buffers must be aligned to at least that."""
        cache = int(getattr(self.device, "global_mem_cache_size", 0) or 0)
        align_bits = int(getattr(self.device, "mem_base_addr_align", 0) or 0)
        return (self.host_cpu_kernels and cache > 0 and align_bits >= 512
                and nbytes >= cache // 2)

    @property
    def compute_units(self) -> int:
        return int(self.device.max_compute_units)

    # -- programs -------------------------------------------------------------------------
    @property
    def kernel_cache_dir(self) -> str | None:
        """Where compiled kernels are kept between processes: ``POCL_CACHE_DIR`` on PoCL
        (clfx points it at ``$XDG_CACHE_HOME/clfx/pocl``), None for another driver (it keeps
        its own cache, if any)."""
        if not is_pocl(self.device.platform.name):
            return None
        return os.environ.get("POCL_CACHE_DIR") or str(default_cache_dir())

    def _built_marker(self, src: str, opts: list[str]) -> Path:
        """The file that says this program was built before with this kernel cache: PoCL
        keys its cache on the source and options, so clfx keeps a marker per (device,
        driver, options, source, shared headers) beside it (deleting the cache deletes
        them); another driver's markers live in clfx's own cache folder."""
        if self._headers is None:
            self._headers = _headers_digest(self.kernel_dir / "lib")
        dev = self.device
        key = "\0".join([dev.platform.name, dev.platform.version, dev.name, dev.driver_version,
                          " ".join(opts), self._headers, src])
        digest = hashlib.sha1(key.encode()).hexdigest()
        root = Path(self.kernel_cache_dir or default_cache_dir().parent / "drivers")
        return root / "clfx-built" / digest[:2] / digest

    def use_fp64(self, wanted: bool) -> bool:
        """Whether a program asked for float64 (a quality Level's ``fp64``) gets it here.
        Where the device lacks ``cl_khr_fp64`` the first such request says so in one line on
        stderr (the ``reference`` level then accumulates in float32) and later ones do not."""
        if wanted and not self.has_fp64 and not self._fp64_said:
            self._fp64_said = True
            with contextlib.suppress(Exception):
                sys.stderr.write(f"clfx: {self.description} has no float64 (cl_khr_fp64): "
                                 f"levels that ask for it (reference) accumulate in float32\n")
                sys.stderr.flush()
        return bool(wanted) and self.has_fp64

    def program(self, file: str, fp64: bool = False, **defines):
        """The built program for ``kernels/<file>`` with ``-D`` defines (cached per process).
        ``fp64``: build with ``CLFX_FP64=1`` (``kernels/lib/precision.h``) where supported."""
        if self.use_fp64(fp64):
            defines["CLFX_FP64"] = 1
        key = (file, tuple(sorted((k, str(v)) for k, v in defines.items())))
        with self._lock:
            prg = self._programs.get(key)
            if prg is None:
                prg = self._build(file, key[1])
                self._programs[key] = prg
            return prg

    def _build(self, file: str, defines):
        cl = self.cl
        path = self.kernel_dir / file
        try:
            src = path.read_text()
        except OSError as exc:
            raise KernelBuildError(f"cannot read kernel file {path}: {exc}") from exc
        opts = list(BUILD_OPTIONS) + [f"-I{self.kernel_dir}"] + [f"-D{k}={v}" for k, v in defines]
        if self.has_fp64:
            opts.append("-DCLFX_HAS_FP64=1")
        if self.host_cpu_kernels:
            opts.append("-DCLFX_HOST_CPU=1")   # kernels/lib/common.h: prefetch, streaming, cold
        marker = self._built_marker(src, opts)
        cold = not marker.exists()
        if cold and not self._cold_said and cold_build_notice is not None:
            self._cold_said = True          # once per process, before the first compile
            cold_build_notice(self)
        caught: list[str] = []
        started = time.perf_counter()
        try:
            with _compiler_quiet(caught):
                prg = cl.Program(self.ctx, src).build(options=opts)
        except cl.Error as exc:
            log = str(exc)
            raise KernelBuildError(f"building kernels/{file} with {' '.join(opts)} failed:\n{log}") from exc
        finally:
            release_freed_heap()
        seconds = time.perf_counter() - started
        self.builds.append(BuildRecord(file, tuple(defines), seconds, cold))
        if cold:
            with contextlib.suppress(OSError):
                marker.parent.mkdir(parents=True, exist_ok=True)
                marker.write_text(f"{file} {' '.join(opts)} {seconds:.3f}\n")
        if BUILD_LOG:
            log_build(file, defines, seconds)
        if caught:
            try:
                log = prg.get_build_info(self.device, cl.program_build_info.LOG).strip()
            except cl.Error:
                log = ""
            warnings.warn(f"kernels/{file} ({' '.join(opts)}): the OpenCL compiler said:\n"
                          f"{log or chr(10).join(caught)}", KernelBuildWarning, stacklevel=2)
        return prg

    def kernel(self, file: str, name: str, fp64: bool = False, arg_types: str | None = None,
               **defines):
        """A reusable ``cl.Kernel`` named ``name`` from ``kernels/<file>`` (``fp64``: see
        :meth:`program`), typed by its declaration in ``clfx.device.kernel_args`` (its
        scalar argument dtypes; REAL is float64 in a ``CLFX_FP64`` build).  A kernel the table
        does not name is refused (:class:`~clfx.device.kernel_args.KernelArgumentError`)
        unless ``arg_types`` declares it here, in the table's words (a kernel from outside
        kernels/, as tests build)."""
        decl = (declaration(file, name) if arg_types is None
                else KernelArgs.parse(name, file, arg_types))
        if self.use_fp64(fp64):
            defines["CLFX_FP64"] = 1
        decl = decl.built_with(defines)
        key = (file, name, tuple(sorted((k, str(v)) for k, v in defines.items())), arg_types)
        with self._lock:
            knl = self._kernels.get(key)
            if knl is None:
                knl = self.cl.Kernel(self.program(file, **defines), name)
                if knl.num_args != len(decl.types):
                    raise KernelArgumentError(
                        f"kernels/{file} {name} takes {knl.num_args} arguments, its "
                        f"declaration {len(decl.types)} ({decl.signature()})")
                dtypes = [None if d is None else np.dtype(d)
                          for d in decl.dtypes(str(defines.get("CLFX_FP64", 0)) == "1")]
                knl.set_scalar_arg_dtypes(dtypes)
                self._signatures[knl.int_ptr] = (decl, tuple(dtypes),
                                                 tuple(_arg_check(d) for d in dtypes))
                self._kernels[key] = knl
            return knl

    def launch(self, knl, global_size, *args, local=None, wait: bool = False):
        """Enqueue ``knl`` (from :meth:`kernel`) over ``global_size`` (x first), rounded up to
        ``local`` if given.

        Arguments as the kernel's declaration types them (``clfx.device.kernel_args``):
        DeviceImages, pooled buffers or None where it takes a buffer, plain Python (or NumPy)
        ints and floats where it takes a scalar, a sequence of numbers for a vector; a call
        that does not match raises :class:`~clfx.device.kernel_args.KernelArgumentError`
        naming the kernel and the argument.
        """
        gsize = tuple(max(1, int(n)) for n in global_size)
        if local is not None:
            gsize = tuple(-(-g // l) * l for g, l in zip(gsize, local))
        elif self.shares_host_cores:
            local = self._row_groups(knl, gsize)
        ev = knl(self.queue, gsize, local, *self._checked_args(knl, args))
        # Submit now: PoCL 3.1 (pthread) left a kernel queued behind a running one for up
        # to ~4 ms more at random (distortion draft at 1080p, two kernels: 5.0 or 9.3 ms;
        # with a flush after each launch 5.1-6.0 ms)
        self.queue.flush()
        if wait:
            ev.wait()
        return ev

    def _row_groups(self, knl, gsize: tuple) -> tuple | None:
        """The work-group size of a launch that leaves it to the device, on a CPU device
        (:func:`row_groups`, per kernel and global size)."""
        key = (knl.int_ptr, gsize)
        try:
            return self._groups[key]
        except KeyError:
            pass
        try:
            most = int(knl.get_work_group_info(self.cl.kernel_work_group_info.WORK_GROUP_SIZE,
                                               self.device))
        except self.cl.Error:
            most = int(self.device.max_work_group_size)
        local = row_groups(gsize, most,
                           tuple(int(n) for n in self.device.max_work_item_sizes),
                           self.compute_units)
        if len(self._groups) > 4096:
            self._groups.clear()
        self._groups[key] = local
        return local

    def _checked_args(self, knl, args) -> list:
        """``args`` for ``knl``'s enqueue, checked against its declaration: buffers (a
        DeviceImage's, a pooled one's) where it takes buffers, scalars that its dtypes hold,
        vectors as its OpenCL vector type."""
        try:
            decl, dtypes, checks = self._signatures[knl.int_ptr]
        except KeyError:
            raise KernelArgumentError(f"launch: kernel {knl.function_name} was not made by "
                                      f"Runtime.kernel (it types its arguments)") from None
        if len(args) != len(dtypes):
            raise KernelArgumentError(
                f"kernels/{decl.file} {decl.kernel} takes {len(dtypes)} arguments, got "
                f"{len(args)} ({decl.signature()})")
        out = []
        # the common cases first, by exact type (a launch checked ~20 arguments at ~3 us each
        # through `_scalar`: ~4 ms of host time per 1080p cinema frame); the rest, and every
        # refusal, through the full checks below
        for i, (a, check) in enumerate(zip(args, checks)):
            kind = type(a)
            if check is _BUFFER:
                if kind is DeviceImage or kind is _PooledBuffer:
                    out.append(a.buffer)
                    continue
            elif check is _FLOAT:
                if kind is float:
                    out.append(a)
                    continue
            elif check is not _VECTOR and kind is int and check[0] <= a <= check[1]:
                out.append(a)
                continue
            out.append(self._checked_arg(a, dtypes[i], decl, i))
        return out

    def _checked_arg(self, a, dt, decl, i: int):
        """Argument ``i`` of ``decl``'s kernel, of dtype ``dt`` (None: a buffer), checked (see
        :meth:`_checked_args`)."""
        given = a
        if isinstance(a, (DeviceImage, _PooledBuffer)):
            a = a.buffer
        is_buffer = a is None or isinstance(a, self.cl.MemoryObjectHolder)
        if (dt is None) != is_buffer:
            want = "a buffer" if dt is None else dt.name
            raise KernelArgumentError(
                f"kernels/{decl.file} {decl.kernel}: argument {i + 1} "
                f"({decl.types[i]} {decl.names[i]}) wants {want}, got {type(given).__name__}")
        return a if dt is None else _scalar(a, dt, decl, i)

    def finish(self) -> None:
        self.queue.finish()

    # -- memory ---------------------------------------------------------------------------
    def buffer(self, nbytes: int):
        """A pooled raw buffer; returned to the pool when the returned handle is dropped."""
        buf = self.cache.take(nbytes)
        holder = _PooledBuffer(buf, nbytes)
        weakref.finalize(holder, self.cache.give, max(int(nbytes), 16), buf)
        return holder

    def image(self, window: Rect | tuple[int, int], channels: int = 4) -> DeviceImage:
        """An uninitialised pooled image covering ``window`` ((h, w) means origin 0, 0)."""
        if not isinstance(window, Rect):
            h, w = window
            window = Rect.from_size(w, h)
        pitch = max(ALIGN_PX, -(-window.width // ALIGN_PX) * ALIGN_PX)
        nbytes = max(window.height, 1) * pitch * channels * 4
        buf = self.cache.take(nbytes)
        img = DeviceImage(buf, window, channels, pitch, self)
        weakref.finalize(img, self.cache.give, nbytes, buf)
        return img

    def upload(self, array: np.ndarray, window: Rect | None = None) -> DeviceImage:
        """Copy a host array (h, w) or (h, w, c) into a new device image."""
        a = np.asarray(array, dtype=np.float32)
        channels = 1 if a.ndim == 2 else a.shape[2]
        h, w = a.shape[:2]
        window = window or Rect.from_size(w, h)
        if window.shape != (h, w):
            raise ValueError(f"array shape {a.shape} does not match window {window}")
        img = self.image(window, channels)
        if img.pitch == w and h > 0 and a.flags.c_contiguous:
            self.cl.enqueue_copy(self.queue, img.buffer, a)  # no padding: copy as is
        else:
            padded = np.zeros((max(h, 1), img.pitch, channels), np.float32)
            padded[:h, :w] = a.reshape(h, w, channels)
            self.cl.enqueue_copy(self.queue, img.buffer, padded)
        return img

    def download(self, img: DeviceImage) -> np.ndarray:
        """Copy a device image to a new host array (h, w) or (h, w, c), padding removed."""
        h, w = img.window.shape
        host = np.empty((max(h, 1), img.pitch, img.channels), np.float32)
        self.cl.enqueue_copy(self.queue, host, img.buffer)
        out = host if (img.pitch == w and h > 0) else np.ascontiguousarray(host[:h, :w])
        return out[..., 0] if img.channels == 1 else out

    def fill(self, img: DeviceImage, value: float = 0.0) -> DeviceImage:
        """Set every float of ``img`` (padding included) to ``value``."""
        self.cl.enqueue_fill_buffer(self.queue, img.buffer, np.float32(value), 0, img.nbytes)
        return img

    def copy(self, src: DeviceImage) -> DeviceImage:
        """A device-side copy of ``src`` (same window, channels and pitch)."""
        dst = self.image(src.window, src.channels)
        self.cl.enqueue_copy(self.queue, dst.buffer, src.buffer, byte_count=src.nbytes)
        return dst

    def reframe(self, img: DeviceImage, window: Rect, border: str = "zero") -> DeviceImage:
        """``img`` moved into ``window``: covered pixels copied, the rest ``border``-filled.

        ``border``: ``"zero"`` (transparent black) or ``"clamp"`` (nearest edge pixel, used to
        extend depth and velocity passes when an effect grows the beauty's window).  The row
        padding is zero, as an upload's: kernels that read whole quads of 4 pixels (the blurs
        of motion) see the same padding in a tile of a tiled render as in the whole render.
        """
        if window == img.window:
            return img
        dst = self.image(window, img.channels)
        knl = self.kernel("lib/image.cl", "image_reframe", CH=img.channels,
                          BORDER={"zero": 0, "clamp": 1}[border])
        dx, dy = window.x0 - img.window.x0, window.y0 - img.window.y0
        self.launch(knl, (dst.pitch // 4, window.height), img, img.pitch, img.width,   # quads
                    img.height, dst, dst.pitch, window.width, window.height, dx, dy, local=None)
        return dst

    def paste(self, src: DeviceImage, dst: DeviceImage, rect: Rect) -> None:
        """Copy the pixels of ``rect`` (frame coordinates, inside both windows) from ``src``
        into ``dst`` (one rectangular buffer copy; the tiles of a tiled render)."""
        if rect.empty:
            return
        ch = src.channels * 4
        sx, sy = rect.x0 - src.window.x0, rect.y0 - src.window.y0
        dx, dy = rect.x0 - dst.window.x0, rect.y0 - dst.window.y0
        self.cl.enqueue_copy(self.queue, dst.buffer, src.buffer,
                             src_origin=(sx * ch, sy, 0), dst_origin=(dx * ch, dy, 0),
                             region=(rect.width * ch, rect.height, 1),
                             src_pitches=(src.pitch * ch, 0), dst_pitches=(dst.pitch * ch, 0))

    def sanitize(self, img: DeviceImage) -> int:
        """Set the non-finite floats of a 4-channel image to 0 in place; return how many
        pixels had one (so a look can say so).  Waits for the count."""
        if img.channels != 4 or img.height == 0:
            return 0
        counter = self.to_device(np.zeros(1, np.int32))
        self.launch(self.kernel("lib/image.cl", "image_sanitize", CH=4, BORDER=0),
                    (-(-img.pitch // 32), img.height),   # 32 pixels a work-item
                    img, img.pitch, img.height, counter)
        return int(self.from_device(counter, np.int32, 1)[0])

    def to_device(self, array: np.ndarray):
        """A pooled raw buffer holding a copy of a small host array (weights, tables).  Up to
        :data:`QUEUED_UPLOAD_BYTES` the array is copied on the host and its upload queued (the
        buffer holds its event, and the event the copy): a blocking write waits for every
        kernel queued before it, so the host could not plan ahead while they ran (streaks'
        span tables between its passes)."""
        if 0 < np.asarray(array).nbytes <= QUEUED_UPLOAD_BYTES:
            a = np.array(array, order="C")                # the caller may change its array
            holder = self.buffer(a.nbytes)
            holder.pending = self.cl.enqueue_copy(self.queue, holder.buffer, a,
                                                  is_blocking=False)
            return holder
        a = np.ascontiguousarray(array)
        holder = self.buffer(a.nbytes)
        self.cl.enqueue_copy(self.queue, holder.buffer, a)
        return holder

    def from_device(self, holder, dtype, count: int) -> np.ndarray:
        out = np.empty(count, dtype)
        self.cl.enqueue_copy(self.queue, out, holder.buffer)
        return out


_BUFFER, _FLOAT, _VECTOR = "buffer", "float", "vector"

QUEUED_UPLOAD_BYTES = 2 ** 20
"""Largest host array `Runtime.to_device` copies and uploads without waiting (tables, spans,
weights); larger ones are written at once (no host copy of a map)."""


def _arg_check(dtype: np.dtype | None):
    """The fast check of a kernel argument of ``dtype`` (`Runtime._checked_args`): a buffer,
    a float, a vector, or the (least, most) an integer type holds."""
    if dtype is None:
        return _BUFFER
    if dtype.names:
        return _VECTOR
    if dtype.kind in "iu":
        info = np.iinfo(dtype)
        return int(info.min), int(info.max)
    return _FLOAT


def _scalar(value, dtype: np.dtype, decl, index: int):
    """``value`` as argument ``index`` of ``decl``'s kernel, of scalar or vector ``dtype``:
    an int (or bool) that the integer type holds, a number for a float, a sequence of as many
    numbers for a vector; else :class:`KernelArgumentError` naming the kernel and argument."""
    def refuse(wants: str):
        raise KernelArgumentError(f"kernels/{decl.file} {decl.kernel}: argument {index + 1} "
                                  f"({decl.types[index]} {decl.names[index]}) wants {wants}")

    if dtype.names:                                 # an OpenCL vector (pyopencl.cltypes)
        if getattr(value, "dtype", None) == dtype and np.size(value) == 1:
            return value                            # cltypes.make_float4(...) and the like
        base = dtype.fields[dtype.names[0]][0]
        try:
            arr = np.ascontiguousarray(value, dtype=base).reshape(-1)
        except (TypeError, ValueError):
            arr = None
        if arr is None or arr.size != len(dtype.names):
            refuse(f"{len(dtype.names)} numbers, got {value!r}")
        return arr.view(dtype)[0]
    if dtype.kind in "iu":
        if not isinstance(value, (int, np.integer, np.bool_)):
            refuse(f"an integer, got {value!r}")
        info, value = np.iinfo(dtype), int(value)
        if not info.min <= value <= info.max:
            refuse(f"a {dtype.name}, got {value} (out of range)")
        return value
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer,
                                                                     np.floating)):
        refuse(f"a number, got {value!r}")
    return value


class _PooledBuffer:
    """Keeps a pooled ``cl.Buffer`` alive; its finaliser returns the buffer to the pool.
    ``pending``: the event of its queued upload (`Runtime.to_device`), which keeps the host
    copy alive (the queue is in order: whoever takes the buffer next runs after it)."""

    __slots__ = ("buffer", "nbytes", "pending", "__weakref__")

    def __init__(self, buffer, nbytes):
        self.buffer = buffer
        self.nbytes = nbytes
        self.pending = None


def no_device_message(reports: list[DeviceReport], selector: str | None) -> str:
    found = "; ".join(f"{r.label}: {r.reason}" for r in reports) or "no OpenCL platforms"
    head = ("no OpenCL device matches " + repr(selector)) if selector else "no usable OpenCL device"
    return f"{head} ({found}); {INSTALL_HINT}"
