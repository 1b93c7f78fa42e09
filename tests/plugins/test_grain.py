"""Film grain: oracle agreement, statistics (mean, variance, autocorrelation, frame
independence), determinism (runs, crops), hard values, identity."""
import math
import os
import subprocess
import sys

import numpy as np
import pytest

from clfx.core.errors import ParamError
from clfx.bench.cases.grain import CASE
from clfx.plugins.grain import STOCKS, Grain, grain_weights
from clfx.core.rect import Rect
from tests.conftest import ROOT, hard_shapes
from tests.plugins.test_distortion import wide_range_image
from tests.reference.grain import grain as reference
from tests.reference.grain import uniform as reference_uniform

# A 2048-wide display window makes "px at 2K" equal to pixels, whatever the data size.
DISPLAY_2K = Rect(0, 0, 2048, 1080)
LEVELS = ("draft", "preview", "final", "reference")
TRUNCATION = {"draft": None, "preview": 2.0, "final": 4.0, "reference": 6.0}


def run(rt, src, quality="final", frame=0, look_seed=0, data_window=None, display=DISPLAY_2K,
        **kw):
    p = Grain.params(**kw)
    out = Grain().apply(rt, p, src, quality=quality, frame=frame, seed=look_seed,
                        data_window=data_window, display_window=display)
    return out, p


def flat(h, w, value=0.18):
    src = np.full((h, w, 4), value, np.float32)
    src[..., 3] = 1.0
    return src


def unit_noise(out, p, level=0.18):
    """The grain field n_c of a flat render at luminance ``level`` (undo the mix)."""
    amounts = np.array(STOCKS[p.stock].amount) * np.array(p.channel_amount)
    sigma = p.amount * amounts * 0.18 * (level / 0.18) ** p.response
    return (out[..., :3].astype(np.float64) - level) / sigma


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
    kw = dict(stock="fast-500t", amount=0.1, size=2.5, response=0.5, seed=3)
    got, p = run(rt, src, frame=5, look_seed=9, **kw)
    want = reference(src, **p.as_dict(), frame=5, look_seed=9, display_width=2048,
                     truncation=TRUNCATION["final"])
    # float32 noise (polynomial log/sincos, rel. error ~2e-7, x |n| <= 6) summed over <= 21
    # taps per pass, mixed into values <= 2.2: a few 1e-7 absolute; 2e-6 leaves margin.
    np.testing.assert_allclose(got, want, rtol=2e-6, atol=2e-6)
    np.testing.assert_array_equal(got[..., 3], src[..., 3])


@pytest.mark.parametrize("quality", LEVELS)
def test_each_level_matches_its_own_filter(rt, rng, quality):
    src = rng.uniform(0.0, 1.0, (23, 41, 4)).astype(np.float32)
    kw = dict(amount=0.2, size=1.7, monochrome=quality == "preview", response=0.3)
    got, p = run(rt, src, quality, frame=2, **kw)
    want = reference(src, **p.as_dict(), frame=2, display_width=2048,
                     truncation=TRUNCATION[quality])
    # same tolerance argument as above (reference: float64 throughout, output rounding only)
    np.testing.assert_allclose(got, want, rtol=2e-6, atol=2e-6)


def test_error_falls_monotonically_with_quality(rt, rng):
    src = rng.uniform(0.0, 1.0, (40, 56, 4)).astype(np.float32)
    kw = dict(stock="medium-250d", amount=0.1, size=2.0, seed=11)
    p = Grain.params(**kw)
    want = reference(src, **p.as_dict(), frame=4, display_width=2048, truncation=6.0)
    errors = [np.abs(run(rt, src, q, frame=4, **kw)[0] - want).max() for q in LEVELS]
    assert all(a >= b for a, b in zip(errors, errors[1:])), errors
    # reference: float64 noise and sums; only the float32 store of values <= ~1.5 remains
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
    want = reference_uniform(0xDEADBEEF, -5, i - 37, 3 * i - 100, i % 7)
    np.testing.assert_array_equal(out, want.astype(np.float32))


# -- statistics -------------------------------------------------------------------------------
def test_mean_is_preserved(rt):
    h = w = 256
    out, p = run(rt, flat(h, w), amount=0.05, size=1.5, seed=1)
    _, weights = grain_weights([1.5] * 3, 4.0)
    taps = weights[:, 1]
    sigma = 0.05 * 0.18
    # Var(mean of N correlated samples) ~= sigma^2 (sum taps)^4 / N (separable kernel)
    sd_mean = sigma * np.sum(taps) ** 2 / math.sqrt(h * w)
    for c in range(3):
        assert abs(out[..., c].astype(np.float64).mean() - 0.18) <= 3 * sd_mean  # 3 sigma


def test_variance_follows_luminance_response(rt):
    levels = (0.01, 0.18, 4.0)
    band = 160
    src = np.concatenate([flat(band, 256, v) for v in levels], axis=0)
    out, p = run(rt, src, amount=0.05, size=1.2, response=0.5, seed=2)
    _, weights = grain_weights([1.2] * 3, 4.0)
    n_eff = effective_count(band * 256, weights[:, 1])
    rel_sd = math.sqrt(2.0 / n_eff) / 2  # relative standard error of a standard deviation
    for i, v in enumerate(levels):
        part = out[i * band:(i + 1) * band, :, :3].astype(np.float64)
        want = 0.05 * 0.18 * (v / 0.18) ** 0.5
        got = part.std(axis=(0, 1))
        np.testing.assert_allclose(got / want, 1.0, atol=4 * rel_sd)  # 4 standard errors


def test_response_zero_is_additive_and_one_is_proportional(rt):
    src = np.concatenate([flat(64, 256, 0.05), flat(64, 256, 2.0)], axis=0)
    add, _ = run(rt, src, amount=0.05, size=0.0, response=0.0)
    prop, _ = run(rt, src, amount=0.05, size=0.0, response=1.0)
    n = 64 * 256
    tol = 4 * math.sqrt(2.0 / n) / 2  # white noise: 4 standard errors of the sd
    for i, v in enumerate((0.05, 2.0)):
        a = (add[i * 64:(i + 1) * 64, :, :3] - v).std()
        b = (prop[i * 64:(i + 1) * 64, :, :3] - v).std()
        assert abs(a / (0.05 * 0.18) - 1) <= tol
        assert abs(b / (0.05 * v) - 1) <= tol


def test_autocorrelation_matches_grain_size(rt):
    """Per-channel sizes of a stock give per-channel correlation lengths as predicted."""
    h = w = 384
    out, p = run(rt, flat(h, w), stock="fast-500t", amount=0.05, size=1.5, seed=5)
    noise = unit_noise(out, p)
    sizes = [1.5 * s for s in STOCKS["fast-500t"].size]
    _, weights = grain_weights(sizes, 4.0)
    for c in range(3):
        n = noise[..., c] - noise[..., c].mean()
        var = np.mean(n * n)
        for lag in (1, 2, 3):
            want = autocorrelation(weights[:, c], lag)
            got_x = np.mean(n[:, :-lag] * n[:, lag:]) / var
            got_y = np.mean(n[:-lag] * n[lag:]) / var
            # standard error of a correlation over N_eff ~ 147k / (8 pi sigma^2) samples is
            # ~0.01-0.02 here; 0.06 is about 4 standard errors
            assert abs(got_x - want) <= 0.06, (c, lag, got_x, want)
            assert abs(got_y - want) <= 0.06, (c, lag, got_y, want)
    # blue grain is the largest in this stock, green the smallest
    lag3 = [np.mean(noise[:, :-3, c] * noise[:, 3:, c]) / np.var(noise[..., c]) for c in range(3)]
    assert lag3[2] > lag3[0] > lag3[1]


def test_unit_variance_normalisation_for_any_size(rt):
    for size in (0.0, 0.3, 3.0):
        out, p = run(rt, flat(256, 256), amount=0.05, size=size, seed=8)
        _, weights = grain_weights([size] * 3, 4.0)
        n_eff = effective_count(256 * 256, weights[:, 1])
        sd = unit_noise(out, p).std(axis=(0, 1))
        np.testing.assert_allclose(sd, 1.0, atol=4 * math.sqrt(2 / n_eff) / 2)


def test_frames_are_uncorrelated_and_differ(rt):
    h = w = 256
    a, p = run(rt, flat(h, w), frame=10, amount=0.05, size=1.0)
    b, _ = run(rt, flat(h, w), frame=11, amount=0.05, size=1.0)
    na, nb = unit_noise(a, p), unit_noise(b, p)
    _, weights = grain_weights([1.0] * 3, 4.0)
    n_eff = effective_count(h * w, weights[:, 1])
    for c in range(3):
        r = np.corrcoef(na[..., c].ravel(), nb[..., c].ravel())[0, 1]
        assert abs(r) <= 4 / math.sqrt(n_eff)  # 4 standard errors of a zero correlation
    assert not np.array_equal(a, b)


def test_colour_channels_are_independent_and_monochrome_shares_one_field(rt):
    colour, p = run(rt, flat(256, 256), amount=0.05, size=1.0)
    n = unit_noise(colour, p)
    r = np.corrcoef(n[..., 0].ravel(), n[..., 1].ravel())[0, 1]
    assert abs(r) < 0.05
    for kw in (dict(monochrome=True), dict(stock="mono-400")):
        mono, p = run(rt, flat(32, 32), amount=0.05, size=1.0, **kw)
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
    full_src = rng.uniform(0.0, 1.0, (40, 60, 4)).astype(np.float32)
    full, _ = run(rt, full_src, quality, frame=7, amount=0.1, size=2.0,
                  data_window=Rect(100, 50, 160, 90))
    crop_src = full_src[7:28, 13:43]
    crop, _ = run(rt, crop_src, quality, frame=7, amount=0.1, size=2.0,
                  data_window=Rect(113, 57, 143, 78))
    assert crop.tobytes() == np.ascontiguousarray(full[7:28, 13:43]).tobytes()


# -- hard cases -------------------------------------------------------------------------------
@pytest.mark.parametrize("quality", LEVELS)
def test_hard_values_stay_finite_and_alpha_is_kept(rt, quality):
    vals = np.array([-1.0, 0.0, 1e-30, 65504.0, 1e5, 3.4e38, np.nan, np.inf, -np.inf],
                    np.float32)
    src = np.repeat(vals[None, :, None], 4, axis=2)
    src = np.repeat(src, 3, axis=0)
    out, _ = run(rt, src, quality, amount=1.0, size=3.0, response=1.0,
                 channel_amount=(4.0, 4.0, 4.0))
    assert np.isfinite(out).all()
    # alpha bit for bit where finite; NaN / Inf (colour or alpha) become 0 first
    assert out[:, :6, 3].tobytes() == src[:, :6, 3].tobytes()
    np.testing.assert_array_equal(out[:, 6:, 3], 0.0)
    assert np.isfinite(run(rt, wide_range_image(np.random.default_rng(1)), quality,
                           amount=1.0, size=3.0, response=1.0)[0]).all()


def test_huge_grain_on_tiny_image(rt, rng):
    src = rng.uniform(0.0, 1.0, (3, 5, 4)).astype(np.float32)
    got, p = run(rt, src, amount=0.1, size=20.0, display=Rect(0, 0, 4096, 2160))
    want = reference(src, **p.as_dict(), display_width=4096, truncation=4.0)
    np.testing.assert_allclose(got, want, rtol=2e-6, atol=2e-6)  # as the oracle test


def test_size_is_resolution_independent(rt):
    """Grain at half resolution has half the correlation length in pixels."""
    out, p = run(rt, flat(192, 192), amount=0.05, size=3.0, display=Rect(0, 0, 1024, 540))
    n = unit_noise(out, p)[..., 1]
    _, weights = grain_weights([1.5] * 3, 4.0)  # 3 px at 2K = 1.5 px at 1K
    got = np.mean(n[:, :-1] * n[:, 1:]) / np.mean(n * n)
    assert abs(got - autocorrelation(weights[:, 1], 1)) <= 0.06


def test_zero_amount_is_identity_with_reason(rt, rng):
    src = rng.uniform(0.0, 1.0, (9, 9, 4)).astype(np.float32)
    p = Grain.params(amount=0.0)
    assert Grain().is_identity(p, None) == "amount is 0"
    assert Grain().is_identity(Grain.params(channel_amount=(0, 0, 0)), None)
    assert Grain().is_identity(Grain.params(), None) is None
    assert np.array_equal(Grain().apply(rt, p, src), src)


def test_descriptor_and_params():
    d = Grain.descriptor
    assert d.frame_varying and not d.spreads_light
    assert set(d.quality) == set(LEVELS)
    assert set(STOCKS) == set(d.param("stock").choices)
    with pytest.raises(ParamError):
        Grain.params(stock="kodak-9999")
    with pytest.raises(ParamError):
        Grain.params(amount=-0.1)


def test_bench_case_renders(rt, rng):
    case = CASE.make(64, 36, rng)
    p = Grain.params(**case["params"])
    out = Grain().apply(rt, p, case["source"], camera=case["camera"])
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
