"""Reading and writing frames with OpenImageIO (the only clfx module that imports it).

Reading (`read_frame`)
----------------------
- Formats: OpenEXR (single- and multipart, scanline or tiled, half/float), PNG, JPEG, TIFF,
  DPX, Radiance HDR, and whatever else OpenImageIO reads.  Deep EXRs are refused.
- Pixels are returned as float32; grey becomes RGB and a missing alpha becomes 1.
- Multipart EXR: every part is scanned (``seek_subimage``).  The beauty, depth and velocity
  may live in different parts; a pass whose part has another data window is placed into the
  beauty's data window (depth outside the pass's window = +inf, velocity = 0).
- Windows: ``Frame.data_window`` is the data window (``spec.x, y, width, height``),
  ``Frame.display_window`` the display window (``spec.full_*``); ``PixelAspectRatio`` becomes
  ``Frame.pixel_aspect``; all attributes of the beauty's part become ``Frame.metadata`` (plain
  JSON-able values; binary blobs, ICC profiles and values over 64 elements / 4096 characters
  are skipped).
- Channels are always looked up by name (``spec.channelindex``); a missing channel is an
  error, never zeros.
- The beauty, depth and velocity search orders and the renderers' conventions are in
  `clfx.io.channels` (``probe`` prints them).  `PassSpec` overrides any of them.
- Depth or velocity in separate files (``depth_path``, ``velocity_path``): same search order in
  that file; if nothing matches and the file holds a single channel (or R/Y), that channel is
  the depth, or R, G are the velocity (forward, y-up unless `PassSpec` says otherwise).  The
  pass's data window must equal the beauty's, else `ClipError` naming both.

Colour
------
Integer-typed files other than EXR (8/16-bit PNG, JPEG, TIFF, and DPX/Cineon of any bit depth)
are display-referred: they are linearised from sRGB with OpenImageIO's colour management
(``colorconvert(buf, "sRGB", "linear")``, alpha divided out around the transfer function) and
``Frame.encoding = "sRGB"``.  EXR, HDR and float TIFF are scene-linear (``"linear"``).  DPX is
often log (Cineon printing density): clfx treats it as sRGB-like display data unless
``colorspace=`` says otherwise (e.g. ``"ACEScct"`` or ``"raw"``).  ``colorspace=`` names the
input colour space: ``"linear"`` (no conversion), ``"sRGB"``, ``"raw"`` (no conversion, pixels
as stored) or any OCIO name OpenImageIO knows (``"ACEScg"``, ``"Linear Rec.2020"``...),
converted to ``"linear"``.  Trap: OpenImageIO's ``"linear"`` is Linear Rec.709, while the
``scene_linear`` role of its built-in config is ACEScg; clfx works in Linear Rec.709.

Writing (`write_frame`)
-----------------------
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

- "display window" outputs hold the display window; pixels outside the data window are
  black with alpha 0, data outside the display window is cropped.  TIFF keeps the windows
  when the display window starts at (0, 0), the data window lies inside it and pixels are
  square (OpenImageIO's TIFF positions are in resolution units), else it writes the display
  window like PNG.
- Half outputs are clamped to +-65504 first (1e5 -> 65504, not inf); NaN stays NaN.
- Display-referred outputs (integer TIFF, PNG, JPEG, DPX) are sRGB-encoded (whatever
  ``frame.encoding``), then clipped to 0..1 (NaN -> 0).  Formats without alpha drop it, which
  shows the premultiplied colour over black.
- EXR compression: none, zip (default), zips, piz, dwaa, dwab, pxr24, b44, rle.  TIFF: none,
  zip (default), lzw, packbits.
- Passes (``write_passes``, EXR only): ``Z`` = planar z in scene units, background +inf (the
  EXR/deep convention, read back as ``Z`` mode z); ``forward.u``, ``forward.v`` = forward
  pixels per frame in Nuke's y-up convention (``forward.v = -velocity[..., 1]``), so Nuke and
  clfx both read them back correctly.  Passes are always float, the beauty half or float.
- Metadata: ``frame.metadata`` is carried through, except attributes that describe the old
  file's layout or that OpenImageIO/EXR would reject (compression, tiling, channel formats,
  part names and views, resolutions, ``oiio:*``, ``openexr:*`` and other format-specific
  prefixes); ``attributes`` are added last (e.g. ``clfx:look``, ``clfx:paramsHash``).
- Atomic: the file is written to ``.<name>.tmp-<pid>-<random><ext>`` in the output folder, then
  renamed over ``path`` with ``os.replace``; on any failure the temp file is removed.  An
  existing output is refused unless ``overwrite``; an output that resolves to one of the
  ``protect`` paths (the inputs) is refused even with ``overwrite``.

Robustness
----------
Every OpenImageIO failure becomes `ImageIOError` naming the file, with OpenImageIO's message on
one line.  Data windows over 65536 pixels a side or 2**31 pixels are refused before any
allocation.  All 186 fuzzed files of the OpenEXR ``Damaged`` set are rejected in-process
(measured with OpenImageIO 3.2 / OpenEXR 3.5: no crash, no hang, < 0.2 s each), so no
subprocess guard is used; a read that returns pixels but leaves an error message is an error.
Non-finite pixel values are not errors (effects sanitise them).
"""
from __future__ import annotations

import contextlib
import math
import os
import secrets
from dataclasses import dataclass, field
from typing import Iterable

import numpy as np
import OpenImageIO as oiio

from clfx.io import channels as ch
from clfx.core.errors import ClipError, ImageIOError
from clfx.core.frame import Frame
from clfx.core.rect import Rect

MAX_SIDE = 65536
MAX_PIXELS = 2 ** 31
HALF_MAX = 65504.0
MAX_PARTS = 4096

EXR_COMPRESSIONS = ("none", "zip", "zips", "piz", "dwaa", "dwab", "pxr24", "b44", "rle")
TIFF_COMPRESSIONS = ("none", "zip", "lzw", "packbits")

# Attributes that describe the old file's layout or that writers reject: never carried over.
_SKIP_NAMES = {
    "compression", "PixelAspectRatio", "name", "view", "multiView", "channels", "tiles",
    "type", "version", "chunkCount", "dataWindow", "displayWindow", "lineOrder",
    "planarconfig", "XResolution", "YResolution", "ResolutionUnit", "ICCProfile",
    "Exif:MakerNote", "BitsPerSample", "Orientation",
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
# Pass overrides

@dataclass(frozen=True)
class PassSpec:
    """Overrides for finding and interpreting depth and velocity.

    Parameters
    ----------
    depth_channel : str, optional
        Exact channel name of the depth, e.g. ``"depth.Z"``; default: the search order.
    depth_mode : {"auto", "z", "inverse", "distance", "normalized"}
        ``auto``: from the matched rule (see `clfx.io.channels`).  ``z``: planar z.  ``inverse``:
        1/z with far = 0 (Nuke).  ``distance``: radial distance from the camera, converted to
        planar z with ``focal_length_px``.  ``normalized``: 0..1 between ``depth_near`` and
        ``depth_far``.
    depth_scale : float
        Multiplies the converted depth (scene-unit conversion, e.g. cm -> m = 0.01).
    depth_near, depth_far : float
        Scene-unit depths of 0 and 1 for ``normalized``.
    velocity_channels : (str, str), optional
        Exact (u, v) channel names; default: the search order.
    velocity_y_up : bool, optional
        True if stored +v points up; None = from the detected convention (y-up when the names
        match no rule).
    velocity_scale : float
        Multiplies both components after conversion (e.g. shutter-interval -> per frame).
    velocity_direction : {"auto", "forward", "backward"}
        ``backward`` vectors are negated; ``auto`` = from the detected convention.
    focal_length_px : float, optional
        Focal length in pixels (pixel heights), required for ``depth_mode="distance"``.
    """

    depth_channel: str | None = None
    depth_mode: str = "auto"
    depth_scale: float = 1.0
    depth_near: float = 0.0
    depth_far: float = 1.0
    velocity_channels: tuple[str, str] | None = None
    velocity_y_up: bool | None = None
    velocity_scale: float = 1.0
    velocity_direction: str = "auto"
    focal_length_px: float | None = None

    def __post_init__(self):
        if self.depth_mode not in ch.DEPTH_MODES:
            raise ClipError(f"depth_mode {self.depth_mode!r} is not one of {ch.DEPTH_MODES}")
        if self.velocity_direction not in ch.VELOCITY_DIRECTIONS:
            raise ClipError(f"velocity_direction {self.velocity_direction!r} is not one of "
                            f"{ch.VELOCITY_DIRECTIONS}")
        if self.velocity_channels is not None and len(self.velocity_channels) != 2:
            raise ClipError(f"velocity_channels {self.velocity_channels!r} must be two names "
                            "(u, v)")
        if self.depth_mode == "distance" and not (self.focal_length_px or 0) > 0:
            raise ClipError("depth_mode='distance' needs focal_length_px > 0 "
                            "(focal length in pixels)")


# ============================================================================================
# Small helpers

def _oneline(msg: str) -> str:
    return " ".join(str(msg).split())


def _geterror(obj=None) -> str:
    """OpenImageIO's pending error message (global or ``obj``'s), decoded even when a damaged
    file put invalid UTF-8 into it (the binding raises UnicodeDecodeError then)."""
    try:
        return (obj.geterror() if obj is not None else oiio.geterror()) or ""
    except UnicodeDecodeError as e:
        raw = e.object if isinstance(e.object, bytes) else b""
        return raw.decode("utf-8", "replace") or "undecodable error message"


def _fail(path, what: str, detail: str = "") -> ImageIOError:
    detail = _oneline(detail)
    return ImageIOError(f"{what} {os.fspath(path)}" + (f": {detail}" if detail else ""))


def _window(spec) -> Rect:
    return Rect.from_size(spec.width, spec.height, spec.x, spec.y)


def _display(spec) -> Rect:
    return Rect.from_size(spec.full_width, spec.full_height, spec.full_x, spec.full_y)


def _win_json(r: Rect) -> dict:
    return {"x": r.x0, "y": r.y0, "width": r.width, "height": r.height}


def _check_size(path, win: Rect, what: str = "data window") -> None:
    """Refuse empty or absurd windows before allocating anything."""
    if win.width <= 0 or win.height <= 0:
        raise _fail(path, f"empty or invalid {what} {win} in")
    if win.width > MAX_SIDE or win.height > MAX_SIDE or win.width * win.height > MAX_PIXELS:
        raise _fail(path, f"{what} {win} exceeds {MAX_SIDE} px a side or 2**31 pixels in")


def _type_name(t) -> str:
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
# Scanning a file

@dataclass
class _Part:
    index: int
    name: str
    channels: tuple[str, ...]
    formats: tuple[str, ...]
    view: str | None
    views: tuple[str, ...]
    data_window: Rect
    display_window: Rect
    pixel_aspect: float
    deep: bool
    spec: object = field(repr=False, default=None)

    def as_dict(self) -> dict:
        """What `clfx.io.channels` needs."""
        return {"channels": list(self.channels), "view": self.view, "views": self.views}


@dataclass
class _File:
    path: str
    format: str
    parts: list[_Part]

    def dicts(self) -> list[dict]:
        return [p.as_dict() for p in self.parts]


@contextlib.contextmanager
def _open(path):
    """Open ``path`` with OpenImageIO; ImageIOError if missing or unreadable."""
    path = os.fspath(path)
    if not os.path.exists(path):
        raise ImageIOError(f"cannot read {path}: no such file")
    if os.path.isdir(path):
        raise ImageIOError(f"cannot read {path}: it is a folder")
    inp = oiio.ImageInput.open(path)
    if inp is None:
        raise _fail(path, "cannot read", _geterror() or "unknown format or damaged file")
    try:
        yield inp
    finally:
        inp.close()


def _part_from_spec(i: int, spec) -> _Part:
    views = spec.getattribute("multiView")
    views = tuple(views) if isinstance(views, (tuple, list)) else ((views,) if views else ())
    names = tuple(spec.channelnames)
    fmts = tuple(_type_name(t) for t in spec.channelformats) if spec.channelformats else \
        (_type_name(spec.format),) * len(names)
    aspect = spec.get_float_attribute("PixelAspectRatio", 1.0)
    if not (math.isfinite(aspect) and aspect > 0):
        aspect = 1.0
    return _Part(i, spec.get_string_attribute("name", ""), names, fmts,
                 spec.get_string_attribute("view", "") or None, views,
                 _window(spec), _display(spec), float(aspect), bool(spec.deep), spec)


def _scan(path) -> _File:
    """Headers of every part (no pixels)."""
    with _open(path) as inp:
        parts = []
        i = 0
        try:
            while i < MAX_PARTS and inp.seek_subimage(i, 0):
                parts.append(_part_from_spec(i, inp.spec()))
                i += 1
        except UnicodeDecodeError:
            raise _fail(path, "cannot read", "undecodable channel or attribute names "
                        "(damaged file)") from None
        _geterror(inp)      # clear "no such subimage" left by the last seek
        if not parts:
            raise _fail(path, "cannot read", "no image in file")
        return _File(os.fspath(path), inp.format_name(), parts)


def _runs(indices: list[int]) -> list[tuple[int, int]]:
    """Contiguous [begin, end) runs of sorted channel indices."""
    runs: list[tuple[int, int]] = []
    for i in sorted(set(indices)):
        if runs and runs[-1][1] == i:
            runs[-1] = (runs[-1][0], i + 1)
        else:
            runs.append((i, i + 1))
    return runs


def _read_channels(path, part: _Part, names) -> dict[str, np.ndarray]:
    """Read named channels of one part as float32 (h, w) arrays covering its data window."""
    if part.deep:
        raise _fail(path, "cannot read deep image", "deep EXR is not supported")
    _check_size(path, part.data_window)
    idx = {}
    for n in names:
        if n not in part.channels:
            raise _fail(path, f"channel {n!r} not found in part {part.index} of",
                        f"channels are {', '.join(part.channels)}")
        idx[n] = part.channels.index(n)
    out: dict[str, np.ndarray] = {}
    with _open(path) as inp:
        for begin, end in _runs(list(idx.values())):
            px = inp.read_image(part.index, 0, begin, end, "float")
            err = _geterror(inp)
            if px is None or err:
                raise _fail(path, "cannot read", err or "read failed")
            px = np.asarray(px, np.float32).reshape(part.data_window.height,
                                                    part.data_window.width, end - begin)
            for n, i in idx.items():
                if begin <= i < end:
                    out[n] = np.ascontiguousarray(px[..., i - begin])
    return out


# ============================================================================================
# Metadata

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


def _metadata(spec) -> dict:
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


def _carry(name: str) -> bool:
    return name not in _SKIP_NAMES and not name.startswith(_SKIP_PREFIXES)


def _set_attribute(spec, name: str, value) -> None:
    """Set one JSON-able attribute on an output spec, guessing its type."""
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


# ============================================================================================
# Planning: which channels, which conventions

@dataclass
class _PassPlan:
    path: str
    part: _Part
    channels: tuple[str, ...]
    rule: str
    why: str
    separate: bool
    mode: str | None = None
    direction: str | None = None
    y_up: bool | None = None


@dataclass
class _Plan:
    file: _File
    beauty: ch.BeautyChoice
    view: str | None
    depth: _PassPlan | None
    velocity: _PassPlan | None
    source_colorspace: str | None     # None: no conversion
    encoding: str


def _select_part(f: _File, part) -> int | None:
    if part is None:
        return None
    if isinstance(part, int):
        if not 0 <= part < len(f.parts):
            raise ImageIOError(f"part {part} not in {f.path} ({len(f.parts)} parts)")
        return part
    for p in f.parts:
        if p.name == part:
            return p.index
    names = ", ".join(repr(p.name) for p in f.parts)
    raise ImageIOError(f"part {part!r} not in {f.path}; parts are {names}")


def _available(f: _File) -> str:
    names = [n for p in f.parts for n in p.channels]
    more = f" (+{len(names) - 30} more)" if len(names) > 30 else ""
    return ", ".join(names[:30]) + more


def _plan_depth(f: _File, spec: PassSpec, view, prefer_part, separate: bool) -> _PassPlan | None:
    parts = f.dicts()
    if spec.depth_channel:
        p = ch.explicit_choice(parts, (spec.depth_channel,), view, prefer_part)
        if p is None:
            raise ClipError(f"depth channel {spec.depth_channel!r} not in {f.path}; "
                            f"channels: {_available(f)}")
        rule = ch.depth_rule_for(spec.depth_channel, f.parts[p].views)
        mode = rule.mode if rule else "z"
        why = f"explicit channel; {rule.source if rule else 'no known convention: planar z'}"
        choice = _PassPlan(f.path, f.parts[p], (spec.depth_channel,),
                           rule.pattern if rule else "explicit", why, separate, mode=mode)
    else:
        found = ch.find_depth(parts, view)
        if found is None and separate:
            found = _single_channel_fallback(f, 1)
        if found is None:
            return None
        choice = _PassPlan(f.path, f.parts[found.part], found.channels, found.rule, found.why,
                           separate, mode=found.mode)
    if spec.depth_mode != "auto":
        choice.mode = spec.depth_mode
        choice.why += f"; mode {spec.depth_mode!r} from PassSpec"
    return choice


def _single_channel_fallback(f: _File, n: int) -> ch.PassChoice | None:
    """For separate pass files: the only channel, or R/Y (depth); R, G (velocity)."""
    p = f.parts[0]
    if n == 1:
        for name in (("R", "Y") if len(p.channels) > 1 else p.channels):
            if name in p.channels:
                return ch.PassChoice(0, (name,), "file fallback",
                                     f"separate depth file: channel {name!r}, planar z",
                                     mode="z")
        return None
    if "R" in p.channels and "G" in p.channels:
        return ch.PassChoice(0, ("R", "G"), "file fallback",
                             "separate velocity file: R, G as forward u, v, y-up",
                             direction="forward", y_up=True)
    return None


def _plan_velocity(f: _File, spec: PassSpec, view, prefer_part, separate: bool) -> _PassPlan | None:
    parts = f.dicts()
    if spec.velocity_channels:
        names = tuple(spec.velocity_channels)
        p = ch.explicit_choice(parts, names, view, prefer_part)
        if p is None:
            raise ClipError(f"velocity channels {names!r} not (both) in one part of {f.path}; "
                            f"channels: {_available(f)}")
        rule = ch.velocity_rule_for(names[0], f.parts[p].views)
        choice = _PassPlan(f.path, f.parts[p], names, rule.label() if rule else "explicit",
                           "explicit channels; " + (rule.source if rule else
                                                    "no known convention: forward, y-up"),
                           separate, direction=rule.direction if rule else "forward",
                           y_up=rule.y_up if rule else True)
    else:
        found = ch.find_velocity(parts, view)
        if found is None and separate:
            found = _single_channel_fallback(f, 2)
        if found is None:
            return None
        choice = _PassPlan(f.path, f.parts[found.part], found.channels, found.rule, found.why,
                           separate, direction=found.direction, y_up=found.y_up)
    if spec.velocity_direction != "auto":
        choice.direction = spec.velocity_direction
        choice.why += f"; direction {spec.velocity_direction!r} from PassSpec"
    if spec.velocity_y_up is not None:
        choice.y_up = bool(spec.velocity_y_up)
        choice.why += f"; y_up={choice.y_up} from PassSpec"
    return choice


def _is_display_referred(f: _File, beauty: ch.BeautyChoice) -> bool:
    """Integer-typed non-EXR/HDR files are display-referred (sRGB)."""
    if f.format in ("openexr", "hdr"):
        return False
    part = f.parts[beauty.part]
    fmt = part.formats[part.channels.index(beauty.rgb[0])]
    return fmt not in ("half", "float")


def _input_colorspace(colorspace: str | None, display: bool) -> tuple[str | None, str]:
    """(source OCIO name or None for no conversion, Frame.encoding)."""
    if colorspace is None:
        return ("sRGB", "sRGB") if display else (None, "linear")
    low = colorspace.lower()
    if low in ("linear", "raw"):
        return None, "linear"
    if low == "srgb":
        return "sRGB", "sRGB"
    return colorspace, ("sRGB" if display else "linear")


def _plan(path, passes: PassSpec, colorspace, depth_path, velocity_path, part) -> _Plan:
    f = _scan(path)
    only = _select_part(f, part)
    beauty = ch.find_beauty(f.dicts(), part=only)
    if beauty is None:
        where = f"part {only} of " if only is not None else ""
        raise ImageIOError(f"no beauty channels (R,G,B or grey) in {where}{f.path}; "
                           f"channels: {_available(f)}")
    if f.parts[beauty.part].deep:
        raise ImageIOError(f"cannot read deep image {f.path}: deep EXR is not supported")
    view = beauty.view
    if depth_path is not None:
        df = _scan(depth_path)
        depth = _plan_depth(df, passes, ch.hero_view(df.dicts()), None, True)
        if depth is None:
            raise ClipError(f"no depth channel in depth file {df.path}; channels: {_available(df)}")
    else:
        depth = _plan_depth(f, passes, view, beauty.part, False)
    if velocity_path is not None:
        vf = _scan(velocity_path)
        velocity = _plan_velocity(vf, passes, ch.hero_view(vf.dicts()), None, True)
        if velocity is None:
            raise ClipError(f"no velocity channels in velocity file {vf.path}; "
                            f"channels: {_available(vf)}")
    else:
        velocity = _plan_velocity(f, passes, view, beauty.part, False)
    source, encoding = _input_colorspace(colorspace, _is_display_referred(f, beauty))
    return _Plan(f, beauty, view, depth, velocity, source, encoding)


# ============================================================================================
# Reading

def _colorconvert(rgba: np.ndarray, src: str, dst: str, path) -> np.ndarray:
    """Convert premultiplied RGBA between OCIO colour spaces (alpha divided out around it)."""
    buf = oiio.ImageBuf(np.ascontiguousarray(rgba, np.float32))
    out = oiio.ImageBufAlgo.colorconvert(buf, src, dst, True)
    if out.has_error or not out.initialized:
        raise _fail(path, f"cannot convert colour {src!r} -> {dst!r} for", _geterror(out))
    return np.asarray(out.get_pixels(oiio.FLOAT), np.float32).reshape(rgba.shape)


def _place(arr: np.ndarray, src: Rect, dst: Rect, fill: float) -> np.ndarray:
    """Copy ``arr`` (covering ``src``) into a new array covering ``dst``, filling the rest."""
    if src == dst:
        return arr
    out = np.full(dst.shape + arr.shape[2:], fill, np.float32)
    common = src.intersect(dst)
    if not common.empty:
        sx, sy = common.offset_in(src)
        dx, dy = common.offset_in(dst)
        out[dy:dy + common.height, dx:dx + common.width] = \
            arr[sy:sy + common.height, sx:sx + common.width]
    return out


def _check_same_window(kind: str, pp: _PassPlan, beauty_path: str, beauty_win: Rect) -> None:
    if pp.part.data_window != beauty_win:
        raise ClipError(f"{kind} file {pp.path} data window {pp.part.data_window} does not "
                        f"match beauty {beauty_path} data window {beauty_win}")


def _read_beauty(plan: _Plan) -> np.ndarray:
    f, b = plan.file, plan.beauty
    part = f.parts[b.part]
    got = _read_channels(f.path, part, b.channels)
    h, w = part.data_window.shape
    rgba = np.empty((h, w, 4), np.float32)
    for i in range(3):
        rgba[..., i] = got[b.rgb[0 if b.grey else i]]
    rgba[..., 3] = got[b.alpha] if b.alpha else 1.0
    if plan.source_colorspace is not None:
        rgba = _colorconvert(rgba, plan.source_colorspace, "linear", f.path)
    return rgba


def _read_depth(plan: _Plan, passes: PassSpec, frame_win: Rect, display: Rect,
                aspect: float) -> np.ndarray | None:
    pp = plan.depth
    if pp is None:
        return None
    if pp.separate:
        _check_same_window("depth", pp, plan.file.path, frame_win)
    raw = _read_channels(pp.path, pp.part, pp.channels)[pp.channels[0]]
    win = pp.part.data_window
    centres = None
    if pp.mode == "distance":
        cx, cy = display.center
        xs = np.arange(win.x0, win.x1, dtype=np.float64) + 0.5 - cx
        ys = np.arange(win.y0, win.y1, dtype=np.float64) + 0.5 - cy
        centres = (xs[None, :], ys[:, None])
    try:
        z = ch.depth_to_planar(raw, pp.mode, scale=passes.depth_scale, near=passes.depth_near,
                               far=passes.depth_far, focal_length_px=passes.focal_length_px,
                               pixel_centres=centres, pixel_aspect=aspect)
    except ValueError as e:
        raise ClipError(f"depth of {pp.path}: {e}") from None
    return _place(z, win, frame_win, np.inf)


def _read_velocity(plan: _Plan, passes: PassSpec, frame_win: Rect) -> np.ndarray | None:
    pp = plan.velocity
    if pp is None:
        return None
    if pp.separate:
        _check_same_window("velocity", pp, plan.file.path, frame_win)
    got = _read_channels(pp.path, pp.part, pp.channels)
    vel = ch.velocity_to_forward(got[pp.channels[0]], got[pp.channels[1]],
                                 direction=pp.direction, y_up=pp.y_up,
                                 scale=passes.velocity_scale)
    return _place(vel, pp.part.data_window, frame_win, 0.0)


def read_frame(path, *, passes: PassSpec = PassSpec(), colorspace: str | None = None,
               depth_path=None, velocity_path=None, part: int | str | None = None) -> Frame:
    """Read one frame: beauty RGBA plus depth and velocity if found.

    Parameters
    ----------
    path : str or os.PathLike
        Image file (EXR single/multipart, PNG, JPEG, TIFF, DPX, HDR...).
    passes : PassSpec
        Overrides for finding and interpreting depth and velocity.
    colorspace : str, optional
        Input colour space: ``"linear"``, ``"sRGB"``, ``"raw"`` or an OCIO name; default:
        sRGB for integer non-EXR files, linear otherwise.
    depth_path, velocity_path : str or os.PathLike, optional
        Separate files holding the depth / velocity (same data window as the beauty).
    part : int or str, optional
        Take the beauty from this part (index or name) instead of searching.

    Returns
    -------
    Frame
        float32 ``rgba`` (h, w, 4) in linear Rec.709, premultiplied; ``depth`` planar z in
        scene units (+inf background) or None; ``velocity`` forward px/frame, +y down, or None.

    Raises
    ------
    ImageIOError
        Missing, unreadable, damaged or absurdly large file; no beauty channels.
    ClipError
        Explicit pass channels missing; pass file without a pass or with another data window.
    """
    plan = _plan(path, passes, colorspace, depth_path, velocity_path, part)
    bpart = plan.file.parts[plan.beauty.part]
    win, display, aspect = bpart.data_window, bpart.display_window, bpart.pixel_aspect
    rgba = _read_beauty(plan)
    depth = _read_depth(plan, passes, win, display, aspect)
    velocity = _read_velocity(plan, passes, win)
    bit_depth = bpart.formats[bpart.channels.index(plan.beauty.rgb[0])]
    return Frame(rgba, win, display, aspect, depth, velocity, _metadata(bpart.spec),
                 plan.encoding, os.fspath(path), bit_depth)


# ============================================================================================
# Probe

_CONVENTION = {True: "y-up", False: "y-down"}


def probe(path, *, passes: PassSpec = PassSpec(), colorspace: str | None = None,
          depth_path=None, velocity_path=None, part: int | str | None = None) -> dict:
    """Describe a file and how `read_frame` would read it (no pixels read).

    Returns
    -------
    dict
        JSON-able: ``file``, ``format``, ``parts`` (name, view, channels, windows, pixel
        aspect), ``view``, ``beauty``, ``depth`` and ``velocity`` (channel, part, mode or
        convention, ``why``) or None, ``ignored_other_views``, ``encoding``, ``colorspace``,
        ``search_order``.
    """
    plan = _plan(path, passes, colorspace, depth_path, velocity_path, part)
    f = plan.file
    info = {
        "file": f.path,
        "format": f.format,
        "parts": [{"index": p.index, "name": p.name, "view": p.view,
                   "views": list(p.views), "channels": list(p.channels),
                   "formats": list(p.formats),
                   "data_window": _win_json(p.data_window),
                   "display_window": _win_json(p.display_window),
                   "pixel_aspect": p.pixel_aspect, "deep": p.deep} for p in f.parts],
        "view": plan.view,
        "beauty": {"part": plan.beauty.part, "channels": plan.beauty.channels,
                   "grey": plan.beauty.grey, "why": plan.beauty.why},
        "depth": None,
        "velocity": None,
        "ignored_other_views": ch.other_view_channels(f.dicts(), plan.view),
        "encoding": plan.encoding,
        "colorspace": {"from": plan.source_colorspace or "linear (no conversion)",
                       "to": "linear" if plan.source_colorspace else "linear (as stored)"},
        "search_order": ch.search_order(),
    }
    if plan.depth:
        d = plan.depth
        info["depth"] = {"file": d.path, "part": d.part.index, "channel": d.channels[0],
                         "rule": d.rule, "mode": d.mode, "scale": passes.depth_scale,
                         "data_window": _win_json(d.part.data_window), "why": d.why}
        if d.mode == "normalized":
            info["depth"]["near_far"] = [passes.depth_near, passes.depth_far]
    if plan.velocity:
        v = plan.velocity
        info["velocity"] = {"file": v.path, "part": v.part.index, "channels": list(v.channels),
                            "rule": v.rule, "direction": v.direction, "y_up": v.y_up,
                            "scale": passes.velocity_scale,
                            "convention": f"{v.direction}, pixels, {_CONVENTION[v.y_up]}"
                                          " -> clfx forward px/frame, +y down",
                            "data_window": _win_json(v.part.data_window), "why": v.why}
    return info


def format_probe(info: dict) -> str:
    """Human-readable lines for a `probe` result."""
    def win(w):
        return f"({w['x']},{w['y']}) {w['width']}x{w['height']}"

    lines = [f"{info['file']}  [{info['format']}]"]
    for p in info["parts"]:
        name = f" {p['name']!r}" if p["name"] else ""
        view = f" view={p['view']}" if p["view"] else ""
        views = f" views={','.join(p['views'])}" if p["views"] else ""
        lines.append(f"  part {p['index']}{name}{view}{views}: data {win(p['data_window'])}, "
                     f"display {win(p['display_window'])}, pixel aspect {p['pixel_aspect']:g}"
                     + (" DEEP" if p["deep"] else ""))
        lines.append(f"    channels: {', '.join(p['channels'])}")
    b = info["beauty"]
    lines.append(f"beauty: part {b['part']} {', '.join(b['channels'])}  ({b['why']})")
    if info.get("view"):
        lines.append(f"view: {info['view']}")
    d = info["depth"]
    if d:
        lines.append(f"depth: {d['channel']} (part {d['part']}"
                     + (f" of {d['file']}" if d["file"] != info["file"] else "")
                     + f"), mode {d['mode']}, scale {d['scale']:g}  ({d['why']})")
    else:
        lines.append("depth: none found")
    v = info["velocity"]
    if v:
        lines.append(f"velocity: {'/'.join(v['channels'])} (part {v['part']}"
                     + (f" of {v['file']}" if v["file"] != info["file"] else "")
                     + f"), {v['convention']}, scale {v['scale']:g}  ({v['why']})")
    else:
        lines.append("velocity: none found")
    if info["ignored_other_views"]:
        lines.append(f"ignored (other views): {', '.join(info['ignored_other_views'])}")
    cs = info["colorspace"]
    lines.append(f"encoding: {info['encoding']}  (colour: {cs['from']} -> {cs['to']})")
    lines.append("search order:")
    for kind, order in info["search_order"].items():
        lines.append(f"  {kind}: " + " > ".join(order))
    return "\n".join(lines)


# ============================================================================================
# Writing

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
                       EXR_COMPRESSIONS, "zip", True),
    ".tif": _OutFormat("tiff", ("uint8", "uint16", "half", "float"), "uint16", True, "tiff",
                       TIFF_COMPRESSIONS, "zip"),
    ".png": _OutFormat("png", ("uint8", "uint16"), "uint8", True, "display"),
    ".jpg": _OutFormat("jpeg", ("uint8",), "uint8", False, "display"),
    ".dpx": _OutFormat("dpx", ("uint8", "uint10", "uint16"), "uint10", False, "display"),
    ".hdr": _OutFormat("hdr", ("float",), "float", False, "display"),
}
_OUT_FORMATS[".tiff"] = _OUT_FORMATS[".tif"]
_OUT_FORMATS[".jpeg"] = _OUT_FORMATS[".jpg"]

_LINEAR_EXTS = {".exr", ".hdr", ".pfm"}
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
        raise ImageIOError(f"cannot write {path}: file exists (use overwrite)")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise ImageIOError(f"cannot write {path}: folder {folder} does not exist "
                           "or is not a folder")
    return folder


def _output_colorspace(colorspace: str | None, encoding: str) -> str | None:
    """OCIO name to encode linear pixels to, or None to write them as they are."""
    if colorspace is None:
        return "sRGB" if encoding == "sRGB" else None
    low = colorspace.lower()
    if low in ("linear", "raw"):
        return None
    return "sRGB" if low == "srgb" else colorspace


def _tiff_keeps_windows(frame: Frame) -> bool:
    d, w = frame.display_window, frame.data_window
    return d == w or (d.x0 == 0 and d.y0 == 0 and w.x0 >= 0 and w.y0 >= 0
                      and d.contains(w) and frame.pixel_aspect == 1.0)


def _beauty_pixels(frame: Frame, fmt: _OutFormat, path: str) -> tuple[np.ndarray, Rect, Rect]:
    """(rgba, data window, display window) to write: windows kept or flattened to display."""
    keep = fmt.windows == "full" or (fmt.windows == "tiff" and _tiff_keeps_windows(frame))
    if keep:
        return frame.rgba, frame.data_window, frame.display_window
    _check_size(path, frame.display_window, "display window")
    rgba = _place(np.asarray(frame.rgba, np.float32), frame.data_window, frame.display_window, 0.0)
    return rgba, frame.display_window, frame.display_window


def _encode(rgba: np.ndarray, target: str | None, display: bool, bit_depth: str,
            path: str) -> np.ndarray:
    rgba = np.asarray(rgba, np.float32)
    if target is not None:
        rgba = _colorconvert(rgba, "linear", target, path)
    if display:
        rgba = np.clip(np.nan_to_num(rgba, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
    elif bit_depth == "half":
        rgba = np.clip(rgba, -HALF_MAX, HALF_MAX)     # 1e5 -> 65504, not inf; NaN stays
    return rgba


def _make_spec(frame: Frame, fmt: _OutFormat, bit_depth: str, compression: str | None,
               data: Rect, display: Rect, names: list[str], pass_count: int,
               target: str | None, attributes: dict | None):
    oiio_type = "uint16" if bit_depth == "uint10" else bit_depth
    spec = oiio.ImageSpec(data.width, data.height, len(names), oiio_type)
    spec.x, spec.y = data.x0, data.y0
    spec.full_x, spec.full_y = display.x0, display.y0
    spec.full_width, spec.full_height = display.width, display.height
    spec.channelnames = tuple(names)
    spec.alpha_channel = 3 if "A" in names else -1
    if pass_count:
        beauty = oiio.TypeDesc(oiio_type)
        spec.channelformats = (beauty,) * (len(names) - pass_count) + (oiio.TypeFloat,) * pass_count
    if bit_depth == "uint10":
        spec.attribute("oiio:BitsPerSample", 10)
    for name, value in (frame.metadata or {}).items():
        if _carry(name):
            _set_attribute(spec, name, value)
    for name, value in (attributes or {}).items():
        _set_attribute(spec, name, value)
    spec.attribute("PixelAspectRatio", float(frame.pixel_aspect))
    if compression:
        spec.attribute("compression", compression)
    if target == "sRGB" and fmt.oiio_name != "openexr":
        spec.attribute("oiio:ColorSpace", "sRGB")
    return spec


WRITE_BLOCK_ROWS = 256
"""Rows assembled and written per call: a 4K frame is never held twice in full."""


def _write_blocks(out, spec, planes: list[np.ndarray]) -> bool:
    """Write ``planes`` (each (h, w, k), concatenated along channels) in row blocks."""
    h = planes[0].shape[0]
    for y0 in range(0, max(h, 1), WRITE_BLOCK_ROWS):
        y1 = min(h, y0 + WRITE_BLOCK_ROWS)
        block = np.concatenate([p[y0:y1] for p in planes], axis=-1) if len(planes) > 1 \
            else planes[0][y0:y1]
        if not out.write_scanlines(spec.y + y0, spec.y + y1, 0,
                                   np.ascontiguousarray(block, np.float32)):
            return False
    return True


def _atomic_write(path: str, folder: str, fmt: _OutFormat, spec, planes: list[np.ndarray]) -> None:
    name = os.path.basename(path)
    ext = os.path.splitext(name)[1]
    tmp = os.path.join(folder, f".{name}.tmp-{os.getpid()}-{secrets.token_hex(4)}{ext}")
    try:
        fd = os.open(tmp, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666)
        os.close(fd)
    except OSError as e:
        raise ImageIOError(f"cannot write {path}: folder {folder} is not writable "
                           f"({e.strerror})") from None
    try:
        out = oiio.ImageOutput.create(fmt.oiio_name)
        if out is None:
            raise _fail(path, "cannot write", _geterror() or f"no {fmt.oiio_name} writer")
        if not out.open(tmp, spec):
            raise _fail(path, "cannot write", _geterror(out))
        ok = _write_blocks(out, spec, planes)
        err = _geterror(out)
        closed = out.close()
        err = err or _geterror(out)
        # Only a False return is a failure: OIIO 3.2's TIFF writer reports "failed
        # TIFFWriteCustomDirectory() of the Exif data" on every close, yet the file is whole.
        if not ok or not closed:
            raise _fail(path, "cannot write", err or "write failed")
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.remove(tmp)
        raise


def write_frame(frame: Frame, path, *, bit_depth: str | None = None,
                compression: str | None = None, colorspace: str | None = None,
                overwrite: bool = False, attributes: dict | None = None,
                write_passes: bool = True, protect: Iterable = ()) -> None:
    """Write a frame atomically (temp file in the same folder, then ``os.replace``).

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
        EXR: none, zip, zips, piz, dwaa, dwab, pxr24, b44, rle (default zip).  TIFF: none,
        zip, lzw, packbits (default zip).  Other formats take none.
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
    ImageIOError
        Unsupported extension, bit depth or compression; output exists; output is an input;
        folder missing or unwritable; any OpenImageIO failure (temp file removed).
    """
    path = os.fspath(path)
    fmt = _out_format(path)
    bit_depth = bit_depth or fmt.default_bit_depth
    if bit_depth not in fmt.bit_depths:
        raise ImageIOError(f"cannot write {path}: bit depth {bit_depth!r} not supported; "
                           f"expected one of {', '.join(fmt.bit_depths)}")
    if compression is not None and compression not in fmt.compressions:
        allowed = ", ".join(fmt.compressions) or "none (no choice for this format)"
        raise ImageIOError(f"cannot write {path}: compression {compression!r} not supported; "
                           f"expected one of {allowed}")
    folder = _check_destination(path, overwrite, protect)

    display = encoding_for(path, bit_depth) == "sRGB"
    target = _output_colorspace(colorspace, "sRGB" if display else "linear")
    rgba, data, display_win = _beauty_pixels(frame, fmt, path)
    if not fmt.alpha:          # composite over black: encode the premultiplied colour as is
        rgba = np.concatenate([rgba[..., :3], np.ones(rgba.shape[:2] + (1,), np.float32)], -1)
    rgba = _encode(rgba, target, display, bit_depth, path)
    planes = [rgba if fmt.alpha else rgba[..., :3]]
    names = ["R", "G", "B"] + (["A"] if fmt.alpha else [])
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
    spec = _make_spec(frame, fmt, bit_depth, compression or fmt.default_compression, data,
                      display_win, names, pass_count, target, extra)
    _atomic_write(path, folder, fmt, spec, planes)
