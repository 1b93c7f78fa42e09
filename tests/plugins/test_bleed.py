import numpy as np
import pytest

from clfx.plugin import RenderContext
from clfx.plugins.bleed import Bleed
from clfx.rect import Rect
from tests.conftest import hard_shapes
from tests.reference.bleed import bleed as reference

LEVELS = ("draft", "preview", "final", "reference")


def oracle(src, p, radius, **kw):
    return reference(src, radius, strength=p.strength, threshold=p.threshold, knee=p.knee,
                     tint=p.tint, **kw)


def radius(p, shape, display=None):
    d = display.diagonal if display else np.hypot(shape[1], shape[0])
    return int(round(p.size * d))


@pytest.mark.parametrize("shape", hard_shapes())
def test_bleed_matches_reference(rt, rng, shape):
    src = rng.uniform(0.0, 3.0, shape + (4,)).astype(np.float32)
    p = Bleed.params(strength=0.4, size=0.08)
    got = Bleed().apply(rt, p, src)
    want = oracle(src, p, radius(p, shape))
    # direct float32 gather of <= 441 taps: ~1e-6 relative
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6 * max(want.max(), 1))


def test_bleed_levels_monotonic_and_hdr(rt, rng):
    src = rng.uniform(0.005, 0.02, (40, 50, 4)).astype(np.float32)
    src[20, 25, :3] = 1e5
    p = Bleed.params(strength=0.3, size=0.1)   # radius 6 px: direct at every level
    want = oracle(src, p, radius(p, (40, 50)))
    errs = [np.abs(Bleed().apply(rt, p, src, quality=q) - want).max() for q in LEVELS]
    assert all(a >= b for a, b in zip(errs, errs[1:])), errs
    got = Bleed().apply(rt, p, src, quality="final").astype(np.float64)
    m = want >= 1e-3
    assert (np.abs(got - want)[m] / want[m]).max() <= 1e-4
    assert got.min() >= -1e-6 * want.max()


def test_bleed_energy_nonfinite_identity_determinism(rt, rng):
    src = np.zeros((24, 24, 4), np.float32)
    src[12, 12, :3] = 100.0
    src[2, 2, 0] = np.nan
    p = Bleed.params(strength=0.5, size=0.1)
    ctx = RenderContext(rt, rt.upload(src))
    out = Bleed().render(rt, p, ctx).download()
    assert np.isfinite(out).all() and any("1 non-finite" in n for n in ctx.notes)
    assert abs(out[..., :3].sum() / 300.0 - 1) <= 1e-5
    assert out.tobytes() == Bleed().render(rt, p, RenderContext(rt, rt.upload(src))).download().tobytes()
    dim = np.full((8, 8, 4), 0.2, np.float32)
    assert Bleed().is_identity(p, RenderContext(rt, rt.upload(dim))) == "no pixel above threshold"


def test_bleed_rod_grows_into_display(rt):
    data, display = Rect(10, 10, 20, 20), Rect(0, 0, 40, 30)
    src = np.zeros((10, 10, 4), np.float32)
    src[0, 0, :3] = 50.0
    p = Bleed.params(size=0.05)
    out, win = Bleed().apply(rt, p, src, data_window=data, display_window=display, keep_rod=True)
    r = radius(p, None, display)
    assert win == data.grown(r)
    want = oracle(src, p, r, data_window=(10, 10, 20, 20),
                  out_window=(win.x0, win.y0, win.x1, win.y1))
    np.testing.assert_allclose(out, want, rtol=1e-5, atol=1e-6 * want.max())
    assert out[r - 1, r - 1, 0] > 0
