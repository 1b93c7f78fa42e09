"""Small real plates for the end-to-end tests: Beachball's frames decimated by 4 (2048x1556 ->
512x389), every part, channel, view, pixel type, compression and attribute kept.

Each output pixel is one source pixel (the one nearest the centre of its 4x4 block), with all
its channels: depth 0 stays where alpha is 0 (the "no hit" convention reads the same), masks
stay 0/1, and only the pixel-unit vectors (``forward.*``, ``disparity*``) are divided by 4.
Data windows shrink with the display window (654,245 877x876 -> 163,61 220x219 in 0,0
512x389), so a render still grows its data window inside the display window.  Tests whose
property does not depend on the frame size (a cluster matches one process, resume, frame
order, signals) render these; the full-size plates stay where the size matters."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

SCALE = 4
PIXEL_UNITS = ("forward.", "disparity")
"""Channel names (prefixes, or a part's layer) whose values are distances in pixels."""


def _window(x: int, width: int) -> tuple[int, int]:
    """(first, count) of the decimated pixels whose source pixel ``X*SCALE + SCALE//2`` lies
    in ``[x, x + width)``."""
    o = SCALE // 2
    first = math.ceil((x - o) / SCALE)
    last = (x + width - 1 - o) // SCALE
    return first, last - first + 1


def decimate(src: Path, dst: Path) -> Path:
    """Write ``src`` (any EXR, single- or multipart) decimated by `SCALE` to ``dst``."""
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(src))
    assert inp, oiio.geterror()
    parts = []
    i = 0
    while inp.seek_subimage(i, 0):
        spec = oiio.ImageSpec(inp.spec())
        px = np.asarray(inp.read_image(i, 0, 0, spec.nchannels, "float"))
        x0, w = _window(spec.x, spec.width)
        y0, h = _window(spec.y, spec.height)
        o = SCALE // 2
        cols = np.arange(x0, x0 + w) * SCALE + o - spec.x
        rows = np.arange(y0, y0 + h) * SCALE + o - spec.y
        small = px[rows][:, cols].copy()
        for k, name in enumerate(spec.channelnames):
            if any(name.startswith(p) for p in PIXEL_UNITS):
                small[..., k] /= SCALE
        spec.x, spec.y, spec.width, spec.height = x0, y0, w, h
        spec.full_x, spec.full_y = spec.full_x // SCALE, spec.full_y // SCALE
        spec.full_width, spec.full_height = spec.full_width // SCALE, spec.full_height // SCALE
        spec.erase_attribute("openexr:chunkCount")
        parts.append((spec, small))
        i += 1
    inp.close()
    out = oiio.ImageOutput.create(str(dst))
    specs = [s for s, _ in parts]
    assert out.open(str(dst), specs) if len(specs) > 1 else out.open(str(dst), specs[0]), \
        out.geterror()
    for i, (spec, px) in enumerate(parts):
        if i:
            assert out.open(str(dst), spec, "AppendSubimage"), out.geterror()
        assert out.write_image(px), out.geterror()
    assert out.close()
    return dst


class SmallBeachball:
    """Decimated Beachball frames, each made on first use in ``folder``: ``path(kind,
    frame)`` is one frame's file (kind ``multipart`` or ``singlepart``); ``pattern(kind,
    frames)`` a sequence ``.../KIND.#.exr`` of exactly those frames (links in a folder of
    their own, so a render without ``--frames`` finds those and no others)."""

    def __init__(self, source: Path, folder: Path):
        self.source, self.folder = source, folder

    def path(self, kind: str, frame: int) -> Path:
        dst = self.folder / f"{kind}.{frame:04d}.exr"
        if not dst.is_file():
            decimate(self.source / f"{kind}.{frame:04d}.exr", dst)
        return dst

    def pattern(self, kind: str, frames) -> str:
        frames = list(frames)
        seq = self.folder / f"{kind}-{'-'.join(map(str, frames))}"
        if not seq.is_dir():
            seq.mkdir()
            for f in frames:
                (seq / f"{kind}.{f:04d}.exr").symlink_to(self.path(kind, f))
        return str(seq / f"{kind}.#.exr")
