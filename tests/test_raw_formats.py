"""Raw pipes beyond raw to raw (issue 33): ``--raw-format`` (gbrpf32le, gbrapf32le,
rgbf32le, rgbaf32le, ffmpeg's names and plane orders), raw frames on stdin to a file
sequence, and a file sequence to raw frames on stdout."""
import io

import numpy as np
import OpenImageIO as oiio
import pytest

from clfx.core.errors import SequenceError
from clfx.core.frame import Frame
from clfx.core.rect import Rect
from clfx.io.raw import FORMATS, read_raw, write_raw
from tests.clirun import run

IDENTITY = ("vignette", "natural=0", "amount=0")     # a step that renders nothing
W, H = 6, 4


def pixels(seed=5, alpha=True):
    px = np.random.default_rng(seed).uniform(0.05, 3.0, (H, W, 4)).astype(np.float32)
    if not alpha:
        px[..., 3] = 1.0
    return px


def encode(px, fmt):
    """``px`` (h, w, 4) as ffmpeg lays out ``fmt``: independent of clfx.io.raw."""
    idx = {"gbrpf32le": [1, 2, 0], "gbrapf32le": [1, 2, 0, 3], "rgbf32le": [0, 1, 2],
           "rgbaf32le": [0, 1, 2, 3]}[fmt]
    if fmt.startswith("gbr"):
        return np.ascontiguousarray(np.moveaxis(px[..., idx], -1, 0), "<f4").tobytes()
    return np.ascontiguousarray(px[..., idx], "<f4").tobytes()


def exr_channels(path):
    inp = oiio.ImageInput.open(str(path))
    names, px = tuple(inp.spec().channelnames), np.asarray(inp.read_image("float"))
    inp.close()
    return names, px


@pytest.mark.parametrize("fmt", sorted(FORMATS))
def test_each_format_round_trips_in_ffmpegs_layout(fmt):
    alpha = "a" in fmt.removesuffix("f32le")[3:] or fmt == "rgbaf32le"
    px = pixels(alpha=alpha)
    data = encode(px, fmt)
    fr = read_raw(io.BytesIO(data * 2), (W, H), 0, pix_fmt=fmt)
    np.testing.assert_array_equal(fr.rgba, px)         # alpha 1 where the format has none
    assert fr.channels == (4 if alpha else 3)
    out = io.BytesIO()
    write_raw(out, fr, Rect.from_size(W, H), pix_fmt=fmt)
    assert out.getvalue() == data


def test_unknown_format_names_the_known_ones():
    with pytest.raises(SequenceError, match="gbrpf32le, gbrapf32le, rgbf32le, rgbaf32le"):
        read_raw(io.BytesIO(b""), (W, H), pix_fmt="yuv420p")


@pytest.mark.parametrize("fmt, want", [("gbrpf32le", ("R", "G", "B")),
                                       ("rgbaf32le", ("R", "G", "B", "A"))])
def test_raw_in_to_an_exr_sequence(tmp_path, rt, fmt, want):
    frames = [pixels(seed, alpha="a" in fmt[3:5]) for seed in (1, 2)]
    data = b"".join(encode(p, fmt) for p in frames)
    r = run("apply", *IDENTITY[:1], "-", tmp_path / "o.#.exr", *IDENTITY[1:], "--raw",
            f"{W}x{H}", "--raw-format", fmt, "--float", "--frames", "1001-1010", input=data)
    assert r.stdout == ""
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o.1001.exr", "o.1002.exr"]
    for n, px in zip((1001, 1002), frames):
        names, got = exr_channels(tmp_path / f"o.{n}.exr")
        assert names == want
        np.testing.assert_array_equal(got, px[..., :len(want)])
    # the outputs exist now: refused before anything is read, unless overwritten
    r = run("apply", *IDENTITY[:1], "-", tmp_path / "o.#.exr", *IDENTITY[1:], "--raw",
            f"{W}x{H}", "--raw-format", fmt, input=data, code=1)
    assert "o.1001.exr exists (and 1 more)" in r.stderr and "--overwrite" in r.stderr


def test_exr_sequence_to_raw_out_and_back(tmp_path, rt):
    from clfx.io.write import write_frame

    frames = [pixels(seed, alpha=False) for seed in (3, 4)]
    for n, px in zip((7, 8), frames):
        write_frame(Frame.from_array(px[..., :3]), tmp_path / f"s.{n:04d}.exr", bit_depth="float")
    r = run("apply", *IDENTITY[:1], tmp_path / "s.#.exr", "-", *IDENTITY[1:],
            "--raw-format", "rgbf32le")
    assert r.stdout_bytes == b"".join(encode(p, "rgbf32le") for p in frames)
    assert f"-pix_fmt rgbf32le -s {W}x{H}" in r.stderr
    r = run("apply", *IDENTITY[:1], tmp_path / "s.#.exr", "-", *IDENTITY[1:])   # default
    assert r.stdout_bytes == b"".join(encode(p, "gbrpf32le") for p in frames)
    back = run("apply", *IDENTITY[:1], "-", "-", *IDENTITY[1:], "--raw", f"{W}x{H}",
               input=r.stdout_bytes)
    assert back.stdout_bytes == r.stdout_bytes
    r = run("apply", *IDENTITY[:1], tmp_path / "s.#.exr", "-", *IDENTITY[1:], "--raw",
            "8x8", code=1)
    assert "has a 6x4 display window" in r.stderr and r.stdout_bytes == b""


def test_raw_usage_errors():
    r = run("render", "-", "o.#.exr", code=2)
    assert "'-' as INPUT needs --raw WxH" in r.stderr
    r = run("render", "a.exr", "b.exr", "--raw-format", "rgbf32le", code=2)
    assert "--raw-format is for raw pipes" in r.stderr
    assert "planes in that order, not R, G, B" in " ".join(run("render", "--help").output.split())


def test_raw_in_to_a_nuke_style_pattern_says_its_padding(tmp_path, rt):
    """Raw frames to ``o.##.exr`` are 8 digits (each # four, oiiotool's way): said once on
    stderr, as for file inputs (`clfx.io.sequence.hash_notice`)."""
    data = encode(pixels(seed=6, alpha=False), "gbrpf32le")
    r = run("-q", "apply", *IDENTITY[:1], "-", tmp_path / "o.##.exr", *IDENTITY[1:], "--raw",
            f"{W}x{H}", input=data)
    assert "o.##.exr: each # is 4 digits" in r.stderr, r.stderr
    assert [p.name for p in tmp_path.iterdir()] == ["o.00000001.exr"]


def test_raw_in_to_exr_keeps_overscan_when_asked(tmp_path, rt):
    """``--keep-overscan`` holds for raw frames to EXR files (the light a blur spreads past
    the frame is kept in the data window), as for file inputs; raw frames on stdout are the
    frame's size, so there it is said on stderr, not dropped silently."""
    data = encode(pixels(seed=7, alpha=False), "gbrpf32le")
    run("apply", "defocus", "-", tmp_path / "o.#.exr", "size=0.2", "--raw", f"{W}x{H}",
        "--keep-overscan", input=data)
    inp = oiio.ImageInput.open(str(tmp_path / "o.0001.exr"))
    spec = inp.spec()
    inp.close()
    assert (spec.full_width, spec.full_height) == (W, H)
    assert spec.width > W and spec.height > H and spec.x < 0 and spec.y < 0
    r = run("apply", "defocus", "-", "-", "size=0.2", "--raw", f"{W}x{H}", "--keep-overscan",
            input=data)
    assert len(r.stdout_bytes) == len(data)
    assert "--keep-overscan" in r.stderr and "raw frames on stdout" in r.stderr, r.stderr
