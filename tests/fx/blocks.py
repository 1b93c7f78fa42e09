"""Force `clfx.fx.fftconv.convolve_blocks` into many small blocks (the 8K path on a test
frame) and record that it took them."""
from clfx.fx import fftconv
from tests.effects import render_effect


def force_blocks(monkeypatch, cells: int = 4096, min_block: int = 8) -> list:
    """Cap the block grid at ``cells`` (sides down to ``min_block``); returns a list that
    gets each blocked call's :class:`clfx.fx.fftconv.ConvolveInfo`."""
    calls = []
    blocked = fftconv._blocked

    def spy(*args):
        blocked(*args)
        calls.append(args[10])        # the call's info (blocks, grid, notes)

    monkeypatch.setattr(fftconv, "MAX_BLOCK_CELLS", cells)
    monkeypatch.setattr(fftconv, "MIN_BLOCK", min_block)
    monkeypatch.setattr(fftconv, "_blocked", spy)
    return calls


def assert_blocks_match(rt, monkeypatch, plugin, p, src, quality, *, cells=6000, tol=1e-6,
                        **kw):
    """``plugin``'s render in forced blocks equals its one-grid render up to FFT rounding
    (``tol`` x the output's peak: float32 transforms ~1e-7, float64 below float32 output);
    returns the blocked render."""
    import numpy as np

    one = render_effect(rt, plugin, p, src, quality=quality, **kw)
    calls = force_blocks(monkeypatch, cells, 16)
    got = render_effect(rt, plugin, p, src, quality=quality, **kw)
    assert calls and all(c.blocks > 1 for c in calls)
    np.testing.assert_allclose(got, one, rtol=0, atol=tol * np.abs(one).max())
    return got
