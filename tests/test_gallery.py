"""`clfx gallery`: labelled before/after contact sheets of effects and looks."""
import json

import numpy as np

from clfx import gallery
from tests.test_cli import run


def test_gallery_sheets_tiles_and_index(tmp_path, monkeypatch):
    monkeypatch.setattr(gallery, "shared_data_dirs", lambda: [tmp_path / "nowhere"])
    r = run("gallery", tmp_path / "g", "--width", "96", "--only", "vignette,lens,star-filter")
    # the missing test images are skipped with one line each
    assert r.stderr.count("not found") == 2
    index = json.loads((tmp_path / "g" / "index.json").read_text())
    assert [e["image"] for e in index["images"]] == ["demo", "sun"]
    for entry in index["images"]:
        names = [(t["kind"], t["name"]) for t in entry["tiles"]]
        assert names == [("effect", "lens"), ("effect", "vignette"), ("look", "star-filter")]
        assert (tmp_path / "g" / entry["image"] / "sheet.png").is_file()
        assert (tmp_path / "g" / entry["image"] / "look-star-filter.png").is_file()
        lens = entry["tiles"][0]
        assert lens["error"] is None                     # the gallery gives it a lens
        assert all(t["caption"] for t in entry["tiles"])


def test_every_tile_has_a_caption_the_font_can_draw():
    """One sentence per tile (what the defect is, where to look), in the sheet's font."""
    from clfx.pipeline.presets import available_looks
    from clfx.plugins import discover

    names = (list(discover()) + list(gallery.VARIANTS)
             + [n for n, (origin, _) in available_looks().items() if origin == "built-in"])
    assert sorted(n for n in names if n not in gallery.CAPTIONS) == []
    for name, text in gallery.CAPTIONS.items():
        assert text.endswith(".") and len(gallery.wrap(text, 52)) <= 3, name
        assert all(c.upper() in gallery._GLYPHS for c in text), name
    tile = np.zeros((60, 320, 3), np.float32) + 0.5
    out = gallery.caption(tile, gallery.CAPTIONS["lens_flare"])
    assert out[:30].min() == 0.5 and out[-20:].max() == 1.0      # text at the bottom only


def test_labels_are_drawn_and_sheet_layout():
    tile = np.zeros((40, 120, 3), np.float32)
    out = gallery.label(tile, ["AB", "c-d"])
    assert out.max() == 1.0 and out[:2].max() == 0.0          # text below a 2 px margin
    assert gallery.text_mask("x").shape == (14, 12)
    sheet = gallery.tile_sheet([tile] * 7, columns=3)
    assert sheet.shape == (3 * 44 + 4, 3 * 124 + 4, 3)


def test_area_resize_keeps_energy_density():
    img = np.random.default_rng(1).uniform(0, 10, (81, 100, 3))
    small = gallery.area_resize(img, 64, 52)
    np.testing.assert_allclose(small.mean(axis=(0, 1)), img.mean(axis=(0, 1)), rtol=1e-3)


def test_option_variants_are_tiles_of_their_own(tmp_path, monkeypatch):
    """Options off at an effect's defaults (cat-eye bokeh, a pulled focus's breathing) get
    tiles that differ from the plain effect's."""
    import cv2

    monkeypatch.setattr(gallery, "shared_data_dirs", lambda: [tmp_path / "nowhere"])
    run("-q", "gallery", tmp_path / "g", "--width", "128", "--only",
        "dof,dof:cat-eye,breathing,breathing:pull-focus")
    demo = tmp_path / "g" / "demo"
    tile = {n: cv2.imread(str(demo / gallery.tile_filename("effect", n))).astype(float)
            for n in ("dof", "dof:cat-eye", "breathing", "breathing:pull-focus")}
    before = cv2.imread(str(demo / "before.png")).astype(float)
    body = slice(40, None)                    # below the labels
    assert np.abs(tile["breathing"][body] - before[body]).max() == 0   # static focus: identity
    assert np.abs(tile["breathing:pull-focus"][body] - before[body]).mean() > 1
    assert np.abs(tile["dof:cat-eye"][body] - tile["dof"][body]).mean() > 0.1


def test_effects_at_zero_defaults_get_demonstration_values_on_their_tiles(tmp_path, monkeypatch):
    """camera_blur and distortion change nothing at their defaults (0): their tiles show them
    at `DEMO_VALUES`, said on the label and the caption, never the input under a caption
    promising the effect (issue 34)."""
    import cv2

    monkeypatch.setattr(gallery, "shared_data_dirs", lambda: [tmp_path / "nowhere"])
    run("-q", "gallery", tmp_path / "g", "--width", "128", "--only", "camera_blur,distortion")
    index = json.loads((tmp_path / "g" / "index.json").read_text())
    for entry in index["images"]:
        folder = tmp_path / "g" / entry["image"]
        before = cv2.imread(str(folder / "before.png")).astype(float)
        for tile in entry["tiles"]:
            values = gallery.DEMO_VALUES[tile["name"]]
            assert tile["settings"] == values
            assert all(v in tile["caption"] for v in values), tile["caption"]
            img = cv2.imread(str(tmp_path / "g" / tile["file"])).astype(float)
            body = slice(40, None)                        # below the label (72 rows)
            diff = np.abs(img[body] - before[body])       # was 0: the input itself
            assert diff.mean() > 0.1 and diff.max() > 10, (entry["image"], tile["name"])


def test_tile_file_names_are_portable():
    """No ``:`` (SMB and Windows shares refuse it) nor any other character past
    [A-Za-z0-9._-] in any name the gallery writes; every tile has its own file."""
    import re

    items = gallery.gallery_looks()
    files = gallery.gallery_files("OUT", ["demo", "sun", "CandleGlass", "Desk"], items)
    names = [p.split("/", 1)[1] for p in files]
    assert len(set(files)) == len(files)
    assert any(":" in name for _, name, _ in items)         # variants are named with one
    for name in names:
        assert all(re.fullmatch(r"[A-Za-z0-9._-]+", part) for part in name.split("/")), name
    assert gallery.tile_filename("effect", "dof:cat-eye") == "effect-dof-cat-eye.png"


def _one_error_line(result):
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("clfx: error: "), result.stderr
    return lines[0]


def test_gallery_never_writes_through_a_link_nor_replaces_without_overwrite(tmp_path,
                                                                          monkeypatch):
    monkeypatch.setattr(gallery, "shared_data_dirs", lambda: [tmp_path / "nowhere"])
    outside = tmp_path / "outside.txt"
    outside.write_text("keep")
    out = tmp_path / "g"
    out.mkdir()
    (out / "index.json").symlink_to(outside)
    args = ("-q", "gallery", out, "--width", "32", "--only", "vignette")
    line = _one_error_line(run(*args, code=1))
    assert "index.json exists" in line and "--overwrite" in line
    assert sorted(p.name for p in out.iterdir()) == ["index.json"]   # nothing rendered
    run(*args, "-y")                                       # -y is --overwrite, as for demo
    assert outside.read_text() == "keep"                   # the link was replaced, not followed
    assert not (out / "index.json").is_symlink()
    assert json.loads((out / "index.json").read_text())["width"] == 32
    # an earlier gallery (its index and tiles) is not replaced without --overwrite
    stamp = (out / "index.json").stat().st_mtime_ns
    _one_error_line(run(*args, code=1))
    assert (out / "index.json").stat().st_mtime_ns == stamp
    # an image folder linked elsewhere is refused, even with --overwrite
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (out / "sun").rename(tmp_path / "sun-old")
    (out / "sun").symlink_to(elsewhere)
    assert "symbolic link" in _one_error_line(run(*args, "--overwrite", code=1))
    assert list(elsewhere.iterdir()) == []


def test_gallery_and_demo_refuse_bad_width_and_a_file_as_outdir(tmp_path):
    for width in ("0", "-5"):
        r = run("gallery", tmp_path / "g", "--width", width, code=2)
        assert "--width" in _one_error_line(r)
    assert not (tmp_path / "g").exists()
    a_file = tmp_path / "a-file"
    a_file.write_text("x")
    for cmd in (("gallery", a_file, "--width", "32", "--only", "vignette"),
                ("demo", a_file, "--frames", "1", "--size", "32x18")):
        assert "not a folder" in _one_error_line(run(*cmd, code=1))
        assert a_file.read_text() == "x"
