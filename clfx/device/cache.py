"""The runtime's one memory budget: idle device buffers and every cached derived object.

Effects keep things between frames (PSF spectra, resampling maps, noise tables, FFT plans,
weights on the device).  They never hold them in attributes or module globals: they ask the
runtime's cache, ``rt.cache.get(key, build)``, which builds on a miss and keeps the value
under one byte cap shared with the idle pooled buffers (``CLFX_POOL_MB``, default 640).

One eviction rule for everything, GreedyDual-Size (Cao & Irani 1997): each entry is worth
what rebuilding it costs per byte it holds (its measured build time; ``BUFFER_COST_S`` for an
idle buffer), plus an inflation value ``L`` that ages entries; a use raises an entry back to
``L + cost / size``; when the bytes held (idle buffers plus cached values) exceed the cap, the
entry worth least goes first and ``L`` becomes its worth.  Among equally costly entries this
is least-recently-used; across kinds it keeps a 100 MB distortion map that took 1.7 s to
build over an idle buffer or a PSF spectrum that takes 0.1 s, so a look whose spectra and maps
together exceed the cap does not rebuild its maps every frame.  A released idle buffer is
freed; an evicted value is dropped, and the pooled buffers it held come back as idle buffers
(and may be evicted in turn).  Entries of size 0 (compiled programs, small host tables) free
nothing and are never evicted.  A value larger than the cap on its own is returned but not
kept.

Keys are tuples whose first element names the owner (``("glare.psf", params_hash, radius)``),
so ``clear(owner)`` drops one effect's entries and ``stats()`` reports bytes per owner, and
the device memory the pool has allocated (``device_bytes``: live and idle buffers; PoCL keeps
them in host memory) with its peak (``device_peak``, restarted by ``reset_peak()``).
"""
from __future__ import annotations

import threading
import time
from collections import OrderedDict
from typing import Callable, Hashable, TypeVar

import numpy as np

from clfx.core.errors import DeviceError
from clfx.core.limits import env_int

T = TypeVar("T")

DEFAULT_BUDGET_BYTES = env_int("CLFX_POOL_MB", 640, minimum=0) * 2 ** 20
"""Bytes kept by idle pooled buffers and cached values together (``CLFX_POOL_MB``).  A 1080p
look's buffers, maps and spectra all fit, so a sequence allocates nothing after its first
frame; at 4K the largest FFT work buffers and spectra are released, bounding memory.  1080p
cinema holds 557 MiB between frames at final, 591 at preview (its CA and distortion maps and
glare's host planes among them): at 512 MiB four frame-sized buffers (~137 MB) were freed at
each frame's end and made again, paged in afresh (~18700 page faults, ~100 ms of CPU a frame).
The pool's device peak is the same either way (482 MiB: the buffers a frame frees are the
ones the next takes again); the process's resident peak over 5 frames was 746 and 774 MiB."""

_BUFFER = "buffer"

BUFFER_COST_S = 0.005
"""What re-creating an idle device buffer costs (PoCL: milliseconds), for eviction."""


def sizeof(value) -> int:
    """Bytes a cached value keeps alive: arrays, device images and buffers, and containers of
    them; objects with an integer ``nbytes``; 0 for anything else."""
    if value is None:
        return 0
    if isinstance(value, np.ndarray):
        return int(value.nbytes)
    if isinstance(value, (tuple, list)):
        return sum(sizeof(v) for v in value)
    if isinstance(value, dict):
        return sum(sizeof(v) for v in value.values())
    n = getattr(value, "nbytes", None)
    if isinstance(n, (int, np.integer)):
        return int(n)
    n = getattr(value, "size", None)  # a raw cl.Buffer
    if isinstance(n, (int, np.integer)) and type(value).__name__ == "Buffer":
        return int(n)
    return 0


class DeviceCache:
    """Idle buffers by size, and derived values by key, in one LRU under one byte cap."""

    def __init__(self, ctx, max_bytes: int = DEFAULT_BUDGET_BYTES):
        self._ctx = ctx
        self.max_bytes = int(max_bytes)
        # key -> (nbytes, value); idle buffers are keyed (_BUFFER, id(buf)) with value
        # (size, buf).  Order = recency, least recently used first (ties of worth).
        self._lru: OrderedDict[Hashable, tuple[int, object]] = OrderedDict()
        self._worth: dict[Hashable, tuple[float, float]] = {}  # key -> (worth, cost per byte)
        # idle buffers' keys by size, the most recently freed last (`take` scanned the LRU:
        # ~40 us a call, 81 calls a 1080p cinema frame)
        self._idle: dict[int, list] = {}
        self._inflation = 0.0
        self._bytes = 0
        self._idle_bytes = 0
        self._lock = threading.RLock()
        self._building: dict[Hashable, threading.Event] = {}   # key -> set when its build ends
        self.hits = 0
        self.misses = 0
        self.device_bytes = 0        # pooled buffers created and not yet released
        self.device_peak = 0         # the most device_bytes since creation or reset_peak()

    # -- derived values -------------------------------------------------------------------
    def get(self, key: tuple, build: Callable[[], T], nbytes: int | None = None,
            cost: float | None = None) -> T:
        """The value cached under ``key``, built by ``build()`` on a miss and kept (``nbytes``:
        its size when :func:`sizeof` cannot tell, e.g. an FFT plan's work memory; ``cost``:
        seconds a rebuild takes, measured on the build when not given).  A key another thread
        is building is waited for, not built twice (a look prepares its maps on a thread
        while the first frame renders)."""
        while True:
            with self._lock:
                hit = self._lru.get(key)
                if hit is not None:
                    self._lru.move_to_end(key)
                    self._touch(key)
                    self.hits += 1
                    return hit[1]
                building = self._building.get(key)
                if building is None:
                    done = self._building[key] = threading.Event()
                    break
            building.wait()   # then look again: kept, or build it here (too big, or failed)
        try:
            t0 = time.perf_counter()
            value = build()  # outside the lock: builds enqueue kernels and may take buffers
            cost = time.perf_counter() - t0 if cost is None else float(cost)
            size = sizeof(value) if nbytes is None else int(nbytes)
            with self._lock:
                self.misses += 1
                if key in self._lru or size > self.max_bytes:
                    return value
                self._lru[key] = (size, value)
                self._worth[key] = (0.0, cost / max(size, 1))
                self._touch(key)
                self._bytes += size
                self._evict()
            return value
        finally:
            with self._lock:
                self._building.pop(key, None)
            done.set()

    def peek(self, key: tuple):
        """The value under ``key`` or None; does not count as a use."""
        with self._lock:
            hit = self._lru.get(key)
            return None if hit is None else hit[1]

    def clear(self, owner: str | None = None) -> None:
        """Drop every cached value (of one owner: keys starting with ``owner``) and, without an
        owner, every idle buffer too."""
        with self._lock:
            keys = [k for k in self._lru
                    if (owner is None or (k[0] == owner and k[0] != _BUFFER))]
            for k in keys:
                self._drop(k)

    def stats(self) -> dict:
        """Bytes held per owner (``buffer`` for idle pooled buffers), hits and misses."""
        with self._lock:
            per: dict[str, int] = {}
            for k, (size, _) in self._lru.items():
                per[str(k[0])] = per.get(str(k[0]), 0) + size
            return {"bytes": self._bytes, "max_bytes": self.max_bytes, "owners": per,
                    "entries": len(self._lru), "hits": self.hits, "misses": self.misses,
                    "device_bytes": self.device_bytes, "device_peak": self.device_peak}

    def reset_peak(self) -> None:
        """Start measuring ``device_peak`` again from the bytes allocated now."""
        with self._lock:
            self.device_peak = self.device_bytes

    @property
    def nbytes(self) -> int:
        return self._bytes

    # -- idle buffers ---------------------------------------------------------------------
    def take(self, nbytes: int):
        """A buffer of ``nbytes``: the most recently freed idle one of that size, or new."""
        import pyopencl as cl   # lazy: ~0.4 s; the CLI loads the runtime without it

        nbytes = max(int(nbytes), 16)
        with self._lock:
            same = self._idle.get(nbytes)
            if same:
                key = same.pop()
                if not same:
                    del self._idle[nbytes]
                _, (size, buf) = self._lru.pop(key)
                self._worth.pop(key, None)
                self._bytes -= size
                self._idle_bytes -= size
                return buf
            self.device_bytes += nbytes      # PoCL: host memory (device buffers count in RSS)
            self.device_peak = max(self.device_peak, self.device_bytes)
        try:
            most = min(d.max_mem_alloc_size for d in self._ctx.devices)
            if nbytes > most:
                raise cl.Error(f"over the device's {most} bytes a buffer")
            return cl.Buffer(self._ctx, cl.mem_flags.READ_WRITE, nbytes)
        except (cl.Error, MemoryError) as exc:
            with self._lock:
                self.device_bytes -= nbytes
            raise DeviceError(f"cannot allocate a device buffer of {nbytes / 2 ** 30:.2f} GiB "
                              f"({' '.join(str(exc).split())[:120]}): a buffer derived from "
                              f"the frame (a blur sized from the diagonal of a thin frame?) "
                              f"is too large for the device") from None

    def give(self, nbytes: int, buf) -> None:
        """Return a buffer nobody uses any more: kept idle for reuse, within the budget."""
        nbytes = max(int(nbytes), 16)
        with self._lock:
            if nbytes > self.max_bytes:
                buf.release()
                self.device_bytes -= nbytes
                return
            key = (_BUFFER, id(buf))
            self._lru[key] = (nbytes, (nbytes, buf))
            self._idle.setdefault(nbytes, []).append(key)
            self._worth[key] = (0.0, BUFFER_COST_S / nbytes)
            self._touch(key)
            self._bytes += nbytes
            self._idle_bytes += nbytes
            self._evict()

    @property
    def idle_bytes(self) -> int:
        return self._idle_bytes

    # -- eviction -------------------------------------------------------------------------
    def _touch(self, key) -> None:
        """A use: the entry is worth the inflation plus its cost per byte again."""
        _, per_byte = self._worth[key]
        self._worth[key] = (self._inflation + per_byte, per_byte)

    def _evict(self) -> None:
        while self._bytes > self.max_bytes:
            # least worth first; ties go to the least recently used (dict order)
            victim = min((k for k, (size, _) in self._lru.items() if size > 0),
                         key=lambda k: self._worth[k][0], default=None)
            if victim is None:
                return
            self._inflation = max(self._inflation, self._worth[victim][0])
            self._drop(victim)

    def _drop(self, key) -> None:
        size, value = self._lru.pop(key)
        self._worth.pop(key, None)
        self._bytes -= size
        if key[0] == _BUFFER:
            same = self._idle[size]
            same.remove(key)
            if not same:
                del self._idle[size]
            self._idle_bytes -= size
            self.device_bytes -= size
            value[1].release()
        # a dropped value's pooled buffers come back through their finalisers (give())
        del value
