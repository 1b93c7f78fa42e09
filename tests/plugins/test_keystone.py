"""keystone against its float64 oracle (tests/reference/keystone.py), and what the model
promises: converging verticals, the centre kept, crop without a border, the horizon."""
import numpy as np
import pytest

from clfx.core.camera import Camera
from clfx.core.rect import Rect
from clfx.fx.resample import FootprintMap
from clfx.plugins.keystone import Keystone, geometry, source_points
from tests.conftest import hard_shapes
from tests.effects import render_effect
from tests.reference import keystone as ref

CAM = Camera(focal_length=35.0, sensor_width=36.0)
QUALITY_FOOTPRINT = {"draft": "quadratic", "preview": "bicubic", "final": "lanczos3",
                     "reference": "elliptical"}


def oracle_args(p, w, h, camera=CAM, pixel_aspect=1.0):
    """The oracle's intrinsics (the camera block's, as documented) and the fit scale the
    effect chose (``fit=none``: 1, checked by ``test_fit_none_is_the_model_unscaled``)."""
    win = Rect(0, 0, w, h)
    fx = p.fx if p.fx > 0 else camera.focal_length * w / camera.sensor_width
    g = geometry(p, camera, win, win, pixel_aspect)
    return dict(tilt=p.tilt, swing=p.swing, fx=fx, fy=fx * pixel_aspect, cx=w / 2, cy=h / 2,
                fit_scale=g["fit_scale"])


def half_fractions(p, w, h, border):
    """The draft pixels whose offsets the kernel reads as float16 (``FootprintMap``'s fast
    path), for the oracle's ``half``."""
    win = Rect(0, 0, w, h)
    g = geometry(p, CAM, win, win, 1.0)
    xs, ys = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    sx, sy, jac = source_points(g, xs, ys, True)
    return FootprintMap(sx, sy, jac, "quadratic", w, h, -(-w // 4) * 4, border).fast_pixels[:, :w]


@pytest.mark.parametrize("quality", ["draft", "preview", "final", "reference"])
@pytest.mark.parametrize("border", ["edge", "black"])
def test_each_quality_matches_its_oracle(rt, rng, quality, border):
    src = rng.uniform(0.0, 1.0, (23, 41, 4)).astype(np.float32)
    p = Keystone.params(tilt=14.0, swing=-9.0, fit="none", border=border)
    got = render_effect(rt, Keystone(), p, src, quality=quality, camera=CAM)
    half = half_fractions(p, 41, 23, border) if quality == "draft" else None
    want = ref.keystone(src, footprint=QUALITY_FOOTPRINT[quality], border=border, half=half,
                        **oracle_args(p, 41, 23))
    tol = 1e-7 if quality == "reference" else 2e-5   # float64 sums; float32 taps and sums
    np.testing.assert_allclose(got, want, rtol=0, atol=tol)


@pytest.mark.parametrize("shape", hard_shapes())
def test_hard_shapes_match_the_oracle(rt, rng, shape):
    h, w = shape
    src = rng.uniform(0.0, 2.0, shape + (4,)).astype(np.float32)
    p = Keystone.params(tilt=-20.0, swing=11.0, fit="crop", border="mirror")
    got = render_effect(rt, Keystone(), p, src, quality="final", camera=CAM)
    want = ref.keystone(src, footprint="lanczos3", border="mirror", **oracle_args(p, w, h))
    np.testing.assert_allclose(got, want, rtol=0, atol=2e-5)


def test_fit_none_is_the_model_unscaled():
    assert oracle_args(Keystone.params(tilt=30.0, fit="none"), 64, 48)["fit_scale"] == 1.0


def test_verticals_converge_towards_the_top_when_tilted_up():
    """Tilted up, a top row reads a wider span of the plate than a bottom row (the facade's
    top is drawn smaller); swung right, the right column a taller span than the left."""
    w, h = 96, 64
    win = Rect(0, 0, w, h)
    xs = np.array([0.5, w - 0.5])
    g = geometry(Keystone.params(tilt=15.0, fit="none"), CAM, win, win, 1.0)
    top = np.ptp(source_points(g, xs, np.full(2, 0.5))[0])
    bottom = np.ptp(source_points(g, xs, np.full(2, h - 0.5))[0])
    assert top > 1.05 * bottom
    g = geometry(Keystone.params(swing=15.0, fit="none"), CAM, win, win, 1.0)
    ys = np.array([0.5, h - 0.5])
    left = np.ptp(source_points(g, np.full(2, 0.5), ys)[1])
    right = np.ptp(source_points(g, np.full(2, w - 0.5), ys)[1])
    assert right > 1.05 * left


def test_the_centre_shows_what_it_showed():
    win = Rect(0, 0, 80, 60)
    g = geometry(Keystone.params(tilt=25.0, swing=-18.0, fit="none"), CAM, win, win, 1.0)
    sx, sy = source_points(g, np.array([40.0]), np.array([30.0]))
    assert abs(sx[0] - 40.0) < 1e-9 and abs(sy[0] - 30.0) < 1e-9


def test_crop_leaves_no_border(rt, rng):
    """``fit=crop`` (the default) with a black border: every pixel of the display window
    reads inside the plate, so an opaque plate stays opaque to the edges."""
    src = rng.uniform(0.2, 1.0, (36, 60, 4)).astype(np.float32)
    src[..., 3] = 1.0
    for tilt, swing in ((20.0, 0.0), (-12.0, 17.0)):
        p = Keystone.params(tilt=tilt, swing=swing, border="black")
        got = render_effect(rt, Keystone(), p, src, quality="preview", camera=CAM)
        assert got[..., 3].min() > 0.999, (tilt, swing, got[..., 3].min())
        none = render_effect(rt, Keystone(), Keystone.params(**{**p.as_dict(), "fit": "none"}), src,
                                quality="preview", camera=CAM)
        assert none[..., 3].min() < 0.5        # unscaled, the receding side reads past it


def test_rays_past_the_horizon_are_transparent_and_noted(rt, rng):
    """A wide lens tilted 60 degrees: the top rows look more than 80 degrees off the plate's
    axis; they get no source (transparent) and the render says how many."""
    from clfx.host import RenderContext

    src = rng.uniform(0.0, 1.0, (40, 64, 4)).astype(np.float32)
    p = Keystone.params(tilt=60.0, fx=20.0, fit="none", border="edge")
    ctx = RenderContext(rt, rt.upload(src), camera=CAM)
    out = rt.download(Keystone().render(rt, p, ctx))
    assert np.all(out[0] == 0.0) and np.isfinite(out).all()
    assert any("keystone:" in n and "80 degrees" in n for n in ctx.notes), ctx.notes


def test_zero_angles_are_identity(rt, rng):
    from clfx.host import RenderContext

    src = rt.upload(rng.uniform(0.0, 1.0, (8, 8, 4)).astype(np.float32))
    assert Keystone().is_identity(Keystone.params(), RenderContext(rt, src))


@pytest.mark.parametrize("variant", [None, "steep"])
def test_final_is_within_5_percent_of_the_reference_on_ground_truth(rt, variant):
    """Issue 35: the bench's keystone cases at 192x108 (tilt 20 / swing -12 on 24 mm, and
    ``steep``: tilt 40 on 16 mm, the top rows compressed ~3x and sheared), scored against
    the area-averaged exact keystoned texture: the error falls as the level rises and final's
    relative RMSE is within 5 % of the reference level's.  Measured on ``steep``: final /
    reference 1.071 with the Lanczos pair's old cap (0.98: one window spread to h = 0.86),
    1.036 with 0.25 (clfx.fx.resample.FOOTPRINTS); the main case 1.00 either way."""
    from clfx.bench.cases import keystone as case
    from clfx.bench.metrics import error_metrics

    c = case.CASE.maker(variant)(192, 108, None)
    p = Keystone.params(**c["params"])
    err = {q: error_metrics(render_effect(rt, Keystone(), p, c["source"], quality=q,
                                          camera=c["camera"]), c["truth"])["rel_rmse"]
           for q in ("draft", "preview", "final", "reference")}
    assert err["draft"] >= err["preview"] >= err["final"] >= err["reference"], err
    assert err["final"] <= 1.05 * err["reference"], err


def test_split_pixels_wholly_outside_a_black_border_are_zero_quads(rt, rng):
    """Tilt 40 on a 16 mm lens, black border, 64x36: the top corners' pixels read far past
    the plate and are wider than one window (split into n x n parts).  Every quad whose
    pixels' footprints (centre +- |J| / 2, +- 12 texels) all miss the source is a zero quad,
    not a checked one re-rendered part by part (on the 320x180 bench case the checked quads
    fell from 50 % to 19 % of the frame); the pixels are still the oracle's."""
    w, h, cam = 64, 36, Camera(focal_length=16.0, sensor_width=36.0)
    p = Keystone.params(tilt=40.0, fit="none", border="black")
    win = Rect(0, 0, w, h)
    xs, ys = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    sx, sy, jac = source_points(geometry(p, cam, win, win, 1.0), xs, ys, True)
    m = FootprintMap(sx, sy, jac, "lanczos3", w, h, w, "black")
    rx = 0.5 * (np.abs(jac[..., 0, 0]) + np.abs(jac[..., 0, 1])) + 12
    ry = 0.5 * (np.abs(jac[..., 1, 0]) + np.abs(jac[..., 1, 1])) + 12
    far = (sx + rx < 0) | (sx - rx > w) | (sy + ry < 0) | (sy - ry > h)
    quads = lambda a: a.reshape(h, w // 4, 4).all(axis=2)
    far_quads = quads(far) & quads(np.isfinite(sx))
    assert far_quads.sum() > 20
    assert np.all(m.entries[..., 0][far_quads] == -2)
    src = rng.uniform(0.0, 1.0, (h, w, 4)).astype(np.float32)
    got = render_effect(rt, Keystone(), p, src, quality="final", camera=cam)
    want = ref.keystone(src, footprint="lanczos3", border="black", **oracle_args(p, w, h, cam))
    np.testing.assert_allclose(got, want, rtol=0, atol=2e-5)
