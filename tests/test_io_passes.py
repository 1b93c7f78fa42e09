"""Every channel kept (issue 13): outputs keep every part and channel the effects do not change
(depth, velocity, masks, IDs, other views), with each rendered view's beauty replaced;
``--passes drop``; ``--view``; the input's pixel type and compression unless overridden."""
import numpy as np
import OpenImageIO as oiio
from click.testing import CliRunner

from clfx.cli import cli
from clfx.core.frame import Frame
from clfx.core.rect import Rect
from clfx.io.read import read_frame, read_views
from clfx.io.write import write_frame
from tests.conftest import EXR_IMAGES as DATA, needs_exr_images

needs_data = needs_exr_images
BEACHBALL = DATA / "Beachball"
VIGNETTE = ("vignette", "amount=0.8")
QUIET = {"notify": lambda message, key: None}


def parts(path):
    """[(name, view, channel names, formats, window, compression, attrs, {channel: pixels})]."""
    inp = oiio.ImageInput.open(str(path))
    out, i = [], 0
    while inp.seek_subimage(i, 0):
        s = inp.spec()
        native = np.asarray(inp.read_image(i, 0, 0, s.nchannels, "double"))
        fmts = [str(t) for t in s.channelformats] or [str(s.format)] * s.nchannels
        out.append(dict(name=s.get_string_attribute("name"), view=s.get_string_attribute("view"),
                        channels=tuple(s.channelnames), formats=fmts,
                        window=(s.x, s.y, s.width, s.height),
                        compression=s.get_string_attribute("compression"),
                        multiview=s.getattribute("multiView"),
                        px={c: native[..., k] for k, c in enumerate(s.channelnames)}))
        i += 1
    inp.close()
    return out


def native(path, channel, fmt):
    """One channel of the first part in its stored type."""
    inp = oiio.ImageInput.open(str(path))
    k = list(inp.spec().channelnames).index(channel)
    px = np.asarray(inp.read_image(0, 0, k, k + 1, fmt))
    inp.close()
    return px


def run(*args):
    r = CliRunner().invoke(cli, [str(a) for a in args])
    assert r.exit_code == 0, (r.output, r.stderr)
    return r


def write_parts(path, specs_pixels):
    """Author a (multi)part EXR: [(spec, pixels (h, w, n) float64)]."""
    out = oiio.ImageOutput.create(str(path))
    specs = [s for s, _ in specs_pixels]
    assert out.open(str(path), specs) if len(specs) > 1 else out.open(str(path), specs[0])
    for i, (spec, px) in enumerate(specs_pixels):
        if i:
            assert out.open(str(path), spec, "AppendSubimage")
        assert out.write_image(np.ascontiguousarray(px)), out.geterror()
    assert out.close()
    return path


def spec_for(w, h, names, fmt="half", formats=None, **attrs):
    spec = oiio.ImageSpec(w, h, len(names), fmt)
    spec.channelnames = tuple(names)
    if formats:
        spec.channelformats = tuple(oiio.TypeDesc(f) for f in formats)
    for k, v in attrs.items():
        if isinstance(v, tuple):
            spec.attribute(k, oiio.TypeDesc(f"string[{len(v)}]"), v)
        else:
            spec.attribute(k, v)
    return spec


def stereo_singlepart(path, rng, w=24, h=16):
    names = ["R", "G", "B", "A", "Z", "left.R", "left.G", "left.B", "left.A", "left.Z", "id"]
    px = rng.uniform(0.1, 2.0, (h, w, len(names)))
    # uint32 ids: OpenImageIO converts floats to uint as normalised values
    px[..., names.index("id")] = rng.integers(2 ** 31, 2 ** 32 - 1, (h, w)) / (2.0 ** 32 - 1)
    spec = spec_for(w, h, names, formats=["half"] * 10 + ["uint"], multiView=("right", "left"))
    return write_parts(path, [(spec, px)]), names


def stereo_multipart(path, rng, w=24, h=16):
    specs = []
    for view, x in (("right", 0), ("left", 3)):
        s = spec_for(w, h, ["R", "G", "B", "A"], name=f"rgba_{view}", view=view)
        s.x = x
        specs.append((s, rng.uniform(0.1, 2.0, (h, w, 4))))
        z = spec_for(w, h, ["Z"], "float", name=f"depth_{view}", view=view)
        z.x = x
        specs.append((z, rng.uniform(1.0, 9.0, (h, w, 1))))
    crypto = spec_for(12, 8, ["crypto.R", "crypto.G"], "float", name="crypto")
    crypto.full_width, crypto.full_height = w, h          # parts share the display window
    bits = rng.integers(0x00800000, 0x7F000000, (8, 12, 2), dtype=np.uint32)   # no NaN/inf
    specs.append((crypto, bits.view(np.float32).astype(np.float64)))
    return write_parts(path, specs)


# --------------------------------------------------------------------------------------------
# The real Beachball files

def test_beachball_multipart_through_cinema_keeps_every_part_and_channel(tmp_path, rt,
                                                                       small_beachball):
    """The multipart file decimated by 4 (tests/plates.py: its 10 parts, views, windows,
    types and compression as stored); the 2K singlepart file is the next test's."""
    src = small_beachball.path("multipart", 1)
    run("render", src, tmp_path / "c.exr", "--look", "cinema")
    a, b = parts(src), parts(tmp_path / "c.exr")
    assert [(p["name"], p["view"], p["channels"]) for p in a] == \
        [(p["name"], p["view"], p["channels"]) for p in b]          # all 10 parts, in order
    for pa, pb in zip(a, b):
        assert pb["formats"] == pa["formats"] and pb["compression"] == pa["compression"]
        if pa["name"].startswith("rgba_"):                            # both eyes rendered
            assert not np.array_equal(pa["px"]["R"], pb["px"]["R"]), pa["name"]
        else:                                                         # copied as stored
            assert pa["window"] == pb["window"]
            for c in pa["channels"]:
                np.testing.assert_array_equal(pb["px"][c], pa["px"][c], err_msg=c)
    assert np.count_nonzero(b[5]["px"]["Z"] == 0) > 0                 # Z = 0 kept as stored


@needs_data
def test_beachball_singlepart_keeps_every_channel_and_both_eyes(tmp_path, rt):
    src = BEACHBALL / "singlepart.0001.exr"
    run("apply", *VIGNETTE[:1], src, tmp_path / "v.exr", *VIGNETTE[1:])
    [a], [b] = parts(src), parts(tmp_path / "v.exr")
    assert b["channels"] == a["channels"] and tuple(b["multiview"]) == ("right", "left")
    for c in a["channels"]:
        same = np.array_equal(a["px"][c], b["px"][c])
        assert same == (c not in ("R", "G", "B", "left.R", "left.G", "left.B")), c


# --------------------------------------------------------------------------------------------
# Generated multi-view files

def test_singlepart_stereo_renders_both_eyes_and_keeps_ids(tmp_path, rng, rt):
    src, names = stereo_singlepart(tmp_path / "st.exr", rng)
    assert [f.layout.view for f in read_views(src)] == ["right", "left"]
    run("apply", *VIGNETTE[:1], src, tmp_path / "o.exr", *VIGNETTE[1:])
    [a], [b] = parts(src), parts(tmp_path / "o.exr")
    assert b["channels"] == a["channels"] and b["formats"] == a["formats"]
    for c in names:
        changed = c in ("R", "G", "B", "left.R", "left.G", "left.B")
        assert np.array_equal(a["px"][c], b["px"][c]) != changed, c
    ids = native(tmp_path / "o.exr", "id", "uint")
    assert ids.min() >= 2 ** 31 and np.array_equal(ids, native(src, "id", "uint"))   # exact
    # --view left: only the left eye is rendered; the right eye is copied
    run("apply", *VIGNETTE[:1], src, tmp_path / "l.exr", *VIGNETTE[1:], "--view", "left")
    [c] = parts(tmp_path / "l.exr")
    assert np.array_equal(c["px"]["R"], a["px"]["R"])
    assert not np.array_equal(c["px"]["left.R"], a["px"]["left.R"])


def test_multipart_stereo_keeps_both_eyes_and_cryptomatte_bits(tmp_path, rng, rt):
    src = stereo_multipart(tmp_path / "mp.exr", rng)
    run("apply", *VIGNETTE[:1], src, tmp_path / "o.exr", *VIGNETTE[1:])
    a, b = parts(src), parts(tmp_path / "o.exr")
    assert [(p["name"], p["view"], p["channels"], p["window"]) for p in a] == \
        [(p["name"], p["view"], p["channels"], p["window"]) for p in b]
    for pa, pb in zip(a, b):
        rendered = pa["name"].startswith("rgba_")
        assert np.array_equal(pa["px"]["R" if rendered else pa["channels"][0]],
                              pb["px"]["R" if rendered else pb["channels"][0]]) != rendered
    bits = lambda p: p["px"]["crypto.R"].astype(np.float32).view(np.uint32)
    np.testing.assert_array_equal(bits(b[-1]), bits(a[-1]))            # hashes bit-exact


def test_view_that_does_not_exist_is_one_line(tmp_path, rng):
    src, _ = stereo_singlepart(tmp_path / "st.exr", rng)
    r = CliRunner().invoke(cli, ["apply", *VIGNETTE[:1], str(src), str(tmp_path / "o.exr"),
                                 *VIGNETTE[1:], "--view", "centre"])
    assert r.exit_code == 1 and "views with a beauty: right, left" in r.stderr, r.stderr


def test_passes_drop_and_non_exr_outputs_write_the_beauty_only(tmp_path, rng, rt):
    src = stereo_multipart(tmp_path / "mp.exr", rng)
    run("apply", *VIGNETTE[:1], src, tmp_path / "d.exr", *VIGNETTE[1:], "--passes", "drop")
    [d] = parts(tmp_path / "d.exr")
    assert d["channels"] == ("R", "G", "B", "A")             # the beauty only
    r = run("apply", *VIGNETTE[:1], src, tmp_path / "d.png", *VIGNETTE[1:])
    assert parts(tmp_path / "d.png")[0]["channels"] == ("R", "G", "B", "A")
    said = [ln for ln in r.stderr.splitlines() if "only the hero view 'right'" in ln]
    assert len(said) == 1, r.stderr


# --------------------------------------------------------------------------------------------
# Pixel type, compression, windows

@needs_data
def test_desk_keeps_piz_and_half(tmp_path, rt):
    src = DATA / "ScanLines" / "Desk.exr"
    run("apply", *VIGNETTE[:1], src, tmp_path / "d.exr", *VIGNETTE[1:])
    [b] = parts(tmp_path / "d.exr")
    assert b["compression"] == "piz" and set(b["formats"]) == {"half"}
    run("apply", *VIGNETTE[:1], src, tmp_path / "f.exr", *VIGNETTE[1:], "--float",
        "--compression", "zip")
    [f] = parts(tmp_path / "f.exr")
    assert f["compression"] == "zip" and set(f["formats"]) == {"float"}


def test_float_input_stays_float(tmp_path, rng):
    fr = Frame.from_array(rng.uniform(0, 1, (6, 8, 4)).astype(np.float32))
    write_frame(fr, tmp_path / "f.exr", bit_depth="float", compression="dwaa")
    back = read_frame(tmp_path / "f.exr")
    write_frame(back, tmp_path / "g.exr")
    [g] = parts(tmp_path / "g.exr")
    assert set(g["formats"]) == {"float"} and g["compression"] == "dwaa"


def test_grown_beauty_pads_the_other_channels(tmp_path, rng):
    w, h = 10, 6
    spec = spec_for(w, h, ["R", "G", "B", "A", "Z", "mask"], "float")
    spec.x, spec.y = 2, 3
    px = rng.uniform(0.5, 1.0, (h, w, 6))
    write_parts(tmp_path / "in.exr", [(spec, px)])
    fr = read_frame(tmp_path / "in.exr", **QUIET)
    grown = Rect.from_size(w + 4, h + 2, 0, 2)
    big = fr.with_rgba(np.ones((h + 2, w + 4, 4), np.float32), grown)
    write_frame(big, tmp_path / "out.exr")
    [b] = parts(tmp_path / "out.exr")
    assert b["window"] == (0, 2, w + 4, h + 2)
    mask = b["px"]["mask"]
    np.testing.assert_array_equal(mask[1:1 + h, 2:2 + w], px[..., 5].astype(np.float32))
    assert mask[0].max() == 0 and mask[:, :2].max() == 0 and mask[:, 2 + w:].max() == 0
    assert np.all(b["px"]["R"] == 1.0)


def test_stereo_explain_json_and_summary_name_every_view(tmp_path, rng, rt):
    """Issue 33: both eyes render, and --explain, --json and the summary say so (they used
    to report the hero's steps without naming the view)."""
    import json

    src, _ = stereo_singlepart(tmp_path / "st.exr", rng)
    r = run("apply", *VIGNETTE[:1], src, tmp_path / "o.exr", *VIGNETTE[1:], "--explain")
    assert "frame 1 (view right):" in r.stderr and "frame 1 (view left):" in r.stderr, r.stderr
    assert "(2 views each: right, left)" in r.stderr, r.stderr
    r = run("apply", *VIGNETTE[:1], src, tmp_path / "j.exr", *VIGNETTE[1:], "--json")
    frame, summary = [json.loads(ln) for ln in r.stdout.splitlines()]
    assert frame["view"] == "right" and frame["ran"] == ["vignette"]
    assert [o["view"] for o in frame["other_views"]] == ["left"]
    assert frame["other_views"][0]["ran"] == ["vignette"]
    assert summary["views"] == ["right", "left"]
    r = run("apply", *VIGNETTE[:1], src, tmp_path / "l.exr", *VIGNETTE[1:], "--json",
            "--view", "left")
    frame, summary = [json.loads(ln) for ln in r.stdout.splitlines()]
    assert frame["view"] == "left" and "other_views" not in frame and summary["views"] == ["left"]
    from clfx.cli import cli
    assert "Default: every view renders" in " ".join(
        CliRunner().invoke(cli, ["render", "--help"]).output.split())
