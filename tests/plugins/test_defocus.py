"""defocus: oracle agreement, identity, regions, pixel aspect, NaN/Inf, HDR, presets."""
import math

import numpy as np
import pytest

from clfx.bench.cases.defocus import CASE
from clfx.core.rect import Rect
from clfx.host import RenderContext
from clfx.plugins.defocus import Defocus, defocus_sigmas
from tests.conftest import hard_shapes
from tests.reference.defocus import defocus as reference
from tests.effects import render_effect

LEVELS = ("draft", "preview", "final", "reference")
# Max |error| for inputs in [0, 1] (see tests/test_blur.py: measured errors x 2-3, two axes)
TOL = {"draft": 6e-3, "preview": 1e-3, "final": 2e-4, "reference": 3e-7}


def run(rt, src, quality="final", **kw):
    params = {k: kw.pop(k) for k in ("size", "aspect", "edges") if k in kw}
    p = Defocus.params(**params)
    return render_effect(rt, Defocus(), p, src, quality=quality, **kw), p


@pytest.mark.parametrize("shape", hard_shapes())
@pytest.mark.parametrize("sigma_px", [1.2, 14.0])
def test_defocus_matches_reference(rt, rng, shape, sigma_px):
    src = rng.uniform(0.0, 1.0, shape + (4,)).astype(np.float32)
    display = Rect(0, 0, 100, 80)  # the tiny data window sits in a larger frame
    size = sigma_px / display.diagonal
    got, p = run(rt, src, size=size, display_window=display)
    want = reference(src, **p.as_dict(), diagonal_px=display.diagonal)
    np.testing.assert_allclose(got, want, rtol=0, atol=TOL["final"])


@pytest.mark.parametrize("quality", LEVELS)
def test_each_quality_level_within_its_tolerance(rt, rng, quality):
    src = rng.uniform(0.0, 1.0, (40, 56, 4)).astype(np.float32)
    for size in (0.03, 0.2):    # sigma 2.1 px (direct) and 13.8 px (pyramid)
        got, p = run(rt, src, quality, size=size)
        want = reference(src, **p.as_dict())
        np.testing.assert_allclose(got, want, rtol=0, atol=TOL[quality])


def test_error_is_monotone_across_levels(rt):
    src = np.zeros((80, 80, 4), np.float32)
    src[37, 41] = 50.0
    src[:, 60:, :] = 1.0
    want = reference(src, size=0.07)   # sigma 7.9 px
    errs = [np.abs(run(rt, src, q, size=0.07)[0] - want).max() for q in LEVELS]
    assert all(a >= b for a, b in zip(errs, errs[1:])), errs


def test_identity_reasons_and_bitwise_copy(rt, rng):
    src = rng.uniform(0.0, 1.0, (9, 11, 4)).astype(np.float32)
    ctx = RenderContext(rt, rt.upload(src))
    assert Defocus().is_identity(Defocus.params(size=0.0), ctx) == "size is 0"
    reason = Defocus().is_identity(Defocus.params(size=0.01), ctx)  # 0.14 px
    assert reason and "below 0.3 px" in reason
    assert Defocus().is_identity(Defocus.params(size=0.05), ctx) is None
    got, _ = run(rt, src, size=0.01)
    assert np.array_equal(got, src)


def test_pixel_aspect_makes_blur_round_on_screen(rt):
    src = np.zeros((41, 41, 4), np.float32)
    src[20, 20] = 1.0
    got, p = run(rt, src, size=0.05, pixel_aspect=2.0)
    want = reference(src, **p.as_dict(), pixel_aspect=2.0)
    np.testing.assert_allclose(got, want, rtol=0, atol=TOL["final"])
    ctx = RenderContext(rt, rt.upload(src), pixel_aspect=2.0)
    sx, sy = defocus_sigmas(p, ctx)
    assert sx == pytest.approx(sy / 2)


def test_anamorphic_aspect(rt, rng):
    src = rng.uniform(0.0, 1.0, (30, 44, 4)).astype(np.float32)
    got, p = run(rt, src, size=0.02, aspect=6.0)
    want = reference(src, **p.as_dict())
    np.testing.assert_allclose(got, want, rtol=0, atol=TOL["final"])


@pytest.mark.parametrize("edges", ["black", "clamp", "mirror"])
def test_light_spreads_past_the_data_window(rt, rng, edges):
    """A data window inside a larger display window: the RoD grows by 3 sigma."""
    src = rng.uniform(0.0, 1.0, (12, 16, 4)).astype(np.float32)
    data, display = Rect(40, 30, 56, 42), Rect(0, 0, 96, 72)
    p = Defocus.params(size=0.02, edges=edges)  # sigma 2.4 px of the 120 px diagonal
    got, window = render_effect(rt, Defocus(), p, src, data_window=data, display_window=display,
                                keep_rod=True)
    sigma = 0.02 * display.diagonal
    g = math.ceil(3 * sigma)
    assert window == data.grown(g)
    want = reference(src, **p.as_dict(), diagonal_px=display.diagonal,
                     offset=(window.x0 - data.x0, window.y0 - data.y0), out_shape=window.shape)
    np.testing.assert_allclose(got, want, rtol=0, atol=TOL["final"])
    if edges == "black":
        # energy that left the data window is all inside the grown window
        assert abs(got.astype(np.float64).sum() / src.astype(np.float64).sum() - 1) < 1e-3


def test_rod_is_clipped_to_the_frame_when_data_equals_display(rt, rng):
    src = rng.uniform(0.0, 1.0, (20, 30, 4)).astype(np.float32)
    got, window = render_effect(rt, Defocus(), Defocus.params(size=0.1), src, keep_rod=True)
    assert window == Rect(0, 0, 30, 20) and got.shape == src.shape


def test_nonfinite_pixels_are_zeroed_and_counted(rt, rng):
    src = rng.uniform(0.0, 1.0, (24, 31, 4)).astype(np.float32)
    src[5, 7, 0] = np.nan
    src[12, 20, :] = np.inf
    src[20, 3, 3] = -np.inf
    ctx = RenderContext(rt, rt.upload(src))
    p = Defocus.params(size=0.08)
    got = Defocus().render(rt, p, ctx).download()
    assert np.isfinite(got).all()
    assert any("3 pixels" in n for n in ctx.notes), ctx.notes
    want = reference(src, **p.as_dict())
    np.testing.assert_allclose(got, want, rtol=0, atol=TOL["final"])
    clean = RenderContext(rt, rt.upload(np.nan_to_num(src, nan=0, posinf=0, neginf=0)))
    Defocus().render(rt, p, clean)
    assert clean.notes == []


def test_hdr_highlight_stays_positive_without_ringing(rt):
    src = np.full((64, 80, 4), 0.01, np.float32)
    src[30, 44, :3] = 1e5
    for quality in LEVELS:
        for size in (0.01, 0.1):
            got, p = run(rt, src, quality, size=size)
            assert got.min() >= 0.01 * (1 - 1e-5) and got.max() <= 1e5
            want = reference(src, **p.as_dict())
            np.testing.assert_allclose(got, want, rtol=0, atol=TOL[quality] * 1e5)


def test_huge_size_keeps_a_flat_field_flat(rt):
    src = np.full((6, 10, 4), 0.5, np.float32)
    for edges in ("clamp", "mirror"):
        got, _ = run(rt, src, size=0.25, edges=edges, display_window=Rect(0, 0, 1920, 1080))
        np.testing.assert_allclose(got, 0.5, rtol=0, atol=1e-6)  # 550 px sigma on 10 px


def test_alpha_is_blurred_like_color(rt, rng):
    """Premultiplied RGBA: every channel takes the same blur, so colour/alpha stays put."""
    src = np.zeros((20, 20, 4), np.float32)
    src[8:12, 8:12] = (0.5, 0.25, 0.125, 0.5)
    got, _ = run(rt, src, size=0.1)
    np.testing.assert_allclose(got[..., 0], got[..., 3], rtol=1e-5, atol=1e-7)


def test_bench_case_is_renderable(rt, rng):
    case = CASE.make(64, 36, rng)
    assert case["source"].shape == (36, 64, 4) and case["depth"] is None
    p = Defocus.params(**case["params"])
    got = render_effect(rt, Defocus(), p, case["source"], camera=case["camera"])
    assert np.isfinite(got).all() and got.min() >= 0


def test_soft_camera_preset_loads():
    from clfx.pipeline.presets import load_look

    look = load_look("soft-camera")
    assert [s.effect for s in look.steps] == ["defocus", "vignette"]
    assert look.description
