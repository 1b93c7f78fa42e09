"""Frame patterns (``shot.####.exr``) and frame ranges (``1001-1100x2``), parsed with fileseq.

Padding tokens
--------------
==================  ======================================  ============================
token               digits                                  frame 7 of ``shot.<t>.exr``
==================  ======================================  ============================
``#`` (alone)       4 (fileseq's default, oiiotool meaning)  ``shot.0007.exr``
``##``, ``####``    one per ``#`` (Nuke/Blender meaning)    ``shot.07.exr``, ``shot.0007.exr``
``@``, ``@@@@``     one per ``@``                           ``shot.7.exr``, ``shot.0007.exr``
``%04d``, ``%d``    printf width                            ``shot.0007.exr``, ``shot.7.exr``
``$F4``, ``$F``     Houdini width                           ``shot.0007.exr``, ``shot.7.exr``
==================  ======================================  ============================

A lone ``#`` is four digits (fileseq's ``PAD_STYLE_HASH4``); two or more ``#`` count one digit
each (``PAD_STYLE_HASH1``), so ``####`` is four digits, not sixteen.  Frames wider than the
padding are written in full (``shot.####.exr``, frame 12345 -> ``shot.12345.exr``); negative
frames follow fileseq (``shot.-007.exr``: the sign counts in the width).

A path without a token is a plain file (``is_sequence`` False).  Its frame number is the one
fileseq finds before the extension (``shot.0042.exr`` -> 42), else 1.  ``-`` (stdin/stdout) is
a plain file and is never checked on disk.

Frame ranges
------------
fileseq's syntax: ``1-100``, ``1-100x2`` (step 2), ``1,5,10-20``, ``10-1`` (descending),
``1-10y3`` (fileseq's inverse step).  ``a-b:n`` means *step n* as on render farms (Slurm,
OpenJD), not fileseq's "staggered" meaning, so it is normalised to ``a-bxn`` first
(``1-10:3`` -> 1, 4, 7, 10).  Subframes are refused.
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass, field

import fileseq

from clfx.core.errors import SequenceError

#: Refuse ranges longer than this (a typo like 1-1000000000 would allocate gigabytes).
MAX_FRAMES = 10_000_000

_FARM_STEP = re.compile(r"(-?\d+)-(-?\d+):(\d+)")
_RANGE_HELP = "expected e.g. '1-100', '1-100x2', '1,5,10-20' or farm step '1-10:3'"


def _normalise_range(spec: str) -> str:
    """Remove blanks and turn farm steps ``a-b:n`` into fileseq's ``a-bxn``."""
    chunks = [c for c in re.sub(r"\s+", "", spec).split(",")]
    out = []
    for c in chunks:
        m = _FARM_STEP.fullmatch(c)
        out.append(f"{m.group(1)}-{m.group(2)}x{m.group(3)}" if m else c)
    return ",".join(out)


def parse_frames(spec: str) -> list[int]:
    """Parse a frame range into frame numbers, in the order written.

    Parameters
    ----------
    spec : str
        ``"1-100"``, ``"1-100x2"``, ``"1,5,10-20"``, ``"10-1"``, ``"1-10:3"`` (farm step).

    Returns
    -------
    list of int
        Frames without duplicates, in order (``"1-10:3"`` -> ``[1, 4, 7, 10]``).

    Raises
    ------
    SequenceError
        Malformed, empty, subframe or over-long range; the message names ``spec``.
    """
    text = str(spec)
    norm = _normalise_range(text)
    if not norm or any(not c for c in norm.split(",")):
        raise SequenceError(f"invalid frame range {text!r}: {_RANGE_HELP}")
    try:
        fs = fileseq.FrameSet(norm)
        if len(fs) > MAX_FRAMES:
            raise SequenceError(f"frame range {text!r} has {len(fs)} frames; "
                                f"more than {MAX_FRAMES}")
        frames = list(fs)
    except SequenceError:
        raise
    except Exception as e:      # fileseq raises ParseException, ValueError, MaxSizeException
        reason = " ".join(str(e).split())
        reason = reason if len(reason) < 80 else "not a frame range"
        raise SequenceError(f"invalid frame range {text!r} ({reason}): {_RANGE_HELP}") from None
    if not frames:
        raise SequenceError(f"invalid frame range {text!r}: no frames; {_RANGE_HELP}")
    if any(int(f) != f for f in frames):
        raise SequenceError(f"invalid frame range {text!r}: subframes are not supported")
    return [int(f) for f in frames]


@dataclass(frozen=True)
class FrameSpec:
    """A parsed frame range: the text as given and its frames.

    Examples
    --------
    >>> FrameSpec.parse("1-10:3").frames
    (1, 4, 7, 10)
    """

    text: str
    frames: tuple[int, ...]

    @classmethod
    def parse(cls, spec: str) -> "FrameSpec":
        return cls(str(spec), tuple(parse_frames(spec)))

    def __iter__(self):
        return iter(self.frames)

    def __len__(self) -> int:
        return len(self.frames)

    def __str__(self) -> str:
        return compact(self.frames)


def compact(frames) -> str:
    """Compact text of frame numbers: ``[3, 4, 5, 9]`` -> ``"3-5,9"``."""
    frames = list(frames)
    return str(fileseq.FrameSet(frames)) if frames else ""


def _pad_style(path: str):
    """HASH4 for a lone ``#``, HASH1 when the token has several ``#`` (see module docs)."""
    probe = fileseq.FileSequence(path, pad_style=fileseq.PAD_STYLE_HASH4)
    token = probe.padding()
    if token.count("#") > 1:
        return fileseq.PAD_STYLE_HASH1
    return fileseq.PAD_STYLE_HASH4


@dataclass(frozen=True)
class Pattern:
    """One input or output path, maybe with a frame token.

    Attributes
    ----------
    text : str
        The path as given.
    is_sequence : bool
        True if it holds a frame token (``#``, ``@``, ``%04d``, ``$F4``).
    """

    text: str
    is_sequence: bool
    _seq: object = field(repr=False, compare=False, default=None)
    _pad_style: object = field(repr=False, compare=False, default=None)

    @classmethod
    def parse(cls, path) -> "Pattern":
        """Parse ``"shot.####.exr"``, ``"shot.%04d.exr"``, ``"shot.$F4.exr"``,
        ``"shot.@.exr"``, ``"shot.#.exr"`` or a plain file path.

        Raises
        ------
        SequenceError
            fileseq cannot parse the path.
        """
        text = os.fspath(path)
        if text in ("", "-"):
            return cls(text, False, None, None)
        try:
            style = _pad_style(text)
            seq = fileseq.FileSequence(text, pad_style=style)
        except Exception as e:
            raise SequenceError(f"invalid frame pattern {text!r}: {' '.join(str(e).split())}") \
                from None
        is_seq = bool(seq.padding()) and seq.frameSet() is None
        return cls(text, is_seq, seq, style)

    def path(self, frame: int) -> str:
        """The file name of ``frame`` (the path itself for a plain file)."""
        if not self.is_sequence:
            return self.text
        return self._seq.frame(int(frame))

    def frame_from_name(self) -> int:
        """For a plain file: the frame number in its name (``shot.0042.exr`` -> 42), else 1."""
        if self._seq is not None and not self.is_sequence:
            fs = self._seq.frameSet()
            if fs is not None and len(fs) == 1:
                return int(list(fs)[0])
        return 1

    def existing_frames(self) -> list[int]:
        """Frames of this pattern present on disk, ascending ([] if none).

        Padding is strict: for ``shot.####.exr``, ``shot.0007.exr`` counts but ``shot.7.exr``
        does not; frames wider than the padding (``shot.12345.exr``) count.
        """
        if not self.is_sequence:
            return [self.frame_from_name()] if os.path.isfile(self.text) else []
        try:
            found = fileseq.findSequenceOnDisk(self.text, strictPadding=True,
                                               pad_style=self._pad_style)
        except fileseq.FileSeqException:
            return []
        fs = found.frameSet()
        return sorted(int(f) for f in fs) if fs is not None else []

    def __str__(self) -> str:
        return self.text


def resolve_inputs(pattern: Pattern, frames: list[int] | None, *,
                   skip_missing: bool) -> list[tuple[int, str]]:
    """The (frame, path) pairs to read.

    Parameters
    ----------
    pattern : Pattern
        Input pattern or plain file.
    frames : list of int, optional
        Frames wanted.  None: every frame on disk (a sequence) or the file's own frame
        number (a plain file).  A plain file with frames serves every frame (a still).
    skip_missing : bool
        Skip missing frames instead of raising.

    Returns
    -------
    list of (int, str)

    Raises
    ------
    SequenceError
        ``"missing frames 3-5,9 of shot.####.exr"``; no frames on disk; missing plain file.
    """
    if not pattern.is_sequence:
        if pattern.text != "-" and not os.path.isfile(pattern.text):
            if skip_missing:
                return []
            raise SequenceError(f"missing file {pattern.text}")
        wanted = frames if frames is not None else [pattern.frame_from_name()]
        return [(int(f), pattern.text) for f in wanted]
    if frames is None:
        on_disk = pattern.existing_frames()
        if not on_disk and not skip_missing:
            raise SequenceError(f"no frames of {pattern.text} on disk")
        return [(f, pattern.path(f)) for f in on_disk]
    pairs = [(int(f), pattern.path(f)) for f in frames]
    missing = [f for f, p in pairs if not os.path.isfile(p)]
    if missing and not skip_missing:
        raise SequenceError(f"missing frames {compact(missing)} of {pattern.text}")
    gone = set(missing)
    return [(f, p) for f, p in pairs if f not in gone]


def output_path(pattern: Pattern, frame: int) -> str:
    """The output file of ``frame`` (the path itself for a plain file)."""
    return pattern.path(frame)
