
import math

import cv2
import numpy as np
import pytest

from clfx.core.camera import Camera
from clfx.core.errors import ParamError
from clfx.plugins.distortion import Distortion, build_map, coefficients, intrinsics
from clfx.core.rect import Rect
from clfx.fx.resample import FootprintMap
from tests.conftest import hard_shapes
from tests.reference import distortion as ref
from tests.effects import render_effect

CAM = Camera(focal_length=24.0, sensor_width=36.0)
QUALITY_FOOTPRINT = {"draft": "quadratic", "preview": "bicubic", "final": "lanczos3",
                     "reference": "elliptical"}


def smooth_image(rng, h, w):
    """Band-limited RGBA (sums of low-frequency cosines) so filter errors rank cleanly."""
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    out = np.empty((h, w, 4))
    for c in range(4):
        a, b, ph = rng.uniform(0.05, 0.35, 3)
        out[..., c] = 1.0 + 0.5 * np.cos(a * xs + b * ys + 6 * ph)
    return out.astype(np.float32)


WIDE_VALUES = np.array([-1e38, 1e38, 1.7e38, 65504.0, -65504.0, 1e-30, 0.0, 1.0, -1.0],
                       np.float32)
"""Finite values across float32's range (half's largest, 2^127, 1e38) for the finite-in,
finite-out checks (issue 10: WideFloatRange.exr and AllHalfValues.exr hold such values)."""


def wide_range_image(rng, h=13, w=22):
    """Every channel drawn from WIDE_VALUES: neighbours jump across the whole range."""
    return rng.choice(WIDE_VALUES, size=(h, w, 4)).astype(np.float32)


def nonfinite_image(rng, h=12, w=18):
    """Values in [0, 1] with NaN, +Inf and -Inf in colour and alpha (4 pixels affected)."""
    src = rng.uniform(0.0, 1.0, (h, w, 4)).astype(np.float32)
    src[2, 3] = np.nan
    src[5, 9, 1] = np.inf
    src[8, 4, 3] = -np.inf
    src[h - 1, w - 1, 0] = np.nan
    return src


def render_with_notes(rt, plugin, p, src, **kw):
    """(output, ctx.notes) of one render of ``src`` (frame analysis computed on demand)."""
    from clfx.host import RenderContext

    ctx = RenderContext(rt, rt.upload(src), **kw)
    return rt.download(plugin.render(rt, p, ctx)), ctx.notes


def half_fractions(p, w, h, border, display=None, data=None, camera=CAM):
    """The pixels whose draft (quadratic) offsets the kernel reads as float16 from the packed
    map (its fast path: ``FootprintMap.fast_pixels``), for the oracle's ``half``."""
    display = display or Rect(0, 0, w, h)
    data = data or display
    sx, sy, info = build_map(p, camera, display, data, 1.0, jacobian=True)
    pitch = -(-w // 4) * 4
    m = FootprintMap(sx - data.x0, sy - data.y0, info["jacobian"], "quadratic", w, h, pitch,
                     border)
    return m.fast_pixels[:, :w]


def oracle_args(p, w, h, pixel_aspect=1.0, camera=CAM):
    win = Rect(0, 0, w, h)
    fx, fy, cx, cy = intrinsics(p, camera, win, pixel_aspect)
    k1, k2, k3, p1, p2 = coefficients(p, camera, win, pixel_aspect)
    _, _, info = build_map(p, camera, win, win, pixel_aspect)
    return dict(k1=k1, k2=k2, k3=k3, p1=p1, p2=p2, fx=fx, fy=fy, cx=cx, cy=cy,
                fit_scale=info["fit_scale"])


# -- the map against OpenCV ----------------------------------------------------------------
@pytest.mark.parametrize("coeffs", [
    dict(k1=-0.25, k2=0.08, k3=-0.01),                               # wide-angle barrel
    dict(k1=0.15, k2=-0.02),                                          # pincushion tele
    dict(k1=-0.28, k2=0.09, k3=-0.012, p1=0.0015, p2=-0.0008),       # typical calibration
    dict(k1=0.05, p1=-0.004, p2=0.003, fx=700.0, fy=690.0, cx=330.2, cy=172.9),
])
def test_map_agrees_with_opencv(coeffs):
    w, h = 640, 360
    p = Distortion.params(fit="none", **coeffs)   # the model itself, unscaled
    win = Rect(0, 0, w, h)
    sx, sy, info = build_map(p, CAM, win, win, 1.0)
    fx, fy, cx, cy = info["fx"], info["fy"], info["cx"], info["cy"]
    K = np.array([[fx, 0, cx - 0.5], [0, fy, cy - 0.5], [0, 0, 1]])   # OpenCV: centres at ints
    k1, k2, k3, p1, p2 = info["k"]
    dist = np.array([k1, k2, p1, p2, k3])
    ok = np.isfinite(sx)
    assert ok.all()
    pts = np.stack([(sx - cx) / fx, (sy - cy) / fy, np.ones_like(sx)], -1).reshape(-1, 1, 3)
    proj, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), K, dist)
    ox, oy = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    err = np.hypot(proj[:, 0, 0] - ox.ravel(), proj[:, 0, 1] - oy.ravel())
    assert err.max() < 1e-3   # brief: 1e-3 px over the frame (measured ~1e-12)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 500, 1e-15)
    und = cv2.undistortPoints(np.stack([ox.ravel(), oy.ravel()], -1)[:, None, :], K, dist,
                              R=None, P=K, criteria=crit)
    err2 = np.hypot(und[:, 0, 0] - (sx.ravel() - 0.5), und[:, 0, 1] - (sy.ravel() - 0.5))
    assert err2.max() < 1e-3


def test_pixel_aspect_uses_fy_equal_fx_times_aspect():
    p = Distortion.params(k1=-0.1)
    fx, fy, cx, cy = intrinsics(p, CAM, Rect(0, 0, 100, 50), 2.0)
    assert fy == pytest.approx(2.0 * fx) and (cx, cy) == (50.0, 25.0)


# -- fold-over ----------------------------------------------------------------------------
def test_fold_over_is_refused_with_a_clear_message(rt):
    # 16:9 with fx = half the width: corner at r = 1.147, k1 = -0.3 folds at r = 1.054
    p = Distortion.params(k1=-0.3, fx=96.0, fy=96.0)
    with pytest.raises(ParamError, match=r"k1=-0\.3.*r=1\.054.*r=1\.147"):
        render_effect(rt, Distortion(), p, np.zeros((108, 192, 4), np.float32))


def test_fold_outside_frame_is_accepted(rt):
    p = Distortion.params(amount=-0.3)            # corner moves 30% inwards: fold beyond it
    out = render_effect(rt, Distortion(), p, np.ones((18, 32, 4), np.float32), quality="draft")
    assert np.isfinite(out).all()


# -- rendering against the oracle ---------------------------------------------------------
@pytest.mark.parametrize("shape", hard_shapes())
@pytest.mark.parametrize("border", ["black", "edge", "mirror"])
def test_matches_reference_hard_shapes(rt, rng, shape, border):
    h, w = shape
    src = rng.uniform(0.0, 2.0, shape + (4,)).astype(np.float32)
    p = Distortion.params(k1=-0.2, k2=0.05, p1=0.002, border=border, fx=max(w, h) * 0.8)
    got = render_effect(rt, Distortion(), p, src, quality="final", camera=CAM)
    want = ref.distortion(src, footprint="lanczos3", border=border, **oracle_args(p, w, h))
    # float32 weights/sums over up to 64 taps of values <= 2: a few 1e-6
    np.testing.assert_allclose(got, want, rtol=0, atol=2e-5)


@pytest.mark.parametrize("quality", ["draft", "preview", "final", "reference"])
def test_each_quality_matches_its_own_filter(rt, rng, quality):
    src = rng.uniform(0.0, 1.0, (23, 41, 4)).astype(np.float32)
    p = Distortion.params(amount=0.15, fit="fit-all", border="edge")
    got = render_effect(rt, Distortion(), p, src, quality=quality, camera=CAM)
    half = half_fractions(p, 41, 23, "edge") if quality == "draft" else None
    want = ref.distortion(src, footprint=QUALITY_FOOTPRINT[quality], border="edge", half=half,
                          **oracle_args(p, 41, 23))
    tol = 1e-7 if quality == "reference" else 1e-5   # float64 sums, float32 output (ulp 6e-8)
    np.testing.assert_allclose(got, want, rtol=0, atol=tol)


def test_error_falls_monotonically_with_quality(rt, rng):
    src = smooth_image(rng, 40, 64)
    p = Distortion.params(k1=-0.15, k2=0.02, fit="fill", border="edge")
    want = ref.distortion(src, footprint="elliptical", border="edge", **oracle_args(p, 64, 40))
    errs = [np.abs(render_effect(rt, Distortion(), p, src, quality=q, camera=CAM) - want).max()
            for q in ("draft", "preview", "final", "reference")]
    assert all(a >= b for a, b in zip(errs, errs[1:])), errs
    assert errs[-1] < 1e-7   # float32 storage of a float64 result


def test_pixel_aspect_and_principal_point(rt, rng):
    src = rng.uniform(0.0, 1.0, (30, 40, 4)).astype(np.float32)
    p = Distortion.params(k1=0.1, p2=0.003, cx=17.0, cy=12.5, border="mirror")
    got = render_effect(rt, Distortion(), p, src, quality="preview", camera=CAM, pixel_aspect=1.5)
    want = ref.distortion(src, footprint="bicubic", border="mirror",
                          **oracle_args(p, 40, 30, pixel_aspect=1.5))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-5)


# -- identity, fit, hard values ------------------------------------------------------------
def test_tiny_coefficient_renders_as_near_identity(rt, rng):
    src = rng.uniform(0.0, 1.0, (16, 24, 4)).astype(np.float32)
    p = Distortion.params(k1=1e-12)
    for q in ("draft", "preview", "final", "reference"):
        got = render_effect(rt, Distortion(), p, src, quality=q)
        np.testing.assert_allclose(got, src, atol=1e-5)   # interpolating filters at integer shift


def test_fill_leaves_no_undefined_border_and_fit_all_keeps_everything(rt):
    w, h = 96, 54
    src = np.ones((h, w, 4), np.float32)
    fill = render_effect(rt, Distortion(), Distortion.params(amount=-0.2, fit="fill"), src,
                         quality="draft")
    assert fill.min() > 0.999                        # every pixel reads inside the source
    win = Rect(0, 0, w, h)
    sx, sy, _ = build_map(Distortion.params(amount=0.2, fit="fit-all"), Camera(), win, win, 1.0)
    # the whole source is visible: the sampled area reaches every source edge
    assert sx.min() <= 0.5 + 1e-6 or sx.max() >= w - 0.5 - 1e-6
    none = render_effect(rt, Distortion(),
                         Distortion.params(amount=-0.2, fit="none", border="black"), src,
                         quality="draft")
    assert none[0, 0, 0] < 0.5                       # barrel without fit, black border: black
    crop = render_effect(rt, Distortion(), Distortion.params(amount=-0.2), src, quality="draft")
    assert crop.min() > 0.999                        # the default (crop, edge): none


def test_hdr_edge_does_not_ring(rt):
    src = np.full((32, 48, 4), 0.01, np.float32)
    src[:, 24:] = 1e5
    src[..., 3] = 1.0
    for q in ("draft", "preview", "final", "reference"):
        got = render_effect(rt, Distortion(), Distortion.params(k1=-0.1, p1=0.003, border="edge"),
                            src, quality=q)
        assert got.min() >= 0.0 and got.max() <= 1e5 * (1 + 1e-6)
        # each output within the min/max of its footprint: far from the edge nothing moves
        np.testing.assert_allclose(got[:, :8, :3], 0.01, rtol=1e-4)


@pytest.mark.parametrize("quality", ["draft", "preview", "final", "reference"])
def test_nan_and_inf_become_zero_and_are_noted(rt, rng, quality):
    src = nonfinite_image(rng)
    p = Distortion.params(k1=-0.1, border="edge")
    got, notes = render_with_notes(rt, Distortion(), p, src, quality=quality, camera=CAM)
    assert np.isfinite(got).all()
    assert "distortion: 4 non-finite pixel(s) read as 0" in notes
    want = render_effect(rt, Distortion(), p, np.nan_to_num(src, nan=0.0, posinf=0.0, neginf=0.0),
                         quality=quality, camera=CAM)
    np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("quality", ["draft", "preview", "final", "reference"])
@pytest.mark.parametrize("border", ["black", "edge"])
def test_finite_input_across_float_range_stays_finite(rt, rng, quality, border):
    src = wide_range_image(rng)
    for p in (Distortion.params(k1=-0.2, p1=0.002, border=border),
              Distortion.params(amount=0.3, fit="fit-all", border=border)):
        got = render_effect(rt, Distortion(), p, src, quality=quality, camera=CAM)
        assert np.isfinite(got).all(), p


def test_map_is_built_once_and_kept_in_the_runtime_cache(rt, rng, monkeypatch):
    import clfx.kit.warp as kit

    builds = []      # the pixel centres a map is built for (the host map's, once)
    centres = kit.pixel_centres
    monkeypatch.setattr(kit, "pixel_centres", lambda *a, **kw: builds.append(a) or centres(*a, **kw))
    src = rng.uniform(0.0, 1.0, (10, 10, 4)).astype(np.float32)
    p = Distortion.params(k1=0.1 + rng.uniform(0, 1e-6))     # a key no other test used
    a = render_effect(rt, Distortion(), p, src, frame=1)
    b = render_effect(rt, Distortion(), p, src, frame=2, quality="draft")   # another level, same map
    c = render_effect(rt, Distortion(), p, src, frame=3)
    assert len(builds) == 1 and np.array_equal(a, c) and not np.array_equal(a, b)
    assert rt.cache.stats()["owners"]["distortion.map"] > 0


def test_regions_are_surveyed_once_a_shot(rt, rng, monkeypatch):
    """The region of definition's Jacobian survey (tens of ms of host time) is asked several
    times a frame (identity, output window, the tiler): it runs once for a shot whose
    geometry does not change, and again when the geometry does."""
    import clfx.kit.warp as kit
    from clfx.host import RenderContext

    surveys = []
    widest = kit.widest
    monkeypatch.setattr(kit, "widest", lambda *a, **kw: surveys.append(a) or widest(*a, **kw))
    p = Distortion.params(k1=-0.1 - rng.uniform(0, 1e-6))    # a key no other test used
    src = rt.upload(rng.uniform(0.0, 1.0, (12, 16, 4)).astype(np.float32))
    windows = set()
    for frame in range(3):
        ctx = RenderContext(rt, src, frame=frame, camera=CAM)
        windows |= {Distortion().output_window(p, ctx) for _ in range(2)}
    assert len(surveys) == 1 and len(windows) == 1
    ctx = RenderContext(rt, src, frame=0, camera=CAM,
                        display_window=Rect(-4, -4, 20, 16))   # another geometry: surveyed
    Distortion().output_window(p, ctx)
    assert len(surveys) == 2


def test_amount_moves_the_corner_by_that_fraction_of_its_radius():
    from clfx.plugins.distortion import corner_radius, project
    win = Rect(0, 0, 160, 90)
    for amount in (-0.1, 0.2):
        p = Distortion.params(amount=amount)
        fx, fy, cx, cy = intrinsics(p, CAM, win, 1.0)
        k = coefficients(p, CAM, win, 1.0)
        xc, yc = (win.x1 - cx) / fx, (win.y1 - cy) / fy
        xd, yd = project(xc, yc, k)
        assert np.hypot(xd, yd) / np.hypot(xc, yc) == pytest.approx(1 + amount, rel=1e-12)
        assert corner_radius(win, fx, fy, cx, cy) == pytest.approx(np.hypot(xc, yc))


def test_data_window_map_is_the_display_map_cropped():
    display, data = Rect(0, 0, 64, 40), Rect(10, 5, 50, 33)
    p = Distortion.params(k1=-0.2, p1=0.002, fit="fill")
    full_x, full_y, _ = build_map(p, CAM, display, display, 1.0)
    sub_x, sub_y, _ = build_map(p, CAM, display, data, 1.0)
    np.testing.assert_allclose(sub_x, full_x[5:33, 10:50], atol=1e-9)
    np.testing.assert_allclose(sub_y, full_y[5:33, 10:50], atol=1e-9)


def test_data_window_render_matches_oracle_in_frame_coordinates(rt, rng):
    """A data window inside the display window: the oracle over the whole frame with the
    pixels outside the data window transparent (``edge`` repeats the frame's edge, not the
    data window's), on the output window (grown: the pincushion carries content out)."""
    from tests.plugins.windows import placed

    display, data = Rect(0, 0, 48, 32), Rect(6, 4, 38, 26)
    src = rng.uniform(0.0, 1.0, (data.height, data.width, 4)).astype(np.float32)
    p = Distortion.params(k1=0.12, border="edge")
    got, window = render_effect(rt, Distortion(), p, src, quality="final", camera=CAM,
                                data_window=data, display_window=display, keep_rod=True)
    assert window.contains(data) and window != data
    sx, sy, info = build_map(p, CAM, display, display, 1.0, jacobian=True)
    want = ref.sample_footprint(placed(src, data, display), sx, sy, info["jacobian"],
                                "lanczos3", "edge")
    # float32 positions and sums of values <= 1 (as the hard shapes' tolerance)
    np.testing.assert_allclose(got, want[window.y0:window.y1, window.x0:window.x1], atol=1e-5)


# -- footprints that follow the map's Jacobian (issue 11, item 7) ----------------------------
@pytest.mark.parametrize("coeffs", [dict(k1=-0.5, k2=0.15), dict(k1=-0.6, k2=0.2, p1=0.004)])
@pytest.mark.parametrize("quality", ["draft", "preview", "final", "reference"])
def test_strong_minification_matches_the_footprint_oracle(rt, rng, coeffs, quality):
    """Up to 4-5x minification: windows too narrow for the footprint are split into n x n
    sub-footprints (the checked kernel); every level against its float64 oracle."""
    src = rng.uniform(0.0, 2.0, (40, 64, 4)).astype(np.float32)
    p = Distortion.params(border="edge", fx=30.0, **coeffs)
    got = render_effect(rt, Distortion(), p, src, quality=quality, camera=CAM)
    half = half_fractions(p, 64, 40, "edge") if quality == "draft" else None
    want = ref.distortion(src, footprint=QUALITY_FOOTPRINT[quality], border="edge", half=half,
                          **oracle_args(p, 64, 40))
    # float32 positions (1e-7 px), weights and sums over up to 64 taps per sub-footprint, of
    # values <= 2: a few 1e-6 (measured <= 4e-6); the reference sums in float64
    tol = 1e-7 if quality == "reference" else 2e-5
    np.testing.assert_allclose(got, want, rtol=0, atol=tol)


def test_magnified_pixels_keep_the_point_filters(rt, rng):
    """Where the map magnifies (pincushion: J <= 1 everywhere) the footprint adds nothing:
    preview, final and reference are today's Keys / Lanczos-3 with the 2x2 clamp."""
    src = rng.uniform(0.0, 2.0, (36, 60, 4)).astype(np.float32)
    p = Distortion.params(k1=0.2, k2=0.05, border="mirror")
    win = Rect(0, 0, 60, 36)
    sx, sy, info = build_map(p, CAM, win, win, 1.0, jacobian=True)
    assert np.linalg.svd(info["jacobian"], compute_uv=False).max() <= 1.0
    for quality, filter_name in (("preview", "bicubic"), ("final", "lanczos3"),
                                 ("reference", "lanczos3")):
        got = render_effect(rt, Distortion(), p, src, quality=quality, camera=CAM)
        want = ref.sample(src, sx, sy, filter_name, "mirror")
        np.testing.assert_allclose(got, want, rtol=0, atol=2e-5)


def test_footprint_spread_follows_the_marginal_widths():
    from clfx.fx.resample import footprint_spread

    jac = np.array([[[1.0, 0.0], [0.0, 0.5]],      # magnified along y: nothing added
                    [[2.0, 0.0], [0.0, 1.0]],      # 2x along x: v = (4 - 1) / 12 = 1/4
                    [[1.2, 1.6], [0.0, 1.0]]])     # sheared: W_x^2 = 1.44 + 2.56 = 4
    hx, hy, n = footprint_spread(jac, "lanczos3")
    np.testing.assert_allclose(hx, [0.0, 0.5, 0.5], atol=1e-3)   # float16 storage
    np.testing.assert_allclose(hy, 0.0)
    assert (n == 1).all()
    hx, _, n = footprint_spread(np.array([[[6.0, 0.0], [0.0, 1.0]]]), "bicubic")
    # v = (36 - 1) / 12 > 1/3: split into n x n with (6 / n)^2 - 1 <= 4, i.e. n = 3
    assert n[0] == 3 and hx[0] == pytest.approx(math.sqrt(3.0 / 12.0), abs=1e-3)


@pytest.mark.parametrize("variant", [None, "moustache"])
def test_every_level_beats_bilinear_remap_and_the_input_on_ground_truth(rt, variant):
    """Strong barrel (k1 = -0.35, k2 = 0.12, k3 = -0.01) and moustache distortion of the
    bench's procedural texture at 192x108, scored in log-PSNR against the area-averaged exact
    distorted texture: every level beats bilinear remap on the exact (float64) map and the
    unchanged input.  Margins measured: >= 1.0 dB over bilinear, > 19 dB over the input."""
    from clfx.bench.cases import distortion as case
    from clfx.bench.metrics import psnr_log

    c = case.CASE.maker(variant)(192, 108, None)
    p = Distortion.params(**c["params"])
    win = Rect(0, 0, 192, 108)
    sx, sy, _ = build_map(p, c["camera"], win, win, 1.0)
    bilinear = psnr_log(ref.sample(c["source"], sx, sy, "bilinear", p.border), c["truth"])
    unchanged = psnr_log(c["source"], c["truth"])
    scores = {q: psnr_log(render_effect(rt, Distortion(), p, c["source"], quality=q,
                                        camera=c["camera"]),
                          c["truth"]) for q in ("draft", "preview", "final", "reference")}
    for q, score in scores.items():
        assert score > bilinear + 0.5, (q, score, bilinear)
        assert score > unchanged + 10.0, (q, score, unchanged)
    assert scores["final"] >= scores["reference"] - 1.0, scores   # issue 11: within 1 dB


@pytest.mark.parametrize("quality", ["draft", "preview", "final"])
def test_map_built_in_bands_is_the_whole_frame_map(rt, rng, monkeypatch, quality):
    """Issue 10 item 10: frames larger than a band build their map band by band (an 8K
    frame's float64 map would take ~5 GB); the pixels are the same."""
    import clfx.fx.resample as resample

    src = rng.uniform(0.0, 2.0, (181, 323, 4)).astype(np.float32)
    p = Distortion.params(k1=-0.3 + rng.uniform(0, 1e-6), p1=0.01, border="mirror")
    whole = render_effect(rt, Distortion(), p, src, quality=quality, camera=CAM)
    rt.cache.clear("distortion.map")
    monkeypatch.setattr(resample, "BAND_PIXELS", 3000)          # 9-row bands
    assert len(resample.map_bands(181, 324)) == 21
    banded = render_effect(rt, Distortion(), p, src, quality=quality, camera=CAM)
    assert np.array_equal(banded, whole)


def plain_and_streamed(rt, monkeypatch, render):
    """``render()`` once with streaming stores refused and once forced
    (``Runtime.streams_stores``): both outputs and the output sizes the effect asked about."""
    asked = []
    monkeypatch.setattr(rt, "streams_stores", lambda n: asked.append(n) or False)
    plain = render()
    monkeypatch.setattr(rt, "streams_stores", lambda n: True)
    return plain, render(), asked


def built_with_streaming(rt, kernel_file: str) -> bool:
    return any(k[0] == kernel_file and ("CLFX_STREAM_STORES", "1") in k[1] for k in rt._programs)


@pytest.mark.parametrize("quality", ["draft", "preview", "final"])
def test_streaming_stores_give_the_same_pixels(rt, rng, monkeypatch, quality):
    """Outputs at least half the device's cache are written with streaming stores
    (Runtime.streams_stores, kernels/lib/common.h); forced on a small frame (black border:
    fast, checked and zero quads all present), every pixel is what plain stores write."""
    src = smooth_image(rng, 61, 90)
    p = Distortion.params(k1=-0.45 + rng.uniform(0, 1e-6), k2=0.1, fit="none", border="black")
    plain, streamed, asked = plain_and_streamed(
        rt, monkeypatch, lambda: render_effect(rt, Distortion(), p, src, quality=quality,
                                               camera=CAM))
    assert asked and asked[-1] >= src.nbytes          # asked with the output's size
    assert np.array_equal(streamed, plain)
    assert built_with_streaming(rt, "distortion.cl")


@pytest.mark.parametrize("coeffs", [dict(k1=-0.45, k2=0.1, fit="none"), dict(k1=-0.02),
                                    dict(amount=0.25)])
def test_lanczos_shortcuts_give_the_general_forms_pixels(rt, rng, monkeypatch, coeffs):
    """Final's fast path takes shortcuts (kernels/lib/resample.h, FP_SHORTCUTS): one 8-wide
    weight evaluation where a quad's two Lanczos sample sets coincide (h = 0) and the 2x2
    clamp from two short rows; built without them, every quad goes through the general
    forms.  On warps with magnified and minified quads, over a plate with +0 and -0 areas
    (the clamp's signed zeros), both builds give the same pixels, bit for bit."""
    src = smooth_image(rng, 61, 90)
    src[10:24, 30:50] = 0.0
    src[30:44, 20:40] = -0.0
    src[40:50, 60:80, :3] *= np.where(rng.uniform(size=(10, 20, 1)) < 0.5, -1e-3, 1e-3)
    p = Distortion.params(**coeffs)
    fast = render_effect(rt, Distortion(), p, src, quality="final", camera=CAM)
    kernel = rt.kernel

    def general(file, name, *args, **defines):
        return kernel(file, name, *args, **defines, FP_SHORTCUTS=0)

    monkeypatch.setattr(rt, "kernel", general)
    rt.cache.clear()
    slow = render_effect(rt, Distortion(), p, src, quality="final", camera=CAM)
    assert any(k[0] == "distortion.cl" and ("FP_SHORTCUTS", "0") in k[1] for k in rt._programs)
    assert np.array_equal(fast.view(np.uint32), slow.view(np.uint32))


# -- tight data windows: the output grows to where the element lands -----------------------
TIGHT_DISPLAY, TIGHT_DATA = Rect(0, 0, 128, 96), Rect(58, 40, 112, 84)
"""A frame and an element's bounding box right of and below its centre (Beachball's ball:
the lens carries it outward, past its box)."""
WARPS = [dict(amount=-0.12, fit="fill"),          # the webcam look: barrel filled: magnified
         dict(amount=0.25),                       # pincushion: outward
         dict(amount=0.2, p1=0.01, p2=-0.008),    # with decentering
         dict(k1=-0.25)]                          # barrel, no fit: inward


@pytest.mark.parametrize("coeffs", WARPS)
@pytest.mark.parametrize("quality", ["draft", "preview", "final", "reference"])
@pytest.mark.parametrize("border", ["black", "edge"])
def test_tight_window_gives_the_full_frame_pixels(rt, rng, coeffs, quality, border):
    """The element in its own data window gives the pixels it gives placed in a full-frame
    data window (over the union of both outputs): nothing is cut at the data window's edge,
    and ``edge`` repeats the frame's (transparent) edge, never the element's box."""
    from tests.plugins.windows import element, tight_and_full

    src = element(rng, TIGHT_DATA)
    p = Distortion.params(border=border, **coeffs)
    tight, full, window = tight_and_full(rt, Distortion(), p, src, TIGHT_DATA, TIGHT_DISPLAY,
                                         quality=quality, camera=CAM)
    # the same map in other window coordinates: float32 fractions differ by ~1e-7 px;
    # values <= 4 (measured: 0 or a few 1e-7)
    np.testing.assert_allclose(tight, full, rtol=0, atol=1e-5)
    assert TIGHT_DISPLAY.contains(window)
    if coeffs.get("k1", 0.0) >= 0.0:     # the content moves outward: the window grows
        assert window.contains(TIGHT_DATA) and window != TIGHT_DATA
        # and stays tight: the element's image (the full render's nonzero pixels) fills
        # the window to within the filters' reach and the margin (a few px)
        ys, xs = np.nonzero(np.abs(full).sum(axis=2) > 0)
        both = window.union(TIGHT_DISPLAY)        # the arrays' window
        x0, y0 = both.x0 + xs.min(), both.y0 + ys.min()
        x1, y1 = both.x0 + xs.max() + 1, both.y0 + ys.max() + 1
        assert max(x0 - window.x0, y0 - window.y0, window.x1 - x1, window.y1 - y1) <= 12


def test_edge_border_on_a_tight_window_repeats_the_frame_not_the_box(rt, rng):
    """A barrel without fit reads past the frame at its corners: ``edge`` repeats the
    frame's edge, transparent for an element inside it, so the element's box edge is not
    smeared to the frame's corners (the output equals the black border's)."""
    src = np.ones((TIGHT_DATA.height, TIGHT_DATA.width, 4), np.float32)   # opaque box
    kw = dict(quality="final", camera=CAM, data_window=TIGHT_DATA, display_window=TIGHT_DISPLAY,
              keep_rod=True)
    edge, ew = render_effect(rt, Distortion(), Distortion.params(k1=-0.2, border="edge"), src, **kw)
    black, bw = render_effect(rt, Distortion(), Distortion.params(k1=-0.2, border="black"), src,
                              **kw)
    assert ew == bw
    np.testing.assert_array_equal(edge, black)
    # inside the display window, beyond the box's image: transparent
    assert np.all(edge[-1] == 0.0) and np.all(edge[:, -1] == 0.0)


@pytest.mark.parametrize("quality", ["draft", "reference"])
def test_tight_window_matches_the_oracle_on_the_grown_window(rt, rng, quality):
    """The float64 oracle on the element placed in the frame (outside the data window:
    transparent black), cropped to the grown window, agrees with the tight render."""
    from tests.plugins.windows import element, placed

    src = element(rng, TIGHT_DATA)
    p = Distortion.params(amount=-0.12, fit="fill", border="edge")
    got, window = render_effect(rt, Distortion(), p, src, quality=quality, camera=CAM,
                                data_window=TIGHT_DATA, display_window=TIGHT_DISPLAY, keep_rod=True)
    full = placed(src, TIGHT_DATA, TIGHT_DISPLAY)
    w, h = TIGHT_DISPLAY.width, TIGHT_DISPLAY.height
    half = half_fractions(p, w, h, "edge") if quality == "draft" else None
    want = ref.distortion(full, footprint=QUALITY_FOOTPRINT[quality], border="edge",
                          half=half, **oracle_args(p, w, h))
    want = want[window.y0:window.y1, window.x0:window.x1]
    # as test_strong_minification_matches_the_footprint_oracle (values <= 4 here); the
    # draft's float16 fractions are the full frame's (its pixels' fast path may differ on
    # the tight canvas: 1e-3 px, a few 1e-4 of the value)
    tol = 1e-6 if quality == "reference" else 2e-3
    np.testing.assert_allclose(got, want, rtol=0, atol=tol)
    assert np.abs(want).sum() == pytest.approx(
        np.abs(ref.distortion(full, footprint=QUALITY_FOOTPRINT[quality], border="edge",
                              half=half, **oracle_args(p, w, h))).sum(), rel=1e-9)


@pytest.mark.parametrize("quality", ["draft", "final"])
def test_tight_window_map_built_in_bands(rt, rng, monkeypatch, quality):
    """A grown window built band by band gives the pixels of the one-band map."""
    import clfx.fx.resample as resample
    from tests.plugins.windows import element

    src = element(rng, TIGHT_DATA)
    p = Distortion.params(amount=0.25 + rng.uniform(0, 1e-6), border="black")
    kw = dict(quality=quality, camera=CAM, data_window=TIGHT_DATA,
              display_window=TIGHT_DISPLAY, keep_rod=True)
    whole, ww = render_effect(rt, Distortion(), p, src, **kw)
    rt.cache.clear("distortion.map")
    monkeypatch.setattr(resample, "BAND_PIXELS", 600)
    banded, bw = render_effect(rt, Distortion(), p, src, **kw)
    assert bw == ww and len(resample.map_bands(ww.height, -(-ww.width // 4) * 4)) > 3
    assert np.array_equal(banded, whole)


def test_regions_bound_what_the_render_reads_and_writes(rt, rng):
    """region_of_definition holds every pixel the element reaches; region_of_interest of
    the output window holds every source pixel that changes it."""
    from clfx.host import RenderContext
    from tests.plugins.windows import element, placed

    src = element(rng, TIGHT_DATA)
    p = Distortion.params(amount=0.25, border="black")
    ctx = RenderContext(rt, rt.upload(src, TIGHT_DATA), display_window=TIGHT_DISPLAY, camera=CAM)
    rod = Distortion().region_of_definition(p, ctx)
    full = render_effect(rt, Distortion(), p, placed(src, TIGHT_DATA, TIGHT_DISPLAY), camera=CAM,
                         quality="final")
    ys, xs = np.nonzero(np.abs(full).sum(axis=2) > 0)
    assert rod.contains(Rect(xs.min(), ys.min(), xs.max() + 1, ys.max() + 1))
    out = Rect(20, 10, 60, 40)
    roi = Distortion().region_of_interest(p, ctx, out)
    assert roi.contains(out)
    # hot source pixels just outside the RoI change nothing in ``out``
    frame = np.zeros((96, 128, 4), np.float32)
    mx, my = (roi.x0 + roi.x1) // 2, (roi.y0 + roi.y1) // 2
    for x, y in ((roi.x0 - 1, my), (roi.x1, my), (mx, roi.y0 - 1), (mx, roi.y1)):
        if 0 <= x < 128 and 0 <= y < 96:
            frame[y, x] = 1e4
    assert frame.any()
    got = render_effect(rt, Distortion(), p, frame, camera=CAM, quality="final")
    assert np.all(got[out.y0:out.y1, out.x0:out.x1] == 0.0)
