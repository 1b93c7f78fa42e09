"""Channels in = channels out (issue 33): an RGB file comes back RGB, a grey one grey, RGBA
stays RGBA, in files and in `clfx.render_array`; the device works on RGBA inside."""
import numpy as np
import OpenImageIO as oiio
import pytest

import clfx
from tests.clirun import run

VIGNETTE = ("vignette", "amount=0.8")


def write_exr(path, names, px, fmt="half"):
    spec = oiio.ImageSpec(px.shape[1], px.shape[0], len(names), fmt)
    spec.channelnames = tuple(names)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec) and out.write_image(np.ascontiguousarray(px)) and out.close()
    return path


def channels(path):
    inp = oiio.ImageInput.open(str(path))
    names, px = tuple(inp.spec().channelnames), np.asarray(inp.read_image("float"))
    inp.close()
    return names, px


@pytest.mark.parametrize("names, out, want", [
    (("R", "G", "B"), "o.exr", ("R", "G", "B")),
    (("R", "G", "B", "A"), "o.exr", ("R", "G", "B", "A")),
    (("Y",), "o.exr", ("Y",)),
    (("Y", "A"), "o.exr", ("Y", "A")),
    (("R", "G", "B"), "o.png", ("R", "G", "B")),
    (("Y",), "o.tif", ("Y",)),
    (("R", "G", "B", "A"), "o.jpg", ("R", "G", "B")),      # JPEG has no alpha
])
@pytest.mark.parametrize("passes", ["keep", "drop"])
def test_file_channels_in_are_channels_out(tmp_path, rng, rt, names, out, want, passes):
    px = rng.uniform(0.1, 0.9, (12, 16, len(names))).astype(np.float32)
    if names[-1] == "A":
        px[..., -1] = 1.0
    src = write_exr(tmp_path / "in.exr", names, px)
    run("apply", *VIGNETTE[:1], src, tmp_path / out, *VIGNETTE[1:], "--passes", passes)
    got, pixels = channels(tmp_path / out)
    assert got == want
    if out.endswith(".exr"):          # the vignette darkened the corners of every channel
        assert pixels[0, 0, 0] < px[0, 0, 0] * 0.9


def test_grey_through_an_identity_comes_back_bit_for_bit(tmp_path, rng, rt):
    px = rng.uniform(0.1, 0.9, (12, 16, 1)).astype(np.float16).astype(np.float32)
    src = write_exr(tmp_path / "y.exr", ("Y",), px)
    run("apply", "vignette", src, tmp_path / "o.exr", "natural=0", "amount=0")
    names, got = channels(tmp_path / "o.exr")
    assert names == ("Y",) and np.array_equal(got, px)


@pytest.mark.parametrize("shape", [(10, 14, 4), (10, 14, 3), (10, 14)])
def test_render_array_returns_the_input_channels(rt, rng, shape):
    src = rng.uniform(0.1, 0.9, shape).astype(np.float32)
    look = {"effects": [{"effect": "vignette", "params": {"amount": 0.8}}]}
    res = clfx.render_array(src, look)
    assert res.rgba.shape == shape and res.rgba.dtype == np.float32
    assert res.rgba[0, 0].mean() < src[0, 0].mean()
    same = clfx.render_array(src, {"effects": []})
    assert np.array_equal(same.rgba, src)           # nothing rendered: the input, exactly
