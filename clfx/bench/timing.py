"""Timing of the bench's measurements: warm-up, timed runs, runs paired with a peer's.

Every figure is the median (and min, max) of warm runs; `timed_pair` alternates two
operations run for run so a shared machine's drift reaches both alike.
"""
from __future__ import annotations

import time

import numpy as np

WARMUP_SHORT_S = 0.1
"""Every measurement gets a second warm-up run; operations shorter than this keep warming up
for `WARMUP_S` (at least 2 more runs).  After a level's one-off set-up (seconds of host NumPy
for a map) the first runs of a millisecond kernel were 1.5-2.5x slower than the rest, for
a dozen runs at times (distortion draft at 1080p: 5.8, 8.8, 8.5, then 4.4-4.5 ms)."""

WARMUP_S = 0.25
"""Warm-up time of an operation shorter than `WARMUP_SHORT_S`: at most this, and at most 50
of its runs (50 runs of a 5 ms kernel; tiny test frames warm up for milliseconds)."""

SHORT_RUNS = 25
"""Timed runs of an operation shorter than `WARMUP_SHORT_S` (``repeat`` if more): on this
2-core PoCL machine a few-millisecond kernel takes one of two times: distortion draft at
1080p ~2.4 ms, or, in 10-25 % of runs and in spells, ~5-6 ms, its time on one PoCL thread
(5.0-5.1 ms with POCL_MAX_PTHREAD_COUNT=1); a median of 5 runs fell on either, the median
of 25 is the usual time (the slow runs show in the max)."""


def warm(fn, repeat: int) -> tuple[object, int]:
    """Warm ``fn`` up; its last result and the number of timed runs it needs."""
    result = fn()  # warm-up: compiles kernels, builds plans and caches
    t0 = time.perf_counter()
    result = fn()
    once = time.perf_counter() - t0
    if once < WARMUP_SHORT_S:
        start, runs = time.perf_counter(), 0
        budget = min(WARMUP_S, 50 * once)
        while runs < 2 or time.perf_counter() - start < budget:
            result = fn()
            runs += 1
        repeat = max(repeat, SHORT_RUNS)
    return result, repeat


def timed(fn, repeat: int) -> tuple[object, list[float]]:
    """``fn`` warmed up (`warm`), then timed: its last result and the times (ms) of its runs."""
    result, repeat = warm(fn, repeat)
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = fn()
        times.append((time.perf_counter() - t0) * 1e3)
    return result, times


def timed_pair(fn, other, repeat: int) -> tuple[object, list[float], list[float]]:
    """``fn`` and ``other`` timed alternately, run for run: ``fn``'s last result, its times
    and ``other``'s.  These shared machines drift (the same kernel 4.5 ms in one minute and
    5.8 ms in the next, with nothing else running here), so a peer timed a minute after the
    level it is compared with can win or lose on the drift alone; alternating exposes both
    to the same spells.  Every run follows one of the other (f o f o ...), as in a pipeline
    where each runs after other work: neither finds its own data left in the cache by its
    previous run.  (Distortion draft against cv2.remap bilinear at 1080p: 0.82-0.93 this
    way; 0.97-0.99 each run back to back in blocks of ten; 0.93-1.02 when the order also
    alternated, half the runs following their own.)"""
    result, n = warm(fn, repeat)
    _, m = warm(other, repeat)
    times, others = [], []
    for _ in range(max(n, m)):
        t0 = time.perf_counter()
        result = fn()
        t1 = time.perf_counter()
        other()
        t2 = time.perf_counter()
        times.append((t1 - t0) * 1e3)
        others.append((t2 - t1) * 1e3)
    return result, times, others


def stats(times: list[float]) -> dict:
    """Median, min and max of ``times`` (ms) as ``ms``, ``ms_min``, ``ms_max``."""
    return {"ms": float(np.median(times)), "ms_min": float(min(times)), "ms_max": float(max(times))}
