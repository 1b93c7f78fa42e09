"""Reading frames with OpenImageIO: scanning a file's parts, planning which channels hold the
beauty, depth and velocity, and reading them (`read_frame`).

Reading
-------
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
  error, never zeros.  ``needs`` limits the passes read to those the caller uses, ``keep``
  says whether the beauty part's other channels are kept for the writer (a batch:
  `clfx.pipeline.plan.BatchPlan.read`); what is not needed is not decoded.
- The beauty, depth and velocity search orders and the renderers' conventions are in
  `clfx.io.channels` (``probe`` prints them).  A depth pass's "no hit" sentinels (0, huge
  values) are read as +inf per `clfx.io.channels.no_hit`; what was assumed is passed to
  ``notify`` (a `DepthConventionWarning` by default).  `PassSpec` overrides any of them.  A file that
  holds only passes (a lone ``Z``) has no beauty and is refused, naming its channels.
- Depth or velocity in separate files (``depth_path``, ``velocity_path``): same search order in
  that file; if nothing matches and the file holds a single channel (or R/Y), that channel is
  the depth, or R, G are the velocity (forward, y-up unless `PassSpec` says otherwise).  The
  pass's data window must equal the beauty's, else `ClipError` naming both.

Colour
------
The beauty is converted from the file's space into the *working space* (``working_space=``,
default scene-linear Rec.709; see `clfx.io.colour`): the file's space is ``colorspace=``, else
its ``oiio:ColorSpace`` (EXR ``colorInteropID``, PNG/JPEG/HDR tags), else an EXR's
``chromaticities``, else the format's default.  Integer-typed files other than EXR (8/16-bit
PNG, JPEG, TIFF, and DPX/Cineon of any bit depth) are display-referred, sRGB by default (alpha
divided out around the transfer function), and ``Frame.encoding = "sRGB"``; EXR, HDR and float
TIFF are scene-linear Rec.709 by default.  DPX is often log (Cineon printing density): clfx
treats it as sRGB-like display data unless ``colorspace=`` says otherwise (e.g. ``"ACEScct"``).
``colorspace="raw"`` keeps the pixels as stored.  ``Frame.colorspace`` names the working
space, ``Frame.source_colorspace`` the file's (outputs go back to it).  Trap: OpenImageIO's
``"linear"`` is Linear Rec.709, while the ``scene_linear`` role of its built-in config is
ACEScg.

Robustness
----------
Every OpenImageIO failure becomes `ImageIOError` naming the file, with OpenImageIO's message on
one line.  Inputs must be regular files (`clfx.io.sequence.check_input_file`): a FIFO,
device or socket is refused before it is opened, so nothing blocks.  Data and display
windows are checked against `clfx.core.limits` (``CLFX_MAX_PIXELS``) from the header, before
any pixel is allocated (a 1x1 data window in a 60000x60000 display window, a tiled file
claiming 16384^2).  All 186
fuzzed files of the OpenEXR ``Damaged`` set are rejected in-process (measured with
OpenImageIO 3.2 / OpenEXR 3.5: no crash, no hang, < 0.2 s each), so no subprocess guard is
used; a read that returns pixels but leaves an error message is an error.  Non-finite pixel
values are not errors (effects sanitise them).
"""
from __future__ import annotations

import contextlib
import math
import os
import warnings
from dataclasses import dataclass, field, replace
from typing import Collection

import numpy as np
import OpenImageIO as oiio

from clfx.core.errors import ClipError, ImageIOError
from clfx.core.frame import Frame, Layout, SourcePart, crop_to
from clfx.core.limits import OVERLAP_MAX_PIXELS
from clfx.core.rect import Rect
from clfx.io import channels as ch
from clfx.io import colour
from clfx.io._oiio import (check_window, codec_quiet, fail, geterror, metadata,
                           spec_data_window,
                           spec_display_window, type_name)
from clfx.io.sequence import check_input_file

MAX_PARTS = 4096

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
    depth_zero : {"auto", "far", "invalid"}
        How exact zeros in the depth are read: ``far`` = no hit (+inf), ``invalid`` = kept
        as 0 (effects treat it as in focus), ``auto`` = decided per frame from the share of
        zeros and the beauty's alpha there (`clfx.io.channels.no_hit`).
    depth_far_threshold : float
        Depths (before ``depth_scale``) of at least this magnitude are no hit (+inf); ``inf``
        keeps them.
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
    depth_zero: str = "auto"
    depth_far_threshold: float = ch.DEPTH_FAR_AS_INF

    def __post_init__(self):
        if self.depth_zero not in ch.DEPTH_ZERO:
            raise ClipError(f"depth_zero {self.depth_zero!r} is not one of {ch.DEPTH_ZERO}")
        if not self.depth_far_threshold > 0:
            raise ClipError(f"depth_far_threshold {self.depth_far_threshold!r} must be > 0 "
                            "(inf keeps every value)")
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
# Codec threads

def set_codec_threads(n: int) -> None:
    """OpenImageIO and OpenEXR's codecs use at most ``n`` threads per read or write from now
    on (process-wide; a Dask worker sets it once, see `codec_threads`)."""
    for k in ("threads", "exr_threads"):
        oiio.attribute(k, int(n))


@contextlib.contextmanager
def codec_threads(n: int):
    """While inside, OpenImageIO and OpenEXR's codecs use at most ``n`` threads per read or
    write (``threads``, ``exr_threads``; 1: everything on the calling thread).  A batch sets
    1 and runs its reads and writes on low-priority threads of its own, so decoding and
    encoding fill the cores the device leaves idle instead of taking them from it
    (`clfx.pipeline.stream`).  Process-wide: restored on exit."""
    saved = {k: oiio.get_int_attribute(k, 0) for k in ("threads", "exr_threads")}
    set_codec_threads(n)
    try:
        yield
    finally:
        for k, v in saved.items():
            oiio.attribute(k, v)


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
    path = check_input_file(path)
    with codec_quiet(path):
        inp = oiio.ImageInput.open(path)
        if inp is None:
            raise fail(path, "cannot read", geterror() or "unknown format or damaged file")
        try:
            yield inp
        finally:
            inp.close()


def _part_from_spec(i: int, spec) -> _Part:
    views = spec.getattribute("multiView")
    views = tuple(views) if isinstance(views, (tuple, list)) else ((views,) if views else ())
    names = tuple(spec.channelnames)
    fmts = tuple(type_name(t) for t in spec.channelformats) if spec.channelformats else \
        (type_name(spec.format),) * len(names)
    aspect = spec.get_float_attribute("PixelAspectRatio", 1.0)
    if not (math.isfinite(aspect) and aspect > 0):
        aspect = 1.0
    return _Part(i, spec.get_string_attribute("name", ""), names, fmts,
                 spec.get_string_attribute("view", "") or None, views,
                 spec_data_window(spec), spec_display_window(spec), float(aspect), bool(spec.deep), spec)


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
            raise fail(path, "cannot read", "undecodable channel or attribute names "
                        "(damaged file)") from None
        geterror(inp)      # clear "no such subimage" left by the last seek
        if not parts:
            raise fail(path, "cannot read", "no image in file")
        return _File(os.fspath(path), inp.format_name(), parts)


RUN_GAP = 8
"""Channels between two wanted runs of a part that are read along rather than starting a
second read: OpenEXR decompresses every channel of a chunk however few are asked for, so a
second read of the same part decodes the whole file again (the beauty, depth and velocity
of one part were decoded three times, 0.2-0.6 s per 1080p float frame)."""

KEEP_CHANNELS = 16
"""A beauty part of at most this many half/float channels is decoded whole once, and the
channels the frame does not use are kept in its `Layout` for the writer to copy, instead
of being decoded again from the file when the output is written."""

KEEP_MAX_PIXELS = OVERLAP_MAX_PIXELS
"""Frames up to this size (4K UHD) keep their beauty part's other channels for the writer
(`KEEP_CHANNELS`).  A larger frame keeps none: they would be held, as float32, through its
whole render (an 8K frame's depth and velocity as stored: 380 MiB), and the writer decodes
them again band by band in seconds of a render that takes minutes."""


def _runs(indices: list[int], gap: int = 0) -> list[tuple[int, int]]:
    """Contiguous [begin, end) runs of sorted channel indices (runs at most ``gap`` channels
    apart merged)."""
    runs: list[tuple[int, int]] = []
    for i in sorted(set(indices)):
        if runs and i - runs[-1][1] <= gap:
            runs[-1] = (runs[-1][0], i + 1)
        else:
            runs.append((i, i + 1))
    return runs


def _read_channels(path, part: _Part, names) -> dict[str, np.ndarray]:
    """Read named channels of one part as float32 (h, w) arrays covering its data window,
    in as few reads as `RUN_GAP` allows (the channels read along are returned too): views
    into the decoded block, copied only where they are kept (`_Decoded.kept`) or converted
    (a 1080p frame's seven float channels: seven 8 MB copies, ~50 ms of CPU, of which the
    beauty's four fed one more copy into RGBA)."""
    if part.deep:
        raise fail(path, "cannot read deep image", "deep EXR is not supported")
    check_window(path, part.data_window)
    idx = []
    for n in names:
        if n not in part.channels:
            raise fail(path, f"channel {n!r} not found in part {part.index} of",
                        f"channels are {', '.join(part.channels)}")
        idx.append(part.channels.index(n))
    out: dict[str, np.ndarray] = {}
    with _open(path) as inp:
        for begin, end in _runs(idx, RUN_GAP):
            px = inp.read_image(part.index, 0, begin, end, "float")
            err = geterror(inp)
            if px is None or err:
                raise fail(path, "cannot read", err or "read failed")
            px = np.asarray(px, np.float32).reshape(part.data_window.height,
                                                    part.data_window.width, end - begin)
            for i in range(begin, end):
                out[part.channels[i]] = px[..., i - begin]
    return out


class _Decoded:
    """The channels one `read_frame` reads, each part decoded once: ``want`` every channel
    of a part first, then ``get`` them (`_read_channels` reads a part's wanted channels in
    one go)."""

    def __init__(self):
        self._want: dict[tuple[str, int], tuple[_Part, set[str]]] = {}
        self._got: dict[tuple[str, int], dict[str, np.ndarray]] = {}

    def want(self, path, part: _Part, names) -> None:
        key = (os.fspath(path), part.index)
        self._want.setdefault(key, (part, set()))[1].update(names)

    def get(self, path, part: _Part, names) -> dict[str, np.ndarray]:
        key = (os.fspath(path), part.index)
        got = self._got.get(key)
        if got is None or any(n not in got for n in names):
            wanted = self._want.get(key, (part, set()))[1] | set(names)
            got = self._got[key] = {**(got or {}), **_read_channels(path, part, sorted(wanted))}
        return {n: got[n] for n in names}

    def kept(self, path, part: _Part, without=()) -> dict[str, np.ndarray]:
        """The channels of ``part`` decoded so far but ``without`` (as stored, float32,
        read-only; each its own array, so the decoded block is not held through a render)."""
        got = {n: np.ascontiguousarray(a)
               for n, a in self._got.get((os.fspath(path), part.index), {}).items()
               if n not in without}
        for a in got.values():
            a.setflags(write=False)
        return got


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
class ReadPlan:
    file: _File
    beauty: ch.BeautyChoice
    view: str | None
    depth: _PassPlan | None
    velocity: _PassPlan | None
    source_colorspace: str            # the file's space (``"raw"``: no conversion)
    encoding: str
    working: str = colour.DEFAULT_WORKING
    colour_why: str = ""


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
        choice = _searched(f, ch.find_depth(parts, view), 1, separate)
    return _overridden(choice, "mode", spec.depth_mode)


def _overridden(choice: _PassPlan | None, field: str, value) -> _PassPlan | None:
    """``choice`` with one convention set from the PassSpec (``"auto"``/None: kept)."""
    if choice is not None and value not in ("auto", None):
        setattr(choice, field, value)
        choice.why += f"; {field} {value!r} from PassSpec"
    return choice


def _searched(f: _File, found: ch.PassChoice | None, n: int, separate: bool) -> _PassPlan | None:
    """The plan for a pass the search order found (or, in a separate file, the fallback)."""
    if found is None and separate:
        found = _single_channel_fallback(f, n)
    if found is None:
        return None
    return _PassPlan(f.path, f.parts[found.part], found.channels, found.rule, found.why,
                     separate, mode=found.mode, direction=found.direction, y_up=found.y_up)


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
        choice = _searched(f, ch.find_velocity(parts, view), 2, separate)
    choice = _overridden(choice, "direction", spec.velocity_direction)
    return _overridden(choice, "y_up", None if spec.velocity_y_up is None
                       else bool(spec.velocity_y_up))


def _is_display_referred(f: _File, beauty: ch.BeautyChoice) -> bool:
    """Integer-typed non-EXR/HDR files are display-referred (sRGB)."""
    if f.format in ("openexr", "hdr"):
        return False
    part = f.parts[beauty.part]
    fmt = part.formats[part.channels.index(beauty.rgb[0])]
    return fmt not in ("half", "float")


def _input_colorspace(f: _File, beauty: ch.BeautyChoice, colorspace: str | None
                      ) -> tuple[str, str, str]:
    """(the file's space, Frame.encoding, why)."""
    display = _is_display_referred(f, beauty)
    spec = f.parts[beauty.part].spec
    chroma = spec.getattribute("chromaticities") if f.format == "openexr" else None
    source, why = colour.input_space(colorspace, file_space=spec.get_string_attribute(
        "oiio:ColorSpace") or None, chroma=chroma, display=display)
    encoding = "sRGB" if display and not colour.is_linear(source) else "linear"
    return source, encoding, why


def plan_read(path, passes: PassSpec, colorspace, depth_path, velocity_path, part,
              working_space: str | None = None, view: str | None = None, *,
              passes_only: bool = False) -> ReadPlan:
    """How ``path`` will be read.  ``passes_only`` (``probe``): a file without a beauty
    (a depth or velocity pass on its own) gives a plan with ``beauty`` None and its passes
    planned as a pass file's, instead of an `ImageIOError`."""
    working = colour.resolve(working_space or colour.DEFAULT_WORKING, "working space")
    if not colour.is_linear(working) or working == colour.RAW:
        raise ImageIOError(f"working space {working_space!r} must be a linear colour space "
                           "(e.g. lin_rec709, ACEScg)")
    f = _scan(path)
    only = _select_part(f, part)
    views = ch.beauty_views(f.dicts())
    if view is not None and view not in views:
        raise ImageIOError(f"view {view!r} not in {f.path}; views with a beauty: "
                           f"{', '.join(v for v in views if v) or 'none (not multi-view)'}")
    beauty = ch.find_beauty(f.dicts(), part=only, view=view)
    if beauty is None and passes_only:
        hero = view or ch.hero_view(f.dicts())
        return ReadPlan(f, None, hero, _plan_depth(f, passes, hero, only, True),
                        _plan_velocity(f, passes, hero, only, True), colour.RAW, "linear",
                        working, "a pass-only file: no colour")
    if beauty is None:
        where = f"part {only} of " if only is not None else ""
        passes_only = ""
        if ch.find_depth(f.dicts(), None) is not None:
            passes_only = " (a depth pass only: use it as a depth file)"
        raise ImageIOError(f"no beauty channels (R,G,B or grey) in {where}{f.path}; "
                           f"channels: {_available(f)}{passes_only}")
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
    source, encoding, why = _input_colorspace(f, beauty, colorspace)
    return ReadPlan(f, beauty, view, depth, velocity, source, encoding, working, why)


# ============================================================================================
# Reading


def _check_same_window(kind: str, pp: _PassPlan, beauty_path: str, beauty_win: Rect) -> None:
    if pp.part.data_window != beauty_win:
        raise ClipError(f"{kind} file {pp.path} data window {pp.part.data_window} does not "
                        f"match beauty {beauty_path} data window {beauty_win}")


def _read_beauty(plan: ReadPlan, dec: _Decoded) -> np.ndarray:
    f, b = plan.file, plan.beauty
    part = f.parts[b.part]
    got = dec.get(f.path, part, b.channels)
    h, w = part.data_window.shape
    rgba = np.empty((h, w, 4), np.float32)
    for i in range(3):
        rgba[..., i] = got[b.rgb[0 if b.grey else i]]
    rgba[..., 3] = got[b.alpha] if b.alpha else 1.0
    return colour.convert(rgba, plan.source_colorspace, plan.working, f.path)


def _read_depth(plan: ReadPlan, passes: PassSpec, frame_win: Rect, display: Rect,
                aspect: float, alpha: np.ndarray | None, dec: _Decoded | None = None
                ) -> tuple[np.ndarray, ch.NoHit] | tuple[None, None]:
    """Planar depth over ``frame_win`` (+inf outside the pass) and how its "no hit"
    sentinels were read; ``alpha`` is the beauty's over ``frame_win`` (None: opaque)."""
    pp = plan.depth
    if pp is None:
        return None, None
    if pp.separate:
        _check_same_window("depth", pp, plan.file.path, frame_win)
    raw = (dec or _Decoded()).get(pp.path, pp.part, pp.channels)[pp.channels[0]]
    win = pp.part.data_window
    centres = None
    if pp.mode == "distance":
        cx, cy = display.center
        xs = np.arange(win.x0, win.x1, dtype=np.float64) + 0.5 - cx
        ys = np.arange(win.y0, win.y1, dtype=np.float64) + 0.5 - cy
        centres = (xs[None, :], ys[:, None])
    try:
        z = ch.depth_to_planar(raw, pp.mode, near=passes.depth_near, far=passes.depth_far,
                               focal_length_px=passes.focal_length_px, pixel_centres=centres,
                               pixel_aspect=aspect, far_threshold=math.inf)
    except ValueError as e:
        raise ClipError(f"depth of {pp.path}: {e}") from None
    if alpha is not None:
        alpha = crop_to(alpha, frame_win, win, 0.0)     # outside the beauty: transparent
    half = pp.part.formats[pp.part.channels.index(pp.channels[0])] == "half"
    nohit = ch.no_hit(z, alpha, zero=passes.depth_zero, far_threshold=passes.depth_far_threshold,
                      half=half)
    z = nohit.apply(z, scale=passes.depth_scale)
    return crop_to(z, win, frame_win, np.inf), nohit


def depth_no_hit(plan: ReadPlan, passes: PassSpec) -> ch.NoHit | None:
    """How ``plan``'s depth pass marks "no hit" (reads the depth and the beauty's alpha only;
    for ``probe``)."""
    if plan.depth is None:
        return None
    b = plan.beauty
    if b is None:          # a pass-only file: the pass's own windows, no alpha
        dpart = plan.depth.part
        return _read_depth(plan, passes, dpart.data_window, dpart.display_window,
                           dpart.pixel_aspect, None)[1]
    bpart = plan.file.parts[b.part]
    alpha = None
    if b.alpha:
        alpha = _read_channels(plan.file.path, bpart, [b.alpha])[b.alpha]
    return _read_depth(plan, passes, bpart.data_window, bpart.display_window,
                       bpart.pixel_aspect, alpha)[1]


class DepthConventionWarning(UserWarning):
    """A depth pass's "no hit" sentinels (0, huge values) were read as infinitely far."""


def _announce(path, plan: ReadPlan, nohit: ch.NoHit | None, notify) -> None:
    """Say once what a depth pass's sentinels were taken to mean (see `read_frame`)."""
    if nohit is None or not nohit.assumed:
        return
    pp = plan.depth
    where = f" in {pp.path}" if pp.separate else ""
    msg = f"{os.fspath(path)}: depth {pp.channels[0]}{where}: {nohit.describe()}"
    key = "depth:" + "+".join(nohit.assumed)
    if notify is None:
        warnings.warn(msg, DepthConventionWarning, stacklevel=3)
    else:
        notify(msg, key)


def _read_velocity(plan: ReadPlan, passes: PassSpec, frame_win: Rect,
                   dec: _Decoded) -> np.ndarray | None:
    pp = plan.velocity
    if pp is None:
        return None
    if pp.separate:
        _check_same_window("velocity", pp, plan.file.path, frame_win)
    got = dec.get(pp.path, pp.part, pp.channels)
    vel = ch.velocity_to_forward(got[pp.channels[0]], got[pp.channels[1]],
                                 direction=pp.direction, y_up=pp.y_up,
                                 scale=passes.velocity_scale)
    return crop_to(vel, pp.part.data_window, frame_win, 0.0)


def _back_channels(pp) -> tuple[str, str] | None:
    """Blender's other half: the Vector pass's X, Y (previous - current, y-up) in the part
    whose Z, W (current - next) are the velocity; None elsewhere."""
    if pp is None or pp.direction != "backward" or not pp.channels[0].endswith("Vector.Z") \
            or not pp.channels[1].endswith("Vector.W"):
        return None
    names = (pp.channels[0][:-1] + "X", pp.channels[1][:-1] + "Y")
    return names if all(n in pp.part.channels for n in names) else None


def _read_velocity_back(plan: ReadPlan, passes: PassSpec, frame_win: Rect,
                        dec: _Decoded) -> np.ndarray | None:
    """Backward motion (current - previous position, px/frame, +y down) where the vector
    pass holds both halves (Blender); None where it holds one."""
    pp = plan.velocity
    names = _back_channels(pp)
    if names is None:
        return None
    got = dec.get(pp.path, pp.part, names)
    # XY = previous - current: a backward vector, negated like ZW -> current - previous
    back = ch.velocity_to_forward(got[names[0]], got[names[1]], direction="backward",
                                  y_up=pp.y_up, scale=passes.velocity_scale)
    return crop_to(back, pp.part.data_window, frame_win, 0.0)


def read_frame(path, *, passes: PassSpec = PassSpec(), colorspace: str | None = None,
               depth_path=None, velocity_path=None, part: int | str | None = None,
               notify=None, working_space: str | None = None,
               view: str | None = None, needs: Collection[str] | None = None,
               keep: bool = True) -> Frame:
    """Read one frame: beauty RGBA plus depth and velocity if found.

    Parameters
    ----------
    path : str or os.PathLike
        Image file (EXR single/multipart, PNG, JPEG, TIFF, DPX, HDR...).
    passes : PassSpec
        Overrides for finding and interpreting depth and velocity.
    colorspace : str, optional
        The file's colour space: an OCIO name or alias (``"sRGB"``, ``"ACEScg"``,
        ``"linear"`` = linear Rec.709) or ``"raw"`` (no conversion); default: the file's
        ``oiio:ColorSpace``, an EXR's ``chromaticities``, else sRGB for integer non-EXR files
        and linear Rec.709 otherwise (`clfx.io.colour.input_space`).
    depth_path, velocity_path : str or os.PathLike, optional
        Separate files holding the depth / velocity (same data window as the beauty).
    part : int or str, optional
        Take the beauty from this part (index or name) instead of searching.
    notify : callable(message, key), optional
        Told what was assumed about the depth's "no hit" values (0 or huge values read as
        +inf; `clfx.io.channels.no_hit`): one line naming the file, and a key that is the
        same for the same assumption on every frame (so a batch says it once per sequence).
        Default: a `DepthConventionWarning`.
    working_space : str, optional
        Linear OCIO space to convert the beauty into; default ``"lin_rec709"``.
    view : str, optional
        Multi-view files: the view whose beauty and passes are read; default the hero.
    needs : collection of {"depth", "velocity"}, optional
        The passes the caller uses (a look's `clfx.pipeline.look.Look.clips_used`); None:
        both.  A pass not needed is neither decoded nor converted (``Frame.depth`` or
        ``velocity`` is None) and nothing is said about its conventions.
    keep : bool
        Keep the beauty part's other channels for the writer (`KEEP_CHANNELS`); False where
        the output copies none (not an EXR, ``--passes drop``): then only the channels the
        frame uses are decoded (1080p float RGBA + Z + velocity: the beauty alone is ~35 %
        less decoding CPU).

    Returns
    -------
    Frame
        float32 ``rgba`` (h, w, 4) in the working space, premultiplied (``colorspace``;
        ``source_colorspace`` is the file's; ``layout`` its parts); ``depth`` planar z in
        scene units (+inf background) or None; ``velocity`` forward px/frame, +y down, or None.

    Raises
    ------
    ImageIOError
        Missing, unreadable, damaged or absurdly large file; no beauty channels.
    ClipError
        Explicit pass channels missing; pass file without a pass or with another data window.
    """
    plan = plan_read(path, passes, colorspace, depth_path, velocity_path, part, working_space,
                     view)
    bpart = plan.file.parts[plan.beauty.part]
    win, display, aspect = bpart.data_window, bpart.display_window, bpart.pixel_aspect
    check_window(path, win)
    check_window(path, display, "display window")   # effects size buffers from it
    if needs is not None:           # what the caller does not use is not read
        plan = replace(plan, depth=plan.depth if "depth" in needs else None,
                       velocity=plan.velocity if "velocity" in needs else None)
    dec = _decoding(plan, keep)
    rgba = _read_beauty(plan, dec)
    alpha = rgba[..., 3] if plan.beauty.alpha else None
    depth, nohit = _read_depth(plan, passes, win, display, aspect, alpha, dec)
    _announce(path, plan, nohit, notify)
    velocity = _read_velocity(plan, passes, win, dec)
    velocity_back = _read_velocity_back(plan, passes, win, dec)
    bit_depth = bpart.formats[bpart.channels.index(plan.beauty.rgb[0])]
    source = None if plan.source_colorspace == colour.RAW else plan.source_colorspace
    return Frame(rgba, win, display, aspect, depth, velocity, metadata(bpart.spec),
                 plan.encoding, os.fspath(path), bit_depth, colorspace=plan.working,
                 source_colorspace=source,
                 layout=_layout(plan, dec.kept(plan.file.path, bpart, without=plan.beauty.channels)
                                if keep and _keeps(bpart) else {}),
                 velocity_back=velocity_back)


def _decoding(plan: ReadPlan, keep: bool = True) -> _Decoded:
    """What `read_frame` will read, by part, so each part is decoded once: the beauty, the
    passes and, for a beauty part the reader keeps (``keep`` and `_keeps`), all of its
    channels (kept for the writer, `Layout.stored`)."""
    dec = _Decoded()
    bpart = plan.file.parts[plan.beauty.part]
    dec.want(plan.file.path, bpart, plan.beauty.channels)
    if keep and _keeps(bpart):
        dec.want(plan.file.path, bpart, bpart.channels)
    for pp in (plan.depth, plan.velocity):
        if pp is not None:
            dec.want(pp.path, pp.part, pp.channels)
    back = _back_channels(plan.velocity)
    if back is not None:
        dec.want(plan.velocity.path, plan.velocity.part, back)
    return dec


def _keeps(part: _Part) -> bool:
    """Whether `read_frame` keeps ``part``'s other channels for the writer (`KEEP_CHANNELS`,
    `KEEP_MAX_PIXELS`)."""
    return (len(part.channels) <= KEEP_CHANNELS and part.data_window.width
            * part.data_window.height <= KEEP_MAX_PIXELS
            and all(f in ("half", "float") for f in part.formats))


def _layout(plan: ReadPlan, stored: dict[str, np.ndarray]) -> Layout:
    """The source file's parts (deep ones left out: they cannot be copied) and the beauty."""
    parts = [p for p in plan.file.parts if not p.deep]
    keep = [SourcePart(p.index, p.name, p.view, p.channels,
                       tuple(str(t) for t in (p.spec.channelformats or
                                              (p.spec.format,) * len(p.channels))),
                       p.data_window, metadata(p.spec)) for p in parts]
    beauty = next(i for i, p in enumerate(parts) if p.index == plan.beauty.part)
    return Layout(plan.file.path, tuple(keep), beauty, tuple(plan.beauty.channels), plan.view,
                  stored={plan.beauty.part: stored} if stored else {})


def beauty_geometry(path, check: bool = False) -> tuple[Rect, Rect, float]:
    """The data window, display window and pixel aspect of the part `read_frame` would take
    the hero's beauty from, from the headers alone (to prepare a look before the first frame
    is read).  ``check``: refuse windows `read_frame` would refuse (empty, or over the limits
    of `clfx.core.limits`), with its message."""
    f = _scan(path)
    b = ch.find_beauty(f.dicts())
    part = f.parts[b.part if b is not None else 0]
    if check:
        check_window(path, part.data_window)
        check_window(path, part.display_window, "display window")
    return part.data_window, part.display_window, part.pixel_aspect


def read_channels(path) -> dict[str, np.ndarray]:
    """Every channel of every part of ``path`` by its name, as float32 (h, w) arrays over its
    part's data window, as stored (no beauty, passes or colour conventions: a data file, e.g.
    the bench's Blender renders; a later part's channel replaces an earlier one's of the same
    name)."""
    out: dict[str, np.ndarray] = {}
    for part in _scan(path).parts:
        out.update({n: np.ascontiguousarray(a)
                    for n, a in _read_channels(path, part, part.channels).items()})
    return out


def read_views(path, *, view: str | None = None, all_views: bool = True, **kw) -> list[Frame]:
    """The frames of every view of a multi-view file (hero first), or of ``view`` only.

    Each frame has its own beauty and passes (those of its view) and the same `Layout`, so
    `clfx.io.write.write_frame(frames[0], ..., views=frames[1:])` writes every view back in
    place.  A file without views, ``view=`` or ``all_views=False`` give one frame (``view``,
    or the hero; with ``all_views=False`` and several views, ``notify`` is told once, key
    ``"views"``).  Other keywords are `read_frame`'s.
    """
    if view is not None:
        return [read_frame(path, view=view, **kw)]
    f = _scan(path)
    views = ch.beauty_views(f.dicts()) if kw.get("part") is None else ()
    if not all_views and len(views) > 1:
        msg = (f"{os.fspath(path)}: multi-view file ({', '.join(views)}): only the hero view "
               f"{views[0]!r} is rendered (this output holds one view; an .exr output with "
               "--passes keep renders and keeps every view)")
        if kw.get("notify"):
            kw["notify"](msg, "views")
        views = views[:1]
    return [read_frame(path, view=v, **kw) for v in views] or [read_frame(path, **kw)]


