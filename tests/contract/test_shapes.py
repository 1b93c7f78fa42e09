"""Tiny and odd frame sizes render at every quality level, with the right shape, finite.

1x1, 1xN, Nx1 and sizes that are no multiple of any work-group or tile size; half-resolution
paths (draft) meet their smallest case here.  Shapes are (height, width).
"""
import numpy as np
import pytest

from clfx.core.rect import Rect
from tests.contract import effects as E
from tests.contract.known import param

SHAPES = [(1, 1), (1, 37), (37, 1), (17, 31), (31, 17), (2, 3)]


@pytest.mark.parametrize("name,quality", [
    param("test_tiny_and_odd_shapes", n, q, id=f"{n}-{q}")
    for n in E.EFFECTS for q in E.QUALITIES])
def test_tiny_and_odd_shapes(rt, name, quality):
    for shape in SHAPES:
        src = E.scene(shape)
        src.reshape(-1, 4)[:: max(src.size // 12, 1), :3] = E.HIGHLIGHT   # light to spread
        out, window = E.apply(rt, name, src, quality=quality, keep_rod=True)
        frame = Rect.from_size(shape[1], shape[0])
        assert out.shape == (window.height, window.width, 4), (shape, window)
        assert window.contains(frame), f"{name} ({quality}) {shape}: {window} lost the frame"
        assert np.isfinite(out).all(), f"{name} ({quality}) {shape}: non-finite output"
        assert E.apply(rt, name, src, quality=quality).shape == src.shape
