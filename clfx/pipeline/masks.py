"""Per-object effects: a look step limited by a mask.

In a look, any step may take a ``mask``::

    effects:
      - effect: motion_blur
        mask: {channel: ball.A}                        # a channel of the frame's own file
      - effect: glare
        mask: {cryptomatte: CryptoObject, names: [lamp, sun]}   # objects by name
      - effect: dof
        mask: {file: mattes/hero.#.exr, channel: A, invert: true, feather: 4px}

Sources (exactly one of ``channel`` and ``cryptomatte``, or a ``file``):

``channel: NAME``
    A channel of the input frame's file (any part), e.g. an object's alpha AOV.  With
    ``file:``, a channel of that file instead.
``file: PATTERN``
    A separate mask sequence (``#``/``%04d``/``$F4`` tokens, or one file for every frame);
    its channel is ``channel:``, else ``A``, ``alpha``, ``mask``, ``R`` or ``Y`` (the first
    present), else its only channel.  Its data window may differ from the frame's (zero
    outside it).
``cryptomatte: LAYER`` with ``names: [...]``
    The summed coverage of the named objects in the Cryptomatte layer (the frame's file, or
    ``file:``), decoded from the manifest in the header (`clfx.io.mattes`).

Options: ``invert: true`` (1 - mask), ``feather`` (the standard deviation of a Gaussian
softening the mask's edges: a number is a fraction of the frame diagonal like every size in
clfx, ``"4px"`` is pixels), ``mode``:

``mix`` (default for effects that do not spread light, and for the blurs that move light
    within the frame: dof, defocus, motion_blur, camera_blur)
    ``out = source + mask * (effect - source)``: the effect where the mask is, the source
    elsewhere, blended by coverage.  The effect runs on the whole frame (a blurred object
    keeps the background its blur uncovers); its light past the mask's edge is cut, so
    feather or widen the mask to keep a motion streak.
``sources`` (default for the other light-spreading effects: glare, streaks, bleed, corona,
    lens_flare, soft_focus)
    The effect renders ``masked = source * mask`` and ``out = source + (effect(masked) -
    masked)``: light sources are taken from the masked region only, but the light they
    spread lands anywhere in the frame; the rest of the frame is the untouched source.

Checked before the first frame: the mask's channel, Cryptomatte layer and names (in the
first frame's header) and every mask file of the sequence.  The mask is read with the frame
(on the I/O thread), uploaded once per frame (steps sharing a mask share the upload) and
blended on the device (`clfx.fx.mask`).
"""
from __future__ import annotations

import difflib
import math
import warnings
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from clfx.core.errors import ClipError
from clfx.core.frame import Frame, crop_to
from clfx.core.rect import Rect
from clfx.fx import mask as mask_fx

MODES = ("auto", "mix", "sources")
MASK_KEYS = ("channel", "file", "cryptomatte", "names", "invert", "feather", "mode")
BLURS = ("dof", "defocus", "motion_blur", "camera_blur")
"""Light-spreading effects whose light is moved (blurred) rather than added: masked as
``mix`` by default (``sources`` would leave the blurred object over black where it was)."""


@dataclass(frozen=True)
class MaskSpec:
    """A step's mask, as configured (see the module docstring)."""

    channel: str | None = None
    file: str | None = None
    cryptomatte: str | None = None
    names: tuple[str, ...] = ()
    invert: bool = False
    feather: float = 0.0
    feather_px: bool = False
    mode: str = "auto"

    def describe(self) -> dict:
        d: dict = {}
        for key in ("file", "channel", "cryptomatte"):
            if getattr(self, key):
                d[key] = getattr(self, key)
        if self.cryptomatte:
            d["names"] = list(self.names)
        if self.invert:
            d["invert"] = True
        if self.feather:
            d["feather"] = f"{self.feather:g}px" if self.feather_px else self.feather
        if self.mode != "auto":
            d["mode"] = self.mode
        return d

    def label(self) -> str:
        """A few words for reports: ``channel ball.A``, ``cryptomatte CryptoObject[ball]``."""
        what = (f"cryptomatte {self.cryptomatte}[{', '.join(self.names)}]" if self.cryptomatte
                else f"channel {self.channel or '(default)'}")
        where = f" of {self.file}" if self.file else ""
        return f"{'inverted ' if self.invert else ''}{what}{where}"

    def mode_for(self, descriptor) -> str:
        """``mix`` or ``sources`` for an effect (``auto``: see the module docstring)."""
        if self.mode != "auto":
            return self.mode
        return "sources" if descriptor.spreads_light and descriptor.name not in BLURS else "mix"

    def sigma_px(self, display: Rect) -> float:
        """The feather's Gaussian standard deviation in pixels for a frame."""
        return self.feather if self.feather_px else self.feather * display.diagonal


def parse_mask(data, where: str) -> MaskSpec:
    """A :class:`MaskSpec` from a look's ``mask:`` mapping; ValueError naming the key."""
    if not isinstance(data, dict):
        raise ValueError(f"{where}: must be a mapping, e.g. {{channel: ball.A}} or "
                         "{cryptomatte: CryptoObject, names: [ball]}")
    for k in data:
        if k not in MASK_KEYS:
            close = difflib.get_close_matches(str(k), MASK_KEYS, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else \
                f" (expected one of: {', '.join(MASK_KEYS)})"
            raise ValueError(f"{where}.{k}: unknown mask key{hint}")
    for k in ("channel", "file", "cryptomatte"):
        if k in data and (not isinstance(data[k], str) or not data[k].strip()):
            raise ValueError(f"{where}.{k}: {data[k]!r} is not a name")
    if "channel" in data and "cryptomatte" in data:
        raise ValueError(f"{where}: give channel or cryptomatte, not both")
    if not any(k in data for k in ("channel", "file", "cryptomatte")):
        raise ValueError(f"{where}: needs channel, file or cryptomatte")
    names: tuple[str, ...] = ()
    if "cryptomatte" in data:
        raw = data.get("names")
        if isinstance(raw, str):
            raw = [raw]
        if not isinstance(raw, list) or not raw or not all(isinstance(n, str) for n in raw):
            raise ValueError(f"{where}.names: a cryptomatte mask needs names: [NAME, ...]")
        names = tuple(raw)
    elif "names" in data:
        raise ValueError(f"{where}.names: only a cryptomatte mask selects names")
    invert = data.get("invert", False)
    if not isinstance(invert, bool):
        raise ValueError(f"{where}.invert: {invert!r} is not true or false")
    feather, in_px = _feather(data.get("feather", 0.0), f"{where}.feather")
    mode = data.get("mode", "auto")
    if mode not in MODES:
        raise ValueError(f"{where}.mode: {mode!r} is not one of {', '.join(MODES)}")
    return MaskSpec(channel=data.get("channel"), file=data.get("file"),
                    cryptomatte=data.get("cryptomatte"), names=names, invert=invert,
                    feather=feather, feather_px=in_px, mode=mode)


def _feather(value, where: str) -> tuple[float, bool]:
    in_px = False
    if isinstance(value, str):
        text = value.strip().lower()
        in_px = text.endswith("px")
        try:
            value = float(text[:-2] if in_px else text)
        except ValueError:
            raise ValueError(f"{where}: {value!r} is not a number (a fraction of the "
                             "diagonal) or pixels like '4px'") from None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or \
            not math.isfinite(value) or value < 0:
        raise ValueError(f"{where}: {value!r} is not a size >= 0 (a fraction of the diagonal, "
                         "or pixels like '4px')")
    if not in_px and value > 1:
        raise ValueError(f"{where}: {value:g} is more than the whole diagonal; write "
                         f"'{value:g}px' for pixels")
    return float(value), in_px


# -- reading the masks of a frame (host) ---------------------------------------------------------
def mask_file(spec: MaskSpec, frame_number: int) -> str | None:
    """The mask file of ``frame_number`` (``spec.file`` with its frame token filled in)."""
    if not spec.file:
        return None
    from clfx.io.sequence import Pattern   # lazy: fileseq, as check_mask

    return Pattern.parse(spec.file).path(frame_number)


class MaskWarning(UserWarning):
    """A mask was read with an assumption (NaN coverage as 0, Cryptomatte ids from names)."""


def _say(notify, message: str, key: str) -> None:
    if notify is None:
        warnings.warn(message, MaskWarning, stacklevel=3)
    else:
        notify(message, key)


def check_feather(spec: MaskSpec, display: Rect, where: str) -> None:
    """Raise `ClipError` if a feather in pixels is wider than the frame's diagonal (its
    blur would cost memory in proportion: 1e7px asked for 88 GiB)."""
    if spec.feather_px and spec.feather > max(display.diagonal, 1.0):
        raise ClipError(f"{where}: mask feather {spec.feather:g}px is more than the frame's "
                        f"diagonal ({display.diagonal:.0f} px); a feather of 1 (the whole "
                        f"diagonal) is the widest")


def check_mask(spec: MaskSpec, source: str, frame_numbers, where: str, notify=None) -> list[str]:
    """Raise `ClipError` before any frame is read if a mask cannot be made: a missing mask
    file, a mask file of another size than the frames (display window), a feather wider than
    the frame, or (from the header of the first) a missing channel, layer or name.
    ``source`` is the first input file.  ``notify(message, key)`` hears what will be assumed
    (a Cryptomatte without manifest, a pattern's ``#`` padding).  Returns the files the mask
    reads (inputs of the render)."""
    # lazy: OpenImageIO and fileseq (~0.3 s): listing looks loads this module
    from clfx.io import mattes
    from clfx.io.sequence import Pattern, hash_notice, resolve_inputs

    files: list[str] = []
    first = source
    if spec.file:
        pat = Pattern.parse(spec.file)
        padding = hash_notice(pat)       # a Nuke-style m.####.exr: 16 digits here
        if padding:
            _say(notify, padding, f"padding:{pat.text}")
        try:
            found = resolve_inputs(pat, list(frame_numbers) if pat.is_sequence else None,
                                   skip_missing=False)
        except Exception as exc:
            raise ClipError(f"{where}: mask {exc}") from None
        files = [p for _, p in found]
        first = files[0]
    try:
        display = mattes.display_window(source)
        if spec.file:
            theirs = mattes.display_window(first)
            if theirs != display:
                raise ClipError(f"{first} is {theirs.width}x{theirs.height} at "
                                f"({theirs.x0}, {theirs.y0}) (display window), the frames "
                                f"{display.width}x{display.height} at ({display.x0}, "
                                f"{display.y0}); a mask must match the frames")
        if spec.cryptomatte:
            if not mattes.check_cryptomatte(first, spec.cryptomatte, spec.names):
                _say(notify, f"{where}: mask: {first}: Cryptomatte {spec.cryptomatte!r} has "
                     f"no manifest; objects are found by the hash of their names (the "
                     f"Cryptomatte spec's ids)", f"crypto-manifest:{spec.cryptomatte}")
            files += mattes.manifest_files(first, spec.cryptomatte)
        else:
            mattes.check_channel(first, spec.channel if (spec.channel or not spec.file) else None)
    except ClipError as exc:
        raise ClipError(f"{where}: mask: {exc}") from None
    check_feather(spec, display, where)
    return files


def read_mask(spec: MaskSpec, frame: Frame, frame_number: int, *,
              channels: Mapping[str, np.ndarray] | None = None, view: str | None = None,
              notify=None) -> np.ndarray:
    """The mask of one frame as float32 (h, w) over ``frame.data_window``, clipped to
    [0, 1], inverted if asked (feathering happens on the device).  NaN coverage counts as 0,
    said through ``notify(message, key)`` (default: a `MaskWarning`).

    ``channels`` (the Python API) supplies channel masks as arrays by name, over the frame's
    data window; otherwise the channel is read from the frame's file (``frame.source``) or
    the mask file.
    """
    from clfx.io import mattes   # lazy: OpenImageIO, as check_mask

    if channels and spec.channel and not spec.file and spec.channel in channels:
        arr = np.asarray(channels[spec.channel], np.float32)
        if arr.shape != frame.data_window.shape:
            raise ClipError(f"mask channel {spec.channel!r}: shape {arr.shape} does not match "
                            f"the frame's {frame.data_window.shape}")
        window = frame.data_window
    else:
        path = mask_file(spec, frame_number) or frame.source
        if not path or path == "stdin":
            raise ClipError(f"mask {spec.label()}: the frame has no file to read it from "
                            "(pass the channel as an array, or use file:)")
        if spec.cryptomatte:
            arr, window = mattes.cryptomatte(path, spec.cryptomatte, spec.names, view=view)
        else:
            channel = spec.channel if (spec.channel or not spec.file) else None
            arr, window = mattes.read_channel(path, channel, view=view)
    check_feather(spec, frame.display_window, f"mask {spec.label()}")
    if spec.cryptomatte and not np.any(arr > 0):    # e.g. a manifest id no pixel carries
        _say(notify, f"mask {spec.label()}: selects no pixel of frame {frame_number} (no "
             f"rank channel holds the id{'s' if len(spec.names) > 1 else ''} its manifest "
             f"gives; `clfx probe` lists the layer's objects)", f"mask-empty:{spec.label()}")
    bad = int(np.count_nonzero(np.isnan(arr)))
    if bad:
        _say(notify, f"mask {spec.label()}: {bad} NaN pixel(s) counted as 0 (not masked)",
             f"mask-nan:{spec.label()}")
    arr = np.nan_to_num(arr, nan=0.0, posinf=1.0, neginf=0.0)
    arr = np.clip(crop_to(arr, window, frame.data_window, 0.0), 0.0, 1.0)
    return (1.0 - arr).astype(np.float32) if spec.invert else arr.astype(np.float32)


def read_masks(look, frame: Frame, frame_number: int, *,
               channels: Mapping[str, np.ndarray] | None = None,
               notify=None) -> dict[MaskSpec, np.ndarray]:
    """Every distinct mask the look's enabled steps use, for one frame (read once each)."""
    view = frame.layout.view if frame.layout is not None else None
    out: dict[MaskSpec, np.ndarray] = {}
    for _, step in look.active_steps():
        if step.mask is not None and step.mask not in out:
            out[step.mask] = read_mask(step.mask, frame, frame_number, channels=channels,
                                       view=view, notify=notify)
    return out


class FrameMasks:
    """A frame's masks on the device: each uploaded (and feathered) once, on first use, and
    placed in the window a step needs."""

    def __init__(self, rt, host: Mapping[MaskSpec, np.ndarray], window: Rect, display: Rect):
        self.rt, self.host, self.window, self.display = rt, host, window, display
        self._device: dict = {}

    def empty(self, spec: MaskSpec) -> bool:
        """Whether the mask selects nothing on this frame."""
        return not np.any(self._host(spec) > 0.0)

    def _host(self, spec: MaskSpec) -> np.ndarray:
        try:
            return self.host[spec]
        except KeyError:
            raise ClipError(f"no pixels for the mask {spec.label()} on this frame (read the "
                            "frame's masks with clfx.pipeline.masks.read_masks)") from None

    def get(self, spec: MaskSpec, window: Rect):
        """The mask over ``window`` (zero outside the frame's data window)."""
        img = self._device.get(spec)
        if img is None:
            img = mask_fx.feather(self.rt, self.rt.upload(self._host(spec), self.window),
                                  spec.sigma_px(self.display))
            self._device[spec] = img
        return self.rt.reframe(img, window, "zero")
