"""Limits every layer checks before allocating: a small hostile file must not take gigabytes.

``MAX_PIXELS`` bounds any frame, data or display window, or buffer derived from them (a
light-spreading effect's grown window, an FFT grid); ``CLFX_MAX_PIXELS`` overrides it.
"""
from __future__ import annotations

import json
import math
import os
import re

from clfx.core.errors import ClfxError


def available_cores() -> int:
    """The cores this process may run on (its CPU affinity where the OS has one)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def env_int(name: str, default: int, *, minimum: int | None = None) -> int:
    """The whole number in environment variable ``name`` (``default`` when unset or empty).
    ``1e3`` reads as 1000; anything else that is not a whole number (``abc``, ``1.5``), or one
    below ``minimum``, is a `ClfxError` naming the variable, in one line."""
    text = os.environ.get(name, "").strip()
    if not text:
        return default
    try:
        value = int(text)
    except ValueError:
        try:
            number = float(text)
        except ValueError:
            number = math.nan
        if not (math.isfinite(number) and number.is_integer()):
            raise ClfxError(f"{name}={text!r} is not a whole number (e.g. {default})") from None
        value = int(number)
    if minimum is not None and value < minimum:
        raise ClfxError(f"{name}={text!r} is below {minimum}")
    return value


MAX_SIDE = 65536
"""Largest width or height of any window, in pixels."""

MAX_PIXELS = env_int("CLFX_MAX_PIXELS", 8192 * 8192, minimum=1)
"""Largest area of any window or derived buffer, in pixels (``CLFX_MAX_PIXELS``; default
8192 x 8192, a 1 GiB float RGBA frame: 8K DCI fits, a claimed 16384^2 does not)."""


def check_pixels(width: int, height: int, what: str, exc: type[ClfxError] = ClfxError) -> None:
    """Raise ``exc`` naming ``what`` when a ``width`` x ``height`` area exceeds the limits."""
    if width > MAX_SIDE or height > MAX_SIDE or width * height > MAX_PIXELS:
        raise exc(f"{what} is {width}x{height}; the limit is {MAX_PIXELS} pixels and "
                  f"{MAX_SIDE} a side (CLFX_MAX_PIXELS)")


MEMORY_BASE_MIB = 600
"""What a render holds whatever the frame size (Python, OpenImageIO, the OpenCL driver and the
compiled kernels), in MiB: the constant of the documented memory budget."""

MEMORY_BYTES_PER_PIXEL = 72
"""Bytes per pixel of the documented memory budget (frame-sized device buffers, the host
frame, the band-wise map builds): peaks measured at 1080p, 4K UHD and 8K UHD, one frame or a
sequence, stay below it."""

OVERLAP_MAX_PIXELS = 3840 * 2160
"""Frames of a sequence up to this size are read and written on I/O threads while the device
renders the previous / next one; a larger frame is read, rendered and written alone, so a
sequence never holds more than one of them (an 8K frame renders for minutes: overlapping its
I/O gains little and would add ~1.5 GB to the peak)."""

PREPARE_MAX_PIXELS = OVERLAP_MAX_PIXELS // 2
"""A look's maps (distortion, chromatic aberration) are built on a thread while the first
frame is read and renders only for frames up to this size (1920x1080, 2K DCI, 2560x1440).
The maps, and the buffers they are built in, then coexist with the steps before them: at
4K UHD that put the cinema look 200-290 MiB higher (1574-1677 MiB, budget 1682), and at 8K,
where a map is too large to keep in the pool and the render built it again, 660 MiB
higher (3794 MiB, budget 3390).  Larger frames build each map when their step needs it."""

MEMORY_OVERLAP_BYTES_PER_PIXEL = 96
"""What a sequence of frames up to :data:`OVERLAP_MAX_PIXELS` adds to the budget per pixel:
the next frame read and the last one written while the device renders."""


def tile_pixels() -> int | None:
    """The most pixels a step that tiles renders at once (`clfx.pipeline.look.render_tiled`):
    ``CLFX_TILE_PIXELS`` (unset or 0: whole frames)."""
    value = env_int("CLFX_TILE_PIXELS", 0)
    return value if value > 0 else None


def memory_budget_mib(pixels: int, pool_mib: float, sequence: bool = False) -> float:
    """The documented bound on the peak resident memory of ``clfx render`` of frames of
    ``pixels`` through the cinema look, with ``CLFX_POOL_MB`` = ``pool_mib``, in MiB:
    ``MEMORY_BASE_MIB + CLFX_POOL_MB + MEMORY_BYTES_PER_PIXEL x pixels``, plus
    ``MEMORY_OVERLAP_BYTES_PER_PIXEL x pixels`` for a ``sequence`` of frames up to
    :data:`OVERLAP_MAX_PIXELS` (docs/performance.md, "Memory")."""
    per_pixel = MEMORY_BYTES_PER_PIXEL
    if sequence and pixels <= OVERLAP_MAX_PIXELS:
        per_pixel += MEMORY_OVERLAP_BYTES_PER_PIXEL
    return MEMORY_BASE_MIB + pool_mib + per_pixel * pixels / 2 ** 20


DERIVED_MIN_BYTES = 256 * 2 ** 20
"""The least a derived buffer may take whatever the frame (a PSF for a small frame)."""

DEVICE_BYTES_PER_PIXEL = 1024
"""Bytes per frame pixel the device buffers of one effect may take beyond ``CLFX_POOL_MB``
(:func:`check_derived`'s ``per_pixel`` for them): dof's padded planes at ``max_coc`` 1 on a
16:9 frame (the frame grown by a CoC radius of half its diagonal on every side, five
RGBA float planes and two CoC planes) take ~570; a 65535x1 frame's at the default 0.25
(the frame grown by 8192 rows above and below) took 28 GiB, 460000 a pixel."""


def check_derived(cells: int, bytes_per_cell: int, frame_w: int, frame_h: int,
                  pool_bytes: int, what: str, exc: type[ClfxError] = ClfxError, *,
                  per_pixel: int = MEMORY_BYTES_PER_PIXEL, hint: str = "lower its size") -> None:
    """Refuse, before allocating, a buffer derived from a ``frame_w`` x ``frame_h`` frame
    (a PSF sized from its diagonal: a thin 65535x1 frame's is 19661^2) whose ``cells`` x
    ``bytes_per_cell`` exceed the frame's share of the memory budget: ``CLFX_POOL_MB`` (at
    least 256 MiB) + ``per_pixel`` (`MEMORY_BYTES_PER_PIXEL`; `DEVICE_BYTES_PER_PIXEL` for
    an effect's device buffers) x its pixels; the line ends with ``hint``."""
    need = cells * bytes_per_cell
    budget = max(pool_bytes, DERIVED_MIN_BYTES) + per_pixel * frame_w * frame_h
    if need > budget:
        raise exc(f"{what} would take {need / 2 ** 30:.1f} GiB; the memory budget of a "
                  f"{frame_w}x{frame_h} frame allows {budget / 2 ** 30:.2f} GiB (CLFX_POOL_MB "
                  f"+ {per_pixel} bytes a pixel): {hint}")


MAX_JSON_NESTING = 32
"""Deepest nesting of JSON arrays and objects clfx reads (a stamped look needs 5, a Cryptomatte
manifest 1); deeper text is refused before parsing (Python's parser recurses per level)."""


def json_nesting(text: str) -> int:
    """The deepest nesting of ``[`` and ``{`` in JSON ``text`` (brackets inside strings not
    counted), in one pass without parsing."""
    depth = deepest = 0
    for ch in re.sub(r'"(?:[^"\\]|\\.)*"', '""', text):
        if ch in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif ch in "]}":
            depth -= 1
    return deepest


class _DuplicateKey(ValueError):
    """A JSON object names a key twice."""


def load_json(text: str, what: str, exc: type[ClfxError] = ClfxError, *,
              max_bytes: int | None = None, max_depth: int = MAX_JSON_NESTING, unique_keys: bool = False):
    """``json.loads(text)``, refusing in one line (``exc`` naming ``what``) text over
    ``max_bytes`` (UTF-8), nested deeper than ``max_depth``, with a key twice in one object
    (``unique_keys``: as look files refuse), or not JSON (an integer of more than Python's 4300 digits
    included)."""
    if max_bytes is not None and len(text) > max_bytes // 4 and len(text.encode()) > max_bytes:
        raise exc(f"{what} is {len(text.encode())} bytes; the limit is {max_bytes}")
    depth = json_nesting(text)
    if depth > max_depth:
        raise exc(f"{what} is nested {depth} levels deep; the limit is {max_depth}")
    def unique(pairs):
        out = {}
        for key, value in pairs:
            if key in out:
                raise _DuplicateKey(key)
            out[key] = value
        return out

    try:
        return json.loads(text, object_pairs_hook=unique if unique_keys else None)
    except _DuplicateKey as e:
        raise exc(f"{what} has the key {e.args[0]!r} twice (JSON would keep the last one)") \
            from None
    except (ValueError, RecursionError) as e:
        raise exc(f"{what} is not JSON ({' '.join(str(e).split())[:200]})") from None
