"""clfx.io.sequence: frame patterns, ranges, missing frames, input files."""
import os

import pytest

from clfx.core.errors import ImageIOError, SequenceError
from clfx.io.sequence import (FrameSpec, Pattern, check_input_file, output_path, parse_frames,
                              resolve_inputs)


@pytest.mark.parametrize("text, frame, want", [
    # oiiotool's padding (fileseq's PAD_STYLE_HASH4): each # four digits, each @ one
    ("shot.#.exr", 7, "shot.0007.exr"),
    ("shot.##.exr", 7, "shot.00000007.exr"),
    ("shot.####.exr", 7, "shot.0000000000000007.exr"),
    ("shot.@.exr", 7, "shot.7.exr"),
    ("shot.@@@.exr", 7, "shot.007.exr"),
    ("shot.@@@@.exr", 7, "shot.0007.exr"),
    ("shot.#@.exr", 7, "shot.00007.exr"),         # mixed: 4 + 1
    ("shot.@#@.exr", 7, "shot.000007.exr"),       # 1 + 4 + 1
    ("shot.%04d.exr", 7, "shot.0007.exr"),
    ("shot.%d.exr", 7, "shot.7.exr"),
    ("shot.$F4.exr", 7, "shot.0007.exr"),
    ("shot.$F.exr", 7, "shot.7.exr"),
    ("/renders/a/shot.#.exr", 1001, "/renders/a/shot.1001.exr"),
    ("shot.#.exr", 12345, "shot.12345.exr"),      # wider than the padding: written in full
])
def test_pattern_tokens(text, frame, want):
    p = Pattern.parse(text)
    assert p.is_sequence
    assert p.path(frame) == want
    assert output_path(p, frame) == want


def test_patterns_match_oiiotool():
    """The same names as oiiotool's own expansion of each token (OpenImageIO 3.2:
    ``oiiotool --frames 7 ... -o x.<token>.exr``): #=0007, ##=00000007, ####=16 digits,
    @@@=007, #@=00007."""
    for token, name in (("#", "x.0007.exr"), ("##", "x.00000007.exr"),
                        ("####", "x.0000000000000007.exr"), ("@@@", "x.007.exr"),
                        ("#@", "x.00007.exr")):
        assert Pattern.parse(f"x.{token}.exr").path(7) == name


def test_several_hashes_are_said():
    """A Nuke user's ``####`` is 16 digits here: said, with what to write for 4."""
    from clfx.io.sequence import hash_notice

    assert hash_notice(Pattern.parse("shot.#.exr")) is None
    assert hash_notice(Pattern.parse("shot.@@@@.exr")) is None
    text = hash_notice(Pattern.parse("shot.####.exr"))
    assert "16 digits" in text and "@@@@" in text and "%04d" in text


@pytest.mark.parametrize("text", ["shot.exr", "shot.0042.exr", "/a/b/plate.tif", "-"])
def test_plain_files(text):
    p = Pattern.parse(text)
    assert not p.is_sequence
    assert p.path(5) == text


def test_plain_file_frame_number():
    assert Pattern.parse("shot.0042.exr").frame_from_name() == 42
    assert Pattern.parse("shot.exr").frame_from_name() == 1


@pytest.mark.parametrize("spec, want", [
    ("1-5", [1, 2, 3, 4, 5]),
    ("1-10x2", [1, 3, 5, 7, 9]),
    ("1,5,10-12", [1, 5, 10, 11, 12]),
    ("1-5,3,2-4", [1, 2, 3, 4, 5]),                 # duplicates dropped, order kept
    ("1-10:3", [1, 4, 7, 10]),                     # farm step, not fileseq's stagger
    ("1-10:3,20", [1, 4, 7, 10, 20]),
    (" 1 - 3 ", [1, 2, 3]),
    ("1001", [1001]),
    ("-3--1", [-3, -2, -1]),
])
def test_parse_frames(spec, want):
    assert parse_frames(spec) == want


def test_parse_frames_long_range():
    assert len(parse_frames("1-100")) == 100
    assert parse_frames("1-100x2")[:3] == [1, 3, 5] and len(parse_frames("1-100x2")) == 50


@pytest.mark.parametrize("spec", [
    "", " ", "abc", "1-", "1,,2", "1-10x0", "1.5", "1-1000000000",
    "5-1", "10-7",                   # backwards: refused, not reversed (issue 10, item 9)
    "1-8y2", "1-10:0",               # fileseq's inverse step; a zero farm step
    "\uff11-\uff15", "1-\u0665",           # full-width and Arabic-Indic digits
    "1-5,\uff19", "1x2", "--1", "0x10-20",
])
def test_bad_ranges_name_the_spec(spec):
    with pytest.raises(SequenceError) as info:
        parse_frames(spec)
    assert repr(spec) in str(info.value)
    assert "\n" not in str(info.value)


def test_bad_range_says_why():
    with pytest.raises(SequenceError, match="runs backwards"):
        parse_frames("5-1")
    with pytest.raises(SequenceError, match="non-ASCII digits"):
        parse_frames("\uff11-\uff15")
    with pytest.raises(SequenceError, match="subframes"):
        parse_frames("1.5")
    with pytest.raises(SequenceError, match="more than"):
        parse_frames("1-9000000,1-9000000")       # counted before any list is built


@pytest.mark.parametrize("text", ["o.$F999999999.exr", "o.%0999999999d.exr", "o.%17d.exr",
                                  "o." + "#" * 5 + ".exr", "o.@@@@@@@@@@@@@@@@@.exr"])
def test_absurd_padding_refused_at_once(text):
    with pytest.raises(SequenceError, match="at most 16") as info:
        Pattern.parse(text)
    assert "\n" not in str(info.value)
    assert Pattern.parse(text.replace("999999999", "16").replace("17", "16")
                         .replace("#" * 5, "#" * 4).replace("@" * 17, "@" * 16)).is_sequence


def test_frame_spec():
    fs = FrameSpec.parse("1-5,9")
    assert fs.frames == (1, 2, 3, 4, 5, 9) and len(fs) == 6 and str(fs) == "1-5,9"
    assert list(fs) == [1, 2, 3, 4, 5, 9]


@pytest.fixture
def shots(tmp_path):
    for f in (1, 2, 5, 6, 7, 10):
        (tmp_path / f"shot.{f:04d}.exr").write_bytes(b"x")
    (tmp_path / "shot.8.exr").write_bytes(b"x")          # wrong padding: not part of #
    (tmp_path / "other.0003.exr").write_bytes(b"x")
    return tmp_path


@pytest.mark.parametrize("token", ["#", "%04d", "$F4", "@@@@"])
def test_existing_frames(shots, token):
    p = Pattern.parse(str(shots / f"shot.{token}.exr"))
    assert p.existing_frames() == [1, 2, 5, 6, 7, 10]


def test_existing_frames_none(tmp_path):
    assert Pattern.parse(str(tmp_path / "none.#.exr")).existing_frames() == []


def test_resolve_inputs_all_on_disk(shots):
    p = Pattern.parse(str(shots / "shot.#.exr"))
    got = resolve_inputs(p, None, skip_missing=False)
    assert [f for f, _ in got] == [1, 2, 5, 6, 7, 10]
    assert got[0][1] == str(shots / "shot.0001.exr")


def test_missing_frames_listed_compactly(shots):
    p = Pattern.parse(str(shots / "shot.#.exr"))
    with pytest.raises(SequenceError) as info:
        resolve_inputs(p, parse_frames("1-10"), skip_missing=False)
    assert "missing frames 3-4,8-9 of" in str(info.value)
    # the files looked for: the first by its whole path, and how many more
    assert f"no file {shots / 'shot.0003.exr'}, nor 3 more up to shot.0009.exr" in str(info.value)
    with pytest.raises(SequenceError) as info:
        resolve_inputs(p, [4], skip_missing=False)
    assert str(info.value) == f"missing frame 4 of {p.text}: no file {shots / 'shot.0004.exr'}"
    got = resolve_inputs(p, parse_frames("1-10"), skip_missing=True)
    assert [f for f, _ in got] == [1, 2, 5, 6, 7, 10]


def test_resolve_single_file(shots):
    p = Pattern.parse(str(shots / "shot.0005.exr"))
    assert resolve_inputs(p, None, skip_missing=False) == [(5, str(shots / "shot.0005.exr"))]
    # a still serves every requested frame
    assert [f for f, _ in resolve_inputs(p, [1, 2], skip_missing=False)] == [1, 2]
    gone = Pattern.parse(str(shots / "gone.exr"))
    with pytest.raises(SequenceError, match="gone.exr"):
        resolve_inputs(gone, None, skip_missing=False)
    assert resolve_inputs(gone, None, skip_missing=True) == []


def test_fifo_input_refused_not_opened(tmp_path):
    """Issue 10 item 5: a FIFO as an input frame is refused by name; nothing opens it."""
    fifo = tmp_path / "pipe.0001.exr"
    os.mkfifo(fifo)
    for pattern, frames in ((fifo, None), (tmp_path / "pipe.#.exr", None),
                            (tmp_path / "pipe.#.exr", [1])):
        with pytest.raises(ImageIOError, match="not a regular file \\(a FIFO\\)") as info:
            resolve_inputs(Pattern.parse(str(pattern)), frames, skip_missing=False)
        assert "pipe.0001.exr" in str(info.value) and "\n" not in str(info.value)
    with pytest.raises(ImageIOError, match="kernel_path of x.*a FIFO"):
        check_input_file(fifo, "kernel_path of x")
    with pytest.raises(ImageIOError, match="folder"):
        check_input_file(tmp_path)


def test_no_frames_on_disk(tmp_path):
    p = Pattern.parse(str(tmp_path / "none.#.exr"))
    with pytest.raises(SequenceError, match="no frames"):
        resolve_inputs(p, None, skip_missing=False)
