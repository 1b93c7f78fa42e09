"""Regions: the region of definition holds the source window, the region of interest of a
window holds that window, and what an effect renders lies inside its region of definition.

The data window sits inside a larger display window (and, in a second case, the display
window is the data window), so effects that spread light have somewhere to put it.
"""
import numpy as np
import pytest

from clfx.core.rect import Rect
from tests.contract import effects as E
from tests.contract.known import param

DISPLAY = Rect(0, 0, 64, 48)
DATA = Rect(10, 7, 52, 40)      # 42 x 33, off-centre inside the display window


def windows_inside(rect: Rect) -> list[Rect]:
    """The whole window, a corner pixel, a central pixel and an off-centre block."""
    cx, cy = (rect.x0 + rect.x1) // 2, (rect.y0 + rect.y1) // 2
    return [rect, Rect(rect.x0, rect.y0, rect.x0 + 1, rect.y0 + 1),
            Rect(cx, cy, cx + 1, cy + 1), Rect(rect.x0 + 3, cy, rect.x1, rect.y1)]


@pytest.mark.parametrize("name,quality", [
    param("test_regions_hold_the_source_and_the_render", n, q, id=f"{n}-{q}")
    for n in E.EFFECTS for q in E.QUALITIES])
@pytest.mark.parametrize("display", [DISPLAY, DATA], ids=["overscan-room", "data-is-display"])
def test_regions_hold_the_source_and_the_render(rt, name, quality, display):
    src = E.scene(DATA.shape)
    p = E.params(name)
    plugin = E.plugin(name)
    ctx = E.context(rt, name, src, quality=quality, window=DATA, display_window=display)
    rod = plugin.region_of_definition(p, ctx)
    assert rod.contains(DATA), f"{name} ({quality}): RoD {rod} misses the source {DATA}"
    for window in windows_inside(display) + windows_inside(DATA):
        roi = plugin.region_of_interest(p, ctx, window)
        assert roi.contains(window), f"{name} ({quality}): RoI {roi} of {window} misses it"
    out, window = E.apply(rt, name, src, quality=quality, data_window=DATA,
                          display_window=display, keep_rod=True)
    assert out.shape == window.shape + (4,)
    assert window.contains(DATA), f"{name} ({quality}): rendered {window} lost {DATA}"
    assert rod.contains(window), f"{name} ({quality}): rendered {window} outside RoD {rod}"
    assert display.union(DATA).contains(window), \
        f"{name} ({quality}): rendered {window} past the display and data windows"
    assert np.isfinite(out).all()
