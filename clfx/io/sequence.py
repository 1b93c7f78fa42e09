"""Frame patterns (``shot.#.exr``, parsed with fileseq), frame ranges (``1001-1100x2``) and
the input files on disk.

Padding tokens
--------------
One convention, oiiotool's (``oiiotool --frames``, OpenImageIO's ``Filesystem::parse_pattern``),
which is fileseq's ``PAD_STYLE_HASH4``: **each ``#`` is four digits of padding, each ``@``
one**, and they add up in a token that mixes them.

==================  ==============================  ============================
token               digits                          frame 7 of ``shot.<t>.exr``
==================  ==============================  ============================
``#``               4                               ``shot.0007.exr``
``##``              8                               ``shot.00000007.exr``
``####``            16 (not 4: write ``#``)         ``shot.0000000000000007.exr``
``@``, ``@@@``      1, 3                            ``shot.7.exr``, ``shot.007.exr``
``#@``, ``@@#``     5, 6 (4 per ``#`` + 1 per ``@``)  ``shot.00007.exr``, ``shot.000007.exr``
``%04d``, ``%d``    printf width                    ``shot.0007.exr``, ``shot.7.exr``
``$F4``, ``$F``     Houdini width                   ``shot.0007.exr``, ``shot.7.exr``
==================  ==============================  ============================

Nuke and Blender count one digit per ``#``; a token of several ``#`` is read oiiotool's way
and said once on stderr (`hash_notice`), since a Nuke user's ``shot.####.exr`` means 16
digits here.  Frames wider than the padding are written in full (``shot.#.exr``, frame
12345 -> ``shot.12345.exr``); negative frames follow fileseq (``shot.-007.exr``: the sign
counts in the width).

A path without a token is a plain file (``is_sequence`` False).  Its frame number is the one
fileseq finds before the extension (``shot.0042.exr`` -> 42), else 1.  ``-`` (stdin/stdout) is
a plain file and is never checked on disk.

Padding is at most ``MAX_PADDING`` digits (``o.$F999999999.exr`` is refused at once instead of
building a billion-character name).

Frame ranges
------------
Comma-separated chunks, each ``N``, ``A-B`` or ``A-BxN`` (step N), ``1-100``, ``1-100x2``,
``1,5,10-20``, ``-3--1``; ``A-B:N`` means *step N* as on render farms (Slurm, OpenJD), not
fileseq's "staggered" meaning (``1-10:3`` -> 1, 4, 7, 10).  Frames keep the order written,
without duplicates.  Strict: ASCII digits only (no full-width ``１-５``), ``A <= B`` (``5-1`` is
refused, not reversed), step >= 1, no fileseq extras (``1-10y3``), no subframes, at most
``MAX_FRAMES`` frames; every refusal is a `SequenceError` naming the text.

Input files
-----------
Inputs must be regular files (`check_input_file`): a FIFO, socket or device as a frame is
refused by its name before anything opens it (opening a FIFO would block).
"""
from __future__ import annotations

import os
import re
import stat
from dataclasses import dataclass, field

import fileseq

from clfx.core.errors import ImageIOError, SequenceError

#: Refuse ranges longer than this (a typo like 1-1000000000 would allocate gigabytes).
MAX_FRAMES = 10_000_000
#: Refuse frame tokens wider than this (``$F999999999`` would build a 1 GB file name).
MAX_PADDING = 16

_INT = r"-?[0-9]{1,9}"
_CHUNK = re.compile(rf"(?P<a>{_INT})(?:-(?P<b>{_INT})(?:[x:](?P<step>[0-9]{{1,9}}))?)?")
_RANGE_HELP = "expected e.g. '1-100', '1-100x2', '1,5,10-20' or farm step '1-10:3'"

_NOT_REGULAR = ((stat.S_ISFIFO, "a FIFO"), (stat.S_ISSOCK, "a socket"),
                (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"))


def _range_error(text: str, why: str) -> SequenceError:
    return SequenceError(f"invalid frame range {text!r}: {why}; {_RANGE_HELP}")


def _chunk_frames(text: str, chunk: str) -> range:
    m = _CHUNK.fullmatch(chunk)
    if m is None:
        if any(c.isdigit() and not c.isascii() for c in chunk):
            raise _range_error(text, f"{chunk!r} has non-ASCII digits")
        if "." in chunk:
            raise _range_error(text, "subframes are not supported")
        raise _range_error(text, f"{chunk!r} is not a frame range")
    a = int(m["a"])
    b = int(m["b"]) if m["b"] is not None else a
    step = int(m["step"]) if m["step"] is not None else 1
    if b < a:
        raise _range_error(text, f"{chunk!r} runs backwards (write {b}-{a})")
    if step < 1:
        raise _range_error(text, f"step in {chunk!r} must be at least 1")
    return range(a, b + 1, step)


def parse_frames(spec: str) -> list[int]:
    """Parse a frame range into frame numbers, in the order written.

    Parameters
    ----------
    spec : str
        ``"1-100"``, ``"1-100x2"``, ``"1,5,10-20"``, ``"-3--1"``, ``"1-10:3"`` (farm step).

    Returns
    -------
    list of int
        Frames without duplicates, in order (``"1-10:3"`` -> ``[1, 4, 7, 10]``).

    Raises
    ------
    SequenceError
        Empty, malformed, backwards (``5-1``), non-ASCII, subframe or over-long range; the
        message names ``spec``.
    """
    text = str(spec)
    norm = re.sub(r"[ \t]+", "", text)
    if not norm:
        raise _range_error(text, "no frames")
    ranges = [_chunk_frames(text, c) for c in norm.split(",")]
    count = sum(len(r) for r in ranges)
    if count > MAX_FRAMES:
        raise SequenceError(f"frame range {text!r} has {count} frames; more than {MAX_FRAMES}")
    return list(dict.fromkeys(f for r in ranges for f in r))


def shown(path) -> str:
    """``path`` as printable text: bytes that are not UTF-8 (a name from a Latin-1 file
    system, ``caf\\xe9.exr``) and lone surrogates as backslash escapes."""
    text = os.fspath(path)
    if isinstance(text, bytes):
        return text.decode("utf-8", "backslashreplace")
    try:
        return os.fsencode(text).decode("utf-8", "backslashreplace")
    except UnicodeEncodeError:
        return text.encode("utf-8", "backslashreplace").decode("ascii")


def check_name(path, verb: str = "cannot read") -> str:
    """Refuse a file name OpenImageIO cannot take (it passes names as UTF-8 text): one whose
    bytes are not UTF-8; return the path as a string."""
    text = os.fspath(path)
    try:
        if isinstance(text, bytes):
            text = text.decode("utf-8")
        else:
            text.encode("utf-8")
    except UnicodeError:
        raise ImageIOError(f"{verb} {shown(path)}: the name is not UTF-8 text, which "
                           f"OpenImageIO cannot open; rename it") from None
    return text


def check_input_file(path, what: str = "input") -> str:
    """Refuse anything but an existing regular file, without opening it (a FIFO would block);
    return the path as a string.

    Raises
    ------
    ImageIOError
        ``cannot read <path>: no such file`` / ``it is a folder`` / ``not a regular file (a
        FIFO)``; ``what`` names the role (``"glare.kernel_path"``) when it is not a frame.
    """
    role = "" if what == "input" else f" ({what})"
    path = check_name(path)
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        raise ImageIOError(f"cannot read {path}{role}: no such file") from None
    except OSError as e:
        raise ImageIOError(f"cannot read {path}{role}: {e.strerror}") from None
    if stat.S_ISDIR(mode):
        raise ImageIOError(f"cannot read {path}{role}: it is a folder")
    if not stat.S_ISREG(mode):
        kind = next((name for test, name in _NOT_REGULAR if test(mode)), "special file")
        raise ImageIOError(f"cannot read {path}{role}: not a regular file ({kind})")
    return path


def _present(path: str) -> bool:
    """An input frame is there: a regular file (True), missing (False), else ImageIOError."""
    if not os.path.lexists(path):
        return False
    if not os.path.exists(path):       # dangling symlink: missing
        return False
    check_input_file(path)
    return True


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


FRAME_TOKEN = re.compile(r"[#@]+|%0?\d*d|\$F\d*")
"""A frame token: ``#`` and ``@`` (mixed too: ``#@``), ``%04d``, ``$F4``."""


PAD_STYLE = fileseq.PAD_STYLE_HASH4
"""oiiotool's padding: ``#`` four digits, ``@`` one (see the module docs)."""


def hash_notice(pattern: "Pattern") -> str | None:
    """One line for a pattern whose token has several ``#`` (``shot.####.exr``: 16 digits
    here, 4 in Nuke), else None."""
    token = pattern.token
    n = token.count("#")
    if n < 2:
        return None
    return (f"{pattern.text}: each # is 4 digits of padding (oiiotool's convention), so "
            f"{token} is {pattern.padding} digits ({os.path.basename(pattern.path(1))}); for "
            f"{n} digits write {'@' * n} or %0{n}d")


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
        """Parse ``"shot.#.exr"`` (4 digits), ``"shot.@@@.exr"`` (3), ``"shot.#@.exr"``
        (5), ``"shot.%04d.exr"``, ``"shot.$F4.exr"`` or a plain file path.

        Raises
        ------
        SequenceError
            fileseq cannot parse the path.
        """
        text = os.fspath(path)
        if text in ("", "-"):
            return cls(text, False, None, None)
        tokens = FRAME_TOKEN.findall(text)
        if len(tokens) > 1:      # fileseq filled one and kept the other literally (or neither)
            raise SequenceError(f"invalid frame pattern {text!r}: {len(tokens)} frame tokens "
                                f"({', '.join(tokens)}); give one")
        try:
            style = PAD_STYLE
            seq = fileseq.FileSequence(text, pad_style=style)
        except Exception as e:
            raise SequenceError(f"invalid frame pattern {text!r}: {' '.join(str(e).split())}") \
                from None
        is_seq = bool(seq.padding()) and seq.frameSet() is None
        if is_seq and seq.zfill() > MAX_PADDING:
            raise SequenceError(f"invalid frame pattern {text!r}: {seq.zfill()} digits of "
                                f"padding; at most {MAX_PADDING}")
        return cls(text, is_seq, seq, style)

    @property
    def token(self) -> str:
        """The frame token as written (``####``, ``@@@``, ``%04d``, ``$F4``; "" for a file)."""
        return self._seq.padding() if self.is_sequence else ""

    @property
    def padding(self) -> int:
        """Digits of padding the token asks for (0 for a plain file)."""
        return self._seq.zfill() if self.is_sequence else 0

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

        Padding is strict: for ``shot.#.exr``, ``shot.0007.exr`` counts but ``shot.7.exr``
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
        ``"missing frame 3 of shot.#.exr: no file /shots/a/shot.0003.exr"`` (several: the
        frames, the first file's whole path, how many more); no frames on disk; missing
        plain file.
    ImageIOError
        An input is there but is not a regular file (a FIFO, a folder).
    """
    if not pattern.is_sequence:
        if pattern.text != "-" and not _present(pattern.text):
            if skip_missing:
                return []
            raise SequenceError(f"missing file {pattern.text}")
        wanted = frames if frames is not None else [pattern.frame_from_name()]
        return [(int(f), pattern.text) for f in wanted]
    if frames is None:
        on_disk = pattern.existing_frames()
        if not on_disk and not skip_missing:
            hint = hash_notice(pattern)
            raise SequenceError(f"no frames of {pattern.text} on disk (looked for files like "
                                f"{pattern.path(1)})" + (f"; {hint}" if hint else ""))
        return [(f, check_input_file(pattern.path(f))) for f in on_disk]
    pairs = [(int(f), pattern.path(f)) for f in frames]
    missing = [(f, p) for f, p in pairs if not _present(p)]
    if missing and not skip_missing:
        raise SequenceError(missing_message(pattern, missing))
    gone = {f for f, _ in missing}
    return [(f, p) for f, p in pairs if f not in gone]


def missing_message(pattern: Pattern, missing: list[tuple[int, str]]) -> str:
    """The frames missing, by the files looked for: ``missing frame 3 of shot.#.exr: no
    file /shots/a/shot.0003.exr`` (several: the first file's whole path, the last's name)."""
    (first, path), last = missing[0], missing[-1][1]
    if len(missing) == 1:
        return f"missing frame {first} of {pattern.text}: no file {path}"
    return (f"missing frames {compact(f for f, _ in missing)} of {pattern.text}: no file "
            f"{path}, nor {len(missing) - 1} more up to {os.path.basename(last)}")


def output_path(pattern: Pattern, frame: int) -> str:
    """The output file of ``frame`` (the path itself for a plain file)."""
    return pattern.path(frame)
