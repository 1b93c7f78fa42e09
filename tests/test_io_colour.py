"""Colour-managed round trips (issue 13, "Colour"): a working space from OCIO, inputs converted
from their space and outputs written back in it, chromaticities written, raw pipes honouring
``--colorspace`` / ``--out-colorspace``, and the working space's RGB -> XYZ matrix."""
import subprocess
import sys

import numpy as np
import OpenImageIO as oiio
import pytest
from click.testing import CliRunner

from clfx.cli import cli
from clfx.core.errors import ImageIOError
from clfx.core.frame import Frame
from clfx.io import colour
from clfx.io.probe import probe
from clfx.io.read import read_frame
from clfx.io.write import write_frame

AP1 = (0.713, 0.293, 0.165, 0.830, 0.128, 0.044, 0.32168, 0.33767)
REC709 = (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290)
D65_XYZ = np.array([0.3127 / 0.3290, 1.0, (1 - 0.3127 - 0.3290) / 0.3290])
# ACEScg -> linear Rec.709 (OCIO's, Bradford D60 -> D65): the (0.5, 0.2, 0.1) ACEScg
# pixel is (0.72, 0.16, 0.077) in Rec.709
ACESCG_TO_709 = np.array([[1.705051, -0.621792, -0.083259],
                          [-0.130256, 1.140805, -0.010548],
                          [-0.024003, -0.128969, 1.152972]])
HALF_REL = 2.0 ** -11                # half rounding, relative
IDENTITY = ("vignette", "amount=0", "natural=0")   # an effect that is skipped: identity


def write_exr(path, rgba, *, attrs=None, chroma=None, fmt="half"):
    h, w = rgba.shape[:2]
    spec = oiio.ImageSpec(w, h, 4, fmt)
    spec.channelnames = ("R", "G", "B", "A")
    for k, v in (attrs or {}).items():
        spec.attribute(k, v)
    if chroma is not None:
        spec.attribute("chromaticities", oiio.TypeDesc("float[8]"), tuple(chroma))
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec) and out.write_image(np.asarray(rgba, np.float32))
    assert out.close()
    return path


def read_raw_file(path):
    inp = oiio.ImageInput.open(str(path))
    spec = inp.spec()
    px = np.asarray(inp.read_image(0, 0, 0, spec.nchannels, "float"))
    inp.close()
    return px, spec


def scene(rng, h=12, w=16):
    rgba = rng.uniform(0.0, 4.0, (h, w, 4)).astype(np.float32)
    rgba[..., 3] = rng.uniform(0.2, 1.0, (h, w))
    rgba[0, 0] = (0.5, 0.2, 0.1, 1.0)                 # the pixel
    return rgba.astype(np.float16).astype(np.float32)  # exactly representable in half


def apply_identity(src, dst, *extra):
    r = CliRunner().invoke(cli, ["apply", IDENTITY[0], str(src), str(dst), *IDENTITY[1:],
                                 *extra])
    assert r.exit_code == 0, (r.output, r.stderr)
    return r


# --------------------------------------------------------------------------------------------
# Spaces and matrices

def test_working_space_rgb_to_xyz_matrices():
    m709 = colour.rgb_to_xyz("lin_rec709")
    np.testing.assert_allclose(m709[1], [0.2126, 0.7152, 0.0722], atol=2e-4)   # luminance
    for space in ("lin_rec709", "ACEScg", "Linear Rec.2020"):
        np.testing.assert_allclose(colour.rgb_to_xyz(space) @ np.ones(3), D65_XYZ, atol=2e-4)
    # a chromaticities-only space equal to AP1 gives OCIO's ACEScg matrix (Bradford both)
    np.testing.assert_allclose(colour.rgb_to_xyz(colour.CHROMA_PREFIX + ",".join(map(str, AP1))),
                               colour.rgb_to_xyz("ACEScg"), atol=2e-4)
    with pytest.raises(ImageIOError, match="not linear"):
        colour.rgb_to_xyz("sRGB")


def test_spaces_resolve_match_and_refuse():
    assert colour.resolve("linear") == colour.resolve("lin_rec709")
    assert colour.from_chromaticities(AP1) == colour.resolve("ACEScg")
    assert colour.from_chromaticities(REC709) == colour.resolve("lin_rec709")
    odd = colour.from_chromaticities((0.63, 0.34, 0.29, 0.61, 0.15, 0.07, 0.3155, 0.3317))
    assert odd.startswith(colour.CHROMA_PREFIX)
    with pytest.raises(ImageIOError, match="did you mean 'ACEScg'"):
        colour.resolve("ACEScgg")


def test_frame_names_its_working_space(tmp_path, rng):
    rgba = scene(rng)
    path = write_exr(tmp_path / "a.exr", rgba, attrs={"oiio:ColorSpace": "ACEScg"})
    fr = read_frame(path)
    assert fr.colorspace == colour.resolve("lin_rec709")
    assert fr.source_colorspace == colour.resolve("ACEScg")
    np.testing.assert_allclose(fr.rgba[..., :3], rgba[..., :3] @ ACESCG_TO_709.T, rtol=1e-4,
                               atol=1e-5)
    cg = read_frame(path, working_space="ACEScg")
    np.testing.assert_array_equal(cg.rgba, rgba)
    info = probe(path)
    assert info["colorspace"]["from"] == colour.resolve("ACEScg")
    assert info["colorspace"]["to"] == colour.resolve("lin_rec709")
    with pytest.raises(ImageIOError, match="must be a linear"):
        read_frame(path, working_space="sRGB")


# --------------------------------------------------------------------------------------------
# Round trips through an identity look

@pytest.mark.parametrize("tag", ["oiio:ColorSpace", "chromaticities", "--colorspace"])
def test_acescg_exr_round_trips_within_half_precision(tmp_path, rng, rt, tag):
    rgba = scene(rng)
    attrs = {"oiio:ColorSpace": "ACEScg"} if tag == "oiio:ColorSpace" else None
    src = write_exr(tmp_path / "cg.exr", rgba, attrs=attrs,
                    chroma=AP1 if tag == "chromaticities" else None)
    extra = ("--colorspace", "ACEScg") if tag == "--colorspace" else ()
    apply_identity(src, tmp_path / "out.exr", *extra)
    got, spec = read_raw_file(tmp_path / "out.exr")
    # working space Rec.709 and back: float32 matrices, then half rounding of the output
    np.testing.assert_allclose(got, rgba, rtol=HALF_REL, atol=1e-6)
    np.testing.assert_allclose(got[0, 0], [0.5, 0.2, 0.1, 1.0], rtol=HALF_REL)
    np.testing.assert_allclose(spec.getattribute("chromaticities"), AP1, atol=1e-5)
    assert spec.get_string_attribute("oiio:ColorSpace") == "lin_ap1_scene"   # colorInteropID
    # --out-colorspace converts: the pixel in Rec.709 (tagged as such)
    apply_identity(src, tmp_path / "709.exr", *extra, "--out-colorspace", "lin_rec709")
    got, spec = read_raw_file(tmp_path / "709.exr")
    np.testing.assert_allclose(got[0, 0, :3], ACESCG_TO_709 @ [0.5, 0.2, 0.1], rtol=2e-3)
    np.testing.assert_allclose(spec.getattribute("chromaticities"), REC709, atol=1e-5)


def test_acescg_working_space_is_bitwise(tmp_path, rng, rt):
    rgba = scene(rng)
    src = write_exr(tmp_path / "cg.exr", rgba, attrs={"oiio:ColorSpace": "ACEScg"})
    apply_identity(src, tmp_path / "out.exr", "--working-space", "ACEScg")
    np.testing.assert_array_equal(read_raw_file(tmp_path / "out.exr")[0], rgba)


def test_odd_chromaticities_round_trip(tmp_path, rng, rt):
    chroma = (0.63, 0.34, 0.29, 0.61, 0.15, 0.07, 0.3155, 0.3317)   # a camera's, as Tree.exr
    rgba = scene(rng)
    src = write_exr(tmp_path / "cam.exr", rgba, chroma=chroma)
    fr = read_frame(src)
    assert fr.source_colorspace.startswith(colour.CHROMA_PREFIX)
    apply_identity(src, tmp_path / "out.exr")
    got, spec = read_raw_file(tmp_path / "out.exr")
    np.testing.assert_allclose(got, rgba, rtol=HALF_REL, atol=1e-6)
    np.testing.assert_allclose(spec.getattribute("chromaticities"), chroma, atol=1e-5)


def test_rec709_exr_is_unchanged_and_tagged(tmp_path, rng, rt):
    rgba = scene(rng)
    apply_identity(write_exr(tmp_path / "a.exr", rgba), tmp_path / "out.exr")
    got, spec = read_raw_file(tmp_path / "out.exr")
    np.testing.assert_array_equal(got, rgba)
    np.testing.assert_allclose(spec.getattribute("chromaticities"), REC709, atol=1e-5)


def test_srgb_png_round_trips_within_one_code(tmp_path, rng, rt):
    u8 = rng.integers(0, 256, (10, 14, 4), dtype=np.uint8)
    u8[..., 3] = 255
    buf = oiio.ImageBuf(oiio.ImageSpec(14, 10, 4, "uint8"))
    buf.set_pixels(oiio.ROI(0, 14, 0, 10), u8)
    assert buf.write(str(tmp_path / "in.png"))
    assert read_frame(tmp_path / "in.png").source_colorspace == colour.resolve("sRGB")
    apply_identity(tmp_path / "in.png", tmp_path / "out.png")
    got = read_raw_file(tmp_path / "out.png")[0]
    assert np.abs(got - u8 / 255.0).max() <= 1 / 255 + 1e-6
    # and into a linear EXR: linear Rec.709 values (the working space), tagged
    apply_identity(tmp_path / "in.png", tmp_path / "out.exr")
    got, spec = read_raw_file(tmp_path / "out.exr")
    lin = colour.convert(u8 / np.float32(255.0), "sRGB", "lin_rec709", "x")
    np.testing.assert_allclose(got, lin, rtol=HALF_REL, atol=1e-6)
    np.testing.assert_allclose(spec.getattribute("chromaticities"), REC709, atol=1e-5)


def test_unknown_colorspace_is_one_line(tmp_path, rng):
    src = write_exr(tmp_path / "a.exr", scene(rng))
    r = CliRunner().invoke(cli, ["apply", *IDENTITY[:1], str(src), str(tmp_path / "o.exr"),
                                 *IDENTITY[1:], "--colorspace", "ACEScgg"])
    assert r.exit_code == 1 and "did you mean 'ACEScg'" in r.stderr, r.stderr


def test_in_memory_frames_write_in_their_space(tmp_path, rng):
    rgba = scene(rng)
    fr = Frame.from_array(rgba)
    write_frame(fr, tmp_path / "a.exr", bit_depth="float")
    np.testing.assert_array_equal(read_raw_file(tmp_path / "a.exr")[0], rgba)
    write_frame(fr, tmp_path / "b.exr", bit_depth="float", colorspace="ACEScg")
    got, spec = read_raw_file(tmp_path / "b.exr")
    np.testing.assert_allclose(got[..., :3] @ ACESCG_TO_709.T, rgba[..., :3], rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(spec.getattribute("chromaticities"), AP1, atol=1e-5)


# --------------------------------------------------------------------------------------------
# Raw pipes

def _pipe(frames, w, h, *flags):
    proc = subprocess.run([sys.executable, "-m", "clfx.cli", "-q", "apply", IDENTITY[0], "-", "-",
                           *IDENTITY[1:], "--raw", f"{w}x{h}", *flags],
                          input=b"".join(np.asarray(f, "<f4").tobytes() for f in frames),
                          capture_output=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return np.frombuffer(proc.stdout, "<f4").reshape(len(frames), 3, h, w)


def test_raw_pipe_honours_both_flags(rt):
    w, h = 4, 3
    gbr = np.stack([np.full((h, w), v, np.float32) for v in (0.2, 0.1, 0.5)])   # G, B, R
    same = _pipe([gbr], w, h, "--colorspace", "ACEScg")           # in and back out: ACEScg
    np.testing.assert_allclose(same[0], gbr, rtol=1e-5)
    to709 = _pipe([gbr], w, h, "--colorspace", "ACEScg", "--out-colorspace", "lin_rec709")
    want = ACESCG_TO_709 @ [0.5, 0.2, 0.1]                        # R, G, B
    np.testing.assert_allclose(to709[0, :, 0, 0], [want[1], want[2], want[0]], rtol=1e-4)
    srgb = _pipe([gbr], w, h, "--out-colorspace", "sRGB")          # linear Rec.709 -> sRGB
    assert srgb[0, 2, 0, 0] == pytest.approx(((0.5 ** (1 / 2.4)) * 1.055 - 0.055), rel=1e-4)


def test_cli_working_space_reaches_spectral_effects(tmp_path, rt, monkeypatch):
    """`clfx render --working-space ACEScg` hands the effects ACEScg's RGB -> XYZ matrix: the
    corona of a Rec.709 EXR rendered in ACEScg (written back in Rec.709) is the one rendered in
    Rec.709, to float32 precision (tolerance as in tests/plugins/test_working_space.py)."""
    from clfx.pipeline import look as look_mod

    src = np.full((48, 64, 4), 0.02, np.float32)
    src[..., 3] = 1.0
    src[20:22, 30:32, :3] = (3e3, 2e3, 1e3)
    write_exr(tmp_path / "in.exr", src, fmt="float")
    (tmp_path / "corona.yaml").write_text(
        "name: corona-only\nschema: 1\neffects:\n  - effect: corona\n"
        "    params: {threshold: 2.0, intensity: 0.5, size: 0.05, extent: 4.0}\n")
    seen = []
    real = look_mod.working_rgb_to_xyz
    monkeypatch.setattr(look_mod, "working_rgb_to_xyz",
                        lambda space: seen.append(real(space)) or seen[-1])
    outs = {}
    for ws in ("lin_rec709", "ACEScg"):
        out = tmp_path / f"out-{ws}.exr"
        r = CliRunner().invoke(cli, ["-q", "render", str(tmp_path / "in.exr"), str(out),
                                     "--look", str(tmp_path / "corona.yaml"), "--float",
                                     "--working-space", ws])
        assert r.exit_code == 0, (r.output, r.stderr)
        outs[ws] = read_raw_file(out)[0].astype(np.float64)
    np.testing.assert_allclose(seen[-1], colour.rgb_to_xyz("ACEScg"), rtol=1e-12)
    d709, dcg = outs["lin_rec709"] - src, outs["ACEScg"] - src
    assert np.abs(d709).max() > 1.0                                     # the corona is there
    # as tests/plugins/test_working_space.py: beyond 8 float32 ulps of each pixel (the
    # conversions in and out), the difference is below 1e-4 of the largest change, per pixel
    # and in L1 per channel (measured: 0 and 0 here)
    err = np.abs(dcg - d709)[..., :3]
    ulp = np.finfo(np.float32).eps * np.abs(outs["lin_rec709"][..., :3]).max(-1, keepdims=True)
    excess = np.maximum(err - 8 * ulp, 0.0)
    l1 = excess.sum(axis=(0, 1)) / np.abs(d709)[..., :3].sum(axis=(0, 1))
    px = excess.max() / np.abs(d709).max()
    print(f"corona via clfx render: relative L1 per channel {l1}, per pixel {px:.3g}, "
          f"before the ulp allowance {err.max() / np.abs(d709).max():.3g}")
    assert (l1 < 1e-4).all() and px < 1e-4, (l1, px)
