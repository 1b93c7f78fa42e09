"""Raw frames on a pipe, as ffmpeg's ``-f rawvideo -pix_fmt gbrpf32le`` writes and reads them.

A frame is three planes of little-endian float32, in the order G, B, R, each ``height`` rows
of ``width`` values, no header; frames follow each other until end of file.  Read frames are
RGBA with alpha 1 and no passes; written frames drop alpha (premultiplied colour).

Colour: the stream's values are in ``colorspace`` (``--colorspace``; default scene-linear
Rec.709, as an untagged EXR) and are converted into the working space (``--working-space``);
frames are written back in ``--out-colorspace``, else in the input's space (`clfx.io.colour`).

Examples
--------
::

    ffmpeg -i in.mov -f rawvideo -pix_fmt gbrpf32le - \\
      | clfx render - - --look default --raw 1920x1080 \\
      | ffmpeg -f rawvideo -pix_fmt gbrpf32le -s 1920x1080 -i - out.mov
"""
from __future__ import annotations

import numpy as np

from clfx.core.errors import ImageIOError, SequenceError
from clfx.core.frame import Frame, crop_to
from clfx.core.limits import check_pixels
from clfx.core.rect import Rect
from clfx.io import colour

PIX_FMT = "gbrpf32le"


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
             working_space: str | None = None) -> Frame | None:
    """The next ``gbrpf32le`` frame of ``stream`` (a binary file), or None at end of file,
    converted from ``colorspace`` (default linear Rec.709; ``"raw"``: as is) into
    ``working_space`` (default linear Rec.709).

    Raises
    ------
    ImageIOError
        The stream ends inside a frame.
    """
    w, h = size
    nbytes = w * h * 3 * 4
    data = stream.read(nbytes)
    if not data:
        return None
    if len(data) != nbytes:
        raise ImageIOError(f"stdin: truncated raw frame {index} ({len(data)} of {nbytes} bytes; "
                            f"is --raw {w}x{h} the size of the frames?)")
    planes = np.frombuffer(data, np.float32).reshape(3, h, w)  # G, B, R
    rgba = np.empty((h, w, 4), np.float32)
    rgba[..., 0], rgba[..., 1], rgba[..., 2], rgba[..., 3] = planes[2], planes[0], planes[1], 1.0
    working = colour.resolve(working_space or colour.DEFAULT_WORKING, "--working-space")
    source = colour.resolve(colorspace, "--colorspace") if colorspace else \
        colour.resolve(colour.DEFAULT_WORKING)
    rgba = colour.convert(rgba, source, working, "stdin")
    return Frame(rgba, Rect.from_size(w, h), Rect.from_size(w, h), source="stdin",
                 colorspace=working, source_colorspace=None if source == colour.RAW else source)


def write_raw(stream, frame: Frame, window: Rect, *, colorspace: str | None = None) -> None:
    """Write ``frame`` cut or padded to ``window`` (the input's) as one ``gbrpf32le`` frame,
    in ``colorspace`` (default: the input's space, ``frame.source_colorspace``)."""
    target = colour.resolve(colorspace, "--out-colorspace") if colorspace else \
        (frame.source_colorspace or frame.colorspace)
    o = colour.convert(frame.rgba, frame.colorspace, target, "stdout")
    if frame.data_window != window:
        o = crop_to(o, frame.data_window, window)
    stream.write(np.ascontiguousarray(np.stack([o[..., 1], o[..., 2], o[..., 0]])).tobytes())
    stream.flush()


def check_stream_size(stream, size: tuple[int, int]) -> None:
    """Before anything is read: when ``stream`` is a regular file (``< frames.raw``), its
    length must be a whole number of ``size`` frames.  Pipes cannot tell their length; their
    frames are checked as they are read (`read_raw` raises on a short frame).

    Raises
    ------
    SequenceError
        The file's length is not a multiple of the frame size (the error says how many
        frames of that size it would hold).
    """
    import os
    import stat

    try:
        st = os.fstat(stream.fileno())
    except (AttributeError, OSError, ValueError):
        return
    if not stat.S_ISREG(st.st_mode):
        return
    w, h = size
    nbytes = w * h * 3 * 4
    try:
        remaining = st.st_size - stream.tell()
    except (AttributeError, OSError, ValueError):
        remaining = st.st_size
    if remaining % nbytes:
        raise SequenceError(f"--raw {w}x{h}: stdin holds {remaining} bytes, {remaining / nbytes:.3g} "
                            f"frames of {nbytes} bytes ({w}x{h} {PIX_FMT}); is the size right?")
