import math

import numpy as np
import pytest

from clfx.fx import spectral
from clfx.core.camera import Camera
from clfx.host import RenderContext
from clfx.plugins.corona import (Corona, PSFGeometry, aperture, far_field,
                                 monochromatic_psf, spectral_psf)
from clfx.core.rect import Rect
from tests.conftest import hard_shapes
from tests.reference.corona import corona as reference

PARAMS = dict(threshold=2.0, intensity=0.5, size=0.05, extent=4.0)


def scene(rng, shape, hot=1e4):
    src = rng.uniform(0.0, 0.5, shape + (4,)).astype(np.float32)
    h, w = shape
    src[h // 3, w // 2, :3] = hot
    src[(2 * h) // 3, w // 5, :3] = (40.0, 20.0, 5.0)
    return src


def psf_for(plugin, rt, p, src, quality, **ctx_kw):
    ctx = RenderContext(rt, rt.upload(src), quality=quality, **ctx_kw)
    return plugin.psf(p, ctx)


@pytest.mark.parametrize("shape", hard_shapes())
def test_corona_matches_reference(rt, rng, shape):
    src = scene(rng, shape)
    p = Corona.params(**PARAMS)
    plugin = Corona()
    for quality in ("final", "reference"):
        got = plugin.apply(rt, p, src, quality=quality)
        want = reference(src, psf_for(plugin, rt, p, src, quality), **p.as_dict())
        # float32 image and PSF storage (FFT in float64): ~1e-7 of the largest value
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6 * np.abs(want).max())


def test_error_falls_with_quality(rt, rng):
    src = scene(rng, (40, 56))
    p = Corona.params(**PARAMS)
    plugin = Corona()
    want = reference(src, psf_for(plugin, rt, p, src, "reference"), **p.as_dict())
    errs = [np.abs(plugin.apply(rt, p, src, quality=q) - want).max()
            for q in ("draft", "preview", "final", "reference")]
    assert errs[0] >= errs[1] >= errs[2] >= errs[3], errs


def first_dark_ring(profile):
    """Sub-pixel radius of the first local minimum of a radial profile (parabola fit)."""
    i = next(i for i in range(1, len(profile) - 1)
             if profile[i] <= profile[i - 1] and profile[i] <= profile[i + 1])
    a, b, c = profile[i - 1:i + 2]
    return i + 0.5 * (a - c) / (a - 2 * b + c)


def test_ring_radius_proportional_to_wavelength():
    r0 = 13.0
    radius = int(math.ceil(8 * r0 * 780 / 550))
    geom = PSFGeometry(r0, radius)
    field = far_field(aperture(geom.m, geom.diameter, 0, 0.0))
    rings = {lam: first_dark_ring(monochromatic_psf(field, geom, lam)[radius, radius:])
             for lam in (420.0, 500.0, 550.0, 620.0, 700.0)}
    for a in rings:
        for b in rings:
            assert abs(rings[a] / rings[b] / (a / b) - 1) < 0.02, rings   # brief: within 2 %
    assert abs(rings[550.0] / r0 - 1) < 0.03          # size = first dark ring at 550 nm


def test_round_aperture_far_field_is_airy():
    from scipy.special import j1

    r0 = 12.0
    geom = PSFGeometry(r0, 60)
    psf = monochromatic_psf(far_field(aperture(geom.m, geom.diameter, 0, 0.0)), geom, 550.0)
    x = np.arange(1, 61) * 3.8317059702075125 / r0
    airy = (2 * j1(x) / x) ** 2
    prof = psf[60, 61:] / psf[60, 60]
    # discretised aperture and bilinear resampling: a few % of the peak
    np.testing.assert_allclose(prof, airy, atol=0.02)


def test_white_balance_and_rainbow():
    k = spectral_psf(10.0, 6.0, 0, 0.0, 40)
    # a spectrally flat light: each channel sums to 1 -> neutral integral
    np.testing.assert_allclose(k.sum(axis=(0, 1)), 1.0, rtol=1e-12)
    assert k.min() >= 0.0
    # the equal-energy spectrum E is pinkish against D65 white (RGB ~ 1.18 : 0.93 : 0.89),
    # which is why the PSF is white-balanced per channel
    e = spectral.spectral_rgb_weights(spectral.wavelengths(400)).sum(axis=0)
    np.testing.assert_allclose(e / e.mean(), [1.18, 0.93, 0.89], atol=0.01)
    # rings run through the rainbow: red's pattern is wider, so the rim of the central disk
    # (r0 = 10 px at 550 nm) is red, and just outside it blue's first bright ring dominates
    r = k.shape[0] // 2
    row = k[r, r:]
    chroma = row[:, 0] / np.maximum(row[:, 2], 1e-30)
    assert chroma[9] > 2.0 and chroma[11] < 0.5


def test_polygon_aperture_symmetry():
    ap = aperture(128, 40.0, 6, 0.0)
    assert abs(ap.sum() - 3 * math.sqrt(3) / 2 * 20 ** 2) / ap.sum() < 0.01   # hexagon area
    k = spectral_psf(8.0, 4.0, 6, 0.0, 16)
    rot = np.rot90(k, 2)                            # a centro-symmetric far field
    np.testing.assert_allclose(k, rot, atol=1e-9 * k.max())


def test_cie_fit_peaks():
    lam = np.arange(380.0, 781.0, 1.0)
    cmf = spectral.cie1931_cmf(lam)
    assert abs(lam[cmf[:, 1].argmax()] - 556) <= 3 and abs(cmf[:, 1].max() - 1.0) < 0.01
    # white (D65-ish) should map to roughly equal RGB; E is close
    assert np.allclose(spectral.xyz_to_rec709([0.95047, 1.0, 1.08883]), 1.0, atol=1e-3)


def test_identities(rt, rng):
    src = rng.uniform(0.0, 1.5, (9, 13, 4)).astype(np.float32)
    for kw in ({"intensity": 0.0}, {}):
        got = Corona().apply(rt, Corona.params(**{**PARAMS, **kw}), src)
        assert np.array_equal(got, src)


def test_hdr_energy_no_negatives_and_shadows(rt):
    src = np.full((96, 96, 4), 0.01, np.float32)
    src[48, 48, :3] = 1e5
    p = Corona.params(**{**PARAMS, "size": 0.03, "extent": 5.0})
    for quality in ("preview", "final"):
        got = Corona().apply(rt, p, src, quality=quality)
        assert got.min() >= 0.0
        added = (got.astype(np.float64) - src)[..., :3].sum(axis=(0, 1))
        # the PSF (radius 29 px) stays inside: energy = intensity * highlight (float32 sums)
        np.testing.assert_allclose(added, 0.5 * (1e5 - 2.0), rtol=1e-5)
        # shadows far from the light keep their value (HDR-safe convolution)
        np.testing.assert_allclose(got[2:8, 2:8, :3], 0.01, rtol=1e-4)


def test_deterministic_and_alpha(rt, rng):
    src = scene(rng, (50, 70))
    src[..., 3] = rng.uniform(0, 1, (50, 70))
    p = Corona.params(**PARAMS)
    a = Corona().apply(rt, p, src)
    b = Corona().apply(rt, p, src)
    assert a.tobytes() == b.tobytes()
    np.testing.assert_array_equal(a[..., 3], src[..., 3])


def test_rod_grows(rt):
    src = np.zeros((16, 16, 4), np.float32)
    src[8, 1, :3] = 1e3
    data, display = Rect(20, 20, 36, 36), Rect(0, 0, 60, 60)
    p = Corona.params(**PARAMS)
    plugin = Corona()
    out, win = plugin.apply(rt, p, src, data_window=data, display_window=display,
                            keep_rod=True)
    assert win.x0 < data.x0 and win.contains(data)
    assert out[8 + data.y0 - win.y0, :data.x0 - win.x0, 1].max() > 0.0
    k = psf_for(plugin, rt, p, src, "final", display_window=display)
    r = k.shape[0] // 2
    want = reference(src, k, **p.as_dict(), pad=r)          # covers data grown by r
    off = data.x0 - r - win.x0, data.y0 - r - win.y0
    x0, y0 = max(0, -off[0]), max(0, -off[1])
    crop = want[y0:y0 + out.shape[0], x0:x0 + out.shape[1]]
    np.testing.assert_allclose(out[max(0, off[1]):max(0, off[1]) + crop.shape[0],
                                   max(0, off[0]):max(0, off[0]) + crop.shape[1]],
                               crop, rtol=1e-5, atol=1e-6 * want.max())


def test_camera_blades_change_the_psf(rt, rng):
    src = scene(rng, (30, 30))
    p = Corona.params(**PARAMS)
    a = psf_for(Corona(), rt, p, src, "draft", camera=Camera(blades=0))
    b = psf_for(Corona(), rt, p, src, "draft", camera=Camera(blades=5))
    assert a.shape == b.shape and np.abs(a - b).max() > 1e-4


def test_huge_size_is_capped_and_finite(rt, rng):
    src = scene(rng, (17, 31))
    p = Corona.params(**{**PARAMS, "size": 0.2, "extent": 40.0})
    plugin = Corona()
    got = plugin.apply(rt, p, src, quality="draft")
    assert np.isfinite(got).all() and got.min() >= 0.0
    k = psf_for(plugin, rt, p, src, "draft")
    assert k.shape[0] <= 2 * (1.5 * math.hypot(17, 31) + 2) + 1      # radius capped
    np.testing.assert_allclose(k.sum(axis=(0, 1)), 1.0, rtol=1e-12)


def test_psf_grid_stays_bounded_for_many_rings():
    from clfx.plugins.corona import MAX_GRID, psf_radius
    g = PSFGeometry(40.0, psf_radius(40.0, 30.0))
    assert g.m <= MAX_GRID and g.bins_per_ring >= 4
