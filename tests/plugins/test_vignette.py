import numpy as np
import pytest

from clfx.core.camera import Camera
from clfx.plugins.vignette import Vignette
from clfx.core.rect import Rect
from tests.conftest import hard_shapes
from tests.plugins.test_distortion import nonfinite_image, render_with_notes, wide_range_image
from tests.reference.vignette import vignette as reference
from tests.effects import render_effect

PARAMS = dict(natural=1.0, amount=0.4, radius=0.3, softness=0.5, roundness=0.5, center=(0.1, -0.2))


def run(rt, src, quality="final", camera=None, **kw):
    p = Vignette.params(**{**PARAMS, **kw})
    return render_effect(rt, Vignette(), p, src, quality=quality, camera=camera), p


@pytest.mark.parametrize("shape", hard_shapes())
def test_vignette_matches_reference(rt, rng, shape):
    src = rng.uniform(0.0, 8.0, shape + (4,)).astype(np.float32)
    got, p = run(rt, src)
    want = reference(src, **p.as_dict())
    # float32 evaluation of a smooth factor in [0, 1]: a few ulps of the factor
    np.testing.assert_allclose(got, want, rtol=2e-6, atol=1e-6)


def test_reference_quality_is_closer_than_final(rt, rng):
    src = rng.uniform(0.0, 1.0, (33, 65, 4)).astype(np.float32)
    want = reference(src, **Vignette.params(**PARAMS).as_dict())
    final, _ = run(rt, src, "final")
    ref, _ = run(rt, src, "reference")
    assert np.abs(ref - want).max() <= np.abs(final - want).max() + 1e-9
    np.testing.assert_allclose(ref, want, rtol=1e-7, atol=1e-7)


def test_vignette_pixel_aspect_and_camera(rt, rng):
    src = rng.uniform(0.0, 1.0, (20, 30, 4)).astype(np.float32)
    cam = Camera(focal_length=12.0, sensor_width=24.0)
    p = Vignette.params(**PARAMS)
    got = render_effect(rt, Vignette(), p, src, camera=cam, pixel_aspect=2.0)
    want = reference(src, **p.as_dict(), focal_length=12.0, sensor_width=24.0, pixel_aspect=2.0)
    np.testing.assert_allclose(got, want, rtol=2e-6, atol=1e-6)


def test_vignette_data_window_inside_display_window(rt, rng):
    src = rng.uniform(0.0, 1.0, (10, 12, 4)).astype(np.float32)
    data, display = Rect(30, 20, 42, 30), Rect(0, 0, 100, 50)
    p = Vignette.params(**PARAMS)
    got = render_effect(rt, Vignette(), p, src, data_window=data, display_window=display)
    want = reference(src, **p.as_dict(), data_origin=(30, 20), display_size=(100, 50))
    np.testing.assert_allclose(got, want, rtol=2e-6, atol=1e-6)


def test_vignette_hard_values_stay_finite_where_input_is(rt):
    vals = np.array([-1.0, 0.0, 1e-30, 65504.0, 1e5, np.nan, np.inf], np.float32)
    src = np.repeat(vals[None, :, None], 4, axis=2)
    got, _ = run(rt, src, amount=1.0)
    assert np.isfinite(got).all()
    assert (got[0, 1:5, :3] >= 0).all()
    np.testing.assert_array_equal(got[0, :5, 3], src[0, :5, 3])  # alpha kept bit for bit
    np.testing.assert_array_equal(got[0, 5:], 0.0)                # NaN / Inf became 0


@pytest.mark.parametrize("quality", ["draft", "preview", "final", "reference"])
def test_nan_and_inf_become_zero_and_are_noted(rt, rng, quality):
    src = nonfinite_image(rng)
    p = Vignette.params(**PARAMS)
    got, notes = render_with_notes(rt, Vignette(), p, src, quality=quality)
    assert np.isfinite(got).all()
    assert "vignette: 4 non-finite pixel(s) set to 0" in notes
    clean = np.nan_to_num(src, nan=0.0, posinf=0.0, neginf=0.0)
    np.testing.assert_array_equal(got, render_effect(rt, Vignette(), p, clean, quality=quality))
    _, clean_notes = render_with_notes(rt, Vignette(), p, clean, quality=quality)
    assert clean_notes == []


@pytest.mark.parametrize("quality", ["draft", "preview", "final", "reference"])
def test_finite_input_across_float_range_stays_finite(rt, rng, quality):
    got, _ = run(rt, wide_range_image(rng), quality, amount=-1.0)   # brightening: factor 1
    assert np.isfinite(got).all()


def test_vignette_factor_far_outside_frame_is_in_unit_range(rt):
    src = np.ones((4, 4, 4), np.float32)
    got = render_effect(rt, Vignette(), Vignette.params(amount=-1.0), src,
                        data_window=Rect(100000, 100000, 100004, 100004),
                        display_window=Rect(0, 0, 16, 9))
    assert np.isfinite(got).all() and (got >= 0).all() and (got <= 1).all()
