"""The layered scene model, the multisample ground truth and the metrics."""
import math

import numpy as np
import pytest

from clfx.bench import metrics
from clfx.bench.groundtruth import aperture_samples, make_case, render_truth, write_case
from clfx.bench.scene import Layer, Light, Scene, Texture, demo_scene, render_sharp
from clfx.core.camera import Camera

CAM = Camera(focal_length=50.0, f_number=1.4, sensor_width=36.0, focus_distance=3.0)


def light_scene(depth, w=96, h=64, radius=1.0, lum=1000.0, velocity=(0.0, 0.0)):
    light = Layer(depth=depth, shape="none", center=(w / 2 + 0.5, h / 2 + 0.5),
                  lights=(Light((0.0, 0.0), (lum, lum, lum), radius),), velocity=velocity)
    return Scene(w, h, (light,), background=((0, 0, 0), (0, 0, 0)))


def test_demo_scene_passes_and_motion():
    a = render_sharp(demo_scene(10, 160, 90))
    b = render_sharp(demo_scene(11, 160, 90))
    assert a.rgba.shape == (90, 160, 4) and a.depth.shape == (90, 160)
    assert np.isfinite(a.rgba).all() and a.rgba.max() > 1000   # HDR lights
    assert np.isinf(a.depth).any() and a.depth[np.isfinite(a.depth)].min() == 1.0
    assert a.velocity[..., 0].max() > 1.0            # the fast ball
    assert not np.array_equal(a.rgba, b.rgba)        # changes smoothly with the frame
    assert np.abs(a.rgba - b.rgba).mean() < 0.5


def test_render_sharp_is_the_over_composite():
    layer = Layer(depth=2.0, texture=Texture("flat", (0.8, 0.4, 0.2)), shape="rect",
                  center=(8, 8), size=(8, 8), opacity=0.5)
    opaque = Layer(depth=4.0, shape="rect", center=(2, 14), size=(4, 4))
    sc = Scene(16, 16, (layer, opaque), background=((0.1, 0.1, 0.1), (0.1, 0.1, 0.1)))
    f = render_sharp(sc)
    np.testing.assert_allclose(f.rgba[8, 8], [0.45, 0.25, 0.15, 1.0], rtol=1e-6)
    np.testing.assert_allclose(f.rgba[0, 0], [0.1, 0.1, 0.1, 1.0], rtol=1e-6)
    # depth is the nearest layer covering more than half the pixel: not a 50% veil
    assert f.depth[0, 0] == math.inf and f.depth[8, 8] == math.inf and f.depth[14, 1] == 4.0
    assert np.isinf(render_sharp(Scene(3, 2)).depth).all()


def test_zero_aperture_and_shutter_reproduce_the_sharp_frame():
    sc = demo_scene(3, 120, 68)
    for ss in (1, 2):
        sharp = render_sharp(sc, ss=ss).rgba
        truth = render_truth(sc, CAM, samples=4, dof=False, motion=False, ss=ss)
        np.testing.assert_array_equal(truth, sharp)


def test_coc_of_ground_truth_matches_the_camera():
    # A tiny light far behind the focus plane spreads into a disk of the camera's CoC.
    depth = 30.0
    sc = light_scene(depth, radius=0.3, lum=1e4)
    # exact_below_px=0: the light is shifted on the sharp frame's sub-sample grid (not
    # rasterised exactly per render), so the average conserves that frame's energy exactly
    truth = render_truth(sc, CAM, samples=2048, ss=2, exact_below_px=0.0)
    coc = CAM.coc_px(depth, sc.width)
    lit = truth[..., 0] > 0
    ys, xs = np.nonzero(lit)
    width = xs.max() - xs.min() + 1
    assert abs(width - coc) <= 2.0, (width, coc)       # within the light's size + a pixel
    assert abs(abs(float(CAM.coc_signed_px(depth, sc.width))) - coc) < 1e-9
    # energy is conserved by the average
    sharp = render_sharp(sc, ss=2).rgba
    assert abs(truth[..., 0].sum() / sharp[..., 0].sum() - 1) < 1e-4


def test_near_and_far_bokeh_of_a_triangle_are_turned():
    cam = CAM.updated(blades=3, sensor_width=6.0)     # CoCs of 5-9 px on 96 px
    far = render_truth(light_scene(30.0, radius=0.3, lum=1e4), cam, samples=2048, ss=2)
    near = render_truth(light_scene(1.9, radius=0.3, lum=1e4), cam, samples=2048, ss=2)
    assert cam.coc_px(1.9, 96) > 5 and cam.coc_px(30, 96) > 8
    # first vertex up: behind the focus plane the triangle's vertex reaches further up from
    # the light (row 32) than its base reaches down; in front of it, the other way round
    def reach(img):
        ys = np.nonzero(img[..., 0] > 0)[0]
        return 32 - ys.min(), ys.max() - 32

    up, down = reach(far)
    assert up > down
    up, down = reach(near)
    assert down > up


def test_aperture_samples_are_uniform_and_weighted():
    pts, w = aperture_samples(4096)
    assert abs(w.sum() - 1) < 1e-12 and np.abs(pts @ np.ones(2) @ w) < 1e-2
    assert np.hypot(*pts.T).max() <= 1.0
    assert abs(np.sum(w * (pts ** 2).sum(1)) - 0.5) < 1e-3     # E|p|^2 = 1/2 on the unit disk
    pts6, w6 = aperture_samples(4096, blades=6)
    assert np.hypot(*pts6.T).max() <= 1.0 + 1e-12


def test_motion_blur_truth_spreads_along_velocity():
    cam = CAM.updated(shutter_angle=180.0)
    assert cam.shutter_interval() == (-0.25, 0.25)
    assert cam.updated(shutter_offset="opening").shutter_interval() == (0.0, 0.5)
    sc = light_scene(3.0, radius=0.5, velocity=(20.0, 0.0))
    truth = render_truth(sc, cam, samples=256, dof=False, motion=True, ss=2)
    lit = truth[..., 0] > 1.0
    ys, xs = np.nonzero(lit)
    assert 9 <= xs.max() - xs.min() + 1 <= 13           # 20 px/frame * 0.5 frame + the light
    assert ys.max() - ys.min() + 1 <= 3


def test_edge_band_and_metrics():
    depth = np.full((20, 30), 5.0, np.float32)
    depth[:, 15:] = np.inf
    band = metrics.edge_band(depth, None, 3)
    assert band[:, 11:19].all() and not band[:, :11].any() and not band[:, 20:].any()
    depth[0, 0] = np.nan                                # invalid depth is an edge too
    assert metrics.edge_band(depth, None, 0)[0, 0]
    vel = np.zeros((20, 30, 2), np.float32)
    vel[10:, :, 0] = 4.0
    vband = metrics.edge_band(None, vel, 2)
    assert vband[8:12].all() and not vband[:7].any()
    a = np.ones((4, 4, 4))
    b = a.copy()
    b[0, 0, 0] = 3.0
    assert metrics.rmse(a, a) == 0.0 and metrics.psnr_log(a, a) == math.inf
    assert metrics.max_err(a, b) == 2.0
    assert abs(metrics.rmse(a, b) - math.sqrt(4 / 48)) < 1e-12
    assert metrics.psnr_log(b, a) < 60


def test_write_case(tmp_path):
    pytest.importorskip("OpenImageIO")
    case = make_case(demo_scene(0, 48, 27), CAM, samples=8)
    paths = write_case(case, tmp_path)
    assert all(p.exists() for p in paths.values())


def test_effects_and_ground_truth_share_one_copy_of_the_physics():
    """The thin-lens CoC and the shutter interval live in clfx.core.camera only: the ground
    truth and the effects read the same functions, so they cannot drift apart."""
    from clfx.bench import groundtruth
    from clfx.core import camera as core
    from clfx.fx import motion
    from clfx.plugins import dof

    for mod in (groundtruth, dof, motion):
        for name in ("coc_scale_px", "coc_signed_px", "shutter_interval", "aperture_radius"):
            fn = getattr(mod, name, None)
            assert fn is None or fn is getattr(core, name, None), (mod.__name__, name)
    # dof's lens with the camera's own values is the camera's K
    p = dof.Dof.params()
    assert dof.lens_scale_px(p, CAM, 0.0, 1920) == CAM.coc_scale_px(1920)
    # signed CoC: K (1 - S/z), K at infinity, 0 for invalid depths
    z = np.array([1.5, 3.0, 30.0, np.inf, 0.0, -1.0, np.nan])
    k = CAM.coc_scale_px(96)
    want = [k * (1 - 3.0 / 1.5), 0.0, k * (1 - 3.0 / 30.0), k, 0.0, 0.0, 0.0]
    np.testing.assert_allclose(CAM.coc_signed_px(z, 96), want, rtol=1e-15)
    assert CAM.coc_px(1.5, 96) == pytest.approx(abs(want[0]), rel=1e-15)
    # the effects' shutter: 'camera' defers to the camera block, overrides win
    params = type("P", (), {"shutter_angle": -1.0, "shutter_offset": "camera"})
    for off in core.SHUTTER_OFFSETS:
        cam = CAM.updated(shutter_angle=270.0, shutter_offset=off)
        assert motion.shutter_from(params, cam) == cam.shutter_interval()
    params.shutter_angle, params.shutter_offset = 90.0, "closing"
    assert motion.shutter_from(params, CAM) == (-0.25, 0.0)


# -- renderer-like ground truth: supersampled beauty, depth and velocity at the pixel centre --
@pytest.mark.parametrize("filt", ["box", "blackman-harris"])
def test_renderer_like_truth_without_blur_is_the_supersampled_sharp_frame(filt):
    from clfx.bench.groundtruth import RENDER_SS

    sc = demo_scene(3, 120, 68)
    sharp = render_sharp(sc, ss=RENDER_SS, pixel_filter=filt, passes="centre")
    truth = render_truth(sc, CAM, samples=1, dof=False, motion=False, ss=RENDER_SS,
                         pixel_filter=filt)
    np.testing.assert_allclose(truth, sharp.rgba, rtol=1e-6, atol=1e-6)
    # antialiased: edge pixels take intermediate values the single-sample frame lacks
    single = render_sharp(sc, ss=1).rgba
    assert not np.array_equal(sharp.rgba, single)


def test_filter_taps():
    from clfx.bench.scene import filter_margin, filter_taps, pixel_filter_weight

    j, w = filter_taps(4)
    assert list(j) == [0, 1, 2, 3] and np.allclose(w, 0.25) and filter_margin(4, j) == 0
    j, w = filter_taps(4, "blackman-harris")            # 1.5 px wide: 6 taps, into neighbours
    assert list(j) == [-1, 0, 1, 2, 3, 4] and abs(w.sum() - 1) < 1e-12
    np.testing.assert_allclose(w, w[::-1])              # symmetric about the centre
    assert filter_margin(4, j) == 1
    assert pixel_filter_weight(0.0, "blackman-harris") == pytest.approx(1.0, abs=1e-12)
    with pytest.raises(ValueError):
        filter_taps(4, "gauss")


def test_centre_passes_are_point_samples_not_coverage():
    # a thin bar over a quarter of a pixel column and its centre: a renderer writes its
    # depth there; the coverage rule does not
    bar = Layer(depth=2.0, shape="rect", center=(10.575, 8.0), size=(0.25, 20.0),
                velocity=(3.0, 0.0))
    sc = Scene(20, 16, (bar,))
    centre = render_sharp(sc, ss=4, passes="centre")
    cover = render_sharp(sc, ss=4, passes="coverage")
    assert centre.depth[8, 10] == 2.0 and tuple(centre.velocity[8, 10]) == (3.0, 0.0)
    assert np.isinf(cover.depth[8, 10])
    assert np.isinf(centre.depth[8, 9]) and np.isinf(centre.depth[8, 11])
    # the beauty is the filtered mixture: a quarter of the bar's grey over the background
    bg = centre.rgba[8, 3]
    np.testing.assert_allclose(centre.rgba[8, 10, :3], 0.75 * bg[:3] + 0.25 * 0.5, rtol=1e-6)


def test_spinning_layer_velocity_and_truth():
    from clfx.bench.groundtruth import make_case

    sp = Layer(depth=2.0, texture=Texture("checker", (1, 1, 1), (0, 0, 0), period=6),
               shape="rect", center=(40.0, 30.0), size=(40.0, 8.0), spin=30.0)
    sc = Scene(80, 60, (sp,), background=((0, 0, 0), (0, 0, 0)), background_alpha=0.0)
    case = make_case(sc, CAM.updated(shutter_angle=180.0), samples=64, dof=False, motion=True,
                     ss=4)
    v = case.sharp.velocity
    om = math.radians(30.0)
    np.testing.assert_allclose(v[30, 55], (-om * 0.5, om * 15.5), rtol=1e-5)   # v = w x r
    np.testing.assert_allclose(v[30, 25], (-om * 0.5, -om * 14.5), rtol=1e-5)
    # the truth turns the bar by +-7.5 degrees: its tips sweep arcs, its centre stays sharp
    tip = case.truth[30 - 3:30 + 4, 57:60, 3]
    assert tip.min() < 0.9 and (case.truth[..., 3] > 0.01).sum() > (case.sharp.rgba[..., 3] > 0.01).sum()
    np.testing.assert_allclose(case.truth[29:31, 38:42, 3], 1.0, atol=1e-6)


def test_blackman_harris_truth_of_a_defocused_light_keeps_its_energy():
    from clfx.bench.groundtruth import make_case

    sc = light_scene(30.0, radius=1.0, lum=1e3)
    case = make_case(sc, CAM, samples=288, dof=True, ss=4, pixel_filter="blackman-harris")
    sharp, truth = case.sharp.rgba[..., 0], case.truth[..., 0]
    # a short path (CoC 1.5 px) is rasterised exactly per render: over many renders the truth
    # integrates the disk's area (pi r^2 x 1000); the 4 x 4 sharp frame estimates it within 6%
    assert abs(truth.sum() / (math.pi * 1e3) - 1) < 1e-3
    assert abs(truth.sum() / sharp.sum() - 1) < 0.08
    assert (truth > 1.0).sum() > (sharp > 1.0).sum()          # and the light spread
    assert case.settings["pixel_filter"] == "blackman-harris"


# -- lens geometry in the bokeh: anamorphic squeeze, axial CA, optical vignetting ------------
SMALL = CAM.updated(sensor_width=4.0)   # CoC ~13 px at 30 m on a 96 px frame


def _extent(img, thresh):
    ys, xs = np.nonzero(img > thresh)
    return np.ptp(xs) + 1, np.ptp(ys) + 1


def test_anamorphic_squeeze_makes_vertical_ovals_of_the_thin_lens_height():
    sc = light_scene(30.0, radius=0.3, lum=1e4)
    cam = SMALL.updated(anamorphic_squeeze=2.0)
    truth = render_truth(sc, cam, samples=2048, ss=2, exact_below_px=0.0)
    coc = SMALL.coc_px(30.0, sc.width)
    wx, hy = _extent(truth[..., 0], 1.0)
    assert abs(hy - coc) <= 2 and abs(wx - coc / 2) <= 2, (wx, hy, coc)
    sharp = render_sharp(sc, ss=2).rgba
    np.testing.assert_allclose(truth[..., 0].sum(), sharp[..., 0].sum(), rtol=1e-5)


def test_axial_ca_offsets_each_channels_coc():
    """Red and blue 100 um behind green at f/1.4: their CoC is 0.0714 mm smaller behind the
    focus plane and larger in front of it; energy per channel is kept."""
    cam = SMALL.updated(axial_ca_red=100.0, axial_ca_blue=100.0)
    d_px = 0.1 / 1.4 * 96 / 4.0                      # delta / N on the sensor, in px
    np.testing.assert_allclose(cam.axial_ca_px(96), (-d_px, -d_px))
    for depth, sign in ((30.0, -1), (1.5, +1)):
        sc = light_scene(depth, radius=0.3, lum=1e4)
        truth = render_truth(sc, cam, samples=2048, ss=2, exact_below_px=0.0)
        wr = _extent(truth[..., 0], 1.0)[0]
        wg = _extent(truth[..., 1], 1.0)[0]
        assert (wr - wg) * sign > 0, (depth, wr, wg)
        assert abs(abs(wr - wg) - d_px) <= 1.5, (depth, wr, wg, d_px)
        np.testing.assert_allclose(truth[..., 0].sum(), truth[..., 1].sum(), rtol=1e-4)


def test_optical_vignetting_clips_lens_rays_per_pixel_and_keeps_a_flat_field():
    flat = Layer(depth=30.0, texture=Texture("flat", (0.5, 0.5, 0.5)), shape="full",
                 center=(48, 32), name="wall")
    cam = SMALL.updated(optical_vignetting=1.2)
    truth = render_truth(Scene(96, 64, (flat,)), cam, samples=512, ss=1)
    np.testing.assert_allclose(truth[..., :3], 0.5, rtol=1e-5)    # no darkening
    # a light near the left edge: a cat's eye, long axis vertical (tangential)
    light = Layer(depth=30.0, shape="none", center=(12.5, 32.5),
                  lights=(Light((0.0, 0.0), (1e4, 1e4, 1e4), 0.3),))
    sc = Scene(96, 64, (light,), background=((0, 0, 0), (0, 0, 0)))
    cat = render_truth(sc, cam, samples=4096, ss=2, exact_below_px=0.0)
    wx, hy = _extent(cat[..., 0], 1.0)
    assert hy > 1.3 * wx, (wx, hy)     # |c| = 0.73: width 2 - |c|, height 2 sqrt(1 - c^2/4)
    round_ = render_truth(sc, SMALL, samples=4096, ss=2, exact_below_px=0.0)
    wx0, hy0 = _extent(round_[..., 0], 1.0)
    assert abs(hy - hy0) <= 2 and abs(wx0 - hy0) <= 1


def test_render_rows_are_the_rows_of_the_whole_render():
    """The rolling shutter's truth renders each row alone at its own time: the same pixels
    as the whole frame's rows."""
    from clfx.bench.cases.rolling_shutter import pan_scene
    from clfx.bench.scene import demo_scene, render_rows, render_sharp

    for scene in (pan_scene(96, 54), demo_scene(1, 96, 54)):
        for t in (0.0, 0.37):
            for jitter in (dict(), dict(jitter_seed=5, samples=8)):
                full = render_sharp(scene, t, ss=2, **jitter).rgba
                for y0, y1 in ((0, 1), (13, 20), (53, 54)):
                    assert np.array_equal(render_rows(scene, t, y0, y1, ss=2, **jitter),
                                          full[y0:y1])


def test_every_pixel_position_integrates_the_whole_shutter():
    # Issue 24: one Weyl sequence over the renders gave sub-pixel position m the instants
    # 0.5 + (m + 16 j) a (mod 1), 31% of the shutter at 64 renders: the truth's blur then
    # depended on the direction of motion.  Now each position has one instant per stratum.
    from clfx.bench.groundtruth import shutter_times

    cam = CAM.updated(shutter_angle=180.0)
    for n, k in ((64, 16), (256, 16), (12, 4), (5, 1)):
        t = shutter_times(n, cam, k)
        u = (t + 0.25) / 0.5
        assert ((u >= 0) & (u < 1)).all()
        for m in range(k):
            strata = np.floor(u[m::k] * (n // k)).astype(int)
            assert sorted(strata) == list(range(n // k)), (n, k, m)


# -- renderer-like jittered sampling (issue 24) ----------------------------------------------
def edge_scene(x_edge, w=24, h=8, velocity=(0.0, 0.0)):
    """A white half plane right of ``x_edge`` (at t = 0) over black."""
    half = Layer(depth=5.0, texture=Texture("flat", (1.0, 1.0, 1.0)), shape="rect",
                 center=(x_edge + 500.0, h / 2), size=(1000.0, 4.0 * h), velocity=velocity)
    return Scene(w, h, (half,), background=((0, 0, 0), (0, 0, 0)))


def test_jittered_points_fill_their_strata_and_repeat_per_seed():
    from clfx.bench.scene import jittered_grid

    x, y = jittered_grid(3, 5, 40, 30, 4, seed=7)
    gy, gx = np.mgrid[0:120, 0:160]
    assert ((x >= 3 + gx / 4) & (x < 3 + (gx + 1) / 4)).all()       # one point per stratum
    assert ((y >= 5 + gy / 4) & (y < 5 + (gy + 1) / 4)).all()
    u = (x - 3) * 4 - gx
    assert abs(u.mean() - 0.5) < 0.01 and abs(u.std() - math.sqrt(1 / 12)) < 0.01   # uniform
    assert abs(np.corrcoef(u.ravel(), ((y - 5) * 4 - gy).ravel())[0, 1]) < 0.02
    # the same pixel gets the same points in any region; another seed or pass other points
    x2, _ = jittered_grid(13, 5, 4, 4, 4, seed=7)
    assert np.array_equal(x2, x[:16, 40:56])
    assert not np.array_equal(jittered_grid(3, 5, 40, 30, 4, seed=8)[0], x)
    assert not np.array_equal(jittered_grid(3, 5, 40, 30, 4, seed=7, index=1)[0], x)


def test_jittered_sharp_frame_has_no_sub_pixel_grid():
    # An edge 0.2 px into a pixel: the 4 x 4 grid (sub-samples at 0.125, 0.375, ...) covers
    # a quarter of the pixel at any offset from 0.125 to 0.375; jittered points cover 0.2.
    sc = edge_scene(10.8)
    grid = render_sharp(sc, ss=4).rgba[4, 10, 0]
    jit = render_sharp(sc, ss=4, jitter_seed=3, samples=1024).rgba[4, 10, 0]
    assert grid == pytest.approx(0.25, abs=1e-6)
    assert jit == pytest.approx(0.2, abs=0.015)
    with pytest.raises(ValueError):
        render_sharp(sc, ss=4, jitter_seed=3, pixel_filter="blackman-harris")


def test_jittered_motion_truth_is_the_exact_box_blur_of_a_moving_edge():
    # An edge at x = 10.3 moving 4 px/frame through a centred 180 degree shutter sweeps
    # [9.3, 11.3]: pixel X averages clamp((x - 9.3) / 2, 0, 1) over [X, X + 1].
    from clfx.bench.groundtruth import jittered_truth

    cam = Camera(shutter_angle=180.0, shutter_offset="centered")
    sc = edge_scene(10.3, velocity=(4.0, 0.0))
    xs = np.linspace(0.0, 24.0, 24 * 2000, endpoint=False) + 0.5 / 2000
    want = np.clip((xs - 9.3) / 2.0, 0.0, 1.0).reshape(24, 2000).mean(axis=1)
    a = jittered_truth(sc, cam, samples=256, ss=4, seed=1)
    b = jittered_truth(sc, cam, samples=256, ss=4, seed=2)
    assert np.array_equal(a, jittered_truth(sc, cam, samples=256, ss=4, seed=1))   # seeded
    assert not np.array_equal(a, b)
    for img in (a, b):
        assert np.abs(img[:, :, 0] - want[None]).max() < 0.02
    # the accumulation buffer's truth rounds each shift to its 4 x 4 grid
    grid = render_truth(sc, cam, samples=256, dof=False, motion=True, ss=4, exact_below_px=0.0)
    assert np.abs(grid[:, :, 0] - want[None]).max() > 0.02


def test_jittered_truth_of_a_thin_bar_is_its_exact_streak():
    # A bar half a pixel wide (narrower than a stratum pair) moving 8 px/frame: every pixel
    # of its streak averages its own points and instants to the exact coverage, unbiased.
    from clfx.bench.groundtruth import jittered_truth

    cam = Camera(shutter_angle=180.0, shutter_offset="centered")
    bar = Layer(depth=5.0, texture=Texture("flat", (1.0, 1.0, 1.0)), shape="rect",
                center=(16.0, 16.0), size=(0.5, 64.0), velocity=(8.0, 0.0))
    sc = Scene(32, 32, (bar,), background=((0, 0, 0), (0, 0, 0)))
    img = jittered_truth(sc, cam, samples=256, ss=4, seed=4)[..., 0]
    # the bar sweeps 4 px, [13.75, 18.25]: 0.5 / 4 of each pixel in [14, 18)
    assert np.abs(img[:, 14:18] - 0.125).max() < 0.06                 # 256 rays' noise
    assert np.abs(img[:, 14:18].mean(axis=0) - 0.125).max() < 0.012    # and no bias
    assert img[:, :13].max() == 0.0 and img[:, 19:].max() == 0.0


def test_make_case_jittered_with_noise_floor():
    cam = Camera(shutter_angle=180.0, shutter_offset="centered")
    sc = Scene(48, 32, (Layer(depth=4.0, texture=Texture("checker", period=3.0),
                              velocity=(3.0, 1.0)),))
    case = make_case(sc, cam, samples=64, dof=False, motion=True, ss=4, jitter_seed=1,
                     noise_floor=True)
    again = render_truth(sc, cam, samples=64, dof=False, motion=True, ss=4, jitter_seed=2)
    assert case.floor == pytest.approx(metrics.error_metrics(again, case.truth)["psnr_log"])
    assert 25.0 < case.floor < 60.0
    assert case.sharp.velocity[..., 0].min() == 3.0          # passes at the pixel centre
    with pytest.raises(ValueError):
        render_truth(sc, cam, samples=64, dof=True, ss=4, jitter_seed=1)
