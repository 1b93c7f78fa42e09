"""Tiled renders (issue 26): an effect that tiles (``whole_frame`` None) gives, band by band
from its region of interest, exactly the pixels of its whole render; every other effect
says why it renders whole."""
import numpy as np
import pytest

from clfx.pipeline.look import render_tiled, tile_bands
from clfx.core.rect import Rect

from . import effects

TILING = [n for n in effects.EFFECTS if effects.plugin(n).whole_frame is None]


def test_every_effect_tiles_or_says_why_not():
    for name in effects.EFFECTS:
        why = effects.plugin(name).whole_frame
        assert why is None or (isinstance(why, str) and len(why) > 10), name
    assert {"vignette", "grain"} <= set(TILING)


def test_bands_cover_the_window_once():
    w = Rect(-3, 2, 97, 75)
    bands = tile_bands(w, 100 * 9)
    assert len(bands) == 9 and bands[0].y0 == 2 and bands[-1].y1 == 75
    assert all(a.y1 == b.y0 for a, b in zip(bands, bands[1:]))
    assert tile_bands(w, None) == [w] and tile_bands(w, 10 ** 9) == [w]


@pytest.mark.parametrize("quality", effects.QUALITIES)
@pytest.mark.parametrize("name", TILING)
def test_tiles_give_the_whole_render(rt, name, quality):
    src = effects.scene((70, 90))
    p = effects.params(name)
    plugin = effects.plugin(name)

    def step():
        ctx = effects.context(rt, name, src, quality=quality).for_step(quality)
        assert plugin.is_identity(p, ctx) is None
        return ctx

    ctx = step()
    window = plugin.output_window(p, ctx)
    whole = rt.download(plugin.render(rt, p, ctx))
    ctx = step()
    tiled = rt.download(render_tiled(rt, plugin, p, ctx, window, 90 * 9))
    assert tiled.shape == whole.shape
    assert np.array_equal(tiled.view(np.uint32), whole.view(np.uint32))
