"""clfx.io.read / probe / write: round trips, pass detection and conventions, colour, atomic writes.

OpenImageIO is imported here only to author odd test files (Nuke/Blender channel layouts,
oversized headers) that clfx.io.write deliberately cannot write.
"""
import json
import os
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

from clfx.io import write as io_write
from clfx.core.errors import ClipError, ImageIOError
from clfx.core.frame import Frame
from clfx.io.read import DepthConventionWarning, PassSpec, read_frame
from clfx.io.write import encoding_for, write_frame
from clfx.io.probe import format_probe, probe
from clfx.core.rect import Rect

from tests.conftest import EXR_IMAGES as DATA, needs_exr_images
needs_data = needs_exr_images

HALF_EPS = 2.0 ** -10          # half has a 10-bit mantissa: relative rounding <= 2**-11


def srgb_to_linear(v):
    v = np.asarray(v, np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def write_raw_exr(path, channels: dict, *, data=None, display=None, formats=None, attrs=None):
    """Author an EXR with arbitrary channel names (float unless ``formats`` says)."""
    names = list(channels)
    first = np.asarray(channels[names[0]])
    h, w = first.shape
    spec = oiio.ImageSpec(w, h, len(names), "float")
    if data is not None:
        spec.x, spec.y = data
    if display is not None:
        spec.full_x, spec.full_y, spec.full_width, spec.full_height = display
    else:
        spec.full_x, spec.full_y, spec.full_width, spec.full_height = spec.x, spec.y, w, h
    spec.channelnames = tuple(names)
    if formats:
        spec.channelformats = tuple(oiio.TypeDesc(formats.get(n, "float")) for n in names)
    for k, v in (attrs or {}).items():
        spec.attribute(k, v)
    px = np.stack([np.asarray(channels[n], np.float32) for n in names], axis=-1)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec), out.geterror()
    assert out.write_image(px), out.geterror()
    assert out.close()


def make_frame(rng, w=37, h=23, *, data_xy=(5, -3), display=(0, 0, 40, 20), aspect=1.0,
               passes=False, scale=4.0):
    rgba = rng.uniform(-0.5, scale, (h, w, 4)).astype(np.float32)
    rgba[..., 3] = rng.uniform(0, 1, (h, w))
    data = Rect.from_size(w, h, *data_xy)
    disp = Rect.from_size(display[2], display[3], display[0], display[1])
    depth = velocity = None
    if passes:
        depth = rng.uniform(0.1, 100.0, (h, w)).astype(np.float32)
        depth[0, :] = np.inf
        velocity = rng.uniform(-20, 20, (h, w, 2)).astype(np.float32)
    return Frame(rgba, data, disp, aspect, depth, velocity,
                 metadata={"clfx:note": "hello", "Software": "clfx-test"})


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


def leftovers(folder):
    return [p.name for p in Path(folder).iterdir() if ".tmp-" in p.name]


# --------------------------------------------------------------------------------------------
# EXR round trips

def test_exr_half_round_trip_values_windows_aspect_metadata(tmp_path, rng):
    fr = make_frame(rng, aspect=1.5)
    out = tmp_path / "half.exr"
    attrs = {"clfx:look": "anamorphic-night", "clfx:version": "0.1.0", "clfx:paramsHash": "abc123",
             "clfx:count": 7, "clfx:gain": 0.25, "clfx:vec": [1.0, 2.0, 3.0]}
    write_frame(fr, out, attributes=attrs)
    back = read_frame(out)
    assert back.data_window == fr.data_window
    assert back.display_window == fr.display_window
    assert back.pixel_aspect == pytest.approx(1.5)
    assert back.bit_depth == "half"
    assert back.encoding == "linear"
    # half rounding: relative error <= 2**-11 (plus denormal floor)
    np.testing.assert_allclose(back.rgba, fr.rgba, rtol=HALF_EPS, atol=1e-4)
    assert back.rgba.dtype == np.float32
    assert back.metadata["clfx:look"] == "anamorphic-night"
    assert back.metadata["clfx:paramsHash"] == "abc123"
    assert back.metadata["clfx:count"] == 7
    assert back.metadata["clfx:gain"] == pytest.approx(0.25)
    assert back.metadata["clfx:vec"] == pytest.approx([1.0, 2.0, 3.0])
    assert back.metadata["clfx:note"] == "hello"          # carried from frame.metadata
    assert back.metadata["compression"] == "zips"          # default compression
    json.dumps(back.metadata)                               # plain JSON-able values


def test_exr_float_round_trip_is_exact(tmp_path, rng):
    fr = make_frame(rng, data_xy=(-4, 2), display=(0, 0, 30, 30))
    out = tmp_path / "float.exr"
    write_frame(fr, out, bit_depth="float", compression="piz")
    back = read_frame(out)
    assert back.bit_depth == "float"
    np.testing.assert_array_equal(back.rgba, fr.rgba)
    assert back.data_window == fr.data_window and back.display_window == fr.display_window
    assert back.metadata["compression"] == "piz"


@pytest.mark.parametrize("compression", io_write.EXR_COMPRESSIONS)
def test_exr_compressions(tmp_path, compression):
    y, x = np.mgrid[0:16, 0:16].astype(np.float32)
    smooth = np.stack([x / 15, y / 15, (x + y) / 30, np.ones_like(x)], -1) * 2.0
    fr = Frame.from_array(smooth)                  # lossy codecs are judged on smooth images
    out = tmp_path / f"c_{compression}.exr"
    write_frame(fr, out, compression=compression)
    back = read_frame(out)
    assert back.metadata["compression"] == compression
    lossy = compression in ("dwaa", "dwab", "b44", "pxr24")
    np.testing.assert_allclose(back.rgba, fr.rgba, rtol=0.05 if lossy else HALF_EPS,
                               atol=0.05 if lossy else 1e-4)


def test_half_output_clamps_to_65504_not_inf(tmp_path):
    rgba = np.array([[[1e5, -1e5, np.inf, 1.0], [np.nan, 70000.0, 1.0, 1.0]]], np.float32)
    fr = Frame.from_array(rgba)
    write_frame(fr, tmp_path / "h.exr")
    back = read_frame(tmp_path / "h.exr")
    assert back.rgba[0, 0, 0] == 65504.0
    assert back.rgba[0, 0, 1] == -65504.0
    assert back.rgba[0, 0, 2] == 65504.0
    assert np.isnan(back.rgba[0, 1, 0])        # NaN is not an error and is not changed
    assert back.rgba[0, 1, 1] == 65504.0
    write_frame(fr, tmp_path / "f.exr", bit_depth="float")
    assert read_frame(tmp_path / "f.exr").rgba[0, 0, 0] == 1e5


def test_passes_round_trip_in_float_with_nuke_forward_vectors(tmp_path, rng):
    fr = make_frame(rng, passes=True)
    out = tmp_path / "passes.exr"
    write_frame(fr, out)
    info = probe(out)
    part = info["parts"][0]
    fmts = dict(zip(part["channels"], part["formats"]))
    assert fmts["R"] == "half" and fmts["Z"] == "float"
    assert fmts["forward.u"] == "float" and fmts["forward.v"] == "float"
    assert info["depth"]["channel"] == "Z" and info["depth"]["mode"] == "z"
    assert info["velocity"]["channels"] == ["forward.u", "forward.v"]
    back = read_frame(out)
    np.testing.assert_array_equal(back.depth, fr.depth)       # float: exact, inf kept
    np.testing.assert_array_equal(back.velocity, fr.velocity)  # y flipped twice
    # the file itself holds Nuke's y-up forward.v
    raw = read_frame(out, passes=PassSpec(velocity_y_up=False))
    np.testing.assert_array_equal(raw.velocity[..., 1], -fr.velocity[..., 1])


def test_write_passes_false_and_non_exr_drop_passes(tmp_path, rng):
    fr = make_frame(rng, passes=True, data_xy=(0, 0), display=(0, 0, 37, 23))
    write_frame(fr, tmp_path / "np.exr", write_passes=False)
    back = read_frame(tmp_path / "np.exr")
    assert back.depth is None and back.velocity is None
    write_frame(fr, tmp_path / "p.tif", bit_depth="float")
    assert read_frame(tmp_path / "p.tif").depth is None


@needs_data
@pytest.mark.parametrize("name", [f"t{i:02d}.exr" for i in range(1, 17)])
def test_display_window_files_round_trip(tmp_path, name):
    src = DATA / "DisplayWindow" / name
    fr = read_frame(src)
    out = tmp_path / name
    write_frame(fr, out)
    back = read_frame(out)
    assert back.data_window == fr.data_window
    assert back.display_window == fr.display_window
    assert back.pixel_aspect == pytest.approx(fr.pixel_aspect)
    np.testing.assert_array_equal(back.rgba, fr.rgba)       # half -> half: exact


@needs_data
@pytest.mark.parametrize("name, aspect", [("t15.exr", 1.5), ("t16.exr", 0.667)])
def test_pixel_aspect_files(name, aspect):
    fr = read_frame(DATA / "DisplayWindow" / name)
    assert fr.pixel_aspect == pytest.approx(aspect, rel=1e-3)
    assert fr.data_window == Rect(0, 0, 400, 300)
    assert fr.rgba.shape == (300, 400, 4)
    assert np.all(fr.rgba[..., 3] == 1.0)        # RGB file: alpha becomes 1


@needs_data
def test_metadata_passthrough_drops_layout_attributes(tmp_path):
    fr = read_frame(DATA / "Beachball" / "multipart.0001.exr", notify=lambda m, k: None)
    assert fr.metadata["view"] == "right"
    write_frame(fr, tmp_path / "m.exr", compression="zip", write_passes=False)  # beauty only
    meta = read_frame(tmp_path / "m.exr").metadata
    assert meta["screenWindowWidth"] == pytest.approx(1.0)
    assert meta["screenWindowCenter"] == pytest.approx([0.0, 0.0])
    assert meta["compression"] == "zip"                 # not the source's zips
    assert "view" not in meta and "name" not in meta
    assert meta.get("openexr:chunkCount") != 876
    # every part kept (the default): the beauty's part keeps its name and view
    write_frame(fr, tmp_path / "k.exr")
    meta = read_frame(tmp_path / "k.exr", notify=lambda m, k: None).metadata
    assert meta["view"] == "right" and meta["name"] == "rgba_right"
    assert meta["compression"] == "zips"                # the source's


# --------------------------------------------------------------------------------------------
# Beachball: singlepart and multipart, depth and velocity

@needs_data
def test_beachball_multipart_matches_singlepart():
    single = read_frame(DATA / "Beachball" / "singlepart.0001.exr")
    multi = read_frame(DATA / "Beachball" / "multipart.0001.exr")
    for fr in (single, multi):
        assert fr.depth is not None and fr.velocity is not None
        assert fr.display_window == Rect(0, 0, 2048, 1556)
    common = single.data_window.intersect(multi.data_window)
    assert common.width > 800

    def crop(fr, a):
        dx, dy = common.offset_in(fr.data_window)
        return a[dy:dy + common.height, dx:dx + common.width]

    for attr in ("rgba", "depth", "velocity"):
        np.testing.assert_array_equal(crop(single, getattr(single, attr)),
                                      crop(multi, getattr(multi, attr)), err_msg=attr)


@needs_data
def test_beachball_velocity_points_along_the_ball_motion():
    # frames 1 -> 2: the ball moves right and down the rows; clfx velocity is +y down.
    fr = read_frame(DATA / "Beachball" / "singlepart.0001.exr")
    ball = fr.rgba[..., 3] > 0.99
    u = np.median(fr.velocity[..., 0][ball])
    v = np.median(fr.velocity[..., 1][ball])
    assert u > 30 and v > 30
    assert 8.5 < np.median(fr.depth[ball]) < 11


@needs_data
@pytest.mark.parametrize("name, depth_part, vel_part, channels", [
    ("singlepart.0001.exr", 0, 0, ["forward.right.u", "forward.right.v"]),
    ("multipart.0001.exr", 5, 6, ["forward.u", "forward.v"]),
])
def test_probe_beachball(name, depth_part, vel_part, channels):
    info = probe(DATA / "Beachball" / name)
    json.dumps(info)
    assert info["format"] == "openexr"
    assert info["beauty"] == {"part": 0, "channels": ["R", "G", "B", "A"], "grey": False,
                              "why": info["beauty"]["why"]}
    assert info["view"] == "right"
    assert info["depth"]["channel"] == "Z" and info["depth"]["part"] == depth_part
    assert info["depth"]["mode"] == "z"
    assert info["velocity"]["channels"] == channels
    assert info["velocity"]["part"] == vel_part
    assert info["velocity"]["direction"] == "forward" and info["velocity"]["y_up"] is True
    assert "y-up" in info["velocity"]["convention"]
    assert any("left" in c for c in info["ignored_other_views"])
    assert info["search_order"]["depth"][0].startswith("Z")
    text = format_probe(info)
    assert "depth: Z" in text and "velocity:" in text and "search order" in text
    if name.startswith("multi"):
        assert len(info["parts"]) == 10 and "part 9" in text


# --------------------------------------------------------------------------------------------
# Renderer conventions and overrides

def test_nuke_inverse_depth_converted_to_planar_z(tmp_path):
    z = np.array([[1.0, 2.0, 4.0, 1000.0]], np.float32)
    inv = np.where(np.isfinite(z), 1.0 / z, 0.0).astype(np.float32)
    inv[0, 3] = 0.0                                    # far = 0
    ones = np.ones_like(z)
    path = tmp_path / "nuke.exr"
    write_raw_exr(path, {"R": ones, "G": ones, "B": ones, "A": ones, "depth.Z": inv,
                         "forward.u": ones * 3, "forward.v": ones * 2})
    info = probe(path)
    assert info["depth"]["channel"] == "depth.Z" and info["depth"]["mode"] == "inverse"
    fr = read_frame(path)
    np.testing.assert_allclose(fr.depth[0, :3], [1.0, 2.0, 4.0], rtol=1e-6)
    assert fr.depth[0, 3] == np.inf
    np.testing.assert_array_equal(fr.velocity[0, 0], [3.0, -2.0])     # y-up -> y-down
    # explicit override: read the same channel as planar z, in cm -> m (its 0, a quarter of
    # the pixels, would be read as no hit: keep it)
    raw = read_frame(path, passes=PassSpec(depth_channel="depth.Z", depth_mode="z",
                                           depth_scale=0.01, depth_zero="invalid"))
    np.testing.assert_allclose(raw.depth, inv * 0.01, rtol=1e-6)


def test_blender_multilayer_conventions(tmp_path):
    h, w = 2, 3
    one = np.ones((h, w), np.float32)
    depth = np.full((h, w), 5.0, np.float32)
    depth[0, 0] = 1e10                                 # Blender background
    chans = {f"ViewLayer.Combined.{c}": one * 0.5 for c in "RGBA"}
    chans.update({"ViewLayer.AO.R": one, "ViewLayer.AO.G": one, "ViewLayer.AO.B": one,
                  "ViewLayer.Depth.Z": depth,
                  "ViewLayer.Vector.X": one * 1.0, "ViewLayer.Vector.Y": one * 2.0,
                  "ViewLayer.Vector.Z": one * -4.0, "ViewLayer.Vector.W": one * 6.0})
    path = tmp_path / "blender.exr"
    write_raw_exr(path, chans)
    info = probe(path)
    assert info["beauty"]["channels"][0] == "ViewLayer.Combined.R"     # not AO
    assert info["depth"]["channel"] == "ViewLayer.Depth.Z"
    assert info["velocity"]["channels"] == ["ViewLayer.Vector.Z", "ViewLayer.Vector.W"]
    with pytest.warns(DepthConventionWarning, match="1 pixel"):     # said, not silent
        fr = read_frame(path)
    assert fr.depth[0, 0] == np.inf and fr.depth[1, 1] == 5.0
    # ZW = current - next, y-up: forward = -(Z, W); then y flipped -> (4, 6)
    np.testing.assert_array_equal(fr.velocity[0, 0], [4.0, 6.0])
    np.testing.assert_allclose(fr.rgba, 0.5)
    # XY only (previous - current): forward ~ -(X, Y), y flipped -> (-1, 2)
    fr_xy = read_frame(path, passes=PassSpec(velocity_channels=("ViewLayer.Vector.X",
                                                                "ViewLayer.Vector.Y")),
                       notify=lambda msg, key: None)
    np.testing.assert_array_equal(fr_xy.velocity[0, 0], [-1.0, 2.0])
    # both halves (issue 24): XY = previous - current, y-up -> backward motion
    # current - previous = -(X, Y), y flipped -> (-1, 2); XY alone: no second half
    np.testing.assert_array_equal(fr.velocity_back[0, 0], [-1.0, 2.0])
    assert fr_xy.velocity_back is None


def test_vray_normalized_and_velocity_overrides(tmp_path):
    one = np.ones((2, 2), np.float32)
    path = tmp_path / "vray.exr"
    write_raw_exr(path, {"R": one, "G": one, "B": one, "VRayZDepth": one * 0.25,
                         "VRayVelocity.R": one * 2, "VRayVelocity.G": one * 3})
    info = probe(path)
    assert info["depth"]["mode"] == "normalized"
    assert info["velocity"]["channels"] == ["VRayVelocity.R", "VRayVelocity.G"]
    fr = read_frame(path, passes=PassSpec(depth_near=1.0, depth_far=101.0))
    np.testing.assert_allclose(fr.depth, 26.0)
    fr = read_frame(path, passes=PassSpec(velocity_y_up=False, velocity_direction="backward",
                                          velocity_scale=0.5))
    np.testing.assert_allclose(fr.velocity[0, 0], [-1.0, -1.5])


def test_distance_depth_to_planar(tmp_path):
    # radial distance d at pixel offset r from the centre: planar z = d * f / sqrt(f^2 + r^2)
    w, h, f = 4, 2, 10.0
    d = np.full((h, w), 20.0, np.float32)
    one = np.ones((h, w), np.float32)
    path = tmp_path / "dist.exr"
    write_raw_exr(path, {"R": one, "G": one, "B": one, "Z": d})
    fr = read_frame(path, passes=PassSpec(depth_mode="distance", focal_length_px=f))
    xs = np.arange(w) + 0.5 - w / 2
    ys = np.arange(h) + 0.5 - h / 2
    r2 = xs[None, :] ** 2 + ys[:, None] ** 2
    np.testing.assert_allclose(fr.depth, 20.0 * f / np.sqrt(f * f + r2), rtol=1e-6)
    with pytest.raises(ClipError, match="focal_length_px"):
        PassSpec(depth_mode="distance")


def test_explicit_missing_channel_is_an_error_not_zeros(tmp_path, rng):
    fr = make_frame(rng, passes=True)
    write_frame(fr, tmp_path / "a.exr")
    with pytest.raises(ClipError, match="nope.Z"):
        read_frame(tmp_path / "a.exr", passes=PassSpec(depth_channel="nope.Z"))
    with pytest.raises(ClipError, match="velocity"):
        read_frame(tmp_path / "a.exr", passes=PassSpec(velocity_channels=("a.u", "a.v")))
    with pytest.raises(ClipError):
        PassSpec(depth_mode="bogus")


def test_separate_depth_and_velocity_files(tmp_path, rng):
    fr = make_frame(rng, passes=True)
    beauty = Frame(fr.rgba, fr.data_window, fr.display_window)
    write_frame(beauty, tmp_path / "beauty.exr")
    write_frame(fr, tmp_path / "passes.exr", bit_depth="float")
    # a plain single-channel depth file (channel "Y") is also accepted
    write_raw_exr(tmp_path / "grey_depth.exr", {"Y": fr.depth}, data=(5, -3),
                  display=(0, 0, 40, 20))
    back = read_frame(tmp_path / "beauty.exr", depth_path=tmp_path / "passes.exr",
                      velocity_path=tmp_path / "passes.exr")
    np.testing.assert_array_equal(back.depth, fr.depth)
    np.testing.assert_array_equal(back.velocity, fr.velocity)
    grey = read_frame(tmp_path / "beauty.exr", depth_path=tmp_path / "grey_depth.exr")
    np.testing.assert_array_equal(grey.depth, fr.depth)
    info = probe(tmp_path / "beauty.exr", depth_path=tmp_path / "grey_depth.exr")
    assert info["depth"]["file"].endswith("grey_depth.exr")

    moved = Frame(fr.rgba, Rect.from_size(37, 23, 0, 0), fr.display_window, depth=fr.depth)
    write_frame(moved, tmp_path / "moved.exr")
    with pytest.raises(ClipError) as info:
        read_frame(tmp_path / "beauty.exr", depth_path=tmp_path / "moved.exr")
    msg = str(info.value)
    assert "moved.exr" in msg and "beauty.exr" in msg and "(0,0)" in msg and "(5,-3)" in msg


def test_multipart_pass_with_other_window_is_placed(tmp_path):
    h, w = 4, 6
    one = np.ones((h, w), np.float32)
    path = tmp_path / "mp.exr"
    specs = []
    for x in (0, 2):
        s = oiio.ImageSpec(w, h, 3 if x == 0 else 1, "float")
        s.x = x
        s.full_width, s.full_height = 10, 4
        s.channelnames = ("R", "G", "B") if x == 0 else ("Z",)
        s.attribute("name", "rgb" if x == 0 else "depth")
        specs.append(s)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), specs)
    assert out.write_image(np.stack([one, one, one], -1))
    assert out.open(str(path), specs[1], "AppendSubimage")
    assert out.write_image((one * 3)[..., None])
    out.close()
    fr = read_frame(path)
    assert fr.data_window == Rect(0, 0, 6, 4)
    assert np.all(np.isinf(fr.depth[:, :2])) and np.all(fr.depth[:, 2:] == 3.0)
    assert read_frame(path, part="rgb").rgba.shape == (4, 6, 4)
    with pytest.raises(ImageIOError, match="part 'nope'"):
        read_frame(path, part="nope")


def test_absurd_size_refused_before_allocating(tmp_path):
    path = tmp_path / "wide.exr"
    write_raw_exr(path, {"Y": np.zeros((1, 70000), np.float32)})
    with pytest.raises(ImageIOError, match="65536"):
        read_frame(path)


# --------------------------------------------------------------------------------------------
# Display-referred formats and colour

@pytest.mark.parametrize("bit_depth, levels", [("uint8", 255), ("uint16", 65535)])
def test_png_linearise_encode_round_trip(tmp_path, bit_depth, levels):
    codes = np.arange(0, levels + 1, max(1, levels // 255), dtype=np.float64)
    enc = np.repeat((codes / levels)[None, :, None], 4, axis=2).astype(np.float32)
    enc[..., 3] = 1.0
    src = tmp_path / f"src_{bit_depth}.png"
    write_frame(Frame.from_array(enc), src, bit_depth=bit_depth, colorspace="raw")
    fr = read_frame(src)
    assert fr.encoding == "sRGB" and fr.bit_depth == bit_depth
    # OCIO's sRGB curve is within 3e-5 (relative) of the exact piecewise formula
    np.testing.assert_allclose(fr.rgba[0, :, 0], srgb_to_linear(codes / levels), rtol=3e-5,
                               atol=2e-6)
    out = tmp_path / f"out_{bit_depth}.png"
    write_frame(fr, out, bit_depth=bit_depth)                 # sRGB-encoded back
    back = read_frame(out, colorspace="raw")
    np.testing.assert_allclose(back.rgba[0, :, :3], enc[0, :, :3], atol=1.0 / levels)
    assert encoding_for(out) == "sRGB"


def test_png_grey_and_alpha(tmp_path):
    grey = np.linspace(0, 1, 8, dtype=np.float32)[None, :].repeat(3, 0)
    write_raw_exr(tmp_path / "g.exr", {"Y": grey})
    fr = read_frame(tmp_path / "g.exr")
    assert np.all(fr.rgba[..., 0] == fr.rgba[..., 2]) and np.all(fr.rgba[..., 3] == 1)
    write_frame(fr, tmp_path / "g.png")
    back = read_frame(tmp_path / "g.png")
    np.testing.assert_allclose(back.rgba[..., :3], fr.rgba[..., :3], atol=0.01)
    # premultiplied alpha survives the sRGB transfer (un/premultiplied around it)
    rgba = np.array([[[0.25, 0.1, 0.05, 0.5]]], np.float32)
    write_frame(Frame.from_array(rgba), tmp_path / "a.png", bit_depth="uint16")
    np.testing.assert_allclose(read_frame(tmp_path / "a.png").rgba, rgba, atol=2e-4)


def test_non_exr_outputs_write_display_window(tmp_path, rng):
    fr = make_frame(rng, data_xy=(5, -3), display=(0, 0, 40, 20), scale=1.0)
    write_frame(fr, tmp_path / "d.png", bit_depth="uint16")
    back = read_frame(tmp_path / "d.png")
    assert back.data_window == back.display_window == Rect(0, 0, 40, 20)
    assert np.all(back.rgba[:, :5] == 0)                     # outside data window: black, A=0
    inner = fr.rgba[3:, :35]                                  # data rows 0.. at display y=-3
    np.testing.assert_allclose(back.rgba[:20, 5:40, 3], inner[:20, :35, 3], atol=1e-4)


def test_jpeg_read(tmp_path):
    x = np.linspace(0, 1, 64, dtype=np.float32)
    rgba = np.stack([np.tile(x, (32, 1))] * 3 + [np.ones((32, 64), np.float32)], -1)
    write_frame(Frame.from_array(rgba), tmp_path / "a.jpg")
    fr = read_frame(tmp_path / "a.jpg")
    assert fr.encoding == "sRGB" and fr.rgba.shape == (32, 64, 4)
    assert np.all(fr.rgba[..., 3] == 1.0)
    np.testing.assert_allclose(fr.rgba[..., :3], rgba[..., :3], atol=0.03)   # JPEG is lossy


def test_tiff_uint16_float_and_windows(tmp_path, rng):
    fr = make_frame(rng, data_xy=(3, 4), display=(0, 0, 50, 40), scale=1.0)
    write_frame(fr, tmp_path / "a.tif")                        # uint16, sRGB, windows kept
    back = read_frame(tmp_path / "a.tif")
    assert back.encoding == "sRGB" and back.bit_depth == "uint16"
    assert back.data_window == fr.data_window and back.display_window == fr.display_window
    ok = fr.rgba[..., 3] > 0.05
    np.testing.assert_allclose(back.rgba[..., :3][ok], np.clip(fr.rgba[..., :3], 0, 1)[ok],
                               atol=2e-3)
    write_frame(fr, tmp_path / "f.tif", bit_depth="float")    # float TIFF: linear, exact
    f = read_frame(tmp_path / "f.tif")
    assert f.encoding == "linear"
    np.testing.assert_array_equal(f.rgba, fr.rgba)
    odd = make_frame(rng, data_xy=(-2, 1), display=(0, 0, 40, 30), aspect=1.5)
    write_frame(odd, tmp_path / "o.tif", bit_depth="float")   # not representable: display
    o = read_frame(tmp_path / "o.tif")
    assert o.data_window == o.display_window == Rect(0, 0, 40, 30)
    assert o.pixel_aspect == pytest.approx(1.5)


def test_dpx_write_read(tmp_path):
    x = np.linspace(0, 1, 40, dtype=np.float32)
    rgba = np.stack([np.tile(x, (10, 1))] * 3 + [np.full((10, 40), 0.5, np.float32)], -1)
    rgba[..., :3] = srgb_to_linear(rgba[..., :3]).astype(np.float32)
    write_frame(Frame.from_array(rgba), tmp_path / "a.dpx")   # 10-bit, RGB
    fr = read_frame(tmp_path / "a.dpx")
    assert fr.encoding == "sRGB" and np.all(fr.rgba[..., 3] == 1.0)
    raw = read_frame(tmp_path / "a.dpx", colorspace="raw")
    # no alpha in the file: the premultiplied colour (over black) is encoded as is
    np.testing.assert_allclose(raw.rgba[..., :3], np.tile(x, (10, 1))[..., None] * np.ones(3),
                               atol=1.5 / 1023)
    write_frame(Frame.from_array(rgba), tmp_path / "b.dpx", bit_depth="uint16")
    assert read_frame(tmp_path / "b.dpx").rgba.shape == (10, 40, 4)


def test_hdr_write_read(tmp_path, rng):
    rgb = rng.uniform(0.01, 400.0, (12, 9, 3)).astype(np.float32)
    write_frame(Frame.from_array(rgb), tmp_path / "a.hdr")
    fr = read_frame(tmp_path / "a.hdr")
    assert fr.encoding == "linear" and np.all(fr.rgba[..., 3] == 1.0)
    # RGBE: 8-bit mantissas sharing the exponent of the largest component
    tol = rgb.max(axis=-1, keepdims=True) * 2.0 ** -7
    assert np.all(np.abs(fr.rgba[..., :3] - rgb) <= tol)


@needs_data
def test_colorspace_override(tmp_path):
    src = DATA / "ScanLines" / "Desk.exr"
    lin = read_frame(src)
    acescg = read_frame(src, colorspace="ACEScg")
    assert not np.allclose(lin.rgba[..., :3], acescg.rgba[..., :3])
    np.testing.assert_array_equal(lin.rgba[..., 3], acescg.rgba[..., 3])
    with pytest.raises(ImageIOError, match="no-such-space"):
        read_frame(src, colorspace="no-such-space")


def test_encoding_for():
    assert encoding_for("a.exr") == "linear" and encoding_for("a.hdr") == "linear"
    assert encoding_for("a.png") == "sRGB" and encoding_for("A.JPG") == "sRGB"
    assert encoding_for("a.dpx") == "sRGB" and encoding_for("a.tif") == "sRGB"
    assert encoding_for("a.tif", "float") == "linear"


def test_bad_write_options(tmp_path, rng):
    fr = make_frame(rng)
    with pytest.raises(ImageIOError, match="bit depth"):
        write_frame(fr, tmp_path / "a.png", bit_depth="half")
    with pytest.raises(ImageIOError, match="compression"):
        write_frame(fr, tmp_path / "a.exr", compression="lzma")
    with pytest.raises(ImageIOError, match="extension"):
        write_frame(fr, tmp_path / "a.xyz")
    assert not list(tmp_path.iterdir())


# --------------------------------------------------------------------------------------------
# Atomic writes and safety

def test_atomic_write_leaves_no_temp_files(tmp_path, rng, monkeypatch):
    fr = make_frame(rng)
    write_frame(fr, tmp_path / "ok.0001.exr")
    assert [p.name for p in tmp_path.iterdir()] == ["ok.0001.exr"]

    def broken(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(io_write.os, "link", broken)       # publish without overwrite
    monkeypatch.setattr(io_write.os, "replace", broken)    # publish with overwrite
    for overwrite in (False, True):
        with pytest.raises(ImageIOError, match="fail.0001.exr: No space left") as info:
            write_frame(fr, tmp_path / "fail.0001.exr", overwrite=overwrite)
        assert "\n" not in str(info.value)
    monkeypatch.undo()
    assert not leftovers(tmp_path) and not (tmp_path / "fail.0001.exr").exists()


def test_oiio_failure_leaves_no_temp_file(tmp_path, rng):
    fr = make_frame(rng, data_xy=(0, 0), display=(0, 0, 37, 23))
    fr.metadata["clfx:bad"] = object()         # not an attribute type: ignored, not fatal
    write_frame(fr, tmp_path / "x.exr")
    huge = Frame(fr.rgba, fr.data_window, Rect(0, 0, 100000, 10))
    with pytest.raises(ImageIOError, match="display window"):
        write_frame(huge, tmp_path / "y.png")
    assert not leftovers(tmp_path) and not (tmp_path / "y.png").exists()


def test_existing_output_refused_without_overwrite(tmp_path, rng):
    out = tmp_path / "a.exr"
    write_frame(make_frame(rng), out)
    before = out.read_bytes()
    with pytest.raises(ImageIOError, match="exists"):
        write_frame(make_frame(rng), out)
    assert out.read_bytes() == before
    write_frame(make_frame(rng), out, overwrite=True)
    assert out.read_bytes() != before
    assert not leftovers(tmp_path)


def test_input_protected_even_with_overwrite(tmp_path, rng):
    src = tmp_path / "in.exr"
    write_frame(make_frame(rng), src)
    link = tmp_path / "link.exr"
    link.symlink_to(src)
    before = src.read_bytes()
    fr = read_frame(src)
    for target in (src, link, tmp_path / "sub" / ".." / "in.exr"):
        (tmp_path / "sub").mkdir(exist_ok=True)
        with pytest.raises(ImageIOError, match="input"):
            write_frame(fr, target, overwrite=True, protect=[src])
    assert src.read_bytes() == before


def test_unwritable_folder_names_it(tmp_path, rng):
    fr = make_frame(rng)
    blocker = tmp_path / "plainfile"
    blocker.write_text("x")
    with pytest.raises(ImageIOError, match="plainfile"):
        write_frame(fr, blocker / "out.exr")                  # a file is not a folder
    with pytest.raises(ImageIOError, match="does not exist"):
        write_frame(fr, tmp_path / "missing" / "out.exr")
    if Path("/proc/self").is_dir():                          # not writable even by root
        with pytest.raises(ImageIOError, match="/proc"):
            write_frame(fr, "/proc/clfx-test-out.exr")


def test_read_only_folder_as_non_root(tmp_path, rng):
    if os.geteuid() == 0:
        pytest.skip("root ignores directory permissions (covered via /proc above)")
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        with pytest.raises(ImageIOError, match="not writable"):
            write_frame(make_frame(rng), ro / "out.exr")
    finally:
        ro.chmod(0o700)
