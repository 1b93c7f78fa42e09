import numpy as np
import pytest
from clfx.host import RenderContext
from clfx.plugins.soft_focus import SoftFocus
from tests.conftest import hard_shapes
from tests.fx.blocks import assert_blocks_match
from tests.reference.soft_focus import soft_focus as reference
from tests.effects import render_effect

LEVELS = ("draft", "preview", "final", "reference")


def oracle(src, p, **kw):
    h, w = src.shape[:2]
    r = int(round(3.0 * p.size * np.hypot(w, h)))      # the support: 3 x size
    return reference(src, r, amount=p.amount, threshold=p.threshold, knee=p.knee, tint=p.tint, **kw)


@pytest.mark.parametrize("shape", hard_shapes())
def test_soft_focus_matches_reference(rt, rng, shape):
    src = rng.uniform(0.0, 2.0, shape + (4,)).astype(np.float32)
    p = SoftFocus.params(amount=0.5, size=0.3)
    got = render_effect(rt, SoftFocus(), p, src)
    want = oracle(src, p)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6 * max(want.max(), 1))


def test_soft_focus_levels_monotonic_energy_and_8bit(rt, rng):
    # display-referred 8-bit-like frame: values in [0, 1], moderately bright areas glow
    src = (rng.integers(0, 256, (48, 64, 4)) / 255.0).astype(np.float32)
    src[10:20, 30:40, :3] = 1.0
    p = SoftFocus.params(amount=0.4, size=0.4)
    ctx = RenderContext(rt, rt.upload(src), display_referred=True)
    assert SoftFocus().is_identity(p, ctx) is None
    want = oracle(src, p)
    outs = [render_effect(rt, SoftFocus(), p, src, quality=q, display_referred=True) for q in LEVELS]
    errs = [np.abs(o - want).max() for o in outs]
    assert all(a >= b for a, b in zip(errs, errs[1:])), errs
    assert errs[-1] <= 1e-6 * want.max()
    assert outs[2].tobytes() == render_effect(rt, SoftFocus(), p, src, display_referred=True).tobytes()


def test_soft_focus_hdr_nonfinite_identity(rt, rng):
    src = rng.uniform(0.005, 0.02, (40, 48, 4)).astype(np.float32)
    src[20, 24, :3] = 1e5
    src[3, 3, 2] = np.inf
    p = SoftFocus.params(amount=0.3, size=0.5)
    ctx = RenderContext(rt, rt.upload(src))
    got = SoftFocus().render(rt, p, ctx).download().astype(np.float64)
    assert any("1 non-finite" in n for n in ctx.notes)
    clean = src.copy()
    clean[3, 3] = 0
    want = oracle(clean, p)
    m = want[..., :3] >= 1e-3
    assert (np.abs(got - want)[..., :3][m] / want[..., :3][m]).max() <= 1e-4
    assert got.min() >= -1e-6 * want.max()
    dark = np.full((32, 32, 4), 0.01, np.float32)
    high = SoftFocus.params(threshold=0.5, knee=0.1)
    assert SoftFocus().is_identity(high, RenderContext(rt, rt.upload(dark))) == "no pixel above threshold"
    assert SoftFocus().is_identity(SoftFocus.params(amount=0.0), ctx) == "amount is 0"


@pytest.mark.parametrize("size", [0.03, 0.1])
def test_point_light_diffusion_fades_smoothly_before_its_support_ends(rt, size):
    # issue 25: exponential diffusion, no disc edge: monotone, no step above 1e-4 of the
    # peak, below it before the support (3 x size) ends
    from tests.light_profile import assert_smooth_tail, point_light, ray

    src = point_light()
    h, w = src.shape[:2]
    out = render_effect(rt, SoftFocus(), SoftFocus.params(size=size), src)
    support = round(3.0 * size * np.hypot(w, h))
    assert_smooth_tail(ray(out, h // 2, w // 2, 1, 0, w // 2), support,
                       what=f"soft_focus size {size}")


@pytest.mark.parametrize("quality", ["draft", "preview", "final"])
def test_soft_focus_in_blocks_is_the_one_grid_soft_focus(rt, rng, monkeypatch, quality):
    src = rng.uniform(0.0, 1.0, (50, 70, 4)).astype(np.float32)
    src[20, 30, :3] = 30.0
    p = SoftFocus.params(size=0.1)
    assert_blocks_match(rt, monkeypatch, SoftFocus(), p, src, quality, cells=600)
