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
    tile = {n: cv2.imread(str(demo / f"effect-{n}.png")).astype(float)
            for n in ("dof", "dof:cat-eye", "breathing", "breathing:pull-focus")}
    before = cv2.imread(str(demo / "before.png")).astype(float)
    body = slice(40, None)                    # below the labels
    assert np.abs(tile["breathing"][body] - before[body]).max() == 0   # static focus: identity
    assert np.abs(tile["breathing:pull-focus"][body] - before[body]).mean() > 1
    assert np.abs(tile["dof:cat-eye"][body] - tile["dof"][body]).mean() > 0.1
