"""Film grain: oracle agreement; the stated model's statistics (autocorrelation, block
statistics / Selwyn's law, the density-dependent amplitude) at two exposures; the same look
at any exposure; determinism (runs, crops); hard values; identity; legacy parameters."""
import math
import os
import subprocess
import sys

import numpy as np
import pytest

from clfx.core.camera import Camera
from clfx.core.errors import ParamError
from clfx.bench.cases.grain import CASE
from clfx.plugins.grain import (D_GREY, FOG, GAMMA, STOCKS, TOE, Grain, grain_amounts,
                                grain_sigmas_px, grain_weights, pixel_variance_1d,
                                selwyn_factor)
from clfx.core.rect import Rect
from tests.conftest import ROOT, hard_shapes
from tests.plugins.test_distortion import wide_range_image
from tests.reference.grain import grain as reference
from tests.reference.grain import uniform as reference_uniform
from tests.effects import render_effect

# A 2048-wide display window: amounts are stated for this width (Selwyn factor 1).
DISPLAY_2K = Rect(0, 0, 2048, 1080)
S35 = Camera(sensor_width=24.89)    # 12.15 um per pixel at 2K
LEVELS = ("draft", "preview", "final", "reference")
TRUNCATION = {"draft": None, "preview": 2.0, "final": 4.0, "reference": 6.0}


def run(rt, src, quality="final", frame=0, look_seed=0, data_window=None, display=DISPLAY_2K,
        camera=S35, **kw):
    p = Grain.params(**kw)
    out = render_effect(rt, Grain(), p, src, quality=quality, frame=frame, seed=look_seed,
                        data_window=data_window, display_window=display, camera=camera)
    return out, p


def want(src, p, display=DISPLAY_2K, camera=S35, **kw):
    return reference(src, **p.as_dict() | {"stock": STOCKS[p.stock]},
                     display_width=display.width, sensor_width=camera.sensor_width, **kw)


def flat(h, w, value=0.18):
    src = np.full((h, w, 4), value, np.float32)
    src[..., 3] = 1.0
    return src


def model_deviation(p, e, width=2048, fmt=24.89):
    """The model's log-exposure deviation s_c at relative exposure e (per channel)."""
    density = FOG + GAMMA * np.log10(1 + e / TOE)
    return np.array(grain_amounts(p, width, fmt)) * (density / D_GREY) ** p.response


def unit_noise(out, p, level=0.18, grey=0.18, width=2048, fmt=24.89):
    """The unit grain field n_c of a flat render at ``level`` (undo the tone model exactly:
    ln(1 + dev / (E (e + TOE))) = s n - s^2 / 2)."""
    e = level / grey
    s = model_deviation(p, e, width, fmt)
    rel = (out[..., :3].astype(np.float64) - level) / (grey * (e + TOE))
    return (np.log1p(rel) + s * s / 2) / s


def autocorrelation(taps, lag):
    return float(np.sum(taps[:-lag] * taps[lag:])) if lag < len(taps) else 0.0


def effective_count(n, taps):
    """Independent samples equivalent to n correlated ones, for the variance estimate:
    n / sum over 2-D lags of rho^2, rho separable = product of 1-D autocorrelations."""
    rho = np.array([np.sum(taps[:len(taps) - d] * taps[d:]) for d in range(len(taps))])
    s1 = rho[0] ** 2 + 2 * np.sum(rho[1:] ** 2)
    return n / s1 ** 2


# -- oracle ----------------------------------------------------------------------------------
@pytest.mark.parametrize("shape", hard_shapes())
def test_grain_matches_reference(rt, rng, shape):
    src = rng.uniform(0.0, 2.0, shape + (4,)).astype(np.float32)
    kw = dict(stock="fast-500t", amount=0.1, diameter=120.0, response=0.5, seed=3)
    got, p = run(rt, src, frame=5, look_seed=9, **kw)
    ref = want(src, p, frame=5, look_seed=9, truncation=TRUNCATION["final"])
    # float32 noise (polynomial log/sincos, rel. error ~2e-7, x |n| <= 6) summed over <= 21
    # taps per pass; the tone model's log / exp2 (rel. ~2e-7 each, x |s n| <= ~1) and the
    # float32 meter (tile sums, rel. ~1e-6): a few 1e-7 absolute on values <= 2.2
    np.testing.assert_allclose(got, ref, rtol=2e-6, atol=2e-6)
    np.testing.assert_array_equal(got[..., 3], src[..., 3])


@pytest.mark.parametrize("quality", LEVELS)
@pytest.mark.parametrize("response", (0.0, 0.5, 1.0, 0.3))
def test_each_level_and_response_matches_its_own_model(rt, rng, quality, response):
    src = rng.uniform(0.0, 1.0, (23, 41, 4)).astype(np.float32)
    kw = dict(amount=0.2, size=1.7, monochrome=quality == "preview", response=response,
              middle_grey=0.3)
    got, p = run(rt, src, quality, frame=2, **kw)
    ref = want(src, p, frame=2, truncation=TRUNCATION[quality])
    # same tolerance argument as above (reference: float64 throughout, output rounding only)
    np.testing.assert_allclose(got, ref, rtol=2e-6, atol=2e-6)


def test_error_falls_monotonically_with_quality(rt, rng):
    src = rng.uniform(0.0, 1.0, (40, 56, 4)).astype(np.float32)
    kw = dict(stock="medium-250d", amount=0.1, diameter=100.0, seed=11)
    p = Grain.params(**kw)
    ref = want(src, p, frame=4, truncation=6.0)
    errors = [np.abs(run(rt, src, q, frame=4, **kw)[0] - ref).max() for q in LEVELS]
    assert all(a >= b for a, b in zip(errors, errors[1:])), errors
    # reference: float64 noise, sums and tone; only the float32 store of values <= ~1.5
    assert errors[-1] <= 2e-7, errors


def test_device_hash_equals_reference_hash(rt):
    """The oracle's uint32 re-implementation is common.h's clfx_uniform, bit for bit."""
    src = """#include "lib/common.h"
    kernel void k(global float *o, const uint seed, const int frame) {
      const int i = get_global_id(0);
      o[i] = clfx_uniform(seed, frame, i - 37, 3 * i - 100, i % 7);
    }"""
    prg = rt.cl.Program(rt.ctx, src).build(options=[f"-I{rt.kernel_dir}"])
    out = np.empty(256, np.float32)
    buf = rt.cl.Buffer(rt.ctx, rt.cl.mem_flags.WRITE_ONLY, out.nbytes)
    prg.k(rt.queue, (256,), None, buf, np.uint32(0xDEADBEEF), np.int32(-5))
    rt.cl.enqueue_copy(rt.queue, out, buf)
    i = np.arange(256)
    expect = reference_uniform(0xDEADBEEF, -5, i - 37, 3 * i - 100, i % 7)
    np.testing.assert_array_equal(out, expect.astype(np.float32))


def test_eight_pixel_uniforms_equal_the_scalar_hash(rt):
    """fastmath.h's clfx_uniform32 (grain's 8 pixels a work-item, their per-pixel hashes
    shared 8 lanes wide) is clfx_uniform at x .. x + 7, channels c0 .. c0 + 3, bit for bit."""
    src = """#include "lib/fastmath.h"
    kernel void k(global float *o, const uint seed, const int frame) {
      const int i = get_global_id(0);
      float16 u0, u1;
      clfx_uniform32(seed, frame, 8 * i - 37, 3 * i - 100, i % 5, &u0, &u1);
      vstore16(u0, 2 * i, o);
      vstore16(u1, 2 * i + 1, o);
    }"""
    prg = rt.cl.Program(rt.ctx, src).build(options=[f"-I{rt.kernel_dir}"])
    out = np.empty((64, 8, 4), np.float32)
    buf = rt.cl.Buffer(rt.ctx, rt.cl.mem_flags.WRITE_ONLY, out.nbytes)
    prg.k(rt.queue, (64,), None, buf, np.uint32(0xDEADBEEF), np.int32(-5))
    rt.cl.enqueue_copy(rt.queue, out, buf)
    i, px, c = np.meshgrid(np.arange(64), np.arange(8), np.arange(4), indexing="ij")
    expect = reference_uniform(0xDEADBEEF, -5, 8 * i - 37 + px, 3 * i - 100, i % 5 + c)
    np.testing.assert_array_equal(out, expect.astype(np.float32))


# -- the model's statistics -------------------------------------------------------------------
def test_film_terms_size_in_pixels():
    """diameter (um on the negative) -> pixels through the format width and display width."""
    p = Grain.params(diameter=40.0)
    # s = d / 4 = 10 um; Super 35 at 2K: 24890 / 2048 = 12.15 um per pixel
    np.testing.assert_allclose(grain_sigmas_px(p, 2048, 24.89), [10 / 12.1533203125] * 3)
    # the same stock on full frame (36 mm) is finer in the frame; at 4K twice the pixels
    np.testing.assert_allclose(grain_sigmas_px(p, 2048, 36.0)[1], 10 * 2048 / 36000)
    np.testing.assert_allclose(grain_sigmas_px(p, 4096, 24.89)[1], 2 * 10 / 12.1533203125)
    # the stock's diameter when 0; the legacy size (px at 2K) when >= 0
    assert grain_sigmas_px(Grain.params(stock="fast-500t"), 2048, 24.89)[1] == \
        pytest.approx(STOCKS["fast-500t"].diameter / 4 / 12.1533203125)
    assert grain_sigmas_px(Grain.params(size=0.8, diameter=300.0), 2048, 24.89)[1] == \
        pytest.approx(0.8)


@pytest.mark.parametrize("plate_scale", (1.0, 0.01))
def test_autocorrelation_matches_the_cloud_model_at_two_exposures(rt, plate_scale):
    """A flat grey plate at 0.18 and at 0.0018 (metered): the grain field's autocorrelation
    is the model's, per channel (blue clouds largest in this stock), at both exposures."""
    h = w = 320
    level = 0.18 * plate_scale
    out, p = run(rt, flat(h, w, level), stock="fast-500t", amount=0.05, seed=5)
    noise = unit_noise(out, p, level=level, grey=level)
    sigmas = grain_sigmas_px(p, 2048, 24.89)
    _, weights = grain_weights(sigmas, 4.0)
    for c in range(3):
        n = noise[..., c] - noise[..., c].mean()
        var = np.mean(n * n)
        for lag in (1, 2, 3, 5):
            # the discrete field's autocorrelation (the taps') ...
            model = autocorrelation(weights[:, c], lag)
            # ... is the continuous cloud model's exp(-lag^2 / 4 s^2) with the pixel's own
            # box (variance 1/12) added to each cloud: within 0.01 for s >= 0.8 px
            s2 = sigmas[c] ** 2 + 1.0 / 12.0
            assert abs(model - math.exp(-lag ** 2 / (4 * s2))) <= 0.01
            got_x = np.mean(n[:, :-lag] * n[:, lag:]) / var
            got_y = np.mean(n[:-lag] * n[lag:]) / var
            # standard error of a correlation over N_eff ~ 102k / (8 pi s^2) samples is
            # ~0.01-0.02 here; 0.06 is about 4 standard errors
            assert abs(got_x - model) <= 0.06, (c, lag, got_x, model)
            assert abs(got_y - model) <= 0.06, (c, lag, got_y, model)
    # clumpy: lag-1 correlation >= 0.7 and lag-2 >= 0.25 for green (40 um clouds at 2K S35)
    g = noise[..., 1] - noise[..., 1].mean()
    assert np.mean(g[:, :-1] * g[:, 1:]) / g.var() >= 0.7
    assert np.mean(g[:, :-2] * g[:, 2:]) / g.var() >= 0.25
    lag3 = [np.mean(noise[:, :-3, c] * noise[:, 3:, c]) / np.var(noise[..., c]) for c in range(3)]
    assert lag3[2] > lag3[0] > lag3[1]


@pytest.mark.parametrize("plate_scale", (1.0, 0.01))
def test_block_statistics_follow_selwyn_at_two_exposures(rt, plate_scale):
    """Block means of the grain field over b x b pixels have the variance the stated
    spectrum predicts, (1/b^2 sum_ij r(i - j))^2 with r the 1-D autocorrelation, which
    tends to Selwyn's law (variance x area constant) once blocks outgrow the clouds; the
    same at both exposures."""
    h = w = 384
    level = 0.18 * plate_scale
    out, p = run(rt, flat(h, w, level), amount=0.04, diameter=40.0, seed=12)
    n = unit_noise(out, p, level=level, grey=level)[..., 1]
    sigma = grain_sigmas_px(p, 2048, 24.89)[1]
    _, weights = grain_weights([sigma] * 3, 4.0)
    taps = weights[:, 1]
    r = np.array([autocorrelation(taps, k) if k else 1.0 for k in range(len(taps))])
    area_var = []
    for b in (1, 2, 4, 8, 16):
        k = np.arange(-b + 1, b)
        v1 = np.sum((b - np.abs(k)) * np.where(np.abs(k) < len(r), r[np.minimum(np.abs(k), len(r) - 1)], 0)) / b ** 2
        model = v1 * v1
        blocks = n.reshape(h // b, b, w // b, b).mean(axis=(1, 3))
        got = blocks.var()
        m = blocks.size
        # relative standard error of a variance over m block means (blocks nearly
        # independent once b exceeds the clouds; for small b, N_eff of the field): 4 of them
        n_eff = min(m, effective_count(h * w, taps))
        assert abs(got / model - 1) <= 4 * math.sqrt(2 / n_eff), (b, got, model)
        # the continuous model (pixel_variance_1d, relative to one pixel's) agrees with the
        # discrete field's to 5 % (the discrete taps add the pixel's box once more)
        continuous = (pixel_variance_1d(b, sigma) / pixel_variance_1d(1, sigma)) ** 2
        assert continuous == pytest.approx(model, rel=0.05)
        area_var.append((got * b * b, model * b * b))
    # Selwyn: variance x area rises to its limit (sum_k r(k))^2 as blocks outgrow the clouds
    # (as 1 - c / b): within 15 % of it at 16 px; the measured ratio 16 px / 8 px within 4
    # standard errors of the model's (576 and 2304 blocks: sqrt(2/576 + 2/2304) = 0.066)
    limit = (r[0] + 2 * np.sum(r[1:])) ** 2
    (g8, m8), (g16, m16) = area_var[3], area_var[4]
    assert m8 < m16 < limit and m16 / limit >= 0.85
    assert abs(g16 / g8 - m16 / m8) <= 4 * 0.066


def test_same_look_at_any_exposure(rt):
    """A plate scaled by k (0.01, 10) is rendered as k times the plate's render (metered
    exposure reference): the same grain after normalising, to float rounding."""
    rng = np.random.default_rng(4)
    src = np.exp(rng.normal(-2.0, 1.5, (48, 64, 4))).astype(np.float32)
    src[..., 3] = 1.0
    src[5, 7, :3] = 0.0                  # black: fog-level grain, scaled too
    kw = dict(stock="medium-250d", amount=0.05, seed=3, frame=2)
    base, _ = run(rt, src, **kw)
    for k in (0.01, 10.0):
        scaled = src.copy()
        scaled[..., :3] *= np.float32(k)     # the light, not the alpha (coverage stays 1)
        got, _ = run(rt, scaled, **kw)
        # float32 rounding of the scaled inputs and the meter (rel. ~1e-6 each) move the
        # grain by ~1e-6 relative; 1e-5 leaves margin
        np.testing.assert_allclose(got[..., :3] / k, base[..., :3], rtol=1e-5,
                                   atol=1e-5 * base[..., :3].max())
        grain = np.abs(base[..., :3] - src[..., :3]).mean()
        assert grain > 1e-3  # and there is grain to compare


def test_stated_middle_grey_scales_like_the_meter(rt):
    src = flat(64, 64, 0.05)
    a, _ = run(rt, src, amount=0.05, middle_grey=0.05, seed=2)
    b, _ = run(rt, src, amount=0.05, seed=2)              # metered: 0.05 on a flat plate
    c, _ = run(rt, src * 4, amount=0.05, middle_grey=0.2, seed=2)
    np.testing.assert_allclose(a, b, rtol=1e-6)
    np.testing.assert_allclose(c[..., :3] / 4, a[..., :3], rtol=2e-6)


@pytest.mark.parametrize("response", (0.0, 0.5, 1.0))
def test_deviation_follows_the_density_model(rt, response):
    """Relative exposures from 5 stops under to 6 over: the log-factor's deviation is
    amount (D(e) / D(1))^response; the mean is kept (the factor's mean is 1)."""
    exposures = (2.0 ** -5, 0.25, 1.0, 8.0, 64.0)
    band = 128
    src = np.concatenate([flat(band, 256, 0.2 * e) for e in exposures], axis=0)
    out, p = run(rt, src, amount=0.06, diameter=30.0, response=response, middle_grey=0.2,
                 seed=2)
    sigma = grain_sigmas_px(p, 2048, 24.89)[1]
    _, weights = grain_weights([sigma] * 3, 4.0)
    n_eff = effective_count(band * 256, weights[:, 1])
    rel_sd = math.sqrt(2.0 / n_eff) / 2  # relative standard error of a standard deviation
    for i, e in enumerate(exposures):
        part = out[i * band:(i + 1) * band, :, :3].astype(np.float64)
        s = model_deviation(p, e)
        log_factor = np.log1p((part - 0.2 * e) / (0.2 * (e + TOE)))
        np.testing.assert_allclose(log_factor.std(axis=(0, 1)) / s, 1.0, atol=4 * rel_sd)
        # mean kept: within 4 standard errors of the block mean (sum of taps^2 over N)
        sd_mean = 0.2 * (e + TOE) * s * np.sum(weights[:, 1]) ** 2 / math.sqrt(band * 256)
        assert np.all(np.abs(part.mean(axis=(0, 1)) - 0.2 * e) <= 4 * sd_mean + 1e-7 * e)
    # relative to the signal (response 0.5) the grain is least ~2 stops under grey, rises
    # into the toe (under-exposed film is grainier) and slowly with density above grey
    # (Nutting: 1.4x at 6 stops over); nothing is speckle: under 1.5 x amount anywhere
    rel = [(out[i * band:(i + 1) * band, :, 1] / (0.2 * e) - 1).std()
           for i, e in enumerate(exposures)]
    if response == 0.5:
        assert rel[0] > rel[1] < rel[2] < rel[3] < rel[4] < 1.5 * 0.06


def test_resolution_follows_selwyn(rt):
    """A 1K render of the same format equals the 2K render averaged 2 x 2 in grain
    deviation (Selwyn's law through the pixel-averaged variance)."""
    src2k, src1k = flat(256, 256), flat(128, 128)
    hi, p = run(rt, src2k, amount=0.05, diameter=30.0, seed=8)
    lo, _ = run(rt, src1k, amount=0.05, diameter=30.0, seed=8, display=Rect(0, 0, 1024, 540))
    hi_avg = hi[..., :3].astype(np.float64).reshape(128, 2, 128, 2, 3).mean(axis=(1, 3))
    sd_hi = (hi_avg / 0.18 - 1).std(axis=(0, 1))
    sd_lo = (lo[..., :3] / 0.18 - 1).std(axis=(0, 1))
    # both estimates over ~16k samples of a correlated field: ~2 % standard error each
    np.testing.assert_allclose(sd_lo / sd_hi, 1.0, atol=0.08)
    sigma = grain_sigmas_px(p, 1024, 24.89)[1]
    assert selwyn_factor(sigma, 0.5) < 1 and selwyn_factor(0.0, 0.5) == 0.5


def test_frames_are_uncorrelated_and_differ(rt):
    h = w = 256
    a, p = run(rt, flat(h, w), frame=10, amount=0.05, diameter=20.0)
    b, _ = run(rt, flat(h, w), frame=11, amount=0.05, diameter=20.0)
    na, nb = unit_noise(a, p), unit_noise(b, p)
    _, weights = grain_weights(grain_sigmas_px(p, 2048, 24.89), 4.0)
    n_eff = effective_count(h * w, weights[:, 1])
    for c in range(3):
        r = np.corrcoef(na[..., c].ravel(), nb[..., c].ravel())[0, 1]
        assert abs(r) <= 4 / math.sqrt(n_eff)  # 4 standard errors of a zero correlation
    assert not np.array_equal(a, b)


def test_colour_channels_are_independent_and_monochrome_shares_one_field(rt):
    colour, p = run(rt, flat(256, 256), amount=0.05, diameter=20.0)
    n = unit_noise(colour, p)
    r = np.corrcoef(n[..., 0].ravel(), n[..., 1].ravel())[0, 1]
    assert abs(r) < 0.05
    for kw in (dict(monochrome=True), dict(stock="mono-400")):
        mono, p = run(rt, flat(32, 32), amount=0.05, diameter=20.0, **kw)
        nm = unit_noise(mono, p)
        np.testing.assert_allclose(nm[..., 0], nm[..., 1], atol=1e-4)
        np.testing.assert_allclose(nm[..., 2], nm[..., 1], atol=1e-4)


# -- determinism ------------------------------------------------------------------------------
@pytest.mark.parametrize("quality", LEVELS)
def test_same_frame_gives_identical_bytes(rt, rng, quality):
    src = rng.uniform(0.0, 1.0, (37, 45, 4)).astype(np.float32)
    a, _ = run(rt, src, quality, frame=3, look_seed=4, amount=0.1, size=2.0)
    b, _ = run(rt, src, quality, frame=3, look_seed=4, amount=0.1, size=2.0)
    assert a.tobytes() == b.tobytes()
    c, _ = run(rt, src, quality, frame=3, look_seed=5, amount=0.1, size=2.0)
    assert not np.array_equal(a, c)  # the look's seed changes the grain


@pytest.mark.parametrize("quality", LEVELS)
def test_crop_gives_same_values_at_same_frame_coordinates(rt, rng, quality):
    """With a stated middle grey (the meter reads what it is given: a crop meters itself)."""
    full_src = rng.uniform(0.0, 1.0, (40, 60, 4)).astype(np.float32)
    kw = dict(amount=0.1, size=2.0, middle_grey=0.18)
    full, _ = run(rt, full_src, quality, frame=7, data_window=Rect(100, 50, 160, 90), **kw)
    crop_src = full_src[7:28, 13:43]
    crop, _ = run(rt, crop_src, quality, frame=7, data_window=Rect(113, 57, 143, 78), **kw)
    assert crop.tobytes() == np.ascontiguousarray(full[7:28, 13:43]).tobytes()


@pytest.mark.parametrize("quality", LEVELS)
@pytest.mark.parametrize("width", (40, 48, 52, 60))   # rows end 8, 0, 4, 12 into 16
@pytest.mark.parametrize("kind", ("colour", "monochrome", "coverage"))
def test_every_row_tail_gives_the_wider_frames_values(rt, rng, quality, width, kind):
    """A work-item takes 16 pixels and rows are padded to 4 only: a row ending 4, 8 or 12
    pixels into its last 16 (and one ending on a whole 16) gets, pixel for pixel, what the
    same frame pixels get inside a wider render, alpha copied."""
    full_src = rng.uniform(0.0, 1.0, (21, 80, 4)).astype(np.float32)
    full_src[..., 3] = rng.uniform(-0.2, 1.2, (21, 80)) if kind == "coverage" else 1.0
    kw = dict(amount=0.1, size=2.0, middle_grey=0.18, monochrome=kind == "monochrome",
              coverage="alpha" if kind == "coverage" else "ignore")
    full, _ = run(rt, full_src, quality, frame=7, data_window=Rect(100, 50, 180, 71), **kw)
    crop, _ = run(rt, np.ascontiguousarray(full_src[:, 8:8 + width]), quality, frame=7,
                  data_window=Rect(108, 50, 108 + width, 71), **kw)
    assert crop.tobytes() == np.ascontiguousarray(full[:, 8:8 + width]).tobytes()
    assert crop[..., 3].tobytes() == full_src[:, 8:8 + width, 3].tobytes()


def test_the_filtered_noise_carries_no_alpha(rt, rng, monkeypatch):
    """Alpha gets no grain, so the noise and its blurred copy hold R, G and B only: 12 bytes
    a pixel each in float32 (RGBA lanes took 16, a quarter of the taps' and the tone model's
    work on zeros)."""
    src = rng.uniform(0.0, 1.0, (30, 400, 4)).astype(np.float32)
    sizes = []
    real_buffer = type(rt).buffer

    def buffer(self, nbytes):
        sizes.append(int(nbytes))
        return real_buffer(self, nbytes)

    monkeypatch.setattr(type(rt), "buffer", buffer)
    _, p = run(rt, src, "final", amount=0.1, size=2.0, middle_grey=0.18)
    radius, _ = grain_weights(grain_sigmas_px(p, DISPLAY_2K.width, S35.sensor_width), 4.0)
    rows = 30 + 2 * radius
    big = sorted(sizes)[-2:]            # the noise and the blurred noise
    assert len(sizes) >= 2 and min(big) >= rows * 400 * 12
    assert sum(big) <= 2 * rows * (400 + 2 * radius + 24) * 12


# -- coverage ---------------------------------------------------------------------------------
@pytest.mark.parametrize("quality", LEVELS)
def test_transparent_pixels_get_no_grain_and_partial_alpha_its_share(rt, rng, quality):
    # Beachball: a premultiplied element on an empty, alpha-0 background.  Grain there (the
    # fog's grain lands on black too) drew a rectangle over the data window; weighted by
    # coverage the background stays 0 and a pixel of alpha a gets a times the grain
    # "ignore" gives it, as sensor_noise weights its noise.
    h, w = 40, 64
    alpha = np.zeros((h, w), np.float32)
    alpha[:, 16:32] = rng.uniform(0.05, 0.95, (h, 16))
    alpha[:, 32:48] = 1.0
    alpha[:, 48:] = 1.5                          # above 1: opaque too
    src = np.zeros((h, w, 4), np.float32)
    src[..., :3] = rng.uniform(0.05, 0.4, (h, w, 3)) * np.minimum(alpha, 1.0)[..., None]
    src[..., 3] = alpha
    kw = dict(amount=0.1, size=1.5, seed=6)
    ignore, _ = run(rt, src, quality, frame=2, coverage="ignore", **kw)
    assert ignore[:, :16, :3].std() > 0          # without coverage the background has grain
    for coverage in ("auto", "alpha"):
        got, _ = run(rt, src, quality, frame=2, coverage=coverage, **kw)
        assert (got[:, :16, :3] == 0).all()
        # the partial band: (got - v) = a (ignore - v); float32 rounding of v + a d (|v| <=
        # 0.4, ulp 3e-8) and of a d itself: a few 1e-8 absolute
        v, a = src[:, 16:32, :3], alpha[:, 16:32, None]
        np.testing.assert_allclose(got[:, 16:32, :3] - v, a * (ignore[:, 16:32, :3] - v),
                                   rtol=1e-5, atol=1e-7)
        assert got[:, 32:].tobytes() == ignore[:, 32:].tobytes()   # opaque: bit for bit
        np.testing.assert_array_equal(got[..., 3], src[..., 3])
    ref = want(src, Grain.params(coverage="alpha", **kw), frame=2, truncation=TRUNCATION[quality])
    np.testing.assert_allclose(got, ref, rtol=2e-6, atol=2e-6)   # as the oracle test


@pytest.mark.parametrize("quality", LEVELS)
def test_opaque_frames_render_as_without_coverage(rt, rng, quality):
    # alpha >= 1 everywhere (and a plate read without alpha: 1): coverage changes no bit, so
    # an opaque frame renders exactly as before coverage existed (the COVERAGE=0 build is
    # the earlier kernel)
    src = rng.uniform(0.0, 2.0, (29, 45, 4)).astype(np.float32)
    src[..., 3] = 1.0
    src[:8, :8, 3] = 2.0
    src[3, 4, :3] = (np.nan, np.inf, -3.0)
    kw = dict(stock="fast-500t", amount=0.1, diameter=60.0, seed=2)
    ignore, _ = run(rt, src, quality, frame=4, coverage="ignore", **kw)
    for coverage in ("auto", "alpha"):
        got, _ = run(rt, src, quality, frame=4, coverage=coverage, **kw)
        assert got.tobytes() == ignore.tobytes()


def test_auto_coverage_reads_a_matte_as_no_coverage(rt):
    # light where alpha is 0 (a photograph's matte, an additive element): auto grains every
    # pixel as "ignore" does
    inside = np.zeros((48, 48, 1), bool)
    inside[16:32, 16:32] = True
    src = np.where(inside, (0.1, 0.1, 0.1, 1.0), (0.1, 0.1, 0.1, 0.0)).astype(np.float32)
    auto, p = run(rt, src, amount=0.1, seed=4)
    ignore, _ = run(rt, src, amount=0.1, seed=4, coverage="ignore")
    assert auto.tobytes() == ignore.tobytes() and auto[:8, :8, :3].std() > 0
    np.testing.assert_allclose(auto, want(src, p, truncation=4.0), rtol=2e-6, atol=2e-6)


def test_auto_coverage_is_judged_on_the_looks_input(rt):
    # chromatic aberration before grain leaves colour fringes where alpha is 0 (so do a
    # resampling filter's lobes, glare, halation): judged on grain's own input the element
    # read as "a matte" and the whole window got grain (the cinema look on Beachball); judged
    # on the look's input the empty background stays empty
    import clfx
    from clfx.core.frame import Frame
    from clfx.pipeline.look import render_frame

    # a tight data window in a larger display window, as Beachball: the fringes grow the
    # window, so grain's input is analysed afresh
    yy, xx = np.mgrid[0:72, 0:72]
    disc = ((xx - 36) ** 2 + (yy - 36) ** 2 < 33 ** 2).astype(np.float32)
    src = np.zeros((72, 72, 4), np.float32)
    src[..., 0], src[..., 1], src[..., 2], src[..., 3] = 0.8 * disc, 0.3 * disc, 0.5 * disc, disc

    def frame():
        return Frame(src.copy(), Rect(40, 20, 112, 92), Rect(0, 0, 160, 112))

    def look(amount):
        return clfx.load_look({"name": "then-grain", "schema": 1, "effects": [
            {"effect": "chromatic_aberration", "params": {"amount": 0.01, "spectral": False}},
            {"effect": "grain", "params": {"amount": amount, "seed": 2}}]})

    before, _ = render_frame(rt, look(0.0), frame())                   # grain skipped
    fringe = (before.rgba[..., 3] <= 0) & (before.rgba[..., :3] != 0).any(-1)
    assert fringe.sum() > 20                     # light where alpha is 0: what grain sees
    out, report = render_frame(rt, look(0.1), frame())
    assert report.steps[-1].ran and out.data_window == before.data_window != frame().data_window
    empty = before.rgba[..., 3] <= 0
    np.testing.assert_array_equal(out.rgba[empty], before.rgba[empty])
    assert (out.rgba[~empty, :3] != before.rgba[~empty, :3]).mean() > 0.9


def test_beachball_background_stays_empty(rt, exr_images):
    from clfx.io.read import read_frame

    fr = read_frame(exr_images / "Beachball/singlepart.0001.exr")
    src = fr.rgba
    kw = dict(amount=0.05, seed=1, data_window=fr.data_window, display=fr.display_window)
    out, _ = run(rt, src, "draft", **kw)
    empty = (src[..., 3] <= 0) & (src[..., :3] == 0).all(axis=-1)
    moved = np.abs(out[..., :3] - src[..., :3]).max(axis=-1)
    assert empty.mean() > 0.2 and (moved[empty] == 0).all()
    assert (moved[src[..., 3] >= 1] > 0).mean() > 0.9            # the ball keeps its grain
    ignore, _ = run(rt, src, "draft", coverage="ignore", **kw)
    assert (np.abs(ignore[..., :3] - src[..., :3]).max(axis=-1)[empty] > 0).mean() > 0.9


# -- hard cases -------------------------------------------------------------------------------
@pytest.mark.parametrize("quality", LEVELS)
def test_hard_values_stay_finite_and_alpha_is_kept(rt, quality):
    vals = np.array([-1.0, 0.0, 1e-30, 65504.0, 1e5, 3.4e38, np.nan, np.inf, -np.inf],
                    np.float32)
    src = np.repeat(vals[None, :, None], 4, axis=2)
    src = np.repeat(src, 3, axis=0)
    for grey in (0.0, 1e-30, 0.18):
        out, _ = run(rt, src, quality, amount=1.0, size=3.0, response=1.0, middle_grey=grey,
                     channel_amount=(4.0, 4.0, 4.0))
        assert np.isfinite(out).all()
        # alpha bit for bit where finite; NaN / Inf (colour or alpha) become 0 first
        assert out[:, :6, 3].tobytes() == src[:, :6, 3].tobytes()
        np.testing.assert_array_equal(out[:, 6:, 3], 0.0)
    assert np.isfinite(run(rt, wide_range_image(np.random.default_rng(1)), quality,
                           amount=1.0, size=3.0, response=1.0)[0]).all()


def test_black_frame_meters_the_fallback_and_gets_fog_grain(rt):
    out, p = run(rt, flat(32, 32, 0.0), amount=0.05, seed=1)
    dev = out[..., :3].std()
    assert 0 < dev < 0.18 * TOE * 0.05 * 3   # fog-level grain around the fallback grey


def test_huge_grain_on_tiny_image(rt, rng):
    src = rng.uniform(0.0, 1.0, (3, 5, 4)).astype(np.float32)
    display = Rect(0, 0, 4096, 2160)
    got, p = run(rt, src, amount=0.1, size=20.0, display=display)
    ref = want(src, p, display=display, truncation=4.0)
    np.testing.assert_allclose(got, ref, rtol=2e-6, atol=2e-6)  # as the oracle test


def test_zero_amount_is_identity_with_reason(rt, rng):
    src = rng.uniform(0.0, 1.0, (9, 9, 4)).astype(np.float32)
    p = Grain.params(amount=0.0)
    assert Grain().is_identity(p, None) == "amount is 0"
    assert Grain().is_identity(Grain.params(channel_amount=(0, 0, 0)), None)
    assert Grain().is_identity(Grain.params(), None) is None
    assert np.array_equal(render_effect(rt, Grain(), p, src), src)


def test_descriptor_and_params():
    d = Grain.descriptor
    assert d.frame_varying and not d.spreads_light
    assert d.version[0] == 2
    assert set(d.quality) == set(LEVELS)
    assert set(STOCKS) == set(d.param("stock").choices)
    text = d.summary.lower()
    assert "dye clouds" in text and "selwyn" in text and "nutting" in text
    with pytest.raises(ParamError):
        Grain.params(stock="kodak-9999")
    with pytest.raises(ParamError):
        Grain.params(amount=-0.1)
    # version-1 parameters still parse (size in px at 2K, response)
    Grain.params(size=0.8, response=0.6, amount=0.03)


def test_bench_case_renders(rt, rng):
    case = CASE.make(64, 36, rng)
    p = Grain.params(**case["params"])
    out = render_effect(rt, Grain(), p, case["source"], camera=case["camera"])
    assert out.shape == (36, 64, 4) and np.isfinite(out).all()


def rendered_in_one_thread(tmp_path, src, imports: str, call: str) -> bytes:
    """The bytes of ``call`` (an expression of ``rt`` and ``src``, after ``imports``) in a
    fresh process whose PoCL runs one thread."""
    np.save(tmp_path / "src.npy", src)
    code = (f"import numpy as np; from clfx.device.runtime import Runtime; {imports}; "
            f"rt = Runtime.get(); src = np.load({str(tmp_path / 'src.npy')!r}); "
            f"np.save({str(tmp_path / 'out.npy')!r}, {call})")
    env = {**os.environ, "POCL_MAX_PTHREAD_COUNT": "1", "POCL_CPU_MAX_CU_COUNT": "1"}
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT, env=env, timeout=120)
    return np.load(tmp_path / "out.npy").tobytes()
