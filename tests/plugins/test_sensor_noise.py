"""Sensor noise: oracle agreement, the photon-transfer variance model at low and high counts
(per site: ``run`` defaults to mosaic "none"), mean preservation, frame independence vs the
fixed PRNU pattern, determinism, hard values; the Bayer demosaic's cross-channel correlation
and spectrum against the exact linear model; the chroma blotches."""
import math

import numpy as np
import pytest

from clfx.bench.cases.sensor_noise import CASE
from clfx.core.camera import Camera
from clfx.host import RenderContext
from clfx.plugins.sensor_noise import (SensorNoise, electrons_per_unit,
                                       noise_variance)
from clfx.core.rect import Rect
from tests.conftest import hard_shapes
from tests.plugins.test_distortion import wide_range_image
from tests.reference.sensor_noise import demosaic_unit
from tests.reference.sensor_noise import sensor_noise as reference
from tests.effects import render_effect

LEVELS = ("draft", "preview", "final", "reference")
SWITCH = {"draft": None, "preview": 10.0, "final": 30.0, "reference": 30.0}
CAMERA = Camera(iso=3200.0)   # gain 32: 312.5 electrons per unit of linear value (green)


def run(rt, src, quality="final", frame=0, look_seed=0, data_window=None, camera=CAMERA,
        display=None, **kw):
    kw.setdefault("mosaic", "none")   # the photon-transfer model per site; demosaic below
    kw.setdefault("middle_grey", 0.18)  # the model's own scale (auto meters: tests below)
    p = SensorNoise.params(**kw)
    out = render_effect(rt, SensorNoise(), p, src, quality=quality, frame=frame, seed=look_seed,
                        data_window=data_window, camera=camera, display_window=display)
    return out, p


def flat(h, w, value):
    src = np.full((h, w, 4), value, np.float32)
    src[..., 3] = 1.0
    return src


def count_flips(got, want, g):
    """Samples whose Poisson count differs (rounding at a CDF step): |diff| ~ one electron."""
    diff = np.abs(got - want)
    flips = diff > 1e-3 * g
    assert (diff[flips] <= 1.01 * g).all()  # never more than one electron apart
    return int(flips.sum())


# -- oracle ----------------------------------------------------------------------------------
@pytest.mark.parametrize("shape", hard_shapes())
def test_sensor_noise_matches_reference(rt, rng, shape):
    src = rng.uniform(-0.01, 0.2, shape + (4,)).astype(np.float32)
    kw = dict(prnu=0.01, channel_sensitivity=(0.5, 1.0, 0.4), seed=2)
    got, p = run(rt, src, frame=5, look_seed=9, **kw)
    want = reference(src, **p.as_dict(), frame=5, look_seed=9, camera_iso=3200.0)
    g = 1 / min(electrons_per_unit(p, CAMERA))
    # float32 Box-Muller (polynomial log/sincos, rel. ~2e-7) and the summed Poisson CDF
    # (rel. ~1e-6) can move a sample across a CDF step: one electron (g) in rare samples.
    assert count_flips(got[..., :3], want[..., :3], g) <= max(2, got[..., :3].size // 1000)
    close = np.abs(got - want)[..., :3] <= 1e-3 * g
    np.testing.assert_allclose(got[..., :3][close], want[..., :3][close], rtol=1e-5, atol=2e-5 * g)
    np.testing.assert_array_equal(got[..., 3], src[..., 3])


def test_reference_level_matches_oracle_exactly_up_to_rounding(rt, rng):
    src = rng.uniform(0.0, 0.15, (40, 50, 4)).astype(np.float32)
    got, p = run(rt, src, "reference", frame=1, prnu=0.02)
    want = reference(src, **p.as_dict(), frame=1, camera_iso=3200.0)
    g = 1 / electrons_per_unit(p, CAMERA)[1]
    # float64 throughout: only the final float32 store (values <= 0.3) remains
    np.testing.assert_allclose(got, want, rtol=1e-7, atol=1e-4 * g)


def test_error_falls_monotonically_with_quality(rt, rng):
    # expected counts 0-60 electrons: both the inversion and the normal branch run
    src = rng.uniform(0.0, 0.2, (48, 64, 4)).astype(np.float32)
    src[..., 3] = 1.0           # opaque: the levels differ in the model, not in the coverage
    kw = dict(read_noise=2.0, seed=6, middle_grey=0.18)
    p = SensorNoise.params(**kw)
    want = reference(src, **p.as_dict(), frame=3, camera_iso=3200.0)
    errors = [np.abs(run(rt, src, q, frame=3, **kw)[0] - want)[..., :3].mean() for q in LEVELS]
    assert all(a >= b for a, b in zip(errors, errors[1:])), errors


# -- statistics -------------------------------------------------------------------------------
# expected electrons per pixel: Poisson inversion below 30, normal approximation above
ELECTRONS = (0.5, 3.0, 12.0, 29.0, 31.0, 100.0, 5e3)   # the well holds 1e4


@pytest.mark.parametrize("read_noise", [0.0, 3.0])
def test_variance_and_mean_follow_the_model(rt, read_noise):
    h, w = 96, 128
    k = electrons_per_unit(SensorNoise.params(), CAMERA)[1]
    values = [e / k for e in ELECTRONS]
    src = np.concatenate([flat(h, w, v) for v in values], axis=0)
    out, p = run(rt, src, read_noise=read_noise, seed=1)
    n = h * w * 3  # channels share the model (sensitivity 1)
    for i, (e, v) in enumerate(zip(ELECTRONS, values)):
        x = (out[i * h:(i + 1) * h, :, :3].astype(np.float64) - v) * k   # electrons
        var = e + read_noise ** 2                  # Poisson variance + read noise, electrons
        np.testing.assert_allclose(noise_variance(v, p, CAMERA) * k * k, var, rtol=1e-9)
        # mean preserved: within 3 sigma / sqrt(N)
        assert abs(x.mean()) <= 3 * math.sqrt(var / n), (e, x.mean())
        # variance: standard error sqrt((kappa4 + 2 var^2) / N); Poisson's kappa4 = lambda
        se = math.sqrt((e + 2 * var * var) / n)
        assert abs(x.var() - var) <= 4 * se, (e, x.var(), var)


def test_low_counts_are_integer_electrons_with_poisson_probabilities(rt):
    k = electrons_per_unit(SensorNoise.params(), CAMERA)[1]
    lam = 1.5
    out, _ = run(rt, flat(128, 128, lam / k), read_noise=0.0, seed=4)
    counts = out[..., :3].astype(np.float64) * k
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-3)  # whole electrons
    counts = np.round(counts).astype(int).ravel()
    n = counts.size
    for j in range(5):
        pmf = math.exp(-lam) * lam ** j / math.factorial(j)
        se = math.sqrt(pmf * (1 - pmf) / n)
        assert abs(np.mean(counts == j) - pmf) <= 4 * se, j


@pytest.mark.parametrize("quality, lam", [("final", 25.0), ("preview", 9.5)])
def test_counts_over_many_inversion_steps_have_poisson_probabilities(rt, quality, lam):
    # the inversion sums the CDF four terms per step: counts up to ~50 cross many steps
    k = electrons_per_unit(SensorNoise.params(), CAMERA)[1]
    out, _ = run(rt, flat(128, 128, lam / k), quality, read_noise=0.0, seed=8)
    counts = out[..., :3].astype(np.float64) * k
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-3)  # whole electrons
    counts = np.round(counts).astype(int).ravel()
    n = counts.size
    for j in range(int(lam - 2 * math.sqrt(lam)), int(lam + 3 * math.sqrt(lam)) + 1):
        pmf = math.exp(-lam + j * math.log(lam) - math.lgamma(j + 1))
        se = math.sqrt(pmf * (1 - pmf) / n)
        assert abs(np.mean(counts == j) - pmf) <= 4.5 * se, j  # 4.5 sigma over ~20 bins


def test_draft_uses_the_normal_approximation_with_the_same_variance(rt):
    k = electrons_per_unit(SensorNoise.params(), CAMERA)[1]
    out, _ = run(rt, flat(128, 128, 5.0 / k), "draft", read_noise=0.0)
    x = out[..., :3].astype(np.float64) * k - 5.0
    assert not np.allclose(x, np.round(x), atol=1e-3)  # continuous, not whole electrons
    assert abs(x.var() - 5.0) <= 4 * math.sqrt(2 * 25 / x.size)


def test_channel_sensitivity_and_iso_scale_the_noise(rt):
    src = flat(128, 128, 0.5)
    out, p = run(rt, src, read_noise=0.0, channel_sensitivity=(0.25, 1.0, 4.0))
    var = (out[..., :3] - 0.5).astype(np.float64).var(axis=(0, 1))
    want = [noise_variance(0.5, p, CAMERA, c) for c in range(3)]
    np.testing.assert_allclose(var, want, rtol=0.05)  # ~3.5 standard errors (2/sqrt(16k) * 2)
    np.testing.assert_allclose(want[0] / want[1], 4.0)
    # iso param overrides the camera block; twice the ISO, twice the shot-noise variance
    hi, _ = run(rt, src, read_noise=0.0, iso=6400.0)
    lo, _ = run(rt, src, read_noise=0.0, iso=3200.0, camera=Camera(iso=100.0))
    ratio = (hi[..., :3] - 0.5).var() / (lo[..., :3] - 0.5).var()
    assert abs(ratio - 2.0) <= 0.1


@pytest.mark.parametrize("middle_grey", [0.0, 0.02])
def test_exposure_reference_matches_the_oracle(rt, rng, middle_grey):
    """``middle_grey`` stated (0.02: a night plate) or metered (0): the electrons scale by
    0.18 / the plate's grey, in the kernel as in the float64 oracle (which meters itself)."""
    src = rng.uniform(0.0, 0.03, (40, 70, 4)).astype(np.float32)
    src[..., 3] = 1.0
    got, p = run(rt, src, "reference", frame=2, prnu=0.01, middle_grey=middle_grey,
                 mosaic="bayer", chroma_noise=0.5)
    want = reference(src, **p.as_dict(), frame=2, camera_iso=3200.0)
    g = 1 / electrons_per_unit(p, CAMERA, middle_grey or 0.015)[1]
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-4 * g)


def test_metered_noise_is_the_same_look_at_any_exposure(rt, rng):
    """Metered (``middle_grey`` 0), a plate 64x darker gives the same frame 64x darker, noise
    included; stated at 0.18 (the default) the darker plate is far noisier, as the sensor
    model says of a plate taken as it is."""
    src = rng.uniform(0.05, 0.4, (64, 64, 4)).astype(np.float32)
    src[..., 3] = 1.0
    dark = src.copy()
    dark[..., :3] /= 64.0
    bright, _ = run(rt, src, middle_grey=0.0, mosaic="bayer", read_noise=3.0)
    dim, _ = run(rt, dark, middle_grey=0.0, mosaic="bayer", read_noise=3.0)
    dev_bright = bright[..., :3] - src[..., :3]
    dev_dim = (dim[..., :3] - dark[..., :3]) * 64.0
    assert dev_bright.std() > 1e-3
    np.testing.assert_allclose(dev_dim, dev_bright, rtol=1e-3, atol=1e-4 * dev_bright.std())
    plain, _ = run(rt, dark, mosaic="bayer", read_noise=3.0)
    assert ((plain[..., :3] - dark[..., :3]) * 64.0).std() > 4.0 * dev_bright.std()


def test_frames_are_uncorrelated_but_prnu_is_fixed(rt):
    src = flat(128, 128, 0.3)
    a, _ = run(rt, src, frame=1)
    b, _ = run(rt, src, frame=2)
    r = np.corrcoef((a - 0.3)[..., :3].ravel(), (b - 0.3)[..., :3].ravel())[0, 1]
    assert abs(r) <= 4 / math.sqrt(a[..., :3].size)
    # the pattern alone is identical on every frame, and has the requested RMS
    fa, _ = run(rt, src, frame=1, shot_noise=False, read_noise=0.0, prnu=0.02)
    fb, _ = run(rt, src, frame=99, shot_noise=False, read_noise=0.0, prnu=0.02)
    assert fa.tobytes() == fb.tobytes()
    rel = (fa[..., :3] / 0.3 - 1).astype(np.float64)
    assert abs(rel.std() / 0.02 - 1) <= 4 * math.sqrt(2 / rel.size) / 2
    # with shot noise on top, frames share exactly the pattern's part of the variance
    sa, _ = run(rt, src, frame=1, read_noise=0.0, prnu=0.02)
    sb, _ = run(rt, src, frame=2, read_noise=0.0, prnu=0.02)
    k = electrons_per_unit(SensorNoise.params(), CAMERA)[1]
    pattern, shot = (0.02 * 0.3) ** 2, 0.3 / k
    r = np.corrcoef((sa - 0.3)[..., :3].ravel(), (sb - 0.3)[..., :3].ravel())[0, 1]
    assert abs(r - pattern / (pattern + shot)) <= 0.05


# -- determinism ------------------------------------------------------------------------------
@pytest.mark.parametrize("quality", LEVELS)
def test_same_frame_gives_identical_bytes_and_crops_agree(rt, rng, quality):
    src = rng.uniform(0.0, 0.1, (40, 60, 4)).astype(np.float32)
    kw = dict(prnu=0.01, seed=3)
    a, _ = run(rt, src, quality, frame=8, data_window=Rect(-20, 10, 40, 50), **kw)
    b, _ = run(rt, src, quality, frame=8, data_window=Rect(-20, 10, 40, 50), **kw)
    assert a.tobytes() == b.tobytes()
    crop, _ = run(rt, src[5:30, 9:50], quality, frame=8, data_window=Rect(-11, 15, 30, 40), **kw)
    assert crop.tobytes() == np.ascontiguousarray(a[5:30, 9:50]).tobytes()
    c, _ = run(rt, src, quality, frame=9, data_window=Rect(-20, 10, 40, 50), **kw)
    assert not np.array_equal(a, c)


def test_cached_prnu_pattern_follows_params_and_window(rt, rng):
    """One instance across a 'sequence' whose params and data window change: every render
    equals a fresh instance's (the cached pattern is rebuilt when its key changes)."""
    src = rng.uniform(0.0, 0.1, (24, 36, 4)).astype(np.float32)
    plugin = SensorNoise()
    cases = [(dict(prnu=0.01, seed=1), None, "final"), (dict(prnu=0.01, seed=1), None, "final"),
             (dict(prnu=0.03, seed=1), None, "final"), (dict(prnu=0.03, seed=2), None, "draft"),
             (dict(prnu=0.03, seed=2), Rect(5, -3, 41, 21), "draft"),
             (dict(prnu=0.03, seed=2), Rect(5, -3, 41, 21), "reference"),
             (dict(prnu=0.0, seed=2), None, "final")]
    for i, (kw, window, quality) in enumerate(cases):
        p = SensorNoise.params(**kw)
        got = render_effect(rt, plugin, p, src, quality=quality, frame=i, data_window=window,
                            camera=CAMERA)
        want = render_effect(rt, SensorNoise(), p, src, quality=quality, frame=i,
                             data_window=window, camera=CAMERA)
        assert got.tobytes() == want.tobytes(), (i, kw, window, quality)
    # unchanged params and window: the pattern is reused, not rebuilt
    p = SensorNoise.params(prnu=0.02)
    ctx = RenderContext(rt, rt.upload(src), camera=CAMERA)
    assert plugin.prnu_pattern(rt, p, ctx, False) is plugin.prnu_pattern(rt, p, ctx, False)


# -- hard cases -------------------------------------------------------------------------------
@pytest.mark.parametrize("quality", LEVELS)
@pytest.mark.parametrize("mosaic", ("none", "bayer"))
def test_hard_values_stay_finite_and_alpha_is_kept(rt, quality, mosaic):
    vals = np.array([-1.0, 0.0, 1e-30, 65504.0, 1e5, 3.4e38, np.nan, np.inf, -np.inf],
                    np.float32)
    src = np.repeat(np.repeat(vals[None, :, None], 4, axis=2), 3, axis=0)
    out, _ = run(rt, src, quality, prnu=0.1, read_noise=100.0, full_well=1.0,
                 channel_sensitivity=(0.01, 1.0, 100.0), iso=1e6, mosaic=mosaic,
                 chroma_noise=3.0)
    assert np.isfinite(out).all()
    # alpha bit for bit where finite; NaN / Inf (colour or alpha) become 0 first
    assert out[:, :6, 3].tobytes() == src[:, :6, 3].tobytes()
    np.testing.assert_array_equal(out[:, 6:, 3], 0.0)
    out, _ = run(rt, wide_range_image(np.random.default_rng(1)), quality, prnu=0.1,
                 read_noise=100.0, full_well=1.0, iso=1e6, mosaic=mosaic, chroma_noise=3.0)
    assert np.isfinite(out).all()


def test_negative_values_keep_their_mean(rt):
    out, p = run(rt, flat(64, 64, -0.05), read_noise=2.0)
    g = 1 / electrons_per_unit(p, CAMERA)[1]
    x = out[..., :3].astype(np.float64)
    # no shot noise below 0; read noise only, zero mean: within 3 sigma / sqrt(N)
    assert abs(x.mean() + 0.05) <= 3 * 2.0 * g / math.sqrt(x.size)
    assert abs(x.std() / (2.0 * g) - 1) <= 0.05


def test_descriptor_and_bench_case(rt, rng):
    d = SensorNoise.descriptor
    assert d.frame_varying and set(d.quality) == set(LEVELS)
    case = CASE.make(64, 36, rng)
    out = render_effect(rt, SensorNoise(), SensorNoise.params(**case["params"]), case["source"],
                        camera=case["camera"])
    assert out.shape == (36, 64, 4) and np.isfinite(out).all()




# -- Bayer mosaic and demosaic, chroma blotches -----------------------------------------------
@pytest.mark.parametrize("shape", hard_shapes())
@pytest.mark.parametrize("extra", (dict(mosaic="bayer"),
                                   dict(mosaic="bayer", chroma_noise=2.0, chroma_size=0.1),
                                   dict(mosaic="none", chroma_noise=1.0)))
def test_camera_pipeline_matches_reference(rt, rng, shape, extra):
    src = rng.uniform(-0.01, 0.2, shape + (4,)).astype(np.float32)
    kw = dict(prnu=0.01, channel_sensitivity=(0.5, 1.0, 0.4), seed=2, **extra)
    window = Rect(3, 6, 3 + shape[1], 6 + shape[0])   # odd origin: the CFA phase moves
    got, p = run(rt, src, frame=5, look_seed=9, data_window=window, **kw)
    want = reference(src, **p.as_dict(), frame=5, look_seed=9, camera_iso=3200.0,
                               data_origin=(3, 6))
    g = 1 / min(electrons_per_unit(p, CAMERA))
    # as the per-site oracle test; a flipped count reaches the 5 x 5 neighbours with weights
    # <= 1 (still <= one electron) and the blotches add float32 log/cos (rel. ~1e-6)
    assert count_flips(got[..., :3], want[..., :3], g) <= max(2, 25 * got[..., :3].size // 1000)
    close = np.abs(got - want)[..., :3] <= 1e-3 * g
    np.testing.assert_allclose(got[..., :3][close], want[..., :3][close], rtol=1e-5,
                               atol=5e-5 * g)
    np.testing.assert_array_equal(got[..., 3], src[..., 3])


def demosaic_covariance(var_site, lag):
    """Exact covariance (3 x 3 channels) of the demosaiced deviation between pixels lag
    (dx, dy) apart, averaged over the four CFA phases: the demosaic is linear, so it is the
    reference demosaic applied to unit impulses at every site of a period, weighted by the
    site colour's variance (the model's demosaic scales each pixel's colours by their own
    deviation, constant on a flat field)."""
    n = 16
    cov = np.zeros((3, 3))
    imp = np.zeros((n, n, 3))
    resp = {}
    y, x = np.mgrid[0:n, 0:n]
    from tests.reference.sensor_noise import cfa
    colours = cfa(x, y)
    for j in range(4, 12):
        for i in range(4, 12):
            imp[:] = 0
            imp[j, i, colours[j, i]] = 1.0
            sd = np.broadcast_to(np.sqrt(var_site), imp.shape)
            resp[(j, i)] = demosaic_unit(imp * sd, sd)
    dx, dy = lag
    for py in (7, 8):
        for px in (7, 8):
            for r in resp.values():
                cov += np.outer(r[py, px], r[py + dy, px + dx])
    return cov / 4


def test_demosaic_correlates_channels_and_neighbours_as_the_linear_model(rt):
    """Flat grey at 0.05, ISO 3200: the measured covariance of the output noise between
    channels (same pixel) and at lags 1 and 2 (spectrum) matches the exact model."""
    h = w = 256
    out, p = run(rt, flat(h, w, 0.05), mosaic="bayer", read_noise=3.0, seed=4)
    d = out[..., :3].astype(np.float64) - 0.05
    var_site = [noise_variance(0.05, p, CAMERA, c) for c in range(3)]
    n = h * w
    for lag in ((0, 0), (1, 0), (0, 1), (2, 0), (1, 1)):
        dx, dy = lag
        a, b = d[:h - dy, :w - dx], d[dy:, dx:]
        got = np.einsum("yxi,yxj->ij", a, b) / a.shape[0] / a.shape[1]
        want = demosaic_covariance(var_site, lag)
        # the estimate's standard error: ~ var / sqrt(N / 25) (neighbourhoods of 25 sites
        # share samples); 5 of them
        tol = 5 * max(var_site) / math.sqrt(n / 25)
        np.testing.assert_allclose(got, want, atol=tol, err_msg=str(lag))
    corr = np.corrcoef(d.reshape(-1, 3).T)
    # correlated colour noise (independent per-pixel noise would give 0 +- 0.01)
    assert corr[0, 1] > 0.3 and corr[1, 2] > 0.3 and corr[0, 2] > 0.3
    lag1 = np.mean(d[:, :-1, 1] * d[:, 1:, 1]) / d[..., 1].var()
    assert lag1 > 0.2


def test_demosaic_keeps_the_mean_and_the_site_colour_follows_the_model(rt):
    out, p = run(rt, flat(128, 128, 0.1), mosaic="bayer", read_noise=3.0, seed=6)
    d = out[..., :3].astype(np.float64) - 0.1
    # the demosaic's weights sum to 1 per channel: mean kept within 4 standard errors
    assert np.all(np.abs(d.mean(axis=(0, 1))) <= 4 * math.sqrt(noise_variance(0.1, p, CAMERA))
                  * 2 / 128)
    # at a site its own colour is the photon-transfer model's (R sites: even, even)
    r_sites = d[0::2, 0::2, 0]
    var = noise_variance(0.1, p, CAMERA, 0)
    assert abs(r_sites.var() / var - 1) <= 4 * math.sqrt(2 / r_sites.size)


def test_bayer_crops_agree_away_from_the_edge(rt, rng):
    src = rng.uniform(0.0, 0.1, (40, 60, 4)).astype(np.float32)
    # one display window (the blotches' cell is a fraction of its diagonal)
    kw = dict(mosaic="bayer", chroma_noise=1.0, seed=3, display=Rect(0, 0, 64, 64))
    a, _ = run(rt, src, frame=8, data_window=Rect(-20, 10, 40, 50), **kw)
    crop, _ = run(rt, src[5:30, 9:50], frame=8, data_window=Rect(-11, 15, 30, 40), **kw)
    inner = np.ascontiguousarray(a[5:30, 9:50])
    assert crop[2:-2, 2:-2].tobytes() == np.ascontiguousarray(inner[2:-2, 2:-2]).tobytes()


def test_chroma_blotches_are_low_frequency_and_keep_luminance(rt):
    h, w = 256, 384
    src = flat(h, w, 0.02)
    base, p = run(rt, src, mosaic="none", seed=7, frame=3)
    blot, _ = run(rt, src, mosaic="none", chroma_noise=2.0, chroma_size=0.05, seed=7, frame=3)
    delta = blot[..., :3].astype(np.float64) - base[..., :3]
    lum = delta @ np.array([0.2126, 0.7152, 0.0722])
    assert np.abs(lum).max() <= 1e-6                        # luminance unchanged
    sd = math.sqrt(noise_variance(0.02, p, CAMERA, 1))
    # value noise of unit node deviation: between ~0.6 and 1 of chroma x sd on average
    assert 0.5 * 2.0 * sd <= delta[..., 0].std() <= 1.05 * 2.0 * sd
    # low frequency: the blotches are nearly equal one pixel apart (cells of 23 px)
    r = delta[..., 0] - delta[..., 0].mean()
    assert np.mean(r[:, :-1] * r[:, 1:]) / r.var() > 0.99
    # and they change every frame
    other, _ = run(rt, src, mosaic="none", chroma_noise=2.0, chroma_size=0.05, seed=7, frame=4)
    assert not np.allclose(other, blot)


# -- coverage ---------------------------------------------------------------------------------
@pytest.mark.parametrize("extra", [dict(mosaic="none"), dict(mosaic="bayer"),
                                   dict(mosaic="none", chroma_noise=1.0, chroma_size=0.1),
                                   dict(mosaic="bayer", chroma_noise=1.0, chroma_size=0.1)])
def test_transparent_pixels_stay_empty_and_edges_get_alpha_share(rt, extra):
    # Beachball: a tight data window around an element whose background is alpha 0.  Read
    # noise there drew a visible rectangle around the element; weighted by coverage the
    # transparent band stays 0, a half-covered band gets half the deviation.
    h, w = 96, 96
    src = np.zeros((h, w, 4), np.float32)
    src[:, 32:64, 3] = 0.5
    src[:, 64:, 3] = 1.0
    kw = dict(read_noise=8.0, prnu=0.02, seed=3, **extra)
    out, p = run(rt, src, **kw)
    interior = slice(4, h - 4)                   # away from the demosaic's mirrored edge
    assert (out[interior, 2:30, :3] == 0).all()
    half = out[interior, 36:60, :3].std()
    full = out[interior, 68:92, :3].std()
    assert full > 0 and abs(half / full - 0.5) < 0.08, (half, full)
    np.testing.assert_array_equal(out[..., 3], src[..., 3])           # alpha bit for bit
    want = reference(src, **p.as_dict(), camera_iso=3200.0)
    np.testing.assert_allclose(out[..., :3], want[..., :3], rtol=1e-4, atol=1e-5)
    # "ignore": noise over the whole data window, transparent or not
    out, _ = run(rt, src, coverage="ignore", **kw)
    assert out[interior, 2:30, :3].std() > 0.5 * full


def test_auto_coverage_reads_a_photographs_matte_as_no_coverage(rt):
    # light where alpha is 0 (a matte in a photograph's alpha, an additive element): auto
    # noises every pixel, as "ignore" does
    src = np.full((64, 64, 4), 0.02, np.float32)
    src[..., 3] = 0.0
    src[20:40, 20:40, 3] = 1.0
    out, p = run(rt, src, read_noise=8.0, seed=4)
    ignore, _ = run(rt, src, read_noise=8.0, seed=4, coverage="ignore")
    np.testing.assert_array_equal(out, ignore)
    assert out[:16, :16, :3].std() > 0


@pytest.mark.parametrize("image, covered", [("Beachball/singlepart.0001.exr", True),
                                            ("ScanLines/CandleGlass.exr", False)])
def test_auto_coverage_on_real_files(rt, exr_images, image, covered):
    from clfx.io.read import read_frame

    fr = read_frame(exr_images / image)
    src = fr.rgba
    out, _ = run(rt, src, read_noise=3.0, seed=1, data_window=fr.data_window,
                 display=fr.display_window)
    empty = (src[..., 3] <= 0) & (src[..., :3] == 0).all(axis=-1)
    moved = np.abs(out[..., :3] - src[..., :3]).max(axis=-1)
    if covered:   # Beachball: the transparent background around the ball stays empty
        assert empty.mean() > 0.2 and (moved[empty] == 0).all()
    else:         # CandleGlass: its alpha is a matte; the dark room around it is noisy
        assert (src[..., 3] <= 0).mean() > 0.5
        assert (moved[src[..., 3] <= 0] > 0).mean() > 0.9


# -- exposure: the plate's own middle grey by default (issue 32, item 3) ---------------------
def test_default_meters_a_dark_plate(rt, exr_images):
    """CandleGlass (mean 0.0004, ~8.6 stops under 0.18) at the defaults: the noise at the
    plate's metered middle grey is the model's at grey (~5 % at ISO 400: 2 x 0.018^-1/2 %
    shot noise of ~1800 e-), not 4x the signal as when 0.18 was taken as middle grey."""
    from clfx.io.read import read_frame
    from tests.reference.grain import meter

    fr = read_frame(exr_images / "ScanLines" / "CandleGlass.exr")
    src = np.ascontiguousarray(fr.rgba[300:600, 0:400])      # the candle and the room
    grey = meter(src.astype(np.float64))
    assert 1e-4 < grey < 2e-3
    p = SensorNoise.params()
    assert p.middle_grey == 0.0    # auto
    out = render_effect(rt, SensorNoise(), p, src, camera=Camera(), seed=3)
    lum = src[..., :3] @ np.array([0.2126, 0.7152, 0.0722])
    near = np.abs(np.log2(np.maximum(lum, 1e-12) / grey)) < 0.25       # within 1/4 stop
    assert near.sum() > 1000
    rel = (out[..., 1] - src[..., 1])[near] / src[..., 1][near]
    want = math.sqrt(noise_variance(grey, p, Camera(), 1, grey)) / grey
    assert 0.02 < want < 0.08
    # the band: the demosaic keeps each colour's variance; green near grey varies +-1/4 stop
    assert 0.7 * want < rel.std() < 1.4 * want, (rel.std(), want)


def test_middle_grey_auto_or_stated_and_explained(tmp_path, exr_images):
    """``middle_grey: auto`` (the default) meters, and --explain says the metered value; a
    stated value is used as it is (no note); anything else is refused in one line."""
    from clfx.core.errors import ParamError
    from tests.clirun import run as cli_run

    assert SensorNoise.params(middle_grey="auto").middle_grey == 0.0
    assert SensorNoise.descriptor.param("middle_grey").describe()["default"] == "auto"
    with pytest.raises(ParamError, match="a number or 'auto'"):
        SensorNoise.params(middle_grey="bright")
    src = exr_images / "ScanLines" / "CandleGlass.exr"
    r = cli_run("apply", "sensor_noise", src, tmp_path / "a.exr", "--frames", "1",
                "--explain", "--quality", "draft")
    assert "middle grey metered at 0.000" in r.stderr, r.stderr
    r = cli_run("apply", "sensor_noise", src, tmp_path / "b.exr", "middle_grey=0.0005",
                "--explain", "--quality", "draft")
    assert "metered" not in r.stderr


# -- the full well and the demosaic (issue 32, items 4 and 5) --------------------------------
def preset_params(look):
    from clfx.pipeline.presets import load_look

    lk = load_look(look)
    step = next(s for s in lk.steps if s.effect == "sensor_noise")
    return step.params, lk.camera


@pytest.mark.parametrize("look", ["high-iso", "phone-pan"])
def test_lights_above_the_full_well_leave_no_demosaic_ring(rt, look):
    """A 1e3 light on grey and on black through the looks' sensor noise: a full site reads
    full (no shot noise past the well), and each pixel's colours get their own noise, so no
    pixel falls below black by more than its read noise (5 sigma) and the pixels just
    outside the light are as noisy as the rest of the grey (before: -11 beside the light at
    ISO 12800, coloured)."""
    from tests.reference.grain import meter

    p, cam = preset_params(look)
    h = w = 160
    src = flat(h, w, 0.18)
    yy, xx = np.mgrid[:h, :w]
    r = np.hypot(xx - 60.3, yy - 50.6)
    src[r < 6.0, :3] = 1e3
    src[100:, 80:, :3] = 0.0                      # black, with a light on it
    src[120:130, 100:112, :3] = 1e3
    out = render_effect(rt, SensorNoise(), p, src, camera=cam, seed=5, frame=1)
    g = 1 / np.array(electrons_per_unit(p, cam, meter(src.astype(np.float64))))
    read_sd = p.read_noise * g                    # per channel
    dev = out[..., :3] - src[..., :3]
    black = (src[..., :3] == 0).all(-1)
    assert (out[..., :3][black] >= -5 * read_sd).all(), (out[..., :3][black].min(0), read_sd)
    ring = (r > 6.5) & (r < 9.5)
    rest = (r > 14) & ~black & (yy < 95)
    sd_ring, sd_rest = dev[ring].std(0), dev[rest].std(0)
    assert (sd_ring < 1.3 * sd_rest).all(), (sd_ring, sd_rest)
    assert (np.abs(dev[ring].mean(0)) < 4 * sd_rest / math.sqrt(ring.sum() / 25)).all()


@pytest.mark.parametrize("look", ["high-iso", "phone-pan"])
@pytest.mark.parametrize("colour", [(0.5, 0.002, 0.002), (0.05, 0.05, 0.05)])
def test_no_bayer_lattice_in_the_noise(rt, look, colour):
    """Over a saturated red (and a grey) flat, each channel's noise has the same amplitude
    at the four phases of the 2 x 2 CFA (before: green and blue 5x as noisy at red sites
    over the red, MHC's Laplacian carrying the red site's noise into them; green's variance
    0.56 at red and blue sites on grey: a lattice of dots every other pixel)."""
    p, cam = preset_params(look)
    src = flat(96, 96, 0.0)
    src[..., :3] = colour
    out = render_effect(rt, SensorNoise(), p, src, camera=cam, seed=2, frame=1)
    d = (out - src)[4:-4, 4:-4, :3]
    for c in range(3):
        phases = np.array([d[i::2, j::2, c].std() for i in (0, 1) for j in (0, 1)])
        # 4 x 1936 samples: the standard error of a phase's std is ~1.6 %
        assert phases.max() / phases.min() < 1.12, (c, phases)
