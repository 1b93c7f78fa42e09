import numpy as np
import pytest

from clfx.fx.resample import lut_lookup, radial_lut
from clfx.plugins.chromatic_aberration import ChromaticAberration as CA
from clfx.fx.spectral import cie1931_cmf as cie1931_xyz
from clfx.plugins.chromatic_aberration import radial_model, spectral_bins
from tests.conftest import hard_shapes
from tests.plugins.test_distortion import (nonfinite_image, render_with_notes, smooth_image,
                                           wide_range_image)
from tests.reference.chromatic_aberration import chromatic_aberration as reference
from tests.effects import render_effect

PARAMS = dict(amount=0.01, cubic=0.4, center=(0.1, -0.2))


def run(rt, src, quality="final", **kw):
    p = CA.params(**{**PARAMS, **kw})
    return render_effect(rt, CA(), p, src, quality=quality), p


def want(src, p, quality, **kw):
    lvl = CA.descriptor.quality[quality]
    return reference(src, **p.as_dict(), n=lvl.wavelengths if p.spectral else 3,
                     filter_name=lvl.filter, **kw)


@pytest.mark.parametrize("shape", hard_shapes())
def test_matches_reference_hard_shapes(rt, rng, shape):
    src = rng.uniform(0.0, 2.0, shape + (4,)).astype(np.float32)
    got, p = run(rt, src, "final")
    # float32 LUT (~1e-7 relative scale) + 16 bicubic reads: values <= 2 to a few 1e-6
    np.testing.assert_allclose(got, want(src, p, "final"), rtol=0, atol=2e-5)


@pytest.mark.parametrize("quality", ["draft", "preview", "final", "reference"])
def test_each_quality_matches_its_oracle(rt, rng, quality):
    src = rng.uniform(0.0, 1.0, (19, 33, 4)).astype(np.float32)
    got, p = run(rt, src, quality, border="mirror")
    # reference: float64 throughout, float32 output (ulp 6e-8 at 1); others float32
    tol = 2e-7 if quality == "reference" else 1e-5
    np.testing.assert_allclose(got, want(src, p, quality), rtol=0, atol=tol)


def test_error_falls_monotonically_with_quality(rt, rng):
    src = smooth_image(rng, 36, 60)
    p = CA.params(**PARAMS)
    ref = want(src, p, "reference")
    errs = [np.abs(render_effect(rt, CA(), p, src, quality=q) - ref).max()
            for q in ("draft", "preview", "final", "reference")]
    assert all(a >= b for a, b in zip(errs, errs[1:])), errs
    assert errs[-1] < 2e-7


def test_white_stays_white(rt):
    src = np.ones((24, 40, 4), np.float32)
    for q in ("draft", "preview", "final", "reference"):
        got, _ = run(rt, src, q, amount=0.05, cubic=1.0)
        assert np.abs(got - 1.0).max() < 1e-4    # brief: white stays white within 1e-4


def test_spectral_white_point_makes_a_rainbow(rt):
    src = np.zeros((9, 61, 4), np.float32)
    src[4, 55, :3] = 1000.0
    src[..., 3] = 1.0
    got, _ = run(rt, src, "reference", amount=0.03, cubic=0.0, center=(0.0, 0.0))
    row = got[4, :, :3]
    lit = row.sum(1) > 1e-3
    assert lit.sum() >= 3                       # spread over several pixels, not 3 copies
    hue_order = np.argmax(row[lit], axis=1)     # blue outside, red inside for amount > 0
    assert hue_order[0] == 0 and hue_order[-1] == 2
    # (no energy check: the anti-ringing clamp removes the negative lobes around a lone
    # 1e3 spike, which adds energy by design; the uniform-field tests cover normalisation)


def test_cmf_fit_is_plausible():
    xyz = cie1931_xyz(np.array([442.0, 555.0, 600.0]))
    assert xyz[1, 1] == pytest.approx(1.0, abs=0.02)             # y-bar peak ~1 at 555 nm
    _, w = spectral_bins(16, 0.0)
    np.testing.assert_allclose(w.sum(0), 1.0, rtol=1e-12)


def test_lut_matches_direct_inversion():
    fwd, _ = radial_model(0.05, 0.7)
    lut = radial_lut(fwd, 3.0, 1.3, 1024)
    r = np.linspace(1e-4, 1.3, 1001)
    lo, hi = np.zeros_like(r), np.full_like(r, 3.0)
    for _ in range(80):
        mid = (lo + hi) / 2
        lo, hi = np.where(fwd(mid) < r, mid, lo), np.where(fwd(mid) < r, hi, mid)
    np.testing.assert_allclose(lut_lookup(lut, (r / 1.3) ** 2), lo / r, rtol=2e-7)


def test_identity_and_hard_values(rt, rng):
    src = rng.uniform(0.0, 1.0, (8, 8, 4)).astype(np.float32)
    assert CA().is_identity(CA.params(amount=0.0), None) == "amount is 0"
    assert np.array_equal(render_effect(rt, CA(), CA.params(amount=0.0), src), src)
    src[4, 4] = np.nan
    src[1, 1] = np.inf
    src[6, 2, :3] = 1e5
    got, _ = run(rt, src, "final", amount=0.05)
    assert np.isfinite(got).all() and got.min() >= 0.0
    assert got.max() <= 1e5 * (1 + 1e-5)


def test_three_channel_switch_and_pixel_aspect(rt, rng):
    src = rng.uniform(0.0, 1.0, (20, 28, 4)).astype(np.float32)
    p = CA.params(**PARAMS, spectral=False)
    got = render_effect(rt, CA(), p, src, quality="preview", pixel_aspect=2.0)
    np.testing.assert_allclose(got, want(src, p, "preview", pixel_aspect=2.0), atol=1e-5)


@pytest.mark.parametrize("quality", ["draft", "preview", "final", "reference"])
@pytest.mark.parametrize("spectral", [True, False])
def test_nan_and_inf_become_zero_and_finite_input_stays_finite(rt, rng, quality, spectral):
    p = CA.params(**PARAMS, spectral=spectral)
    src = nonfinite_image(rng)
    got, notes = render_with_notes(rt, CA(), p, src, quality=quality)
    assert np.isfinite(got).all()
    assert "chromatic_aberration: 4 non-finite pixel(s) read as 0" in notes
    clean = np.nan_to_num(src, nan=0.0, posinf=0.0, neginf=0.0)
    np.testing.assert_array_equal(got, render_effect(rt, CA(), p, clean, quality=quality))
    assert np.isfinite(render_effect(rt, CA(), p, wide_range_image(rng), quality=quality)).all()


def test_packed_map_built_in_bands_is_the_whole_frame_map(rt, rng, monkeypatch):
    """Issue 10 item 10: frames larger than a band build their map band by band; the pixels
    are the same."""
    import clfx.fx.resample as resample

    src = rng.uniform(0.0, 2.0, (181, 323, 4)).astype(np.float32)
    p = CA.params(amount=0.01 + rng.uniform(0, 1e-6), spectral=False, border="black")
    whole = render_effect(rt, CA(), p, src, quality="final")
    rt.cache.clear("chromatic_aberration.packed")
    monkeypatch.setattr(resample, "BAND_PIXELS", 3000)
    banded = render_effect(rt, CA(), p, src, quality="final")
    assert np.array_equal(banded, whole)


@pytest.mark.parametrize("quality", ["preview", "final"])
@pytest.mark.parametrize("tile_pixels", [None, 300])
def test_blended_bins_are_both_bins_bit_for_bit(rt, rng, monkeypatch, quality, tile_pixels):
    """The bicubic three-bin levels render both bins in one pass (kernels/
    chromatic_aberration.cl, chromatic_aberration_packed_rb): the same bits as each bin
    whole, signed zeros included (black and transparent pixels, -0 from a subtraction
    upstream), NaN read as 0, odd sizes, whole or in bands."""
    src = rng.uniform(-0.5, 2.0, (37, 45, 4)).astype(np.float32)
    src[rng.random(src.shape) < 0.25] = 0.0
    src[rng.random(src.shape) < 0.25] = -0.0
    src[12:20, 5:30] = -0.0                          # a region of -0: every footprint all zeros
    src[rng.random(src.shape) < 0.01] = np.nan
    p = CA.params(**PARAMS, spectral=False)
    blended = render_effect(rt, CA(), p, src, quality=quality, tile_pixels=tile_pixels)
    monkeypatch.setattr(CA, "blended_bins", False)
    whole = render_effect(rt, CA(), p, src, quality=quality, tile_pixels=tile_pixels)
    assert np.array_equal(blended.view(np.uint32), whole.view(np.uint32))


def test_matches_reference_in_acescg(rt, rng):
    # the Rec.709 model on the pixels carried into Rec.709 and back
    from clfx.io.colour import rgb_to_xyz
    from tests.reference import in_reference_basis

    aces = rgb_to_xyz("ACEScg")
    src = smooth_image(rng, 24, 36)
    for spectral in (True, False):
        p = CA.params(**PARAMS, spectral=spectral)
        got = render_effect(rt, CA(), p, src, quality="final", working_space="ACEScg")
        # as test_matches_reference_hard_shapes: float32 LUT and 16 bicubic reads, values <= 2
        # (values <= 3.4 in Rec.709)
        np.testing.assert_allclose(
            got, in_reference_basis(lambda s: want(s, p, "final"), src, aces), atol=4e-5)
        # the ACEScg pixels taken as Rec.709 ones (no conversion) give other fringes
        assert np.abs(got - render_effect(rt, CA(), p, src, quality="final")).max() > 1e-4


@pytest.mark.parametrize("quality", ["draft", "preview", "reference"])
@pytest.mark.parametrize("params", [dict(amount=0.04), dict(amount=-0.04, cubic=1.0),
                                    dict(amount=0.03, spectral=False, border="black")])
def test_tight_window_gives_the_full_frame_pixels(rt, rng, quality, params):
    """An element in its own data window (right of and below the centre) gives the pixels it
    gives placed in a full-frame window: its fringes past the box are kept (the window
    grows), and ``edge`` repeats the frame's transparent edge, not the box's."""
    from clfx.core.rect import Rect
    from tests.plugins.windows import element, tight_and_full

    display, data = Rect(0, 0, 128, 96), Rect(70, 50, 120, 90)
    p = CA.params(**params)
    tight, full, window = tight_and_full(rt, CA(), p, element(rng, data), data, display,
                                         quality=quality)
    # the tables span the window's largest radius: interpolated to ~1e-7 of the radius
    # (~1e-5 px), values <= 4: measured <= 7e-6
    np.testing.assert_allclose(tight, full, rtol=0, atol=3e-5)
    assert window.contains(data) and window != data and display.contains(window)
