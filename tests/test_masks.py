"""Per-object effects (issue 13): a look step limited by a channel, a mask sequence or a
Cryptomatte selection, with invert and feather; light-spreading effects masked at their
sources."""
import json

import numpy as np
import OpenImageIO as oiio
import pytest

import clfx
from clfx.core.errors import ClipError, PresetError
from clfx.io import mattes

H, W = 48, 72
BOX_A = (slice(16, 32), slice(10, 24))     # rows, cols
BOX_B = (slice(16, 32), slice(46, 60))


def write_exr(path, channels: dict, attributes: dict | None = None):
    """An EXR with the given float32 channels (name -> (h, w)) and header attributes."""
    names = list(channels)
    spec = oiio.ImageSpec(W, H, len(names), "float")
    spec.channelnames = tuple(names)
    for k, v in (attributes or {}).items():
        spec.attribute(k, v)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec), oiio.geterror()
    assert out.write_image(np.stack([channels[n] for n in names], -1).astype(np.float32))
    out.close()


def scene():
    """A striped background and two striped boxes, both moving 6 px/frame to the right."""
    rng = np.random.default_rng(3)
    rgb = np.empty((H, W, 3), np.float32)
    rgb[:] = 0.2 + 0.1 * (np.arange(W) % 5 == 0)[None, :, None]
    alpha_a = np.zeros((H, W), np.float32)
    alpha_a[BOX_A] = 1.0
    alpha_b = np.zeros((H, W), np.float32)
    alpha_b[BOX_B] = 1.0
    stripes = (0.5 + 0.5 * (np.arange(W) % 3 == 0))[None, :].repeat(H, 0)
    for alpha, colour in ((alpha_a, (1.0, 0.3, 0.1)), (alpha_b, (0.1, 0.4, 1.0))):
        for c in range(3):
            rgb[..., c] = np.where(alpha > 0, colour[c] * stripes, rgb[..., c])
    rgb += rng.uniform(0, 0.01, rgb.shape).astype(np.float32)
    u = np.where((alpha_a + alpha_b) > 0, 6.0, 0.0).astype(np.float32)
    chans = {"R": rgb[..., 0], "G": rgb[..., 1], "B": rgb[..., 2], "A": np.ones((H, W), np.float32),
             "forward.u": u, "forward.v": np.zeros((H, W), np.float32),
             "boxA.A": alpha_a, "boxB.A": alpha_b}
    return chans, alpha_a, alpha_b


def crypto_channels(coverage: dict[str, np.ndarray]):
    """CryptoObject00.R/G/B/A: the two largest coverages per pixel as (id, coverage) pairs."""
    names = list(coverage)
    stack = np.stack([coverage[n] for n in names])
    order = np.argsort(-stack, axis=0)
    ids = np.array([mattes.id_to_float(mattes.name_hash(n)) for n in names], np.float32)
    chans = {}
    for rank, (cid, ccov) in enumerate((("R", "G"), ("B", "A"))):
        pick = order[rank]
        cov = np.take_along_axis(stack, pick[None], 0)[0]
        chans[f"CryptoObject00.{cid}"] = np.where(cov > 0, ids[pick], 0.0).astype(np.float32)
        chans[f"CryptoObject00.{ccov}"] = cov.astype(np.float32)
    manifest = json.dumps({n: f"{mattes.name_hash(n):08x}" for n in names})
    key = f"{mattes.mm3_hash32(b'CryptoObject'):08x}"[:7]
    attrs = {f"cryptomatte/{key}/name": "CryptoObject", f"cryptomatte/{key}/hash": "MurmurHash3_32",
             f"cryptomatte/{key}/conversion": "uint32_to_float32",
             f"cryptomatte/{key}/manifest": manifest}
    return chans, attrs


def look_with(effect, mask=None, params=None):
    step = {"effect": effect, "params": params or {}}
    if mask is not None:
        step["mask"] = mask
    return {"name": "masked", "camera": {"shutter_angle": 360}, "effects": [step]}


def render(tmp_path, name, look):
    out = tmp_path / name
    clfx.render_file(tmp_path / "in.exr", out, look, overwrite=True, as_float=True)
    from clfx.io.read import read_frame

    return read_frame(out).rgba


def test_murmur3_and_cryptomatte_ids():
    assert mattes.mm3_hash32(b"") == 0
    assert mattes.mm3_hash32(b"hello") == 0x248BFA47          # the reference test vector
    for name in ("ball", "bunny", "a/b/c", "\u00e9t\u00e9"):
        h = mattes.name_hash(name)
        assert (h >> 23) & 0xFF not in (0, 255)              # a finite, normal float32
        assert np.isfinite(mattes.id_to_float(h))


def test_mask_selects_one_object_for_motion_blur(rt, tmp_path):
    """Box A is masked by its alpha AOV: it blurs; box B (also moving) stays sharp."""
    chans, alpha_a, alpha_b = scene()
    write_exr(tmp_path / "in.exr", chans)
    src = np.stack([chans[c] for c in "RGB"], -1)
    everything = render(tmp_path, "all.exr", look_with("motion_blur"))
    only_a = render(tmp_path, "a.exr", look_with("motion_blur", {"channel": "boxA.A"}))
    in_a, in_b = alpha_a > 0, alpha_b > 0
    # unmasked, both boxes blur
    assert np.abs(everything[..., :3] - src)[in_b].max() > 0.05
    # masked: box A blurs like the unmasked render, box B and the rest are the source exactly
    np.testing.assert_array_equal(only_a[~in_a][:, :3], src[~in_a])
    np.testing.assert_allclose(only_a[in_a], everything[in_a], atol=1e-6)
    assert np.abs(only_a[..., :3] - src)[in_a].max() > 0.05
    # inverted: the other way round
    inverted = render(tmp_path, "inv.exr", look_with("motion_blur", {"channel": "boxA.A",
                                                                      "invert": True}))
    np.testing.assert_array_equal(inverted[in_a][:, :3], src[in_a])
    assert np.abs(inverted[..., :3] - src)[in_b].max() > 0.05


def test_cryptomatte_selection_by_name(rt, tmp_path):
    chans, alpha_a, alpha_b = scene()
    soft_a = alpha_a.copy()
    soft_a[BOX_A[0], BOX_A[1].start] = 0.5                   # an anti-aliased edge
    cover = {"boxA": soft_a, "boxB": alpha_b, "background": 1.0 - soft_a - alpha_b}
    crypto, attrs = crypto_channels(cover)
    write_exr(tmp_path / "in.exr", {**chans, **crypto}, attrs)
    # the decoder: the manifest's names, the selected coverage summed over ranks
    assert set(mattes.cryptomatte_layers(tmp_path / "in.exr")["CryptoObject"]) == set(cover)
    matte, window = mattes.cryptomatte(tmp_path / "in.exr", "CryptoObject", ["boxA"])
    np.testing.assert_allclose(matte, soft_a, atol=1e-7)
    both, _ = mattes.cryptomatte(tmp_path / "in.exr", "CryptoObject", ["boxA", "boxB"])
    np.testing.assert_allclose(both, soft_a + alpha_b, atol=1e-7)
    # a look selecting boxA by name: defocus there only
    src = np.stack([chans[c] for c in "RGB"], -1)
    look = look_with("defocus", {"cryptomatte": "CryptoObject", "names": ["boxA"]},
                     {"size": 0.03})
    out = render(tmp_path, "crypto.exr", look)
    outside = soft_a == 0
    np.testing.assert_array_equal(out[outside][:, :3], src[outside])
    assert np.abs(out[..., :3] - src)[alpha_a > 0].max() > 0.02
    # names are checked before any frame is rendered, with the closest suggested
    bad = look_with("defocus", {"cryptomatte": "CryptoObject", "names": ["boxa"]})
    with pytest.raises(ClipError, match="'boxa' is not in the manifest; did you mean 'boxA'"):
        clfx.render_file(tmp_path / "in.exr", tmp_path / "bad.exr", bad)
    with pytest.raises(ClipError, match="no Cryptomatte layer 'CryptoObjekt'; did you mean"):
        clfx.render_file(tmp_path / "in.exr", tmp_path / "bad.exr", look_with(
            "defocus", {"cryptomatte": "CryptoObjekt", "names": ["boxA"]}))
    assert not (tmp_path / "bad.exr").exists()


def test_light_spreading_effect_takes_sources_from_the_mask(rt, tmp_path):
    """Glare masked to the left light: only that light glows, and its glow spreads past the
    mask over the whole frame; the right light stays as it was."""
    rgb = np.full((H, W, 3), 0.05, np.float32)
    rgb[24, 16] = rgb[24, 56] = 200.0
    mask = np.zeros((H, W), np.float32)
    mask[20:29, 12:21] = 1.0
    write_exr(tmp_path / "in.exr", {"R": rgb[..., 0], "G": rgb[..., 1], "B": rgb[..., 2],
                                    "A": np.ones((H, W), np.float32), "lamp.A": mask})
    params = {"strength": 0.2, "size": 0.2, "psf": "gaussians"}
    full = render(tmp_path, "full.exr", look_with("glare", None, params))
    masked = render(tmp_path, "masked.exr", look_with("glare", {"channel": "lamp.A"}, params))
    near_left = (slice(30, 34), slice(14, 19))                # below the mask, near the left light
    near_right = (slice(30, 34), slice(54, 59))
    glow = lambda img, at: float((img[at][..., 0] - rgb[at][..., 0]).mean())  # noqa: E731
    assert glow(full, near_right) > 0.003 and glow(full, near_left) > 0.003
    # the masked light still glows outside its mask (light spreads over the whole frame)...
    assert glow(masked, near_left) > 0.5 * glow(full, near_left)
    # ...while the unmasked light adds (almost) nothing: what remains is the left light's
    assert glow(masked, near_right) < 0.2 * glow(full, near_right)
    assert masked[24, 56, 0] == pytest.approx(200.0, rel=1e-6)


def test_mask_sequence_feather_and_checks(rt, tmp_path):
    chans, alpha_a, _ = scene()
    write_exr(tmp_path / "in.exr", chans)
    for f in (1, 2):
        write_exr(tmp_path / f"m.{f:04d}.exr", {"A": alpha_a})
    from clfx.io.read import read_frame
    from clfx.pipeline.masks import FrameMasks, parse_mask, read_mask

    spec = parse_mask({"file": str(tmp_path / "m.#.exr"), "feather": "3px"}, "mask")
    frame = read_frame(tmp_path / "in.exr")
    host = read_mask(spec, frame, 2)
    np.testing.assert_array_equal(host, alpha_a)
    dev = FrameMasks(rt, {spec: host}, frame.data_window, frame.display_window)
    soft = dev.get(spec, frame.data_window).download()
    row = soft[24]
    assert 0.2 < row[BOX_A[1].start] < 0.8 and row[BOX_A[1].start - 6] < 0.05   # a soft edge
    assert spec.describe() == {"file": str(tmp_path / "m.#.exr"), "feather": "3px"}
    # a missing mask frame is named before anything renders
    seq_in = tmp_path / "s.#.exr"
    for f in (1, 2, 3):
        write_exr(tmp_path / f"s.{f:04d}.exr", chans)
    look = look_with("defocus", {"file": str(tmp_path / "m.#.exr")}, {"size": 0.01})
    with pytest.raises(ClipError, match=r"missing frame 3 of .*m\.#\.exr: no file .*m\.0003\.exr"):
        clfx.render_sequence(seq_in, tmp_path / "o.#.exr", look)
    assert not list(tmp_path.glob("o.*.exr"))
    # a channel that is not there
    with pytest.raises(ClipError, match="no channel 'ball.A'"):
        clfx.render_file(tmp_path / "in.exr", tmp_path / "x.exr",
                         look_with("defocus", {"channel": "ball.A"}))


@pytest.mark.parametrize("mask, message", [
    ({"chanel": "a"}, "did you mean 'channel'"),
    ({"channel": "a", "cryptomatte": "C", "names": ["x"]}, "not both"),
    ({"cryptomatte": "CryptoObject"}, "needs names"),
    ({"channel": "a", "feather": 3}, "write '3px' for pixels"),
    ({"channel": "a", "mode": "add"}, "is not one of auto, mix, sources"),
    ("ball.A", "must be a mapping"),
])
def test_bad_masks_are_one_line_naming_the_key(tmp_path, mask, message):
    (tmp_path / "l.yaml").write_text(
        "name: l\neffects:\n  - effect: glare\n    mask: " + json.dumps(mask) + "\n")
    with pytest.raises(PresetError, match=message) as info:
        clfx.load_look(str(tmp_path / "l.yaml"))
    assert "l.yaml:4: effects[0].mask" in str(info.value)


def test_array_api_takes_mask_channels(rt):
    chans, alpha_a, alpha_b = scene()
    rgba = np.stack([chans[c] for c in "RGBA"], -1)
    vel = np.stack([chans["forward.u"], np.zeros((H, W), np.float32)], -1)
    look = look_with("motion_blur", {"channel": "boxB.A"})
    res = clfx.render_array(rgba, look, velocity=vel, channels={"boxB.A": alpha_b})
    np.testing.assert_array_equal(res.rgba[alpha_b == 0], rgba[alpha_b == 0])
    assert np.abs(res.rgba - rgba)[alpha_b > 0].max() > 0.05
    assert any("masked by channel boxB.A (mix)" in n for s in res.report.steps for n in s.notes)
    with pytest.raises(ClipError, match="no file to read it from"):
        clfx.render_array(rgba, look, velocity=vel)


def test_a_nuke_style_mask_pattern_is_said(rt, tmp_path, capfd):
    """A mask sequence's ``m.##.exr`` is 8 digits (each # four, oiiotool's way): said once
    on stderr, as for the frames' own patterns."""
    chans, alpha_a, _ = scene()
    write_exr(tmp_path / "in.0001.exr", chans)
    write_exr(tmp_path / "m.00000001.exr", {"A": alpha_a})
    look = look_with("vignette", {"file": str(tmp_path / "m.##.exr")}, {"amount": 0.5})
    clfx.render_sequence(tmp_path / "in.#.exr", tmp_path / "o.#.exr", look, verbosity=0)
    assert (tmp_path / "o.0001.exr").is_file()
    err = capfd.readouterr().err
    assert err.count("m.##.exr: each # is 4 digits") == 1, err
