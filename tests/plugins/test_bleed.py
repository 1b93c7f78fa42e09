import numpy as np
import pytest
from clfx.host import RenderContext
from clfx.plugins.bleed import Bleed
from clfx.core.rect import Rect
from tests.conftest import hard_shapes
from tests.fx.blocks import assert_blocks_match
from tests.reference.bleed import bleed as reference
from tests.effects import render_effect

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
    got = render_effect(rt, Bleed(), p, src)
    want = oracle(src, p, radius(p, shape))
    # direct float32 gather of <= 441 taps: ~1e-6 relative
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6 * max(want.max(), 1))


def test_bleed_levels_monotonic_and_hdr(rt, rng):
    src = rng.uniform(0.005, 0.02, (40, 50, 4)).astype(np.float32)
    src[20, 25, :3] = 1e5
    p = Bleed.params(strength=0.3, size=0.1)   # radius 6 px: direct at every level
    want = oracle(src, p, radius(p, (40, 50)))
    errs = [np.abs(render_effect(rt, Bleed(), p, src, quality=q) - want).max() for q in LEVELS]
    assert all(a >= b for a, b in zip(errs, errs[1:])), errs
    got = render_effect(rt, Bleed(), p, src, quality="final").astype(np.float64)
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
    out, win = render_effect(rt, Bleed(), p, src, data_window=data, display_window=display,
                             keep_rod=True)
    r = radius(p, None, display)
    assert win == data.grown(r)
    want = oracle(src, p, r, data_window=(10, 10, 20, 20),
                  out_window=(win.x0, win.y0, win.x1, win.y1))
    np.testing.assert_allclose(out, want, rtol=1e-5, atol=1e-6 * want.max())
    assert out[r - 1, r - 1, 0] > 0


def test_separable_psf_errors_as_documented():
    from clfx.fx import psf as psflib
    from clfx.plugins.bleed import separable_psf, separable_psf_error

    # the module docstring's table: L1 error (fraction of the leaked light misplaced)
    table = {1: (0.0, 0.074), 2: (0.025, 0.24), 4: (0.047, 0.18), 7: (0.059, 0.14)}
    for r, (e2, e1) in table.items():
        k = psflib.exponential(r, r / 3.0)
        assert separable_psf_error(k, 2) == pytest.approx(e2, abs=2e-3)
        assert separable_psf_error(k, 1) == pytest.approx(e1, abs=3e-3)
        for rank in (1, 2):
            h, v = separable_psf(k, rank)
            assert np.einsum("ki,kj->ij", v, h).sum() == pytest.approx(1.0, abs=1e-12)  # energy


@pytest.mark.parametrize("quality", ["draft", "preview"])
def test_bleed_separable_levels_within_psf_error(rt, rng, quality):
    from clfx.fx import psf as psflib
    from clfx.plugins.bleed import LEVELS, separable_psf_error

    src = rng.uniform(0.0, 3.0, (37, 45, 4)).astype(np.float32)
    p = Bleed.params(strength=0.4, size=0.08)          # radius 5 px: the fused path
    r = radius(p, src.shape[:2])
    want = oracle(src, p, r)
    got = render_effect(rt, Bleed(), p, src, quality=quality)
    # |PSF_m * h - PSF * h| <= L1(PSF_m - PSF) max(h) (h <= max rgb), times strength; plus
    # float32 round-off of a <= 441-tap sum
    l1 = separable_psf_error(psflib.exponential(r, r / 3.0), LEVELS[quality].rank)
    bound = p.strength * l1 * src[..., :3].max() + 1e-5 * want.max()
    assert np.abs(got - want).max() <= bound
    np.testing.assert_array_equal(got[..., 3], src[..., 3])   # alpha kept


def test_bleed_block_skipping_sparse_specks(rt, rng):
    # sparse specks on block corners, frame edges and in isolation: skipped blocks must be
    # exactly the source, gathered ones the oracle
    src = rng.uniform(0.0, 0.5, (150, 203, 4)).astype(np.float32)
    for y, x in ((0, 0), (7, 3), (8, 4), (149, 202), (75, 100), (40, 199), (100, 1)):
        src[y, x, :3] = (5.0, 1e3, 2.0)
    p = Bleed.params(strength=0.3, size=0.02)          # radius 5 px
    out, win = render_effect(rt, Bleed(), p, src, keep_rod=True)
    r = radius(p, src.shape[:2])
    want = oracle(src, p, r, out_window=(win.x0, win.y0, win.x1, win.y1))
    # float32 gather of <= 441 taps: ~1e-6 relative
    np.testing.assert_allclose(out, want, rtol=1e-5, atol=1e-6 * want.max())
    far = np.ones(out.shape[:2], bool)                 # pixels out of every speck's reach
    yy, xx = np.mgrid[win.y0:win.y1, win.x0:win.x1]
    for y, x in ((0, 0), (7, 3), (8, 4), (149, 202), (75, 100), (40, 199), (100, 1)):
        far &= np.maximum(abs(yy - y), abs(xx - x)) > r
    inside = far[-win.y0:-win.y0 + 150, -win.x0:-win.x0 + 203]
    assert np.array_equal(out[-win.y0:-win.y0 + 150, -win.x0:-win.x0 + 203][inside], src[inside])


def test_bleed_large_radius_uses_glare_path(rt, rng):
    src = rng.uniform(0.0, 0.2, (90, 120, 4)).astype(np.float32)
    src[30, 40, :3] = 50.0
    p = Bleed.params(strength=0.3, size=0.1)           # radius 15 px > 10: FFT path
    got = render_effect(rt, Bleed(), p, src, quality="final")
    want = oracle(src, p, radius(p, src.shape[:2]))
    # float64 FFT: ~1e-7 relative of the peak
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6 * want.max())


def test_bleed_reference_float64_and_final_agree_tightly(rt, rng):
    src = rng.uniform(0.005, 0.02, (55, 70, 4)).astype(np.float32)
    src[27, 35, :3] = 1e5
    p = Bleed.params(strength=0.3, size=0.09)          # radius 8 px
    want = oracle(src, p, radius(p, src.shape[:2]))
    ref = render_effect(rt, Bleed(), p, src, quality="reference").astype(np.float64)
    fin = render_effect(rt, Bleed(), p, src, quality="final").astype(np.float64)
    m = want >= 1e-3
    # float64 sums: only float32 output rounding and the float32 mix remain (~1e-7 relative)
    assert (np.abs(ref - want)[m] / want[m]).max() <= 2e-6
    # float32 weights and sums next to a 1e5 pixel: ~1e-7 of the peak's leaked light
    assert np.abs(fin - want).max() <= 1e-6 * 0.3 * 1e5


def test_bleed_in_blocks_is_the_one_grid_bleed(rt, rng, monkeypatch):
    src = rng.uniform(0.0, 0.2, (90, 120, 4)).astype(np.float32)
    src[30, 40, :3] = 50.0
    p = Bleed.params(strength=0.3, size=0.1)           # radius 15 px > 10: FFT path
    assert_blocks_match(rt, monkeypatch, Bleed(), p, src, "final", cells=1500)
