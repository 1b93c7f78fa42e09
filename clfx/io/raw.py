"""Raw frames on a pipe, as ffmpeg's ``-f rawvideo`` writes and reads them.

Formats (``--raw-format``, ffmpeg's ``-pix_fmt`` names); every value is a little-endian
float32, no header, frames follow each other until end of file:

=============  ======================================================================
gbrpf32le      (default) planar: the G plane, then B, then R (each ``height`` rows of
               ``width`` values): ffmpeg's order, not R, G, B
gbrapf32le     planar with alpha: G, B, R, then A
rgbf32le       packed: R, G, B of each pixel in turn
rgbaf32le      packed with alpha: R, G, B, A of each pixel in turn
=============  ======================================================================

A writer that sends R, G, B planes as ``gbrpf32le`` gets its channels swapped: send G, B, R,
or packed ``rgbf32le``.  Frames read without alpha get alpha 1 (RGB: files written from them
are RGB); written without alpha, they carry the premultiplied colour (over black).  With
alpha, colour is premultiplied by it, as in an EXR.  Raw frames carry no passes.

Colour: the stream's values are in ``colorspace`` (``--colorspace``; default scene-linear
Rec.709, as an untagged EXR) and are converted into the working space (``--working-space``);
frames are written back in ``--out-colorspace``, else in the input's space (`clfx.io.colour`).

Examples
--------
::

    ffmpeg -i in.mov -f rawvideo -pix_fmt gbrpf32le - \\
      | clfx render - - --look default --raw 1920x1080 \\
      | ffmpeg -f rawvideo -pix_fmt gbrpf32le -s 1920x1080 -i - out.mov
    ffmpeg -i in.mov -f rawvideo -pix_fmt gbrpf32le - | clfx render - out.#.exr --raw 1920x1080
    clfx render shot.#.exr - --raw-format rgbf32le | ffmpeg -f rawvideo -pix_fmt rgbf32le ...
"""
from __future__ import annotations

import numpy as np

from clfx.core.errors import ImageIOError, SequenceError
from clfx.core.frame import Frame, crop_to
from clfx.core.limits import check_pixels
from clfx.core.rect import Rect
from clfx.io import colour
import os
import stat

PIX_FMT = "gbrpf32le"
"""The default format (ffmpeg's planar float RGB)."""

FORMATS = {"gbrpf32le": ("GBR", True), "gbrapf32le": ("GBRA", True),
           "rgbf32le": ("RGB", False), "rgbaf32le": ("RGBA", False)}
"""ffmpeg pixel format -> (the channels in stream order, planar)."""


def check_format(pix_fmt: str) -> str:
    """``pix_fmt`` when it is one of `FORMATS`, else SequenceError naming them."""
    if pix_fmt not in FORMATS:
        raise SequenceError(f"--raw-format {pix_fmt!r}: expected one of {', '.join(FORMATS)}")
    return pix_fmt


def frame_bytes(size: tuple[int, int], pix_fmt: str = PIX_FMT) -> int:
    """Bytes of one ``size`` frame in ``pix_fmt``."""
    w, h = size
    return w * h * len(FORMATS[check_format(pix_fmt)][0]) * 4


def parse_size(text: str) -> tuple[int, int]:
    """``"1920x1080"`` -> ``(1920, 1080)``.

    Raises
    ------
    SequenceError
        Not ``WxH`` with positive integers, or over `clfx.core.limits` (checked before any
        buffer is allocated).
    """
    w, h = parse_wxh(text)
    check_pixels(w, h, "--raw frame", SequenceError)  # before a frame's bytes are read
    return w, h


def parse_wxh(text: str) -> tuple[int, int]:
    """``"1920x1080"`` -> ``(1920, 1080)`` without the size limit; SequenceError unless
    ``WxH`` with positive integers (the CLI's usage check, `parse_size`'s first half)."""
    parts = str(text).lower().split("x")
    if len(parts) != 2 or not all(v.isascii() and v.isdigit() and int(v) > 0 for v in parts):
        raise SequenceError(f"--raw {text!r} is not WxH (two positive whole numbers)")
    return int(parts[0]), int(parts[1])


def read_raw(stream, size: tuple[int, int], index: int = 0, *, colorspace: str | None = None,
             working_space: str | None = None, pix_fmt: str = PIX_FMT) -> Frame | None:
    """The next ``pix_fmt`` frame of ``stream`` (a binary file; see the module's table), or
    None at end of file, converted from ``colorspace`` (default linear Rec.709; ``"raw"``: as
    is) into ``working_space`` (default linear Rec.709).  ``Frame.channels`` says whether the
    stream had alpha (4) or not (3).

    Raises
    ------
    ImageIOError
        The stream ends inside a frame.
    """
    w, h = size
    order, planar = FORMATS[check_format(pix_fmt)]
    nbytes = frame_bytes(size, pix_fmt)
    data = stream.read(nbytes)
    if not data:
        return None
    if len(data) != nbytes:
        raise ImageIOError(f"stdin: truncated raw frame {index} ({len(data)} of {nbytes} bytes; "
                           f"is --raw {w}x{h} the size of the frames, {pix_fmt} their format?)")
    values = np.frombuffer(data, "<f4")
    planes = values.reshape(len(order), h, w) if planar else \
        np.moveaxis(values.reshape(h, w, len(order)), -1, 0)
    rgba = np.ones((h, w, 4), np.float32)
    for plane, name in zip(planes, order):
        rgba[..., "RGBA".index(name)] = plane
    working = colour.resolve(working_space or colour.DEFAULT_WORKING, "--working-space")
    source = colour.resolve(colorspace, "--colorspace") if colorspace else \
        colour.resolve(colour.DEFAULT_WORKING)
    rgba = colour.convert(rgba, source, working, "stdin")
    return Frame(rgba, Rect.from_size(w, h), Rect.from_size(w, h), source="stdin",
                 colorspace=working, source_colorspace=None if source == colour.RAW else source,
                 channels=len(order))


def write_raw(stream, frame: Frame, window: Rect, *, colorspace: str | None = None,
              pix_fmt: str = PIX_FMT) -> None:
    """Write ``frame`` cut or padded to ``window`` (the input's: a raw input's frame, a
    file's display window) as one ``pix_fmt`` frame, in ``colorspace`` (default: the
    input's space, ``frame.source_colorspace``)."""
    order, planar = FORMATS[check_format(pix_fmt)]
    target = colour.resolve(colorspace, "--out-colorspace") if colorspace else \
        (frame.source_colorspace or frame.colorspace)
    o = colour.convert(frame.rgba, frame.colorspace, target, "stdout")
    if frame.data_window != window:
        o = crop_to(o, frame.data_window, window)
    channels = [o[..., "RGBA".index(name)] for name in order]
    data = np.stack(channels) if planar else np.stack(channels, axis=-1)
    stream.write(np.ascontiguousarray(data, "<f4").tobytes())
    stream.flush()


def check_stream_size(stream, size: tuple[int, int], pix_fmt: str = PIX_FMT) -> None:
    """Before anything is read: when ``stream`` is a regular file (``< frames.raw``), its
    length must be a whole number of ``size`` frames in ``pix_fmt``.  Pipes cannot tell
    their length; their frames are checked as they are read (`read_raw` raises on a short
    frame).

    Raises
    ------
    SequenceError
        The file's length is not a multiple of the frame size (the error says how many
        frames of that size it would hold).
    """
    try:
        st = os.fstat(stream.fileno())
    except (AttributeError, OSError, ValueError):
        return
    if not stat.S_ISREG(st.st_mode):
        return
    w, h = size
    nbytes = frame_bytes(size, pix_fmt)
    try:
        remaining = st.st_size - stream.tell()
    except (AttributeError, OSError, ValueError):
        remaining = st.st_size
    if remaining % nbytes:
        raise SequenceError(f"--raw {w}x{h}: stdin holds {remaining} bytes, {remaining / nbytes:.3g} "
                            f"frames of {nbytes} bytes ({w}x{h} {pix_fmt}); is the size right?")
