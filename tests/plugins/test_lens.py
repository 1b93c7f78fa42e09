import lensfunpy
import numpy as np
import pytest

from clfx.fx import lensdb
from clfx.core.camera import Camera
from clfx.core.errors import ParamError
from clfx.plugins.lens import Lens, channel_points
from clfx.core.rect import Rect
from tests.reference import lens as ref
from tests.plugins.test_distortion import (nonfinite_image, render_with_notes, smooth_image,
                                           wide_range_image)
from tests.effects import render_effect

CANON = ("Canon", "Canon EF 24-70mm f/2.8L II USM")       # ptlens + poly3 TCA + pa vignetting
LENSES = [  # (maker, model, focal mm, camera crop): one per model family
    ("Canon", "Canon EF 24-70mm f/2.8L II USM", 30.0, 1.6),                 # ptlens, TCA poly3
    ("", "Beroflex 1:8 500mm", 500.0, 1.6),                                 # poly3, TCA poly3
    ("Nikon", "Nikon AF-S DX Nikkor 35mm f/1.8G", 35.0, 1.6),               # ptlens, TCA linear
    ("", "Canon PowerShot G12 & compatibles (Standard)", 10.0, 4.63),       # poly5
]
FLAGS = lensfunpy.ModifyFlags


def camera_for_crop(crop, w, h, **kw):
    """A camera block whose sensor has crop factor ``crop`` at the frame's aspect."""
    diag = lensdb.FULL_FRAME_DIAGONAL_MM / crop
    sw = diag * w / np.hypot(w, h)
    return Camera(sensor_width=sw, **kw)


def lensfun_points(lens, crop, w, h, focal, flags):
    """lensfunpy's reverse (simulating) per-channel coordinates, one column per call.

    One column keeps lensfun on its scalar code path: its SSE path (4+ points per call)
    inverts with _mm_rcp_ps/_mm_rsqrt_ps approximations and is itself off by up to ~0.35 px
    at 1080p (measured), so it cannot serve as a 1e-2 px reference."""
    m = lensfunpy.Modifier(lens, crop, w, h)
    m.initialize(focal, 2.8, 1000.0, scale=1.0, flags=flags, reverse=True)
    return np.concatenate([m.apply_subpixel_geometry_distortion(x, 0, 1, h) for x in range(w)], 1)


@pytest.mark.parametrize("maker,model,focal,crop", LENSES)
def test_coordinates_agree_with_lensfun(maker, model, focal, crop):
    w, h = 150, 100
    lens = lensdb.get_lens(maker, model, crop)
    cal = lensdb.calibration(lens, focal, 2.8, 1000.0)
    norm = lensdb.Normalisation.for_image(cal, crop, w, h)
    win = Rect(0, 0, w, h)
    pts, _ = channel_points(cal, norm, win, win)
    want = lensfun_points(lens, crop, w, h, focal, FLAGS.DISTORTION | FLAGS.TCA)
    for i, c in enumerate(("red", "green", "blue")):
        sx, sy = pts[c]
        err = np.hypot(want[..., i, 0] - (sx - 0.5), want[..., i, 1] - (sy - 0.5))
        # brief: 1e-2 px; measured ~1e-3 (lensfun's float32 Newton, NEWTON_EPS 1e-5)
        assert np.nanmax(err) < 1e-2, (c, np.nanmax(err))


def test_vignetting_agrees_with_lensfun(rt):
    w, h = 90, 60
    cam = camera_for_crop(1.6, w, h, focal_length=30.0, f_number=4.0, focus_distance=3.0)
    lens = lensdb.get_lens(*CANON, 1.6)
    m = lensfunpy.Modifier(lens, 1.6, w, h)
    m.initialize(30.0, 4.0, 3.0, scale=1.0, pixel_format=np.float32, flags=FLAGS.VIGNETTING,
                 reverse=True)
    ones = np.ones((h, w, 3), np.float32)
    m.apply_color_modification(ones)
    p = Lens.params(maker=CANON[0], model=CANON[1], distortion=False, tca=False)
    src = np.ones((h, w, 4), np.float32)
    got = render_effect(rt, Lens(), p, src, camera=cam, quality="draft")
    # float32 polynomial on both sides
    np.testing.assert_allclose(got[..., :3], ones, rtol=2e-6, atol=1e-6)
    np.testing.assert_array_equal(got[..., 3], 1.0)


def oracle(src, p, cam, quality_filter, crop):
    assert p.fit == "none" or not p.distortion      # the oracle is lensfun's: scale 1
    h, w = src.shape[:2]
    lens = lensdb.get_lens(p.maker, p.model, crop)
    cal = lensdb.calibration(lens, cam.focal_length, cam.f_number, cam.focus_distance)
    return ref.lens(src, filter_name=quality_filter, border=p.border, crop=crop,
                    cal_crop=cal.crop_factor, cal_aspect=cal.aspect_ratio,
                    center=(cal.center_x, cal.center_y),
                    distortion=cal.distortion if p.distortion else None,
                    tca=cal.tca if p.tca else None,
                    vignetting=cal.vignetting[1] if p.vignetting else None)


@pytest.mark.parametrize("quality,filt", [("draft", "bilinear"), ("preview", "bicubic"),
                                          ("final", "lanczos3"), ("reference", "lanczos3")])
def test_matches_reference(rt, rng, quality, filt):
    h, w = 40, 60
    src = rng.uniform(0.0, 1.0, (h, w, 4)).astype(np.float32)
    cam = camera_for_crop(1.0, w, h, focal_length=24.0, f_number=2.8, focus_distance=2.0)
    p = Lens.params(maker=CANON[0], model=CANON[1], border="mirror", fit="none")
    got = render_effect(rt, Lens(), p, src, camera=cam, quality=quality)
    want = oracle(src, p, cam, filt, 1.0)
    # float32 map/LUT (~1e-6 px) and sums; reference float64 with float32 output
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-7 if quality == "reference" else 1e-5)


def test_error_falls_monotonically_with_quality(rt, rng):
    h, w = 40, 60
    src = smooth_image(rng, h, w)
    cam = camera_for_crop(1.0, w, h, focal_length=24.0, f_number=2.8, focus_distance=2.0)
    p = Lens.params(maker=CANON[0], model=CANON[1], fit="none")
    want = oracle(src, p, cam, "lanczos3", 1.0)
    errs = [np.abs(render_effect(rt, Lens(), p, src, camera=cam, quality=q) - want).max()
            for q in ("draft", "preview", "final", "reference")]
    assert all(a >= b for a, b in zip(errs, errs[1:])), errs


def test_hdr_edge_does_not_ring(rt):
    src = np.full((30, 45, 4), 0.01, np.float32)
    src[:, 22:] = 1e5
    p = Lens.params(maker=CANON[0], model=CANON[1], vignetting=False)
    got = render_effect(rt, Lens(), p, src, camera=Camera(focal_length=24.0), quality="final")
    assert got.min() >= 0.0 and got.max() <= 1e5 * (1 + 1e-6)


def test_identity_and_errors(rt):
    p = Lens.params(model="x", distortion=False, tca=False, vignetting=False)
    assert Lens().is_identity(p, None) == "distortion, tca and vignetting are all off"
    with pytest.raises(ParamError, match="no lens chosen"):
        Lens().is_identity(Lens.params(), None)
    with pytest.raises(ParamError, match="no lens 'Canon EF 24-70mm f/2.9'"):
        render_effect(rt, Lens(), Lens.params(model="Canon EF 24-70mm f/2.9"),
                      np.ones((4, 4, 4), np.float32))
    # a compact camera's lens on a full-frame sensor folds over before the corner
    with pytest.raises(ParamError, match="poly5 distortion.*fold over"):
        render_effect(rt, Lens(), Lens.params(model=LENSES[3][1], focal_length=10.0),
                      np.ones((20, 30, 4), np.float32), camera=Camera(sensor_width=36.0))


def test_find_lenses():
    hits = lensdb.find_lenses("canon 24-70 2.8L II")
    assert any(h["model"] == CANON[1] for h in hits)
    assert {"maker", "model", "focal_range", "distortion", "tca", "vignetting"} <= set(hits[0])
    assert len(lensdb.find_lenses("", limit=7)) == 7
    assert lensdb.find_lenses("no such lens qwerty") == []


def test_fill_reads_only_inside_the_frame():
    w, h = 120, 80
    lens = lensdb.get_lens(*CANON, 1.0)
    cal = lensdb.calibration(lens, 24.0, 2.8, 1000.0)
    norm = lensdb.Normalisation.for_image(cal, 1.0, w, h)
    win = Rect(0, 0, w, h)
    from clfx.plugins.lens import simulation_geometry
    gx, gy, info = simulation_geometry(cal, norm, win, win, "fill")
    assert info["fit_scale"] != 1.0
    # pixel centres read inside the frame's outline (1e-3 px: boundary sampling)
    assert gx.min() >= -1e-3 and gx.max() <= w + 1e-3
    assert gy.min() >= -1e-3 and gy.max() <= h + 1e-3


@pytest.mark.parametrize("quality,filt", [("draft", "bilinear"), ("final", "lanczos3")])
@pytest.mark.parametrize("distortion,tca,vignetting,border", [
    (True, False, False, "black"), (False, True, False, "edge"), (False, False, True, "black"),
    (True, True, False, "mirror"), (False, True, True, "black")])
def test_packed_channels_match_reference(rt, rng, quality, filt, distortion, tca, vignetting,
                                         border):
    """Each channel's packed map (and the in-place read without one) against the oracle,
    interior quads (fast kernel) and border quads (checked kernel) alike."""
    h, w = 37, 70          # not a multiple of 4: padded quads
    src = rng.uniform(0.0, 1.0, (h, w, 4)).astype(np.float32)
    cam = camera_for_crop(1.0, w, h, focal_length=24.0, f_number=2.8, focus_distance=2.0)
    p = Lens.params(maker=CANON[0], model=CANON[1], distortion=distortion, tca=tca,
                    vignetting=vignetting, border=border, fit="none")
    got = render_effect(rt, Lens(), p, src, camera=cam, quality=quality)
    want = oracle(src, p, cam, filt, 1.0)
    # float32 fractions (~6e-8 px) and float32 sums of values <= 1
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-5)


@pytest.mark.parametrize("quality", ["draft", "preview", "final", "reference"])
@pytest.mark.parametrize("distortion,tca", [(True, True), (False, False)])
def test_nan_and_inf_become_zero_and_finite_input_stays_finite(rt, rng, quality, distortion,
                                                               tca):
    cam = Camera(focal_length=24.0, f_number=2.8, focus_distance=2.0)
    p = Lens.params(maker=CANON[0], model=CANON[1], distortion=distortion, tca=tca)
    src = nonfinite_image(rng)
    got, notes = render_with_notes(rt, Lens(), p, src, quality=quality, camera=cam)
    assert np.isfinite(got).all()
    assert "lens: 4 non-finite pixel(s) read as 0" in notes
    clean = np.nan_to_num(src, nan=0.0, posinf=0.0, neginf=0.0)
    np.testing.assert_array_equal(got, render_effect(rt, Lens(), p, clean, quality=quality,
                                                     camera=cam))
    got = render_effect(rt, Lens(), p, wide_range_image(rng), quality=quality, camera=cam)
    assert np.isfinite(got).all()


@pytest.mark.parametrize("quality", ["draft", "final"])
@pytest.mark.parametrize("fit", ["none", "fill"])
def test_maps_built_in_bands_are_the_whole_frame_maps(rt, rng, monkeypatch, quality, fit):
    """Frames larger than a band build their packed map band by band (an 8K frame's float64
    points took 7.5 GB of peak memory for `real-lens`); the TCA tables' scale (the largest
    green radius, found band by band) and so the pixels are the same."""
    import clfx.fx.resample as resample

    h, w = 97, 203
    cam = camera_for_crop(1.6, w, h, focal_length=30.0, f_number=2.8, focus_distance=3.0)
    src = rng.uniform(0.0, 2.0, (h, w, 4)).astype(np.float32)
    p = Lens.params(maker=CANON[0], model=CANON[1], fit=fit, border="mirror",
                    aperture=2.8 + rng.uniform(0, 1e-6))
    whole = render_effect(rt, Lens(), p, src, quality=quality, camera=cam)
    rt.cache.clear("lens.geometry")
    rt.cache.clear("lens.device")
    monkeypatch.setattr(resample, "BAND_PIXELS", 2048)          # 10-row bands
    assert len(resample.map_bands(h, 204)) == 10
    banded = render_effect(rt, Lens(), p, src, quality=quality, camera=cam)
    assert np.array_equal(banded, whole)


@pytest.mark.parametrize("quality", ["draft", "final", "reference"])
@pytest.mark.parametrize("fit,border", [("none", "edge"), ("fill", "black"), ("none", "mirror")])
def test_tight_window_gives_the_full_frame_pixels(rt, rng, quality, fit, border):
    """An element in its own data window gives the pixels it gives placed in a full-frame
    window: what the lens carries past the box is kept (the window grows)."""
    from clfx.core.rect import Rect
    from tests.plugins.windows import element, tight_and_full

    display, data = Rect(0, 0, 120, 80), Rect(66, 40, 116, 76)
    cam = camera_for_crop(1.0, 120, 80, focal_length=24.0, f_number=2.8, focus_distance=2.0)
    p = Lens.params(maker=CANON[0], model=CANON[1], fit=fit, border=border)
    tight, full, window = tight_and_full(rt, Lens(), p, element(rng, data), data, display,
                                         quality=quality, camera=cam)
    # TCA tables span the window's largest radius (~1e-5 px apart), values <= 4: <= 4e-6
    np.testing.assert_allclose(tight, full, rtol=0, atol=3e-5)
    assert window.contains(data) and window != data and display.contains(window)
