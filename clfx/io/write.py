"""Writing frames with OpenImageIO: formats and encodings, and an atomic, checked publish.

================  ==================  =========  =======  ==========================
extension         bit depths          default    alpha    windows
================  ==================  =========  =======  ==========================
.exr              half, float         half       yes      data + display kept
.tif .tiff        uint8/16, half,     uint16     yes      kept when TIFF can store them
                  float                                   exactly, else display window
.png              uint8, uint16       uint8      yes      display window
.jpg .jpeg        uint8               uint8      no       display window
.dpx              uint8, uint10,      uint10     no       display window
                  uint16
.hdr              float               float      no       display window
================  ==================  =========  =======  ==========================

- Channels out = channels in: an output holds the beauty channels its input had (RGBA, RGB,
  grey ``Y`` with or without alpha, under their own names in an EXR that keeps its parts;
  `clfx.io.channels.beauty_out`), less an alpha the format cannot store; DPX and HDR have no
  grey (RGB).  Frames made in memory are written RGBA.
- "display window" outputs hold the display window; pixels outside the data window are
  black with alpha 0, data outside the display window is cropped.  TIFF keeps the windows
  when the display window starts at (0, 0), the data window lies inside it and pixels are
  square (OpenImageIO's TIFF positions are in resolution units), else it writes the display
  window like PNG.
- Half outputs are clamped to +-65504 first (1e5 -> 65504, not inf); NaN stays NaN.
- Display-referred outputs (integer TIFF, PNG, JPEG, DPX) are sRGB-encoded (whatever
  ``frame.encoding``), then clipped to 0..1 (NaN -> 0).  Formats without alpha drop it, which
  shows the premultiplied colour over black.
- EXR compression: none, zip, zips, piz, dwaa, dwab, pxr24, b44, rle; default: an EXR
  input's, else `DEFAULT_EXR_COMPRESSION` (zips).  TIFF: none, zip (default), lzw, packbits.
- Passes (``write_passes``, EXR only): ``Z`` = planar z in scene units, background +inf (the
  EXR/deep convention, read back as ``Z`` mode z); ``forward.u``, ``forward.v`` = forward
  pixels per frame in Nuke's y-up convention (``forward.v = -velocity[..., 1]``), so Nuke and
  clfx both read them back correctly.  Passes are always float, the beauty half or float.
- Metadata: ``frame.metadata`` is carried through, except attributes that describe the old
  file's layout or that OpenImageIO/EXR would reject (compression, tiling, channel formats,
  part names and views, resolutions, ``oiio:*``, ``openexr:*`` and other format-specific
  prefixes); ``attributes`` are added last (e.g. ``clfx:look``, ``clfx:paramsHash``).
- Deterministic bytes: the same frame and attributes give the same file.  OpenImageIO would
  stamp the write time as ``DateTime`` (EXR, TIFF): clfx writes no ``DateTime`` unless the
  input carried one (then it is kept).  DPX headers name the file: the output's name is
  written there, not the temp file's.

Atomic, checked, exclusive
--------------------------
1. The file is written to ``.<name>.tmp-<pid>-<8 hex>-<host><ext>`` in the output folder (created
   exclusively).  JPEG is encoded in memory first and copied (libjpeg ends the process on a
   write error), so a full disk is an error, never an exit.
2. Every result is checked: OpenImageIO's write and close return values; the temp file is not
   empty, its header reads back with the size and channels written, and PNG / JPEG end with
   their end-of-image marker (their writers do not report a short write).
3. Publish: without ``overwrite`` the temp file is hard-linked to ``path`` (``link`` fails if
   anything, even a dangling symlink, appeared there meanwhile: `OutputExistsError`), then
   unlinked; with ``overwrite`` it is renamed over ``path`` (``os.replace``).  File systems
   without hard links claim ``path`` with ``O_CREAT | O_EXCL`` and rename over the claim.
4. On any failure the temp file is removed and nothing is left at ``path``; the error is one
   line naming the output.  An output that resolves to one of the ``protect`` paths (the
   inputs) is refused even with ``overwrite``.

Text files (`write_text`: the gallery's index.json) are published the same way, and
`output_folder` creates an output folder (a file there, or a link out of the folder the
outputs belong in, is one error line).

A process killed mid-write leaves its temp file; `sweep_stale_temps` removes those whose
process is gone (``clfx render --skip-existing`` calls it).  On shared storage a farm task may
be retried on another machine, where the dead writer's PID means nothing: temp names carry a
token of the writer's host name, and a temp of another host is removed only once it has not
been written to for `REMOTE_TEMP_STALE_S` (a frame is written in seconds).
"""
from __future__ import annotations

import contextlib
import errno
import hashlib
import os
import re
import secrets
import socket
import threading
import time
from dataclasses import dataclass
from typing import Callable, Iterable, Sequence

import numpy as np
import OpenImageIO as oiio

from clfx.core.errors import ImageIOError
from clfx.core.frame import Frame, Layout, SourcePart, crop_to
from clfx.core.rect import Rect
from clfx.io import colour
from clfx.io._oiio import carry, check_window, fail, geterror, set_attribute
from clfx.io.channels import beauty_out, beauty_out_names
from clfx.io.sequence import check_input_file, check_name

HALF_MAX = 65504.0

EXR_COMPRESSIONS = ("none", "zip", "zips", "piz", "dwaa", "dwab", "pxr24", "b44", "rle")

DEFAULT_EXR_COMPRESSION = "zips"
"""EXR compression when neither the caller nor an EXR input says: lossless, as small as zip
and no dearer to write and read (1-scanline zip; Nuke's default), measured on this machine
(docs/pipeline.md, "EXR compression"): none and rle cost 40-60 % less CPU but write files 1.3-24x
larger, which a shared file server pays for (docs/scaling.md)."""
TIFF_COMPRESSIONS = ("none", "zip", "lzw", "packbits")


class OutputExistsError(ImageIOError):
    """The output exists (or appeared while it was being written) and ``overwrite`` is off."""


@dataclass(frozen=True)
class _OutFormat:
    oiio_name: str
    bit_depths: tuple[str, ...]
    default_bit_depth: str
    alpha: bool
    windows: str                  # "full", "tiff" (when representable) or "display"
    compressions: tuple[str, ...] = ()
    default_compression: str | None = None
    passes: bool = False


_OUT_FORMATS = {
    ".exr": _OutFormat("openexr", ("half", "float"), "half", True, "full",
                       EXR_COMPRESSIONS, DEFAULT_EXR_COMPRESSION, True),
    ".tif": _OutFormat("tiff", ("uint8", "uint16", "half", "float"), "uint16", True, "tiff",
                       TIFF_COMPRESSIONS, "zip"),
    ".png": _OutFormat("png", ("uint8", "uint16"), "uint8", True, "display"),
    ".jpg": _OutFormat("jpeg", ("uint8",), "uint8", False, "display"),
    ".dpx": _OutFormat("dpx", ("uint8", "uint10", "uint16"), "uint10", False, "display"),
    ".hdr": _OutFormat("hdr", ("float",), "float", False, "display"),
}
_OUT_FORMATS[".tiff"] = _OUT_FORMATS[".tif"]
_OUT_FORMATS[".jpeg"] = _OUT_FORMATS[".jpg"]

_DISPLAY_EXTS = {".png", ".jpg", ".jpeg", ".dpx", ".cin", ".tga", ".bmp", ".gif", ".webp"}


def encoding_for(path, bit_depth: str | None = None) -> str:
    """Guess an output's encoding from its extension (and bit depth for TIFF).

    Returns
    -------
    str
        ``"linear"`` for EXR, HDR, PFM and float/half TIFF; ``"sRGB"`` for PNG, JPEG, DPX,
        Cineon, TGA, BMP, GIF, WebP and integer TIFF (the TIFF default is uint16); ``"linear"``
        for anything else.
    """
    ext = os.path.splitext(os.fspath(path))[1].lower()
    if ext in (".tif", ".tiff"):
        return "linear" if bit_depth in ("half", "float") else "sRGB"
    if ext in _DISPLAY_EXTS:
        return "sRGB"
    return "linear"


def check_output_format(path, bit_depth: str | None = None,
                        compression: str | None = None) -> _OutFormat:
    """The output format of ``path``'s extension, with ``bit_depth`` and ``compression``
    checked against it: what `write_frame` refuses, said before any frame renders.

    Raises
    ------
    ImageIOError
        Unsupported extension, bit depth or compression (the allowed ones listed).
    """
    path = check_name(path, "cannot write")
    fmt = _out_format(path)
    if bit_depth is not None and bit_depth not in fmt.bit_depths:
        raise ImageIOError(f"cannot write {path}: bit depth {bit_depth!r} not supported; "
                           f"expected one of {', '.join(fmt.bit_depths)}")
    if compression is not None and compression not in fmt.compressions:
        allowed = ", ".join(fmt.compressions) or "none (no choice for this format)"
        raise ImageIOError(f"cannot write {path}: compression {compression!r} not supported; "
                           f"expected one of {allowed}")
    return fmt


def _out_format(path: str) -> _OutFormat:
    ext = os.path.splitext(path)[1].lower()
    if ext not in _OUT_FORMATS:
        raise ImageIOError(f"cannot write {path}: unsupported extension {ext or '(none)'!r}; "
                           f"expected one of {', '.join(sorted(_OUT_FORMATS))}")
    return _OUT_FORMATS[ext]


def _check_destination(path: str, overwrite: bool, protect: Iterable) -> str:
    """Refuse inputs, existing files (unless overwrite) and missing folders; return folder."""
    real = os.path.realpath(path)
    for p in protect:
        p = os.fspath(p)
        if p in ("", "-"):
            continue
        same = os.path.realpath(p) == real
        if not same and os.path.exists(p) and os.path.exists(path):
            with contextlib.suppress(OSError):
                same = os.path.samefile(p, path)
        if same:
            raise ImageIOError(f"refusing to write {path}: it is the input {p}")
    if os.path.isdir(path):
        raise ImageIOError(f"cannot write {path}: it is a folder")
    if os.path.lexists(path) and not overwrite:
        raise OutputExistsError(f"cannot write {path}: file exists (use overwrite)")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise ImageIOError(f"cannot write {path}: folder {folder} does not exist "
                           "or is not a folder")
    return folder


def _tiff_keeps_windows(frame: Frame) -> bool:
    d, w = frame.display_window, frame.data_window
    return d == w or (d.x0 == 0 and d.y0 == 0 and w.x0 >= 0 and w.y0 >= 0
                      and d.contains(w) and frame.pixel_aspect == 1.0)


def _beauty_pixels(frame: Frame, fmt: _OutFormat, path: str) -> tuple[np.ndarray, Rect, Rect]:
    """(rgba, data window, display window) to write: windows kept or flattened to display."""
    keep = fmt.windows == "full" or (fmt.windows == "tiff" and _tiff_keeps_windows(frame))
    if keep:
        return frame.rgba, frame.data_window, frame.display_window
    check_window(path, frame.display_window, "display window", "cannot write")
    rgba = crop_to(np.asarray(frame.rgba, np.float32), frame.data_window, frame.display_window)
    return rgba, frame.display_window, frame.display_window


def _encode(rgba: np.ndarray, source: str, target: str, display: bool, bit_depth: str,
            path: str) -> np.ndarray:
    rgba = colour.convert(np.asarray(rgba, np.float32), source, target, path)
    if display:
        rgba = np.clip(np.nan_to_num(rgba, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
    elif bit_depth == "half":
        rgba = np.clip(rgba, -HALF_MAX, HALF_MAX)     # 1e5 -> 65504, not inf; NaN stays
    return rgba


def _colour_attributes(spec, fmt: _OutFormat, target: str) -> None:
    """Tag the output's colour space: EXR ``chromaticities`` (linear spaces) and
    ``colorInteropID`` (from ``oiio:ColorSpace``, named spaces); sRGB PNG/TIFF/JPEG tags."""
    if target == colour.RAW:
        return
    if fmt.oiio_name == "openexr":
        chroma = colour.chromaticities(target)
        if chroma is not None:
            spec.attribute("chromaticities", oiio.TypeDesc("float[8]"), chroma)
        if not target.startswith(colour.CHROMA_PREFIX):
            spec.attribute("oiio:ColorSpace", target)
    elif colour.same(target, "sRGB"):
        spec.attribute("oiio:ColorSpace", "sRGB")


def _new_spec(data: Rect, display: Rect, names, formats, aspect: float):
    spec = oiio.ImageSpec(data.width, data.height, len(names), formats[0])
    spec.x, spec.y = data.x0, data.y0
    spec.full_x, spec.full_y = display.x0, display.y0
    spec.full_width, spec.full_height = display.width, display.height
    spec.channelnames = tuple(names)
    spec.alpha_channel = list(names).index("A") if "A" in names else -1
    if len(set(formats)) > 1:
        spec.channelformats = tuple(oiio.TypeDesc(f) for f in formats)
    spec.attribute("PixelAspectRatio", float(aspect))
    return spec


def _finish_spec(spec, metadata: dict, attributes: dict | None, compression: str | None):
    for name, value in (metadata or {}).items():
        if carry(name):
            set_attribute(spec, name, value)
    for name, value in (attributes or {}).items():
        set_attribute(spec, name, value)
    if not spec.get_string_attribute("DateTime"):
        spec.attribute("DateTime", "")     # else OpenImageIO stamps the time: bytes would vary
    if compression:
        spec.attribute("compression", compression)


def _make_spec(frame: Frame, fmt: _OutFormat, bit_depth: str, compression: str | None,
               data: Rect, display: Rect, names: list[str], pass_count: int,
               target: str, attributes: dict | None):
    oiio_type = "uint16" if bit_depth == "uint10" else bit_depth
    formats = [oiio_type] * (len(names) - pass_count) + ["float"] * pass_count
    spec = _new_spec(data, display, names, formats, frame.pixel_aspect)
    if bit_depth == "uint10":
        spec.attribute("oiio:BitsPerSample", 10)
    _finish_spec(spec, frame.metadata, attributes, compression)
    _colour_attributes(spec, fmt, target)
    return spec


WRITE_BLOCK_ROWS = 256
"""Rows assembled and written per call: a 4K frame is never held twice in full."""


@dataclass
class _OutPart:
    """One part (subimage) to write: its spec and ``rows(y0, y1)``, the pixels of rows
    ``y0 <= y < y1`` (file coordinates) as an (rows, width, channels) array."""

    spec: object
    rows: Callable[[int, int], np.ndarray]


def _planes_part(spec, planes: list[np.ndarray]) -> _OutPart:
    """A part whose pixels are ``planes`` (each (h, w, k), concatenated along channels)."""
    def rows(y0, y1):
        a, b = y0 - spec.y, y1 - spec.y
        return np.concatenate([p[a:b] for p in planes], axis=-1) if len(planes) > 1 \
            else planes[0][a:b]
    return _OutPart(spec, rows)


def _write_blocks(out, part: _OutPart) -> bool:
    """Write a part in row blocks."""
    spec = part.spec
    for y0 in range(spec.y, spec.y + max(spec.height, 1), WRITE_BLOCK_ROWS):
        y1 = min(spec.y + spec.height, y0 + WRITE_BLOCK_ROWS)
        block = part.rows(y0, y1)
        dtype = block.dtype if block.dtype in (np.float64, np.uint32) else np.float32
        if not out.write_scanlines(y0, y1, 0, np.ascontiguousarray(block, dtype)):
            return False
    return True


_TEMP_NAME = re.compile(r"\.(?P<name>.+)\.tmp-(?P<pid>[0-9]+)-[0-9a-f]{8}(?:-(?P<host>[0-9a-f]{8}))?"
                        r"(?P<ext>\.[^.]*)?")
REMOTE_TEMP_STALE_S = 3600.0
"""A temp file another host left is stale once it has not been written to for this long."""


def _host_token() -> str:
    """8 hex digits naming this machine in temp names (a PID is only meaningful on its host)."""
    return hashlib.sha1(socket.gethostname().encode("utf-8", "replace")).hexdigest()[:8]
_TRAILERS = {"png": b"\x00\x00\x00\x00IEND\xaeB`\x82", "jpeg": b"\xff\xd9"}
_IN_MEMORY = {"jpeg"}    # libjpeg calls exit() on a write error: encode in memory, then copy
_NO_HARD_LINKS = {errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EMLINK, errno.ENOSYS}
_COPY_CHUNK = 1 << 20


def _temp_path(path: str, folder: str) -> str:
    name = os.path.basename(path)
    ext = os.path.splitext(name)[1]
    return os.path.join(folder, f".{name}.tmp-{os.getpid()}-{secrets.token_hex(4)}-"
                                f"{_host_token()}{ext}")


def _memory_file() -> int | None:
    """An anonymous in-memory file OpenImageIO can open by name, or None where there is none."""
    if not hasattr(os, "memfd_create") or not os.path.isdir("/proc/self/fd"):
        return None
    return os.memfd_create("clfx-encode", getattr(os, "MFD_CLOEXEC", 0))


def _copy_into(src_fd: int, dst: str, path: str) -> None:
    """Copy an in-memory file into ``dst``, every write checked (a full disk raises)."""
    fd = os.open(dst, os.O_WRONLY | os.O_TRUNC)
    try:
        offset = 0
        while chunk := os.pread(src_fd, _COPY_CHUNK, offset):
            view = memoryview(chunk)
            while view:
                view = view[os.write(fd, view):]
            offset += len(chunk)
    except OSError as e:
        raise fail(path, "cannot write", e.strerror or str(e)) from None
    finally:
        os.close(fd)


def _name_dpx(target: str, path: str) -> None:
    """DPX headers carry a file name (100 bytes at offset 36): the output's, not the temp's."""
    with open(target, "r+b") as f:
        if f.read(4) in (b"SDPX", b"XPDS"):
            f.seek(36)
            f.write(os.path.basename(path).encode("utf-8", "replace")[:99].ljust(100, b"\0"))


def _encode_file(tmp: str, path: str, fmt: _OutFormat, parts: list[_OutPart]) -> None:
    """Encode into ``tmp`` (JPEG through memory), checking every OpenImageIO result."""
    mem = _memory_file() if fmt.oiio_name in _IN_MEMORY else None
    target = tmp if mem is None else f"/proc/self/fd/{mem}"
    try:
        out = oiio.ImageOutput.create(fmt.oiio_name)
        if out is None:
            raise fail(path, "cannot write", geterror() or f"no {fmt.oiio_name} writer")
        specs = [p.spec for p in parts]
        if not (out.open(target, specs) if len(parts) > 1 else out.open(target, specs[0])):
            raise fail(path, "cannot write", geterror(out))
        ok = True
        for i, part in enumerate(parts):
            if i and not out.open(target, part.spec, "AppendSubimage"):
                raise fail(path, "cannot write", geterror(out))
            if not _write_blocks(out, part):
                ok = False
                break
        err = geterror(out)
        closed = out.close()
        err = err or geterror(out)
        # Only a False return is a failure: OIIO 3.2's TIFF writer reports "failed
        # TIFFWriteCustomDirectory() of the Exif data" on every close, yet the file is whole.
        if not ok or not closed:
            raise fail(path, "cannot write", err or "write failed")
        if fmt.oiio_name == "dpx":
            _name_dpx(target, path)
        if mem is not None:
            _copy_into(mem, tmp, path)
    finally:
        if mem is not None:
            os.close(mem)


def _verify(tmp: str, path: str, fmt: _OutFormat, specs: list) -> None:
    """The written file is whole: not empty, every part's header reads back as written, and
    formats whose writers ignore short writes end with their end-of-image marker."""
    size = os.stat(tmp).st_size
    if size == 0:
        raise fail(path, "cannot write", "the file written is empty (disk full?)")
    inp = oiio.ImageInput.open(tmp)
    if inp is None:
        raise fail(path, "cannot write", "the file written does not read back: "
                   + (geterror() or "unreadable header"))
    try:
        for i, spec in enumerate(specs):
            if i and not inp.seek_subimage(i, 0):
                raise fail(path, "cannot write", f"the file written has no part {i}: "
                           + geterror(inp))
            got = inp.spec()
            if (got.width, got.height, got.nchannels) != (spec.width, spec.height,
                                                          spec.nchannels):
                raise fail(path, "cannot write", f"the file written reads back as {got.width}x"
                           f"{got.height}x{got.nchannels}, not {spec.width}x{spec.height}x"
                           f"{spec.nchannels}" + (f" (part {i})" if i else ""))
    finally:
        inp.close()
    trailer = _TRAILERS.get(fmt.oiio_name)
    if trailer:
        with open(tmp, "rb") as f:
            f.seek(max(size - len(trailer), 0))
            if f.read() != trailer:
                raise fail(path, "cannot write", f"the file written is truncated ({size} "
                           "bytes, no end-of-image marker; disk full?)")


def _publish(tmp: str, path: str, overwrite: bool) -> None:
    """Move the finished temp file to ``path``; never replace what appeared there meanwhile
    unless ``overwrite`` (hard link, which fails if ``path`` exists, even as a dangling link)."""
    if overwrite:
        os.replace(tmp, path)
        return
    exists = OutputExistsError(f"cannot write {path}: the file appeared while it was being "
                               "written (another writer?); not replaced without overwrite")
    try:
        os.link(tmp, path)
    except FileExistsError:
        raise exists from None
    except OSError as e:
        if e.errno not in _NO_HARD_LINKS:
            raise
        try:   # no hard links here: claim the name exclusively, then rename over the claim
            os.close(os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666))
        except FileExistsError:
            raise exists from None
        try:
            os.replace(tmp, path)
        except OSError:
            with contextlib.suppress(OSError):
                os.unlink(path)           # our empty claim
            raise
        return
    with contextlib.suppress(OSError):
        os.unlink(tmp)


_IN_FLIGHT: set[str] = set()
"""Temp files being written now (`abandon_writes` removes them)."""
_PUBLISHING = threading.Lock()
"""Held while a temp file is moved into place, and for ever by `abandon_writes`."""


def abandon_writes(timeout: float = 2.0) -> None:
    """For a process about to end at once (a SIGTERM its main thread did not answer in
    time): wait for a file being moved into place, then remove every temp file being
    written and publish nothing more (the lock is kept)."""
    _PUBLISHING.acquire(timeout=timeout)
    for tmp in list(_IN_FLIGHT):
        with contextlib.suppress(OSError):
            os.remove(tmp)


def _atomic_write(path: str, folder: str, fmt: _OutFormat, parts: list[_OutPart],
                  overwrite: bool) -> None:
    tmp = _temp_path(path, folder)
    try:
        fd = os.open(tmp, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666)
        os.close(fd)
    except OSError as e:
        raise ImageIOError(f"cannot write {path}: folder {folder} is not writable "
                           f"({e.strerror})") from None
    _IN_FLIGHT.add(tmp)
    try:
        _encode_file(tmp, path, fmt, parts)
        _verify(tmp, path, fmt, [p.spec for p in parts])
        with _PUBLISHING:
            _publish(tmp, path, overwrite)
    except OSError as e:
        raise fail(path, "cannot write", e.strerror or str(e)) from None
    except ImageIOError as e:
        if tmp not in str(e):
            raise
        raise type(e)(str(e).replace(tmp, path)) from None    # name the output, not the temp
    finally:
        _IN_FLIGHT.discard(tmp)
        with contextlib.suppress(OSError):
            os.remove(tmp)


def write_text(text: str, path, *, overwrite: bool = False, protect: Iterable = ()) -> None:
    """Write a text file (UTF-8) as `write_frame` writes an image: a temp file in the same
    folder, written and flushed in full, then published (hard link without ``overwrite``,
    ``os.replace`` with it).  Nothing is ever written through a symbolic link at ``path``:
    without ``overwrite`` it is an existing file (`OutputExistsError`), with it the link
    itself is replaced, never its target.  On any failure nothing is left at ``path``.

    Raises
    ------
    OutputExistsError
        ``path`` exists (even as a dangling link), or appeared while writing, and
        ``overwrite`` is off.
    ImageIOError
        ``path`` is a folder or an input (``protect``), its folder is missing or not
        writable, or a write failed (full disk).
    """
    path = os.fspath(path)
    folder = _check_destination(path, overwrite, protect)
    tmp = _temp_path(path, folder)
    try:
        fd = os.open(tmp, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666)
    except OSError as e:
        raise ImageIOError(f"cannot write {path}: folder {folder} is not writable "
                           f"({e.strerror})") from None
    try:
        try:
            view = memoryview(text.encode("utf-8"))
            while view:
                view = view[os.write(fd, view):]
        finally:
            os.close(fd)
        _publish(tmp, path, overwrite)
    except OSError as e:
        raise fail(path, "cannot write", e.strerror or str(e)) from None
    finally:
        with contextlib.suppress(OSError):
            os.remove(tmp)


def output_folder(path, *, inside=None, create: bool = True) -> str:
    """Create the folder ``path`` (and its parents) for outputs and return it; with
    ``create`` off only check that it could be one (a folder, or nothing yet).

    ``inside``: a folder ``path`` must stay in: ``path`` being a symbolic link (e.g.
    ``OUT/demo`` pointing elsewhere) is refused, so nothing is written outside ``inside``.

    Raises
    ------
    ImageIOError
        ``path`` exists and is not a folder, is a link out of ``inside``, or cannot be
        created.
    """
    path = os.fspath(path)
    if inside is not None and os.path.islink(path):
        raise ImageIOError(f"cannot write into {path}: it is a symbolic link "
                           f"({os.readlink(path)}); outputs stay in {os.fspath(inside)}")
    if os.path.lexists(path) and not os.path.isdir(path):
        raise ImageIOError(f"cannot write into {path}: it exists and is not a folder")
    if not create:
        return path
    try:
        os.makedirs(path, exist_ok=True)
    except OSError as e:
        raise ImageIOError(f"cannot create folder {path}: {e.strerror or e}") from None
    return path


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except (ProcessLookupError, OverflowError):
        return False
    except OSError:            # EPERM: someone else's live process
        return True
    return True


def sweep_stale_temps(outputs: Iterable) -> list[str]:
    """Remove temp files that a killed clfx left next to ``outputs``.

    A temp file ``.<name>.tmp-<pid>-<8 hex>-<host><ext>`` is removed when ``<name>`` is one of
    the outputs' names and, if it was written on this host (or names no host), process
    ``<pid>`` no longer exists (a live writer's file is kept); if another host wrote it, when
    it has not been modified for `REMOTE_TEMP_STALE_S`.

    Returns
    -------
    list of str
        The paths removed.
    """
    names: dict[str, set[str]] = {}
    for p in outputs:
        folder, name = os.path.split(os.path.abspath(os.fspath(p)))
        names.setdefault(folder, set()).add(name)
    removed, here, now = [], _host_token(), time.time()
    for folder, wanted in names.items():
        try:
            entries = list(os.scandir(folder))
        except OSError:
            continue
        for entry in entries:
            m = _TEMP_NAME.fullmatch(entry.name)
            if (m is None or m["name"] not in wanted
                    or (m["ext"] or "") != os.path.splitext(m["name"])[1]
                    or not entry.is_file(follow_symlinks=False)):
                continue
            if m["host"] in (None, here):
                if _alive(int(m["pid"])):
                    continue
            else:
                with contextlib.suppress(OSError):
                    if now - entry.stat(follow_symlinks=False).st_mtime < REMOTE_TEMP_STALE_S:
                        continue
            with contextlib.suppress(FileNotFoundError):
                os.unlink(entry.path)
                removed.append(entry.path)
    return removed


# ============================================================================================
# Defaults kept from the input; every channel and part written back

def _default_bit_depth(frame: Frame, fmt: _OutFormat) -> str:
    """EXR keeps the input's half or float; other formats have their own default."""
    if fmt.oiio_name == "openexr" and frame.bit_depth in fmt.bit_depths:
        return frame.bit_depth
    return fmt.default_bit_depth


def _default_compression(attributes: dict, fmt: _OutFormat, source: str = "") -> str | None:
    """The input's compression when this format has it (``dwaa:45`` -> dwaa) and the input
    is not a file of another format (a TIFF's or PNG's zip says nothing about an EXR), else
    the format's default (EXR: `DEFAULT_EXR_COMPRESSION`)."""
    ext = os.path.splitext(source or "")[1].lower()
    if ext and _OUT_FORMATS.get(ext) is not fmt:
        return fmt.default_compression
    got = str((attributes or {}).get("compression", "")).split(":")[0].lower()
    return got if got in fmt.compressions else fmt.default_compression


_EXR_TYPES = {"half": "half", "float": "float", "double": "float", "uint": "uint",
              "int": "uint"}


def _beauty_names(layout: Layout) -> tuple[tuple[str, ...], set[str]]:
    """(names an output writes a view's beauty under, the names it replaces): the input's
    own, so channels in = channels out (``left.R, left.G, left.B`` stay RGB, ``Y`` stays
    grey, an alpha stays; `clfx.io.channels.beauty_out` makes the pixels)."""
    return tuple(layout.beauty), set(layout.beauty)


class _Source:
    """The source file of a layout, open while its channels are copied."""

    def __init__(self, path: str, out_path: str, stored: dict | None = None):
        self.path, self.out_path, self.inp = path, out_path, None
        self.stored = stored or {}

    def rows(self, part: SourcePart, y0: int, y1: int, dtype, names: list[str],
             out: np.ndarray) -> None:
        """Channels ``names`` of rows ``y0..y1`` (inside the part's window) as stored, into
        ``out`` (rows, width, len(names)): from what the reader kept (`Layout.stored`) when
        it has them (each straight into its place: no stacked copy), else from the file."""
        kept = self.stored.get(part.index, {})
        if dtype == np.float32 and all(n in kept for n in names):
            a = y0 - part.data_window.y0
            for j, n in enumerate(names):
                out[..., j] = kept[n][a:a + y1 - y0]
            return
        got = self._file_rows(part, y0, y1, dtype)
        out[...] = got[..., [part.channels.index(n) for n in names]]

    def _file_rows(self, part: SourcePart, y0: int, y1: int, dtype) -> np.ndarray:
        if self.inp is None:
            check_input_file(self.path)
            self.inp = oiio.ImageInput.open(self.path)
            if self.inp is None:
                raise fail(self.out_path, "cannot write",
                           f"cannot copy channels from {self.path}: {geterror()}")
        fmt = "double" if dtype == np.float64 else "float"
        px = self.inp.read_scanlines(part.index, 0, y0, y1, 0, 0, len(part.channels), fmt)
        err = geterror(self.inp)
        if px is None or err:
            raise fail(self.out_path, "cannot write",
                       f"cannot copy channels from {self.path}: {err or 'read failed'}")
        return np.asarray(px, dtype).reshape(y1 - y0, part.data_window.width, -1)

    def close(self):
        if self.inp is not None:
            self.inp.close()


def _layout_parts(frame: Frame, views: list[Frame], fmt: _OutFormat, bit_depth: str,
                  compression: str | None, target: str, attributes: dict | None,
                  path: str, source: _Source) -> list[_OutPart]:
    """Every part of the frame's source file, in order: each rendered view's beauty in place
    of its channels, every other channel copied from the source as stored (padded with 0
    where a part's window grew with the beauty's)."""
    lay = frame.layout
    for v in views:
        if v.layout is None or v.layout.path != lay.path or v.layout.parts != lay.parts:
            raise ImageIOError(f"cannot write {path}: view {v.layout and v.layout.view!r} "
                               f"does not come from {lay.path}")
    rendered: dict[int, list] = {}
    for fr in [frame] + views:
        names, replaced = _beauty_names(fr.layout)
        pixels = beauty_out(_encode(fr.rgba, fr.colorspace, target, False, bit_depth, path),
                            len(names))
        rendered.setdefault(fr.layout.beauty_part, []).append((fr, names, replaced, pixels))
    out = []
    for i, sp in enumerate(lay.parts):
        subs = rendered.get(i, [])
        replaced = set().union(*(r[2] for r in subs)) if subs else set()
        carried = [(c, _EXR_TYPES.get(f, "float")) for c, f in zip(sp.channels, sp.formats)
                   if c not in replaced]
        window = sp.data_window if carried or not subs else subs[0][0].data_window
        for fr, *_ in subs:
            window = window.union(fr.data_window)
        names = [n for _, ns, _, _ in subs for n in ns] + [c for c, _ in carried]
        formats = [bit_depth] * sum(len(ns) for _, ns, _, _ in subs) + [f for _, f in carried]
        if not names:
            continue
        spec = _new_spec(window, frame.display_window, names, formats, frame.pixel_aspect)
        if subs and subs[0][0] is frame:
            meta, extra = frame.metadata, attributes
        else:
            meta, extra = sp.attributes, None
        own = sp.attributes.get("compression") if not (subs and subs[0][0] is frame) else \
            frame.metadata.get("compression")
        _finish_spec(spec, meta, extra, compression or _default_compression(
            {"compression": own}, fmt, lay.path))
        if sp.name:
            spec.attribute("name", sp.name)
        if sp.view:
            spec.attribute("view", sp.view)
        if sp.attributes.get("multiView"):
            set_attribute(spec, "multiView", sp.attributes["multiView"])
        if subs:
            _colour_attributes(spec, fmt, target)
        elif sp.attributes.get("chromaticities"):
            set_attribute(spec, "chromaticities", sp.attributes["chromaticities"])
        out.append(_OutPart(spec, _part_rows(sp, window, subs, [c for c, _ in carried],
                                             source)))
    return out


def _part_rows(sp: SourcePart, window: Rect, subs: list, carried: list[str], source: _Source):
    """``rows(y0, y1)`` of one output part (see `_layout_parts`)."""
    dtype = np.float64 if any(f in ("uint", "int") for c, f in zip(sp.channels, sp.formats)
                              if c in carried) else np.float32

    beauty = sum(len(names) for _, names, _, _ in subs)
    # every channel covers the part's window: each row block is filled whole, no zeros first
    whole = all(fr.data_window == window for fr, *_ in subs) and \
        (not carried or sp.data_window == window)

    def rows(y0, y1):
        block = (np.empty if whole else np.zeros)((y1 - y0, window.width,
                                                    beauty + len(carried)), dtype)
        k = 0
        for fr, names, _, pixels in subs:
            _place(block, y0, window, pixels, fr.data_window, slice(k, k + len(names)))
            k += len(names)
        if carried:
            w = sp.data_window
            a, b = max(y0, w.y0), min(y1, w.y1)
            if a < b:
                x = w.x0 - window.x0
                source.rows(sp, a, b, dtype, carried, block[a - y0:b - y0, x:x + w.width, beauty:])
        return block
    return rows


def _place(block, y0, window: Rect, pixels, win: Rect, channels: slice) -> None:
    """Copy the rows of ``pixels`` (covering ``win``) that fall in ``block``."""
    a, b = max(y0, win.y0), min(y0 + block.shape[0], win.y1)
    if a < b:
        x = win.x0 - window.x0
        block[a - y0:b - y0, x:x + win.width, channels] = pixels[a - win.y0:b - win.y0]


GREY_FORMATS = ("openexr", "tiff", "png", "jpeg")
"""Formats an output keeps a grey input grey in (DPX and Radiance HDR get RGB)."""


def _out_channel_count(frame: Frame, fmt: _OutFormat) -> int:
    """How many beauty channels a written-afresh output holds: the input's (its layout's
    beauty: 4 RGBA, 3 RGB, 2 grey + alpha, 1 grey; else ``frame.channels``, a raw stream's;
    4 for frames made in memory), less the
    alpha a format cannot store, grey as RGB where the format has no grey."""
    count = len(frame.layout.beauty) if frame.layout is not None else frame.channels or 4
    if not fmt.alpha and count in (2, 4):
        count -= 1
    if count < 3 and fmt.oiio_name not in GREY_FORMATS:
        count = 3
    return count


def write_frame(frame: Frame, path, *, bit_depth: str | None = None,
                compression: str | None = None, colorspace: str | None = None,
                overwrite: bool = False, attributes: dict | None = None,
                write_passes: bool = True, protect: Iterable = (),
                views: Sequence[Frame] = ()) -> None:
    """Write a frame atomically: a temp file in the same folder, checked, then published
    (hard link without ``overwrite``, ``os.replace`` with it; see the module docstring).

    Parameters
    ----------
    frame : Frame
        Linear premultiplied RGBA plus optional passes (internal conventions).
    path : str or os.PathLike
        Output file; the extension picks the format (see the module docstring's table).
    bit_depth : {"half", "float", "uint8", "uint10", "uint16"}, optional
        Beauty bit depth; default per format (EXR half, TIFF uint16, PNG/JPEG uint8, DPX
        10-bit, HDR float).
    compression : str, optional
        EXR: none, zip, zips, piz, dwaa, dwab, pxr24, b44, rle (default: the input's when it
        is an EXR, else zips).  TIFF: none, zip, lzw, packbits (default: the input's when it
        is a TIFF, else zip).  Other formats take none.
    colorspace : str, optional
        Output colour space: ``"linear"``/``"raw"`` (write the values), ``"sRGB"`` or an OCIO
        name; default `encoding_for` the output (sRGB for display-referred formats).
    overwrite : bool
        Replace an existing file.
    attributes : dict, optional
        Extra header attributes, e.g. ``{"clfx:look": "...", "clfx:paramsHash": "..."}``.
    write_passes : bool
        EXR only: also write depth as ``Z`` and velocity as ``forward.u/v`` (float).
    protect : iterable of paths
        Inputs that must never be overwritten, even with ``overwrite``.

    Raises
    ------
    OutputExistsError
        The output exists, or appeared while writing, and ``overwrite`` is off.
    ImageIOError
        Unsupported extension, bit depth or compression; output is an input; folder missing
        or unwritable; any OpenImageIO failure, short write or full disk (temp file removed,
        nothing at ``path``).
    """
    path = os.fspath(path)
    bit_depth = bit_depth or _default_bit_depth(frame, _out_format(path))
    fmt = check_output_format(path, bit_depth, compression)
    folder = _check_destination(path, overwrite, protect)

    display = encoding_for(path, bit_depth) == "sRGB"
    target = colour.output_space(colorspace, source=frame.source_colorspace,
                                 working=frame.colorspace, display=display)
    if write_passes and fmt.passes and frame.layout is not None:
        source = _Source(frame.layout.path, path, frame.layout.stored)
        try:
            parts = _layout_parts(frame, list(views), fmt, bit_depth, compression, target,
                                  attributes, path, source)
            _atomic_write(path, folder, fmt, parts, overwrite)
        finally:
            source.close()
        return
    rgba, data, display_win = _beauty_pixels(frame, fmt, path)
    count = _out_channel_count(frame, fmt)
    if not fmt.alpha:          # composite over black: encode the premultiplied colour as is
        rgba = np.concatenate([rgba[..., :3], np.ones(rgba.shape[:2] + (1,), np.float32)], -1)
    rgba = _encode(rgba, frame.colorspace, target, display, bit_depth, path)
    planes = [beauty_out(rgba, count)]
    names = list(beauty_out_names(count))
    pass_count = 0
    if write_passes and fmt.passes and data == frame.data_window:
        if frame.depth is not None:
            planes.append(np.asarray(frame.depth, np.float32)[..., None])
            names.append("Z")
            pass_count += 1
        if frame.velocity is not None:
            vel = np.asarray(frame.velocity, np.float32)
            planes.append(np.stack([vel[..., 0], -vel[..., 1]], axis=-1))   # Nuke: y-up
            names += ["forward.u", "forward.v"]
            pass_count += 2
    extra = dict(attributes or {})
    if pass_count:
        extra.setdefault("clfx:passes", "Z: planar z, scene units, inf background; "
                                        "forward.u/v: forward px/frame, y-up (Nuke)")
    compression = compression or _default_compression(frame.metadata, fmt, frame.source)
    spec = _make_spec(frame, fmt, bit_depth, compression, data, display_win, names,
                      pass_count, target, extra)
    _atomic_write(path, folder, fmt, [_planes_part(spec, planes)], overwrite)
