"""clfx.io.raw: ffmpeg gbrpf32le frames on a pipe."""
import io

import numpy as np
import pytest

from clfx.core.errors import ImageIOError, SequenceError
from clfx.core.frame import Frame
from clfx.core.rect import Rect
from clfx.io.raw import parse_size, read_raw, write_raw


def test_round_trip_plane_order():
    w, h = 5, 3
    rgb = np.random.default_rng(3).uniform(-1, 4, (h, w, 3)).astype(np.float32)
    stream = io.BytesIO()
    write_raw(stream, Frame.from_array(rgb), Rect.from_size(w, h))
    data = stream.getvalue()
    assert len(data) == w * h * 3 * 4
    planes = np.frombuffer(data, "<f4").reshape(3, h, w)
    np.testing.assert_array_equal(planes[0], rgb[..., 1])        # G, B, R
    np.testing.assert_array_equal(planes[2], rgb[..., 0])
    stream = io.BytesIO(data * 2)
    first, second = read_raw(stream, (w, h), 0), read_raw(stream, (w, h), 1)
    assert read_raw(stream, (w, h), 2) is None
    for fr in (first, second):
        np.testing.assert_array_equal(fr.rgba[..., :3], rgb)
        assert np.all(fr.rgba[..., 3] == 1.0) and fr.source == "stdin"


def test_output_cut_to_the_input_window():
    grown = Frame.from_array(np.ones((5, 7, 4), np.float32))
    grown = Frame(grown.rgba, Rect.from_size(7, 5, -1, -1), Rect.from_size(5, 3))
    stream = io.BytesIO()
    write_raw(stream, grown, Rect.from_size(5, 3))
    assert len(stream.getvalue()) == 5 * 3 * 3 * 4


def test_truncated_frame_is_one_line():
    with pytest.raises(ImageIOError, match="truncated raw frame 4 \\(7 of 180 bytes; is --raw 5x3"):
        read_raw(io.BytesIO(b"x" * 7), (5, 3), 4)


@pytest.mark.parametrize("text, want", [("1920x1080", (1920, 1080)), ("64X32", (64, 32))])
def test_parse_size(text, want):
    assert parse_size(text) == want


@pytest.mark.parametrize("text, why", [("-64x32", "two positive"), ("0x10", "two positive"),
                                       ("60000x60000", "CLFX_MAX_PIXELS"), ("64", "not WxH"),
                                       ("axb", "not WxH"), ("1x2x3", "not WxH")])
def test_bad_sizes_refused_before_allocating(text, why):
    with pytest.raises(SequenceError, match=why) as info:
        parse_size(text)
    assert "\n" not in str(info.value)
