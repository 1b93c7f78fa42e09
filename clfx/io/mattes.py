"""Mattes for per-object effects: a named channel of a file, a mask file, or a Cryptomatte
ID selection by name.

Cryptomatte (Friedman & Jones, Psyop 2015; the spec "Cryptomatte Specification 1.2.0")
--------------------------------------------------------------------------------------
A Cryptomatte layer ``<layer>`` (e.g. ``CryptoObject``) stores ranks of ``(id, coverage)``
pairs in the channels ``<layer>00.R/G/B/A``, ``<layer>01.R/G/B/A``, ... (R, G = the first
pair of the rank, B, A = the second).  An id is the 32-bit MurmurHash3 (x86, seed 0) of the
object's name (UTF-8), reinterpreted as a float32 whose exponent is never 0 or 255 (bit 23 is
flipped when it would be: no denormals, infinities or NaNs).  The header names the layer
under ``cryptomatte/<key>/name`` and maps names to hashes (8 hex digits) in the JSON
``cryptomatte/<key>/manifest`` (or a sidecar JSON file named by ``manif_file``, relative to
the image).  The matte of a selection is the sum of the coverages whose id is selected.
Names missing from the manifest are an error naming the closest ones.
"""
from __future__ import annotations

import difflib
import os
import struct

import numpy as np

from clfx.core.errors import ClipError, ImageIOError
from clfx.core.limits import load_json
from clfx.core.rect import Rect
from clfx.io.read import _Part, _read_channels, _scan
from clfx.io.sequence import check_input_file

MASK_CHANNELS = ("A", "alpha", "mask", "R", "Y")
"""The channel a mask file is read from when none is named: the first present (or its only
channel)."""


# -- hashing -------------------------------------------------------------------------------
def mm3_hash32(data: bytes, seed: int = 0) -> int:
    """MurmurHash3 x86 32-bit of ``data`` (Austin Appleby's reference, public domain)."""
    c1, c2, mask = 0xCC9E2D51, 0x1B873593, 0xFFFFFFFF
    h = seed & mask
    n = len(data) // 4
    for (k,) in struct.iter_unpack("<I", data[:n * 4]):
        k = (k * c1) & mask
        k = ((k << 15) | (k >> 17)) & mask
        k = (k * c2) & mask
        h ^= k
        h = ((h << 13) | (h >> 19)) & mask
        h = (h * 5 + 0xE6546B64) & mask
    tail = data[n * 4:]
    k = 0
    for i, b in enumerate(tail):
        k |= b << (8 * i)
    if tail:
        k = (k * c1) & mask
        k = ((k << 15) | (k >> 17)) & mask
        k = (k * c2) & mask
        h ^= k
    h ^= len(data)
    h ^= h >> 16
    h = (h * 0x85EBCA6B) & mask
    h ^= h >> 13
    h = (h * 0xC2B2AE35) & mask
    h ^= h >> 16
    return h


def name_hash(name: str) -> int:
    """The Cryptomatte hash of ``name``: its MurmurHash3 with the float32 exponent kept
    away from 0 and 255 (what the manifest lists, and the bits of the id channel)."""
    h = mm3_hash32(name.encode("utf-8"))
    exponent = (h >> 23) & 0xFF
    if exponent in (0, 255):
        h ^= 1 << 23
    return h


def id_to_float(h: int) -> float:
    """The float32 an id channel stores for hash ``h``."""
    return float(np.array([h], np.uint32).view(np.float32)[0])


# -- reading -------------------------------------------------------------------------------
def _part_with(f, names, view: str | None) -> _Part:
    """The part holding every channel of ``names`` (the one of ``view`` first)."""
    parts = [p for p in f.parts if all(n in p.channels for n in names) and not p.deep]
    if not parts:
        raise ClipError(f"{f.path}: no channel {names[0]!r}; channels: "
                        f"{', '.join(n for p in f.parts for n in p.channels)}")
    return next((p for p in parts if view is not None and p.view == view), parts[0])


def mask_channel(path, channel: str | None = None) -> str:
    """The channel a mask is read from: ``channel``, else the first of `MASK_CHANNELS`
    present, else the file's only channel."""
    if channel:
        return channel
    f = _scan(path)
    names = [n for p in f.parts for n in p.channels]
    for n in MASK_CHANNELS:
        if n in names:
            return n
    if len(names) == 1:
        return names[0]
    raise ClipError(f"{f.path}: which channel is the mask? none of {', '.join(MASK_CHANNELS)}; "
                    f"channels: {', '.join(names)} (name one with channel:)")


def read_channel(path, channel: str | None = None, *, view: str | None = None
                 ) -> tuple[np.ndarray, Rect]:
    """One channel of an image file as float32 (h, w) and the data window it covers.

    ``channel`` None: see `mask_channel`.  Multi-part files are searched part by part (the
    part of ``view`` first).

    Raises
    ------
    ClipError
        No such channel (the file's channels are named).
    ImageIOError
        The file cannot be read.
    """
    name = mask_channel(path, channel)
    f = _scan(path)
    part = _part_with(f, [name], view)
    return np.ascontiguousarray(_read_channels(f.path, part, [name])[name]), part.data_window


def check_channel(path, channel: str | None = None) -> str:
    """Raise `ClipError` now (from the header only) if the mask channel is not in ``path``;
    return its name."""
    name = mask_channel(path, channel)
    _part_with(_scan(path), [name], None)
    return name


def _layer_attributes(f) -> dict[str, dict]:
    """Cryptomatte layer name -> its header attributes (``manifest``, ``hash``, ...)."""
    layers: dict[str, dict] = {}
    for p in f.parts:
        by_key: dict[str, dict] = {}
        for a in p.spec.extra_attribs:
            name = a.name
            if name.startswith("cryptomatte/") and name.count("/") == 2:
                _, key, field = name.split("/")
                by_key.setdefault(key, {})[field] = a.value
        for attrs in by_key.values():
            if "name" in attrs:
                layers.setdefault(str(attrs["name"]), attrs)
    return layers


def _sidecar(f, attrs: dict) -> str | None:
    """The manifest file a layer names (``manif_file``, relative to the image), or None."""
    return os.path.join(os.path.dirname(f.path), str(attrs["manif_file"])) \
        if attrs.get("manif_file") else None


def manifest_files(path, layer: str) -> list[str]:
    """The sidecar manifest file of ``layer`` in ``path``, if it has one (an input)."""
    side = _sidecar(_scan(path), _layer_attributes(_scan(path)).get(layer, {}))
    return [side] if side and os.path.exists(side) else []


def _manifest(f, layer: str, attrs: dict) -> dict[str, int]:
    text = attrs.get("manifest")
    side = _sidecar(f, attrs)
    if text is None and side:
        try:
            check_input_file(side, f"Cryptomatte {layer!r} manifest")   # a FIFO would block
            with open(side, encoding="utf-8") as fh:
                text = fh.read()
        except ImageIOError as exc:
            raise ClipError(f"{f.path}: {exc}") from None
        except OSError as exc:
            raise ClipError(f"{f.path}: Cryptomatte {layer!r}: cannot read its manifest "
                            f"{side}: {exc.strerror}") from None
    if text is None:
        return {}
    data = load_json(str(text), f"{f.path}: Cryptomatte {layer!r}: the manifest", ClipError)
    try:
        out = {str(k): int(str(v), 16) for k, v in data.items()}
        if any(not 0 <= h <= 0xFFFFFFFF for h in out.values()):
            raise ValueError("a hash of more than 8 hex digits")
        return out
    except (ValueError, AttributeError, TypeError):
        raise ClipError(f"{f.path}: Cryptomatte {layer!r}: the manifest is not JSON of "
                        "name -> hex hash") from None


def cryptomatte_layers(path) -> dict[str, dict[str, int]]:
    """Every Cryptomatte layer of ``path``: layer name -> manifest (name -> hash)."""
    f = _scan(path)
    return {layer: _manifest(f, layer, attrs) for layer, attrs in _layer_attributes(f).items()}


def _rank_channels(f, layer: str) -> list[str]:
    names = {n for p in f.parts for n in p.channels}
    out = []
    rank = 0
    while all(f"{layer}{rank:02d}.{c}" in names for c in "RGBA"):
        out += [f"{layer}{rank:02d}.{c}" for c in "RGBA"]
        rank += 1
    return out


def _selection(f, layer: str, names) -> tuple[list[str], list[int]]:
    """(rank channels, selected hashes), checked from the header."""
    layers = _layer_attributes(f)
    channels = _rank_channels(f, layer)
    if layer not in layers and not channels:
        known = sorted(set(layers) | {n.split(".")[0][:-2] for p in f.parts for n in p.channels
                                      if n.split(".")[0][-2:] == "00"})
        close = difflib.get_close_matches(layer, known, n=1)
        hint = f"; did you mean {close[0]!r}?" if close else \
            (f" (layers: {', '.join(known)})" if known else " (the file has none)")
        raise ClipError(f"{f.path}: no Cryptomatte layer {layer!r}{hint}")
    if not channels:
        raise ClipError(f"{f.path}: Cryptomatte {layer!r} has no rank channels "
                        f"({layer}00.R/G/B/A)")
    manifest = _manifest(f, layer, layers.get(layer, {}))
    hashes = []
    for name in names:
        if name in manifest:
            hashes.append(manifest[name])
        elif manifest:
            close = [n for n in manifest if n.lower() == name.lower()] or \
                difflib.get_close_matches(name, list(manifest), n=3)
            hint = f"; did you mean {', '.join(map(repr, close))}?" if close else \
                f" (it lists {len(manifest)} names)"
            raise ClipError(f"{f.path}: Cryptomatte {layer!r}: {name!r} is not in the "
                            f"manifest{hint}")
        else:            # no manifest: the id is the name's hash (the spec's definition)
            hashes.append(name_hash(name))
    return channels, hashes


def check_cryptomatte(path, layer: str, names) -> bool:
    """Raise `ClipError` now (from the header only) if the layer or a name is missing;
    return whether the layer has a manifest (without one, names are matched by hash)."""
    f = _scan(path)
    _selection(f, layer, names)
    return bool(_manifest(f, layer, _layer_attributes(f).get(layer, {})))


def display_window(path) -> Rect:
    """The display window of ``path``'s first part (from the header)."""
    return _scan(path).parts[0].display_window


def cryptomatte(path, layer: str, names, *, view: str | None = None) -> tuple[np.ndarray, Rect]:
    """The matte of the objects ``names`` of Cryptomatte layer ``layer``: float32 (h, w)
    coverage in [0, 1] and the data window it covers.

    Raises
    ------
    ClipError
        No such layer, no rank channels, a name not in the manifest.
    """
    f = _scan(path)
    channels, hashes = _selection(f, layer, names)
    part = _part_with(f, channels, view)
    got = _read_channels(f.path, part, channels)
    wanted = np.array(sorted(set(hashes)), np.uint32)
    matte = np.zeros(part.data_window.shape, np.float32)
    for i in range(0, len(channels), 2):
        ids = np.ascontiguousarray(got[channels[i]]).view(np.uint32)
        hit = np.isin(ids, wanted)
        matte += np.where(hit, got[channels[i + 1]], 0.0).astype(np.float32)
    return np.clip(matte, 0.0, 1.0), part.data_window
