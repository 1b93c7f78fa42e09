"""clfx.fx.blur: the device Gaussian blur library against its float64 oracle."""
import math

import numpy as np
import pytest

import clfx.fx.blur as B
from clfx.core.rect import Rect
from tests.conftest import hard_shapes
from tests.reference.defocus import gaussian_blur as reference

LEVELS = ("draft", "preview", "final", "reference")

# Max |error| for inputs in [0, 1], from the measured impulse/step errors (clfx/fx/blur.py
# docstring) with a 2-3x margin; two axes add.  reference: float32 output rounding (6e-8 of
# the value) plus float32 intermediate between the passes.
TOL = {"draft": 6e-3, "preview": 1e-3, "final": 2e-4, "reference": 3e-7}


def blur(rt, src, sigma_x, sigma_y=None, window=None, **kw):
    img = rt.upload(src)
    out = None if window is None else rt.image(window, img.channels)
    return B.gaussian_blur(rt, img, sigma_x, sigma_y, out=out, **kw).download()


@pytest.mark.parametrize("quality", LEVELS)
@pytest.mark.parametrize("sigma,border", [(0.8, "clamp"), (2.0, "mirror"), (6.0, "zero"),
                                          (17.0, "clamp"), (45.0, "mirror")])
def test_blur_matches_oracle(rt, rng, quality, sigma, border):
    src = rng.uniform(0.0, 1.0, (45, 67, 4)).astype(np.float32)
    got = blur(rt, src, sigma, quality=quality, border=border)
    want = reference(src, sigma, border=border)
    np.testing.assert_allclose(got, want, rtol=0, atol=TOL[quality])


@pytest.mark.parametrize("channels", [1, 2])
@pytest.mark.parametrize("quality", ["final", "reference"])
def test_blur_other_channel_counts(rt, rng, channels, quality):
    shape = (23, 29) if channels == 1 else (23, 29, 2)
    src = rng.uniform(0.0, 1.0, shape).astype(np.float32)
    for sigma in (1.5, 9.0):
        got = blur(rt, src, sigma, quality=quality, border="mirror")
        want = reference(src, sigma, border="mirror")
        assert got.shape == shape
        np.testing.assert_allclose(got, want, rtol=0, atol=TOL[quality])


@pytest.mark.parametrize("shape", hard_shapes())
@pytest.mark.parametrize("sigma", [0.5, 3.0, 60.0])
def test_blur_hard_shapes(rt, rng, shape, sigma):
    src = rng.uniform(0.0, 1.0, shape + (4,)).astype(np.float32)
    for border in ("clamp", "mirror", "zero"):
        got = blur(rt, src, sigma, border=border)
        want = reference(src, sigma, border=border)
        assert got.shape == src.shape and np.isfinite(got).all()
        np.testing.assert_allclose(got, want, rtol=0, atol=TOL["final"])


@pytest.mark.parametrize("sigma", [3.0, 12.0, 40.0])
def test_error_falls_monotonically_across_levels(rt, sigma):
    n = int(10 * sigma) + 40
    src = np.zeros((n, n, 4), np.float32)
    src[n // 2, n // 3] = 1.0              # impulse
    src[:, 2 * n // 3:, 1] = 1.0           # step
    want = reference(src, sigma)
    errors = [np.abs(blur(rt, src, sigma, quality=q) - want).max() for q in LEVELS]
    assert all(a >= b for a, b in zip(errors, errors[1:])), errors
    assert errors[-1] <= 1e-7  # float64 accumulation: float32 rounding only


@pytest.mark.parametrize("quality,tol", [("reference", 1e-5), ("final", 2e-5),
                                         ("preview", 3e-4), ("draft", 4e-3)])
@pytest.mark.parametrize("sigma", [2.5, 30.0])
def test_interior_impulse_energy_is_conserved(rt, quality, tol, sigma):
    n = int(10 * sigma) + 16
    src = np.zeros((n, n, 1), np.float32)[..., 0]
    src[n // 2 + 1, n // 2 - 1] = 1e4
    got = blur(rt, src, sigma, quality=quality, border="zero")
    # measured: reference 6e-8, final <= 7e-6, preview <= 1.2e-4, draft <= 2e-3 per axis
    assert abs(got.astype(np.float64).sum() / 1e4 - 1) <= tol


@pytest.mark.parametrize("quality", LEVELS)
@pytest.mark.parametrize("border", ["clamp", "mirror"])
def test_flat_field_stays_flat_with_sigma_larger_than_image(rt, quality, border):
    src = np.full((5, 9, 4), 0.37, np.float32)
    for sigma in (4.0, 50.0, 300.0):
        got = blur(rt, src, sigma, quality=quality, border=border)
        # every gather's weights sum to 1; float32 rounding of ~1e2 terms
        np.testing.assert_allclose(got, 0.37, rtol=0, atol=1e-6)


def test_hdr_highlight_has_no_negatives_and_no_ringing(rt):
    src = np.full((96, 128, 4), 0.01, np.float32)
    src[40, 70] = 1e5
    for quality in LEVELS:
        for sigma in (1.0, 4.0, 25.0):
            got = blur(rt, src, sigma, quality=quality)
            # positive weights only: output stays within the input's range
            assert got.min() >= 0.01 * (1 - 1e-5)
            assert got.max() <= 1e5
            want = reference(src, sigma)
            np.testing.assert_allclose(got, want, rtol=0, atol=TOL[quality] * 1e5)


@pytest.mark.parametrize("border", ["zero", "clamp", "mirror"])
@pytest.mark.parametrize("sigma", [2.0, 20.0])
def test_output_window_larger_and_offset(rt, rng, border, sigma):
    src = rng.uniform(0.0, 1.0, (21, 30, 4)).astype(np.float32)
    grow = math.ceil(3 * sigma)
    data = Rect(10, 20, 40, 41)
    out_window = Rect(data.x0 - grow, data.y0 - grow + 3, data.x1 + grow, data.y1 + grow - 5)
    img = rt.upload(src, data)
    out = rt.image(out_window, 4)
    got = B.gaussian_blur(rt, img, sigma, border=border, out=out).download()
    want = reference(src, sigma, border=border, offset=(out_window.x0 - data.x0,
                                                        out_window.y0 - data.y0),
                     out_shape=out_window.shape)
    np.testing.assert_allclose(got, want, rtol=0, atol=TOL["final"])


def test_anamorphic_and_copied_axis(rt, rng):
    src = rng.uniform(0.0, 1.0, (40, 50, 4)).astype(np.float32)
    for sx, sy in [(1.0, 9.0), (25.0, 2.0), (0.1, 12.0), (7.0, 0.0)]:
        for quality in ("final", "reference"):
            got = blur(rt, src, sx, sy, quality=quality)
            want = reference(src, sx, sy)
            np.testing.assert_allclose(got, want, rtol=0, atol=TOL[quality])


def test_tiny_sigma_is_a_copy(rt, rng):
    src = rng.uniform(-1.0, 1.0, (7, 9, 4)).astype(np.float32)
    assert B.blur_plan(0.29).method == "copy"
    np.testing.assert_array_equal(blur(rt, src, 0.29), src)


def test_plan_is_cost_flat_and_reference_direct():
    assert B.blur_plan(2.0, "final").method == "direct"
    f50, f200 = B.blur_plan(50.0, "final"), B.blur_plan(200.0, "final")
    assert f50.method == f200.method == "pyramid"
    # coarse sigma stays in [s_min, 2 s_min]: cost per output pixel independent of sigma
    for p in (f50, f200):
        assert 2.0 <= math.sqrt(p.coarse_variance) <= 4.5
    assert B.blur_plan(200.0, "reference").method == "direct"


def test_deterministic_bytes(rt, rng):
    src = rng.uniform(0.0, 1.0, (33, 47, 4)).astype(np.float32)
    for sigma in (2.0, 15.0):
        a, b = blur(rt, src, sigma), blur(rt, src, sigma)
        assert a.tobytes() == b.tobytes()


def test_sanitize_nonfinite_counts_pixels(rt):
    src = np.ones((5, 6, 4), np.float32)
    src[1, 2, 0] = np.nan
    src[3, 4, :] = np.inf
    src[4, 5, 3] = -np.inf
    clean, n = B.sanitize_nonfinite(rt, rt.upload(src))
    assert n == 3
    got = clean.download()
    assert np.isfinite(got).all() and got[1, 2, 0] == 0 and got[1, 2, 1] == 1
    assert (got[3, 4] == 0).all()


def test_nonfinite_stays_in_the_kernel_footprint(rt):
    """A NaN reaches exactly the pixels within the kernel's radius, and an Inf gives Inf,
    never NaN: no tap past the real kernel is read, not even with weight 0 (0 * Inf is NaN;
    the tap-count ladder skips the rung's spare taps)."""
    n, at = 400, 200
    for sigma, quality in ((2.3, "final"), (2.0, "draft"), (3.0, "reference"), (12.0, "reference")):
        radius = B.blur_plan(sigma, quality).radius
        src = np.zeros((1, n), np.float32)
        src[0, at] = np.nan
        got = blur(rt, src, sigma, 0.0, quality=quality)[0]
        x = np.arange(n)
        assert (np.isnan(got) == (abs(x - at) <= radius)).all(), (sigma, quality, radius)
    for sigma in (9.0, 30.0):   # pyramids: decimation, coarse blur and B-spline gathers
        src = np.zeros((1, n), np.float32)
        src[0, at] = np.inf
        got = blur(rt, src, sigma, 0.0)[0]
        assert not np.isnan(got).any() and np.isposinf(got[at]), sigma


def test_few_programs_cover_every_sigma(rt, monkeypatch):
    """Tap counts share a ladder of programs (B.TAP_RUNGS): a cold kernel cache compiles a
    handful for blurs of every size, not one per tap count (an animated size rebuilt)."""
    programs, taps = set(), set()
    kernel = rt.kernel

    def spy(file, name, fp64=False, **defines):
        if file == B.KERNEL_FILE:
            programs.add((fp64, tuple(sorted(defines.items()))))
        return kernel(file, name, fp64=fp64, **defines)

    monkeypatch.setattr(rt, "kernel", spy)
    img = rt.upload(np.ones((9, 70, 4), np.float32))
    for sigma in np.linspace(0.3, 30.0, 45):
        B.gaussian_blur(rt, img, float(sigma), quality="final")
        taps.add(2 * B.blur_plan(float(sigma), "final").radius + 1)
    assert len(taps) > 2 * len(programs)
    for fp64 in (False, True):   # gathers of over LONG_SUM_TAPS taps sum in float64
        rungs = [p for p in programs if p[0] == fp64]
        assert len(rungs) <= len(B.TAP_RUNGS) + 1, sorted(programs)


def test_pyramid_helpers(rt, rng):
    src = np.full((37, 50, 4), 2.5, np.float32)
    coarse = B.downsample2x(rt, rt.upload(src))
    assert coarse.shape == (19, 25, 4)
    np.testing.assert_allclose(coarse.download(), 2.5, atol=1e-6)
    fine = B.upsample2x(rt, coarse, rt.image(Rect.from_size(50, 37), 4)).download()
    np.testing.assert_allclose(fine, 2.5, atol=1e-6)
    # energy of an interior impulse survives a down/up round trip (factor 4)
    imp = np.zeros((64, 64), np.float32)
    imp[30, 33] = 1.0
    c4 = B.downsample(rt, rt.upload(imp), 4)
    assert abs(c4.download().sum() * 16 - 1) < 1e-5
    back = B.upsample(rt, c4, 4, rt.image(Rect.from_size(64, 64), 1)).download()
    assert abs(back.sum() - 1) < 1e-5 and back.min() >= 0


def test_bad_arguments_raise(rt):
    img = rt.upload(np.zeros((4, 4, 4), np.float32))
    with pytest.raises(ValueError, match="border"):
        B.gaussian_blur(rt, img, 2.0, border="wrap")
    with pytest.raises(ValueError, match="quality"):
        B.gaussian_blur(rt, img, 2.0, quality="best")
    with pytest.raises(ValueError, match="sigma"):
        B.gaussian_blur(rt, img, float("nan"))
    with pytest.raises(ValueError, match="channels"):
        B.gaussian_blur(rt, img, 2.0, out=rt.image(img.window, 1))


def test_levels_are_data_defocus_declares():
    """The blur's quality levels are Level data, and defocus declares exactly them."""
    from clfx.core.plugin import Level
    from clfx.plugins.defocus import Defocus

    assert all(isinstance(lvl, B.BlurLevel) and isinstance(lvl, Level) for lvl in B.LEVELS.values())
    assert dict(Defocus.descriptor.quality) == B.LEVELS
    assert B.LEVELS["reference"].fp64 and not B.LEVELS["final"].fp64
    assert B.blur_plan(50.0, B.LEVELS["final"]) == B.blur_plan(50.0, "final")


def test_tables_live_in_the_runtime_cache(rt, rng):
    src = rng.uniform(0.0, 1.0, (20, 30, 4)).astype(np.float32)
    blur(rt, src, 9.0, 2.0, quality="final")
    assert rt.cache.stats()["owners"].get("blur", 0) > 0
    assert not [n for n in vars(B) if n.startswith("_CACHE")]
