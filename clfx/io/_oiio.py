"""What reading, probing and writing share: OpenImageIO errors as one line, windows and their
limits, header attributes as plain values.  Private to `clfx.io`."""
from __future__ import annotations

import contextlib
import os
import re
import sys
import tempfile
import threading

import OpenImageIO as oiio

from clfx.core.errors import ImageIOError
from clfx.core.limits import check_pixels
from clfx.core.rect import Rect
from clfx.io.sequence import shown

# Attributes that describe the old file's layout or that writers reject: never carried over.
_SKIP_NAMES = {
    "compression", "PixelAspectRatio", "name", "view", "multiView", "channels", "tiles",
    "type", "version", "chunkCount", "dataWindow", "displayWindow", "lineOrder",
    "planarconfig", "XResolution", "YResolution", "ResolutionUnit", "ICCProfile",
    "Exif:MakerNote", "BitsPerSample", "Orientation",
    "chromaticities", "colorInteropID",      # written from the output's colour space
}
_SKIP_PREFIXES = ("oiio:", "openexr:", "exr:", "tiff:", "png:", "jpeg:", "dpx:", "hdr:",
                  "cineon:", "targa:", "webp:", "heif:")
_KNOWN_ATTR_TYPES = {
    "smpte:TimeCode": oiio.TypeTimeCode,
    "smpte:KeyCode": oiio.TypeKeyCode,
    "FramesPerSecond": oiio.TypeRational,
    "worldToCamera": oiio.TypeMatrix44,
    "worldToNDC": oiio.TypeMatrix44,
    "screenWindowCenter": oiio.TypeFloat2,
    "adoptedNeutral": oiio.TypeFloat2,
}
_MAX_ATTR_ELEMENTS = 64
_MAX_ATTR_CHARS = 4096


# ============================================================================================
# Errors

def oneline(msg: str) -> str:
    return " ".join(str(msg).split())


_FILE_BYTES = re.compile(r"magic 0x[0-9A-Fa-f]+ \(-?\d+\) flags 0x[0-9A-Fa-f]+"
                         r"(?: \(-?\d+\))?")
"""OpenEXR's "not an OpenEXR file" names the file's first 8 bytes (as magic and flags): of a
file that is no image (a link to a key, a password file), that is its content."""


def geterror(obj=None) -> str:
    """OpenImageIO's pending error message (global or ``obj``'s), decoded even when a damaged
    file put invalid UTF-8 into it (the binding raises UnicodeDecodeError then)."""
    try:
        text = (obj.geterror() if obj is not None else oiio.geterror()) or ""
    except UnicodeDecodeError as e:
        raw = e.object if isinstance(e.object, bytes) else b""
        text = raw.decode("utf-8", "replace") or "undecodable error message"
    return _FILE_BYTES.sub("no OpenEXR magic number", text)


def fail(path, what: str, detail: str = "") -> ImageIOError:
    """``ImageIOError("<what> <path>: <detail>")`` on one line, never quoting the file's
    own bytes."""
    detail = _FILE_BYTES.sub("no OpenEXR magic number", oneline(detail))
    return ImageIOError(f"{what} {os.fspath(path)}" + (f": {detail}" if detail else ""))


# ============================================================================================
# Windows

def spec_data_window(spec) -> Rect:
    return Rect.from_size(spec.width, spec.height, spec.x, spec.y)


def spec_display_window(spec) -> Rect:
    return Rect.from_size(spec.full_width, spec.full_height, spec.full_x, spec.full_y)


def win_json(r: Rect) -> dict:
    return {"x": r.x0, "y": r.y0, "width": r.width, "height": r.height}


def check_window(path, win: Rect, what: str = "data window", verb: str = "cannot read") -> None:
    """Refuse empty windows and windows over `clfx.core.limits` before allocating anything."""
    if win.width <= 0 or win.height <= 0:
        raise fail(path, f"empty or invalid {what} {win} in")
    check_pixels(win.width, win.height, f"{verb} {os.fspath(path)}: {what}", ImageIOError)


def type_name(t) -> str:
    """OIIO TypeDesc -> one of half/float/uint8/uint16 (what clfx calls a bit depth)."""
    b = t.basetype
    if b == oiio.HALF:
        return "half"
    if b in (oiio.FLOAT, oiio.DOUBLE):
        return "float"
    if b in (oiio.UINT8, oiio.INT8):
        return "uint8"
    return "uint16"


# ============================================================================================
# Attributes

def _json_value(value):
    """A JSON-able copy of an attribute value, or None to skip it."""
    if isinstance(value, bool):
        return value
    if isinstance(value, (int, float)):
        return value
    if isinstance(value, str):
        return value if len(value) <= _MAX_ATTR_CHARS else None
    if isinstance(value, (tuple, list)):
        flat = []
        for v in value:
            if isinstance(v, (tuple, list)):
                flat.extend(v)
            else:
                flat.append(v)
        if not flat or len(flat) > _MAX_ATTR_ELEMENTS:
            return None
        if not all(isinstance(v, (int, float, str)) for v in flat):
            return None
        return flat
    return None


def metadata(spec) -> dict:
    """All attributes of a spec as plain JSON-able values (binary and huge ones skipped)."""
    meta = {}
    for p in spec.extra_attribs:
        if p.name in ("ICCProfile", "Exif:MakerNote"):
            continue
        t = p.type
        if t.basetype in (oiio.UINT8, oiio.INT8) and (t.arraylen != 0 or
                                                      t.aggregate != oiio.SCALAR):
            continue           # binary blob
        try:
            value = _json_value(p.value)
        except Exception:      # an attribute type the Python binding cannot convert
            continue
        if value is not None:
            meta[p.name] = value
    return meta


def carry(name: str) -> bool:
    """Whether an input attribute is carried into outputs (layout and format ones are not)."""
    return name not in _SKIP_NAMES and not name.startswith(_SKIP_PREFIXES)


_STDERR = threading.RLock()
_quieted = 0


@contextlib.contextmanager
def codec_quiet(path: str):
    """While a PNG is read, descriptor 2 goes to a temp file: libpng prints its errors on
    stderr itself (``libpng error: IDAT: ...``) before OpenImageIO returns them, and clfx
    says them in its own one line.  Whatever else was written meanwhile (other threads'
    messages) is passed on afterwards; other formats are read as they are."""
    global _quieted
    try:
        with open(path, "rb") as f:
            png = f.read(8) == b"\x89PNG\r\n\x1a\n"
    except OSError:
        png = False
    if not png:
        yield
        return
    with _STDERR:
        if _quieted:
            yield
            return
        sys.stderr.flush()
        saved = os.dup(2)
        with tempfile.TemporaryFile() as held:
            os.dup2(held.fileno(), 2)
            _quieted += 1
            try:
                yield
            finally:
                _quieted -= 1
                sys.stderr.flush()
                os.dup2(saved, 2)
                os.close(saved)
                held.seek(0)
                rest = [line for line in held.read().decode("utf-8", "replace").splitlines(True)
                        if not line.startswith("libpng ")]
                if rest:
                    sys.stderr.write("".join(rest))


def _utf8(text: str) -> str:
    """``text`` as OpenImageIO can store it (UTF-8): what is not (a file name's non-UTF-8
    bytes on the command line, a lone surrogate) as backslash escapes (`shown`)."""
    try:
        text.encode("utf-8")
        return text
    except UnicodeEncodeError:
        return shown(text)


def set_attribute(spec, name: str, value) -> None:
    """Set one JSON-able attribute on an output spec, guessing its type (text that is not
    UTF-8 stamped with backslash escapes)."""
    if isinstance(value, str):
        value = _utf8(value)
    elif isinstance(value, (list, tuple)) and any(isinstance(v, str) for v in value):
        value = [_utf8(v) if isinstance(v, str) else v for v in value]
    if isinstance(value, bool):
        spec.attribute(name, int(value))
    elif isinstance(value, (int, float, str)):
        spec.attribute(name, value)
    elif isinstance(value, (list, tuple)) and value:
        value = tuple(value)
        if name in _KNOWN_ATTR_TYPES:
            spec.attribute(name, _KNOWN_ATTR_TYPES[name], value)
        elif all(isinstance(v, str) for v in value):
            spec.attribute(name, oiio.TypeDesc(f"string[{len(value)}]"), value)
        elif all(isinstance(v, int) and not isinstance(v, bool) for v in value):
            spec.attribute(name, oiio.TypeDesc(f"int[{len(value)}]"), value)
        elif all(isinstance(v, (int, float)) for v in value):
            floats = tuple(float(v) for v in value)
            if len(floats) == 16:
                spec.attribute(name, oiio.TypeMatrix44, floats)
            elif len(floats) == 9:
                spec.attribute(name, oiio.TypeMatrix33, floats)
            else:
                spec.attribute(name, oiio.TypeDesc(f"float[{len(floats)}]"), floats)
