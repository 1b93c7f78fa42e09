"""Tiled renders (issue 26): an effect that tiles (``whole_frame`` None) gives, band by band
from its region of interest, exactly the pixels of its whole render; every other effect
says why it renders whole."""
import numpy as np
import pytest

from clfx.pipeline.look import render_tiled, tile_bands
from clfx.core.rect import Rect

from . import effects

TILING = [n for n in effects.EFFECTS if effects.plugin(n).whole_frame is None]

WARPS = [n for n in TILING
         if any(prm.name == "border" for prm in effects.plugin(n).descriptor.params)]
"""Tiling effects that read the source at mapped points, with a border rule at the frame."""

LAYOUTS = {
    # data window strictly inside the display window: transparent black around it
    "inside": (Rect(6, 5, 96, 75), Rect(0, 0, 110, 84)),
    # overscan: a data window past the display window on every side (negative origin)
    "overscan": (Rect(-7, -9, 83, 61), Rect(0, 0, 76, 52)),
}
"""(data window, display window) of a 70x90 frame placed off the origin."""


def test_every_effect_tiles_or_says_why_not():
    for name in effects.EFFECTS:
        why = effects.plugin(name).whole_frame
        assert why is None or (isinstance(why, str) and len(why) > 10), name
    assert {"vignette", "grain", "chromatic_aberration", "distortion",
            "sensor_noise"} <= set(TILING)


def test_bands_cover_the_window_once():
    w = Rect(-3, 2, 97, 75)
    bands = tile_bands(w, 100 * 9)
    assert len(bands) == 9 and bands[0].y0 == 2 and bands[-1].y1 == 75
    assert all(a.y1 == b.y0 for a, b in zip(bands, bands[1:]))
    assert tile_bands(w, None) == [w] and tile_bands(w, 10 ** 9) == [w]


def assert_tiles_give_the_whole_render(rt, name, p, quality, src, rows=9, **where):
    """``name`` at ``quality`` over ``src`` (context keywords ``where``): bands of ``rows``
    rows give its whole render bit for bit."""
    plugin = effects.plugin(name)

    def step():
        ctx = effects.context(rt, name, src, quality=quality, **where).for_step(quality)
        assert plugin.is_identity(p, ctx) is None
        return ctx

    ctx = step()
    window = plugin.output_window(p, ctx)
    whole = rt.download(plugin.render(rt, p, ctx))
    ctx = step()
    renders = []
    plugin.render = lambda *a: renders.append(a[2].tiling) or type(plugin).render(plugin, *a)
    try:
        tiled = rt.download(render_tiled(rt, plugin, p, ctx, window, window.width * rows))
    finally:
        del plugin.render
    bands = tile_bands(window, window.width * rows)
    assert len(bands) > 2 and [t.band for t in renders] == bands   # not the whole fallback
    assert tiled.shape == whole.shape
    assert np.array_equal(tiled.view(np.uint32), whole.view(np.uint32))


@pytest.mark.parametrize("quality", effects.QUALITIES)
@pytest.mark.parametrize("name", TILING)
def test_tiles_give_the_whole_render(rt, name, quality):
    assert_tiles_give_the_whole_render(rt, name, effects.params(name), quality,
                                       effects.scene((70, 90)))


@pytest.mark.parametrize("quality", effects.QUALITIES)
@pytest.mark.parametrize("layout", sorted(LAYOUTS))
@pytest.mark.parametrize("border", ["black", "edge", "mirror"])
@pytest.mark.parametrize("name", WARPS)
def test_warp_tiles_at_every_border_and_window(rt, name, border, layout, quality):
    # the canvas (frame, overscan, the border's repeated edge) is the whole render's in
    # every band; bands of 7 rows, so some band's rows need the canvas past the frame
    window, display = LAYOUTS[layout]
    assert_tiles_give_the_whole_render(rt, name, effects.params(name, border=border), quality,
                                       effects.scene((70, 90)), rows=7, window=window,
                                       display_window=display)


@pytest.mark.parametrize("quality", effects.QUALITIES)
@pytest.mark.parametrize("mosaic", ["bayer", "none"])
def test_sensor_noise_tiles_with_its_mosaic_and_chroma(rt, mosaic, quality):
    p = effects.params("sensor_noise", mosaic=mosaic, chroma_noise=1.0)
    window, display = LAYOUTS["overscan"]
    assert_tiles_give_the_whole_render(rt, "sensor_noise", p, quality, effects.scene((70, 90)),
                                       rows=5, window=window, display_window=display)


@pytest.mark.parametrize("mosaic", ["bayer", "none"])
def test_sensor_noise_is_the_same_on_a_crop_at_the_same_place(rt, mosaic):
    """Noise is hashed on frame coordinates: a crop (odd origin) gets the frame's noise at
    its pixels (with a mosaic, away from the crop's edges the demosaic reads past)."""
    name = "sensor_noise"
    plugin = effects.plugin(name)
    p = effects.params(name, mosaic=mosaic, chroma_noise=1.0, coverage="ignore")
    src = effects.scene((70, 90))
    window, crop = Rect(-7, -9, 83, 61), Rect(-2, 4, 61, 41)
    full = rt.download(plugin.render(rt, p, effects.context(rt, name, src, window=window)))
    part = src[crop.y0 - window.y0:crop.y1 - window.y0, crop.x0 - window.x0:crop.x1 - window.x0]
    cropped = rt.download(plugin.render(rt, p, effects.context(rt, name, part.copy(),
                                                               window=crop,
                                                               display_window=window)))
    inner = crop.grown(-2) if mosaic == "bayer" else crop
    want = full[inner.y0 - window.y0:inner.y1 - window.y0, inner.x0 - window.x0:inner.x1 - window.x0]
    got = cropped[inner.y0 - crop.y0:inner.y1 - crop.y0, inner.x0 - crop.x0:inner.x1 - crop.x0]
    assert np.array_equal(got.view(np.uint32), want.view(np.uint32))
    assert not np.array_equal(got, part[inner.y0 - crop.y0:inner.y1 - crop.y0,
                                        inner.x0 - crop.x0:inner.x1 - crop.x0])


@pytest.mark.parametrize("quality", effects.QUALITIES)
@pytest.mark.parametrize("layout", sorted(LAYOUTS))
@pytest.mark.parametrize("reference_focus", [0.5, 20.0])   # the frame widens / narrows
def test_breathing_tiles_in_every_window(rt, reference_focus, layout, quality):
    window, display = LAYOUTS[layout]
    p = effects.params("breathing", reference_focus=reference_focus)
    assert_tiles_give_the_whole_render(rt, "breathing", p, quality, effects.scene((70, 90)),
                                       rows=7, window=window, display_window=display)


@pytest.mark.parametrize("quality", effects.QUALITIES)
@pytest.mark.parametrize("layout", ["frame", "overscan"])
@pytest.mark.parametrize("streamed", [False, True], ids=["whole-passes", "streamed"])
@pytest.mark.parametrize("mode", ["star", "anamorphic"])
def test_streaks_tiles_from_the_frames_streak_sum(rt, monkeypatch, mode, streamed, layout,
                                                  quality):
    # the plan's streak sum is the whole frame's (its passes over frame-sized buffers, or
    # streamed through in chunks of 3 rows as an 8K frame is); a band composes its rows of it
    # (a band reads only its rows of the source: one past the data window makes
    # render_tiled render whole, so "inside" is not a layout here)
    import clfx.plugins.streaks as mod
    if streamed:
        monkeypatch.setattr(mod, "streams", lambda *a: True)
        monkeypatch.setattr(mod, "CHUNK_PIXELS", 3 * 96)
    window, display = LAYOUTS.get(layout, (None, None))
    p = effects.params("streaks", mode=mode, angle=30.0, length=0.3, streaks=5)
    assert_tiles_give_the_whole_render(rt, "streaks", p, quality, effects.scene((70, 90)),
                                       rows=7, window=window, display_window=display)
