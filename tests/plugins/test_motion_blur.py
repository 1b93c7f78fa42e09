import math

import numpy as np
import pytest

from clfx.bench import metrics
from clfx.bench.cases.motion_blur import CASE, CASES
from clfx.bench.cases.shared import line_blur_per_pixel as naive_line_blur
from clfx.bench.metrics import EDGE_BAND_PX, error_metrics
from clfx.core.camera import Camera
from clfx.core.rect import Rect
from clfx.fx.motion import MAX_RADIUS_PX, SHORT_MAX_PX, tile_size
from clfx.host import RenderContext
from clfx.plugins.motion_blur import MotionBlur
from tests.conftest import hard_shapes
from tests.reference.motion_blur import line_blur, naive_blur, short_blur
from tests.effects import render_effect

QUALITIES = ("draft", "preview", "final", "reference")
CENTRED = Camera(shutter_angle=180.0, shutter_offset="centered")


def smooth_texture(rng, h, w):
    """Random texture with ~4 px features: the bilinear quadrature error stays small."""
    coarse = rng.uniform(0.0, 1.0, (h // 4 + 3, w // 4 + 3, 4))
    ys, xs = (np.mgrid[0:h, 0:w] + 0.5) / 4.0
    y0, x0 = ys.astype(int), xs.astype(int)
    fy, fx = (ys - y0)[..., None], (xs - x0)[..., None]
    c = coarse
    img = ((c[y0, x0] * (1 - fx) + c[y0, x0 + 1] * fx) * (1 - fy)
           + (c[y0 + 1, x0] * (1 - fx) + c[y0 + 1, x0 + 1] * fx) * fy)
    return img.astype(np.float32)


def run(rt, src, vel, depth=None, quality="final", camera=CENTRED, **kw):
    return render_effect(rt, MotionBlur(), MotionBlur.params(**kw), src, velocity=vel, depth=depth,
                         quality=quality, camera=camera)


def uniform(shape, v):
    vel = np.zeros(shape + (2,), np.float32)
    vel[...] = v
    return vel


@pytest.mark.parametrize("offset,t", [("centered", (-0.25, 0.25)), ("opening", (0.0, 0.5)),
                                      ("closing", (-0.5, 0.0))])
@pytest.mark.parametrize("v", [(9.0, -3.5), (19.0, -7.0)])
def test_uniform_velocity_is_box_line_blur(rt, rng, offset, t, v):
    src = smooth_texture(rng, 40, 57)
    # blurs shorter than the level's cubic_max_px (CUBIC_MAX_PX, FINE_CUBIC_MAX_PX at final
    # and reference) read through the clamped Catmull-Rom, longer ones bilinearly: the
    # oracle reads the same way
    length = math.hypot(*v) * 0.5
    errs = []
    for q in QUALITIES:
        cubic = length < MotionBlur.descriptor.quality[q].cubic_max_px
        want = line_blur(src, v, t0=t[0], t1=t[1], interp="cubic" if cubic else "linear")
        got = run(rt, src, uniform(src.shape[:2], v), quality=q, max_blur=0.25,
                  camera=Camera(shutter_angle=180.0, shutter_offset=offset))
        errs.append(np.abs(got - want).max())
    # reference: midpoint rule with <= 0.25 px spacing on a smooth image with ~4 px
    # features: quadrature error ~ spacing^2 x curvature < 2e-3 of the [0, 1] range
    assert errs[-1] < 2e-3, errs
    # final: samples every <= 0.5 px (midpoint rule: jitter only where samples are sparse)
    assert errs[2] < 0.02, errs
    # draft and preview: a sample per px (the midpoint rule again up to 8 / 16 samples)
    assert errs[0] < 0.05, errs
    # error falls (or stays equal) draft -> preview -> final -> reference
    assert all(b <= a + 1e-6 for a, b in zip(errs, errs[1:])), errs


def test_constant_image_stays_constant(rt, rng):
    src = np.full((33, 45, 4), 0.37, np.float32)
    vel = rng.normal(0.0, 20.0, (33, 45, 2)).astype(np.float32)
    depth = rng.uniform(0.5, 50.0, (33, 45)).astype(np.float32)
    for q in QUALITIES:
        got = run(rt, src, vel, depth, quality=q)
        np.testing.assert_allclose(got, 0.37, rtol=1e-6, atol=0)   # normalised weights


def test_zero_velocity_is_identity_with_reason(rt, rng):
    src = rng.uniform(0.0, 1.0, (16, 16, 4)).astype(np.float32)
    vel = np.zeros((16, 16, 2), np.float32)
    vel[3, 3] = (0.16, 0.0)   # 0.08 px over a 180 degree shutter: below MIN_BLUR_PX
    got = run(rt, src, vel)
    assert np.array_equal(got, src)
    ctx = RenderContext(rt, rt.upload(src), velocity=rt.upload(vel), camera=CENTRED)
    assert "below 0.1 px" in MotionBlur().is_identity(MotionBlur.params(), ctx)
    # a 0.3 px smear is blurred: a renderer shows it at sharp edges
    vel[3, 3] = (0.6, 0.0)
    assert not np.array_equal(run(rt, src, vel), src)
    assert MotionBlur().is_identity(MotionBlur.params(shutter_angle=0.0), ctx) == "shutter angle is 0"


@pytest.mark.parametrize("shape", hard_shapes())
def test_hard_shapes_finite_and_constant_preserved(rt, rng, shape):
    src = np.full(shape + (4,), 2.5, np.float32)
    vel = rng.normal(0.0, 30.0, shape + (2,)).astype(np.float32)
    got = run(rt, src, vel, rng.uniform(1, 9, shape).astype(np.float32))
    assert got.shape == src.shape
    np.testing.assert_allclose(got, 2.5, rtol=1e-6)


def test_nan_velocity_depth_and_pixels(rt, rng):
    src = rng.uniform(0.0, 1.0, (40, 48, 4)).astype(np.float32)
    vel = uniform((40, 48), (8.0, 0.0))
    depth = np.full((40, 48), 3.0, np.float32)
    vel[5, 5] = np.nan
    vel[6, 6] = (np.inf, -np.inf)
    depth[7, 7], depth[8, 8], depth[9, 9], depth[10, 10] = np.nan, 0.0, -1.0, np.inf
    src[20, 20] = np.nan
    src[30, 30, 1] = np.inf
    got = run(rt, src, vel, depth)
    assert np.isfinite(got).all()
    clean = src.copy()
    clean[20, 20] = 0.0
    clean[30, 30, 1] = 0.0
    ref = run(rt, clean, vel, depth)
    np.testing.assert_array_equal(got, ref)   # non-finite pixels count as 0


def test_huge_velocity_is_clamped(rt, rng):
    src = rng.uniform(0.0, 1.0, (64, 80, 4)).astype(np.float32)
    vel = uniform((64, 80), (1000.0, 0.0))
    got = run(rt, src, vel, max_blur=0.05, quality="reference")
    r = min(0.05 * math.hypot(80, 64), MAX_RADIUS_PX)   # reach clamped to the max radius
    # centred: reach = |v| / 4; a 10 px blur reads through the cubic at reference
    cubic = 2 * r < MotionBlur.descriptor.quality["reference"].cubic_max_px
    want = line_blur(src, (4 * r, 0.0), t0=-0.25, t1=0.25, interp="cubic" if cubic else "linear")
    assert np.isfinite(got).all()
    # the clamped velocity's box blur (float32 velocity scaling: ~1e-6 px of length)
    assert np.abs(got - want).max() < 1e-2
    assert tile_size(1e9) == MAX_RADIUS_PX


def test_hdr_highlight_energy_and_alpha(rt):
    src = np.zeros((32, 64, 4), np.float32)
    src[..., 3] = 1.0
    src[16, 32, :3] = 1e5
    got = run(rt, src, uniform((32, 64), (26.0, 0.0)), quality="reference", max_blur=0.25)
    # energy kept (a 13 px blur, past FINE_CUBIC_MAX_PX: bilinear, and midpoint samples of a
    # bilinear point are exact up to float64 rounding)
    np.testing.assert_allclose(got[..., :3].sum(), 3e5, rtol=1e-5)
    np.testing.assert_allclose(got[..., 3], 1.0, rtol=1e-6)
    assert (got[16, 27:38, 0] > 1e3).all() and got[16, 45, 0] < 1.0
    # a short blur reads through the clamped cubic: its negative lobes are cut, which keeps
    # the dark side dark (no ringing) and adds a little energy
    got = run(rt, src, uniform((32, 64), (6.0, 0.0)), quality="reference", max_blur=0.25)
    assert got.min() >= 0.0
    np.testing.assert_allclose(got[..., :3].sum(), 3e5, rtol=0.1)
    assert (got[16, 31:34, 0] > 1e3).all() and got[16, 38, 0] == 0.0


def test_static_pixels_keep_their_colour_beside_moving_object(rt, rng):
    h, w = 48, 96
    src = rng.uniform(0.0, 1.0, (h, w, 4)).astype(np.float32)
    vel = np.zeros((h, w, 2), np.float32)
    vel[10:20, 10:30] = (20.0, 0.0)
    depth = np.full((h, w), 10.0, np.float32)
    depth[10:20, 10:30] = 2.0
    got = run(rt, src, vel, depth)
    # rows the object never passes over are untouched
    np.testing.assert_allclose(got[30:], src[30:], atol=1e-6)
    np.testing.assert_allclose(got[:8], src[:8], atol=1e-6)


def test_all_samples_rejected_falls_back_to_centre(rt):
    # a far pixel surrounded by a near layer moving perpendicular: everything is rejected
    src = np.zeros((24, 24, 4), np.float32)
    src[12, 12] = (3.0, 2.0, 1.0, 1.0)
    vel = uniform((24, 24), (0.0, 12.0))
    vel[12, 12] = (12.0, 0.0)
    depth = np.full((24, 24), 1.0, np.float32)
    depth[12, 12] = 100.0
    got = run(rt, src, vel, depth)
    assert np.isfinite(got).all()


# -- against renderer-like ground truth (issue 11) ---------------------------------------------
GT_SIZE = (240, 135)
"""The cases' frame: every speed and size but the slow cases' (in pixels) scales with the
width.  At 160x90 the fast lights shrink to a pixel and final ends 1.4 dB behind reference;
at 240x135 every assertion holds with the margins of ``test_beats_naive_and_input_on_ground_
truth`` (and the same at jitter seeds 2 and 3), in half the time of 320x180."""
GT_SAMPLES = 256
"""Rays a pixel of the cases' jittered truths.  At 128 (at 320x180) the truth's own noise in
the edge band (linear RMSE, led by crossing's light of 400: a second seed's truth scores 0.119
against it) equals the naive blur's score there (0.120), and final's 0.146 measured the
truth's noise: against a 1024-ray truth final scores 0.125, the naive blur 0.209."""


@pytest.fixture(scope="module")
def gt_cases():
    """Every motion_blur bench case at ``GT_SIZE``: beauty and truth sampled as a renderer
    samples (jittered rays), centre-sampled passes (3-5 s a case on one core, 60 % of it the
    256-ray beauty, 40 % the truth)."""
    return {name: make(*GT_SIZE, None, truth_samples=GT_SAMPLES, noise_floor=False)
            for name, make in CASES.items()}


def _psnr(out, case):
    edge = metrics.edge_band(case["depth"], case["velocity"], EDGE_BAND_PX)
    return error_metrics(out, case["truth"], edge)


@pytest.mark.parametrize("period", [3.0, 4.0, 6.0])
@pytest.mark.parametrize("speed", [1.0, 2.0, 4.0])
def test_slow_motion_over_fine_stripes_ends_closer_to_truth_than_the_input(rt, period, speed):
    """Issue 11 item 6: stripes 1.5-3 px wide moving 1-4 px/frame (smears of 0.5-2 px): every
    level ends closer to the supersampled truth than the unblurred frame."""
    from clfx.bench.groundtruth import RENDER_SS, make_case
    from clfx.bench.scene import Layer, Scene, Texture

    panel = Layer(depth=4.0, texture=Texture("stripes", (0.8, 0.78, 0.7), (0.08, 0.08, 0.1),
                                             period=period, angle=15.0),
                  shape="full", velocity=(speed, 0.3 * speed))
    gt = make_case(Scene(96, 64, (panel,)), CENTRED, samples=128, dof=False, motion=True,
                   ss=RENDER_SS)
    f, inner = gt.sharp, np.s_[8:-8, 8:-8]

    def psnr(out):
        return error_metrics(out[inner], gt.truth[inner])["psnr_log"]

    unblurred = psnr(f.rgba)
    for q in QUALITIES:
        got = psnr(run(rt, f.rgba, f.velocity, f.depth, quality=q))
        assert got > unblurred, (q, got, unblurred)


@pytest.mark.parametrize("texture,period,angle", [("stripes", 2.5, 15.0), ("checker", 2.0, 15.0),
                                                   ("noise", 1.5, 0.0)])
def test_slow_fine_texture_never_worse_than_the_input_in_any_direction(rt, texture, period,
                                                                       angle):
    """Issue 24: fine texture moving 1-3 px/frame in any direction (180 degrees: smears of
    0.5-1.5 px) ends closer to the supersampled truth than the unblurred frame, at every
    level.  Measured (final, 96x64, 256 renders) before the cubic reached half-pixel smears:
    1 px/frame at 200 degrees 4.3 (stripes), 3.6 (checker), 8.2 dB (noise) below the input;
    after: 2.9, 0.7, 2.8 dB above it."""
    from clfx.bench.groundtruth import RENDER_SS, make_case
    from clfx.bench.scene import Layer, Scene, Texture

    inner = np.s_[8:-8, 8:-8]
    for speed in (1.0, 2.0, 3.0):
        for direction in (200.0, 90.0):
            a = math.radians(direction)
            panel = Layer(depth=4.0, texture=Texture(texture, (0.8, 0.78, 0.7),
                                                     (0.08, 0.08, 0.1), period=period,
                                                     angle=angle, seed=2),
                          shape="full", velocity=(speed * math.cos(a), speed * math.sin(a)))
            gt = make_case(Scene(96, 64, (panel,)), CENTRED, samples=256, dof=False,
                           motion=True, ss=RENDER_SS)
            f = gt.sharp

            def psnr(out):
                return error_metrics(out[inner], gt.truth[inner])["psnr_log"]

            unblurred = psnr(f.rgba)
            for q in QUALITIES:
                got = psnr(run(rt, f.rgba, f.velocity, f.depth, quality=q))
                assert got > unblurred, (speed, direction, q, got, unblurred)


@pytest.mark.parametrize("texture,period,angle", [("stripes", 2.5, 15.0), ("checker", 2.0, 15.0),
                                                   ("noise", 1.5, 0.0)])
def test_sub_pixel_smears_never_worse_than_the_input(rt, texture, period, angle):
    """Issue 24: fine texture moving 0.4 and 0.75 px/frame (smears of 0.2 and 0.375 px
    through a centred 180 degree shutter) ends closer to the truth than the unblurred frame
    at every level.  Measured (final, 96x64, 256 renders, 200 degrees) through the tent:
    5.1/6.5 (stripes), 3.1/4.3 (checker), 19.6/13.1 dB (noise) below the input; with the
    closed form of kernels/lib/motion.cl ``mb_short_smear``: 0.13/1.26, 0.07/0.32 and
    1.31/3.20 dB above it."""
    from clfx.bench.groundtruth import RENDER_SS, make_case
    from clfx.bench.scene import Layer, Scene, Texture

    inner = np.s_[8:-8, 8:-8]
    for speed in (0.4, 0.75):
        a = math.radians(200.0)
        panel = Layer(depth=4.0, texture=Texture(texture, (0.8, 0.78, 0.7), (0.08, 0.08, 0.1),
                                                 period=period, angle=angle, seed=2),
                      shape="full", velocity=(speed * math.cos(a), speed * math.sin(a)))
        gt = make_case(Scene(96, 64, (panel,)), CENTRED, samples=256, dof=False, motion=True,
                       ss=RENDER_SS)
        f = gt.sharp
        unblurred = error_metrics(f.rgba[inner], gt.truth[inner])["psnr_log"]
        for q in QUALITIES:
            got = error_metrics(run(rt, f.rgba, f.velocity, f.depth, quality=q)[inner],
                                gt.truth[inner])["psnr_log"]
            assert got > unblurred, (speed, q, got, unblurred)


def band_limited_texture(h, w, v, t0, t1, seed):
    """A texture of 12 plane waves (0.08-0.4 cycles/px, as a renderer's filtered pixels hold
    them) sampled at the pixel centres, and its exact time average under uniform motion ``v``
    (px/frame) over ``[t0, t1]``, a centred shutter: each wave times ``sinc(f . v (t1 - t0))``."""
    rng = np.random.default_rng(seed)
    ys, xs = np.mgrid[0:h, 0:w] + 0.5
    src, truth = np.full((h, w), 0.5), np.full((h, w), 0.5)
    for _ in range(12):
        f, a = rng.uniform(0.08, 0.4), rng.uniform(0.0, 2.0 * math.pi)
        fx, fy = f * math.cos(a), f * math.sin(a)
        amp, phase = rng.uniform(0.02, 0.06), rng.uniform(0.0, 2.0 * math.pi)
        wave = amp * np.cos(2.0 * math.pi * (fx * xs + fy * ys) + phase)
        src += wave
        truth += np.sinc((fx * v[0] + fy * v[1]) * (t1 - t0)) * wave
    return (np.repeat(src[..., None], 4, -1).astype(np.float32),
            np.repeat(truth[..., None], 4, -1))


@pytest.mark.parametrize("v", [(17.1, 5.3), (-21.0, -4.0), (4.3, -2.9)])
def test_finer_levels_do_not_blur_texture_more(rt, v):
    """Issue 35: fine texture moving 2.5-9 px over the shutter, against its exact time average:
    the error falls (or stays) as the level rises, final within 5% of reference.  Before,
    final's and reference's bilinear reads at every sub-pixel offset summed the tent's blur
    that preview's sample per pixel does not (9 px blurs: RMSE 0.0107 preview, 0.0113 final;
    now through the cubic 0.0046), and their cubic reads at 2 and 4 samples per pixel on
    2.6 px blurs more of the cubic's (0.0045 preview, 0.0052 final, 0.0053 reference; now a
    sample per pixel at every level under SHORT_MAX_PX)."""
    h, w = 48, 64
    t0, t1 = CENTRED.shutter_interval()
    src, truth = band_limited_texture(h, w, v, t0, t1, seed=5)
    inner = np.s_[12:-12, 12:-12]                      # away from the clamped edges
    errs = [float(np.sqrt(np.mean((run(rt, src, uniform((h, w), v), quality=q, max_blur=0.25)
                                   - truth)[inner][..., :3] ** 2))) for q in QUALITIES]
    assert all(b <= a * (1 + 1e-4) for a, b in zip(errs, errs[1:-1])), errs
    # reference's quarter-pixel samples through the cubic: within 1-2% of final here
    assert errs[3] <= errs[2] * 1.05 and errs[2] <= errs[3] * 1.05, errs


@pytest.mark.parametrize("speed", [0.4, 0.75, 0.9, 1.7, 2.6])
@pytest.mark.parametrize("direction", [0.0, 90.0, 200.0, 37.0])
def test_sub_pixel_smear_matches_the_oracle(rt, rng, speed, direction):
    """Issues 24 and 35: one velocity under 1.5 px of smear (0.2, 0.375, 0.45, 0.85 and 1.3 px
    through a centred 180 degree shutter): the closed form (tests/reference ``short_smear``)
    up to 3/8 px, blended into the cubic line blur by 1/2 px, and the step model
    (``step_smear``) over both on the flat patches and their edges, at every level; flat
    fields stay flat."""
    h, w = 40, 48
    src = rng.uniform(0.0, 1.0, (h, w, 4)).astype(np.float32)
    src[8:16, 8:30] = 0.25                            # flat patches and pixel-aligned edges
    src[20:30:2, 10:40] = 0.9                         # alternation across rows
    src[22:32, 12:40:2] = 0.05                        # ... and along them
    a = math.radians(direction)
    v = (speed * math.cos(a), speed * math.sin(a))
    t0, t1 = CENTRED.shutter_interval()
    inner = np.s_[4:-4, 4:-4]
    for q in QUALITIES:
        lvl = MotionBlur.descriptor.quality[q]
        length = speed * (t1 - t0)
        spacing = lvl.short_spacing if length < SHORT_MAX_PX else lvl.spacing
        n = int(np.clip(math.ceil(length / spacing), 2, lvl.max_samples))
        want = short_blur(src, v, t0=t0, t1=t1, n=n)
        got = run(rt, src, uniform((h, w), v), np.full((h, w), 3.0, np.float32), quality=q)
        np.testing.assert_allclose(got[inner], want[inner], atol=2e-5, err_msg=q)
        flat = run(rt, np.full((h, w, 4), 0.37, np.float32), uniform((h, w), v), quality=q)
        np.testing.assert_allclose(flat, 0.37, rtol=1e-6, atol=0)


@pytest.mark.parametrize("speed", [0.4, 0.9, 1.3])
def test_sub_pixel_smears_of_mixed_directions_match_the_oracle_to_the_edges(rt, rng, speed):
    """The closed forms run on a quad's four pixels at once (kernels/lib/motion.cl
    mb_short_quad): lanes moving in different directions (here every pixel's differs from
    its neighbours', one speed and one depth, so each pixel gets the oracle of its own
    velocity) read their taps lane by lane, and the frame's edges and a width that is no
    multiple of 4 clamp each lane's taps on its own: the whole frame matches."""
    h, w = 22, 46
    src = rng.uniform(0.0, 1.0, (h, w, 4)).astype(np.float32)
    src[4:12, 6:20] = 0.25                            # flat patches and pixel-aligned edges
    src[14:20:2, 8:40] = 0.9
    angles = np.radians([15.0, 100.0, 200.0, 290.0, 45.0])
    which = (np.arange(w)[None, :] * 3 + np.arange(h)[:, None] * 2) % len(angles)
    vels = [(speed * math.cos(a), speed * math.sin(a)) for a in angles]
    vel = np.zeros((h, w, 2), np.float32)
    for i, v in enumerate(vels):
        vel[which == i] = v
    t0, t1 = CENTRED.shutter_interval()
    length = speed * (t1 - t0)
    for q in ("draft", "final"):
        lvl = MotionBlur.descriptor.quality[q]
        spacing = lvl.short_spacing if length < SHORT_MAX_PX else lvl.spacing
        n = int(np.clip(math.ceil(length / spacing), 2, lvl.max_samples))
        want = np.zeros((h, w, 4))
        for i, v in enumerate(vels):
            want[which == i] = short_blur(src, np.float32(v), t0=t0, t1=t1, n=n)[which == i]
        got = run(rt, src, vel, np.full((h, w), 3.0, np.float32), quality=q)
        np.testing.assert_allclose(got, want, atol=2e-5, err_msg=q)


def test_naive_baseline_is_the_per_pixel_line_blur(rng):
    src = smooth_texture(rng, 24, 31)
    vel = rng.normal(0.0, 6.0, (24, 31, 2)).astype(np.float32)
    longest = float(np.hypot(vel[..., 0], vel[..., 1]).max()) * 0.5
    n = min(max(2, math.ceil(longest / 0.5)), 64)
    want = naive_blur(src, vel, t0=-0.25, t1=0.25, n=n)
    np.testing.assert_allclose(naive_line_blur(src, vel, -0.25, 0.25), want, atol=2e-5)


@pytest.mark.parametrize("name", list(CASES))
def test_beats_naive_and_input_on_ground_truth(rt, gt_cases, name):
    """Issue 11: on every case, draft and final end closer to the truth than the per-pixel line
    blur and than the unblurred input (log-PSNR), final within 1 dB of reference.

    Margins at 240x135 (measured; draft / final): over the naive blur layers +2.1 / +2.3 dB,
    crossing +3.5 / +3.5, spin +2.3 / +1.9, fast_light +10.4 / +10.8, shutter_270 +2.4 /
    +2.3, slow_stripes +6.0, slow_checker +0.53 (the tightest: +0.02 at 320x180); over the
    input +2.2 dB or more (spin); final at most 0.16 dB behind reference (fast_light); final's
    edge-band RMSE 2.6 % (slow_checker) to 89 % below the naive blur's.  Caught at this size:
    no clamped cubic on short blurs (slow_stripes 1.4 dB behind the input), a shutter 25 %
    short (slow_checker 2.8 dB behind the naive blur, fast_light final 1.3 dB behind
    reference)."""
    c = gt_cases[name]
    t0, t1 = c["camera"].shutter_interval()
    naive = _psnr(naive_line_blur(c["source"], c["velocity"], t0, t1), c)
    unblurred = _psnr(c["source"], c)
    got = {q: _psnr(run(rt, c["source"], c["velocity"], c["depth"], quality=q,
                        camera=c["camera"]), c) for q in QUALITIES}
    for q in ("draft", "final"):
        assert got[q]["psnr_log"] > naive["psnr_log"], (q, got[q], naive)
        assert got[q]["psnr_log"] > unblurred["psnr_log"], (q, got[q], unblurred)
    assert got["final"]["psnr_log"] > got["reference"]["psnr_log"] - 1.0, got
    # and the edge band, where the naive blur bleeds and occlusion matters
    assert got["final"]["edge_rmse"] < naive["edge_rmse"], (got["final"], naive)


def test_static_tiles_are_skipped(rt, rng):
    c = CASE.make(320, 180, rng, truth=False, moving_fraction=0.1)
    src, vel, dep = (rt.upload(c["source"]), rt.upload(c["velocity"]), rt.upload(c["depth"]))
    ctx = RenderContext(rt, src, velocity=vel, depth=dep, camera=CENTRED)
    out = MotionBlur().render(rt, MotionBlur.params(), ctx).download()
    note = ctx.notes[-1]
    moving, total = (int(x) for x in note.split(": ")[1].split(" tiles")[0].split("/"))
    assert moving < 0.35 * total, note
    far = np.abs(c["velocity"]).max(-1) == 0
    far[:, 100:220] = False
    np.testing.assert_array_equal(out[far], c["source"][far])


@pytest.mark.parametrize("with_depth", [True, False])
def test_object_crossing_a_tight_data_window_is_not_cut(rt, with_depth):
    """Issue 11 item 5: a bar moving right out of a data window tighter than the display
    window.  The region of definition grows by the smear's reach, light lands past the data
    window, and the profile falls off like the line blur instead of stopping at a hard edge."""
    display, data = Rect(0, 0, 96, 48), Rect(24, 12, 64, 36)
    h, w = data.height, data.width
    src = np.zeros((h, w, 4), np.float32)
    src[6:18, 20:] = 1.0                          # touches the data window's right edge
    vel = np.zeros((h, w, 2), np.float32)
    vel[6:18, 20:] = (16.0, 0.0)                  # 16 px/frame, 180 deg centred: +-4 px
    depth = np.full((h, w), 10.0, np.float32)
    depth[6:18, 20:] = 2.0
    out, window = render_effect(rt, MotionBlur(), MotionBlur.params(), src, velocity=vel,
                                depth=depth if with_depth else None, data_window=data,
                                display_window=display, camera=CENTRED, quality="reference",
                                keep_rod=True)
    assert window.contains(data) and window != data and display.contains(window)
    assert window.x1 >= data.x1 + 4                # the whole smear fits
    row = out[12 + data.y0 - window.y0, :, 0]      # a row through the bar
    edge = data.x1 - window.x0                     # first column past the data window
    assert row[edge] > 0.3 and row[edge + 2] > 0.1     # light outside the data window
    # line blur of the bar against the black outside: ~1/8 per pixel, no step at the edge
    assert np.abs(np.diff(row[edge - 6:edge + 6])).max() < 0.2, row[edge - 6:edge + 6]
    want = line_blur(src, (16.0, 0.0), t0=-0.25, t1=0.25)   # clamps at the window edge
    assert row[edge - 1] < want[12, -1, 0] - 0.3              # ... which the output must not
    assert np.isfinite(out).all()


def test_rod_is_the_source_window_when_data_equals_display(rt, rng):
    src = smooth_texture(rng, 24, 40)
    out, window = render_effect(rt, MotionBlur(), MotionBlur.params(), src,
                                velocity=uniform((24, 40), (9.0, 0.0)), camera=CENTRED,
                                keep_rod=True)
    assert window == Rect(0, 0, 40, 24) and out.shape == src.shape


def _spinning_light(size=128, radius=40.0, deg_per_frame=72.0, theta0=30.0):
    """A small HDR light (1.5 px, 1000) on a circle of ``radius`` about the centre, over a dark
    static wall; the forward and backward motion of the light's pixels are the chords to its
    positions one frame later and earlier (as Blender's Vector pass writes them)."""
    c = size / 2.0
    w = math.radians(deg_per_frame)

    def pos(t):
        a = math.radians(theta0) + w * t
        return np.array([c + radius * math.cos(a), c + radius * math.sin(a)])

    p0 = pos(0.0)
    ss = 8
    g = (np.arange(size * ss) + 0.5) / ss
    xx, yy = np.meshgrid(g, g)
    cover = ((xx - p0[0]) ** 2 + (yy - p0[1]) ** 2 <= 1.5 ** 2).astype(np.float64)
    cover = cover.reshape(size, ss, size, ss).mean(axis=(1, 3))
    src = np.zeros((size, size, 4), np.float32)
    src[..., :3] = 0.02 + 1000.0 * cover[..., None]
    src[..., 3] = 1.0
    light = cover > 0.0
    depth = np.where(light, 5.0, 100.0).astype(np.float32)
    fwd = np.zeros((size, size, 2), np.float32)
    back = np.zeros((size, size, 2), np.float32)
    fwd[light] = pos(1.0) - p0
    back[light] = p0 - pos(-1.0)
    return src, fwd, back, depth, c, radius, math.radians(theta0), w


def _streak_radius(img, c, angles, radius):
    """Intensity-weighted radius of the streak (over its background) across each angle."""
    lum = img[..., :3].sum(-1) - 3 * 0.02
    rs = np.arange(radius - 10.0, radius + 10.0, 0.25)
    out = []
    for a in angles:
        x, y = c + rs * math.cos(a) - 0.5, c + rs * math.sin(a) - 0.5
        x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
        fx, fy = x - x0, y - y0
        v = (lum[y0, x0] * (1 - fx) * (1 - fy) + lum[y0, x0 + 1] * fx * (1 - fy)
             + lum[y0 + 1, x0] * (1 - fx) * fy + lum[y0 + 1, x0 + 1] * fx * fy)
        v = np.maximum(v, 0.0)
        out.append((rs * v).sum() / max(v.sum(), 1e-9))
    return np.array(out)


def test_spinning_light_streak_follows_its_arc_with_both_halves(rt):
    """Issue 24: with both halves of the vector pass the streak of a light turning 72
    deg/frame follows its arc (centre line within 1 px of the true radius along the inner
    70% of the swept arc); with the forward half alone it runs along the forward chord
    (measured at final: up to 5.9 px off the arc; 0.65 px with both halves)."""
    src, fwd, back, depth, c, r, th0, w = _spinning_light()
    t0, t1 = CENTRED.shutter_interval()
    angles = th0 + w * np.linspace(t0, t1, 21)[3:-3]
    for q in QUALITIES:
        curved = render_effect(rt, MotionBlur(), MotionBlur.params(), src, velocity=fwd,
                               velocity_back=back, depth=depth, quality=q, camera=CENTRED)
        err = np.abs(_streak_radius(curved, c, angles, r) - r)
        assert err.max() <= 1.0, (q, err.round(2))
    straight = render_effect(rt, MotionBlur(), MotionBlur.params(), src, velocity=fwd, depth=depth,
                             camera=CENTRED)
    assert np.abs(_streak_radius(straight, c, angles, r) - r).max() > 3.0
    # one half: today's behaviour, bit for bit
    same = render_effect(rt, MotionBlur(), MotionBlur.params(), src, velocity=fwd, depth=depth,
                         velocity_back=fwd, camera=CENTRED)
    np.testing.assert_allclose(same, straight, rtol=1e-5, atol=1e-3)


def test_explain_says_which_halves_of_the_vector_pass_were_used(rt):
    """Issue 24: a frame with both halves (Blender's XY and ZW) blurs along curved paths,
    one with the forward half alone keeps the straight ones; the step's notes say which."""
    from dataclasses import replace

    from clfx.core.frame import Frame
    from clfx.pipeline.look import Look, Step, render_frame
    from clfx.plugins import get_plugin

    src, fwd, back, depth, *_ = _spinning_light(size=64, radius=20.0)
    look = Look("m", steps=[Step("motion_blur", get_plugin("motion_blur").params())],
                camera=CENTRED)
    one = Frame.from_array(src, depth=depth, velocity=fwd)
    both = replace(one, velocity_back=back)
    notes = {}
    for label, frame in (("one", one), ("both", both)):
        _, report = render_frame(rt, look, frame, frame_number=1)
        notes[label] = " ".join(n for s in report.steps for n in s.notes)
    assert "straight paths along the forward motion (one half" in notes["one"], notes
    assert "curved paths through the previous, current and next positions" in notes["both"]


def test_slow_fine_checker_beats_the_naive_line_blur_at_every_level(rt):
    """Issue 35: a checker of 3 px squares on the pixel grid drifting 1.7 px/frame over a fine
    static wall (the ``slow_checker`` bench case, 0.86 px smears of hard edges): every level
    ends closer to the truth than the naive line blur (exact on such edges) and the input, the
    error never rises with the level, final within 5% of reference.  Before the step model
    (96x54, 128 rays): 33.89 dB at draft to final, 34.55 reference, against the naive blur's
    37.74; after: 37.76 at every level."""
    from clfx.bench.cases.motion_blur import make_slow_checker

    c = make_slow_checker(96, 54, None, truth_samples=128, noise_floor=False)
    t0, t1 = c["camera"].shutter_interval()
    naive = _psnr(naive_line_blur(c["source"], c["velocity"], t0, t1), c)
    unblurred = _psnr(c["source"], c)
    got = {q: _psnr(run(rt, c["source"], c["velocity"], c["depth"], quality=q,
                        camera=c["camera"]), c) for q in QUALITIES}
    for q in QUALITIES:
        assert got[q]["psnr_log"] > naive["psnr_log"], (q, got[q], naive)
        assert got[q]["psnr_log"] > unblurred["psnr_log"], (q, got[q], unblurred)
    errs = [got[q]["rel_rmse"] for q in QUALITIES]
    assert all(b <= a * (1 + 1e-4) for a, b in zip(errs, errs[1:])), errs
    assert errs[2] <= 1.05 * errs[3], errs


# -- issue 37: the gather's CPU ------------------------------------------------------------------
def _layered_scene(rng, h=64, w=90):
    """A sub-pixel pan of a far textured wall (0.9 px/frame), a near card moving fast across
    it, a static sky at infinity down the right side, and a mid-depth patch creeping."""
    src = (smooth_texture(rng, h, w) * 2.0).astype(np.float32)
    vel = uniform((h, w), (0.9, 0.0))
    depth = np.full((h, w), 20.0, np.float32)
    depth[18:34, 20:44], vel[18:34, 20:44] = 3.0, (26.0, -6.0)
    depth[44:56, 8:30], vel[44:56, 8:30] = 8.0, (0.0, 0.7)
    depth[:, 72:], vel[:, 72:] = np.inf, 0.0
    return src, vel, depth


@pytest.mark.parametrize("quality", QUALITIES)
@pytest.mark.parametrize("curved", [False, True])
def test_front_free_tiles_render_as_if_every_depth_test_ran(rt, rng, monkeypatch, quality,
                                                             curved):
    """Issue 37: tiles where nothing the gather reads lies in front of any of their pixels
    (the tiles' depth ranges, clfx.fx.motion._front_free) skip the occluder set and the soft
    depth tests, each of which gives exactly 0 there: the frame is the one every test runs
    for, bit for bit, on a plate with both kinds of tiles, short (cubic) and long ones."""
    from clfx.fx import motion

    src, vel, depth = _layered_scene(rng)
    back = None
    if curved:   # a gentle turn: the backward motion rotated by 10 degrees
        c, s = math.cos(0.17), math.sin(0.17)
        back = np.stack([c * vel[..., 0] - s * vel[..., 1], s * vel[..., 0] + c * vel[..., 1]],
                        -1).astype(np.float32)
    seen = []
    real = motion._front_free

    def spy(*a):
        seen.append(real(*a))
        return seen[-1]

    def render():
        return render_effect(rt, MotionBlur(), MotionBlur.params(), src, velocity=vel,
                             velocity_back=back, depth=depth, quality=quality, camera=CENTRED)

    monkeypatch.setattr(motion, "_front_free", spy)
    got = render()
    free = np.concatenate([f.ravel() for f in seen])
    assert free.any() and not free.all(), free
    monkeypatch.setattr(motion, "_front_free", lambda z, k, reach: np.zeros(z.shape[:2], bool))
    np.testing.assert_array_equal(got.view(np.uint32), render().view(np.uint32))   # -0 too


def test_front_free_needs_the_whole_reach_behind_the_tile():
    """A tile is front-free when its largest depth is at most the smallest of every tile its
    reads reach: one tile around it while the reach fits in a tile, two beyond."""
    from clfx.fx.motion import _front_free

    zr = np.full((6, 8, 2), 10.0, np.float32)
    zr[3, 4] = 2.0                         # a near tile
    zr[0, 0] = (5.0, 10.0)                 # a tile with its own nearer pixels
    want = np.ones((6, 8), bool)
    want[2:5, 3:6] = False
    want[3, 4] = True                      # nothing lies in front of the near tile itself
    want[0, 0] = want[0, 1] = want[1, 0] = want[1, 1] = False
    np.testing.assert_array_equal(_front_free(zr, 8, 8.0), want)
    np.testing.assert_array_equal(_front_free(zr, 8, 0.2), want)   # the taps' 2 px
    want[1:6, 2:7] = False                 # a read 9 px away: two tiles around
    want[3, 4] = True
    want[0:3, 0:3] = False
    np.testing.assert_array_equal(_front_free(zr, 8, 8.6), want)


def test_rim_dilation_matches_the_oracle(rt, rng):
    """The rim dilation (motion_dilate) against its oracle, record for record: small bright
    lights moving over a dark wall and a nearer static bar, some on the image's edges, on a
    width that is not a multiple of 4 (most quads take the kernel's no-candidate path)."""
    from clfx.fx import motion
    from tests.reference.motion_blur import rim_dilation

    h, w = 29, 45
    col = np.zeros((h, w, 4), np.float32)
    col[..., :3] = rng.uniform(0.01, 0.03, (h, w, 3))
    col[..., 3] = 1.0
    vel = uniform((h, w), (0.0, 0.0))
    depth = np.full((h, w), 30.0, np.float32)
    depth[20:23, :] = 12.0                                     # a nearer static bar
    for y, x, v in ((5, 7, (9.0, 2.0)), (0, 20, (-6.0, 0.0)), (13, 44, (0.0, 7.0)),
                    (21, 30, (5.0, 5.0)), (28, 0, (8.0, -3.0)), (10, 26, (4.0, 0.0))):
        col[y, x, :3] = 50.0                                   # the light
        vel[y, x], depth[y, x] = v, 4.0
        for dy in (-1, 0, 1):                                  # its antialiased rim
            for dx in (-1, 0, 1):
                yy, xx = y + dy, x + dx
                if (dy or dx) and 0 <= yy < h and 0 <= xx < w:
                    col[yy, xx, :3] = rng.uniform(2.0, 9.0)
    col[10, 27, :3] = 0.2      # a rim pixel too dark to take the light's motion
    duration = 0.5
    aux, _ = motion._prepared(rt, rt.upload(col), rt.upload(vel), rt.upload(depth), None,
                              motion._defines(motion.LEVELS["final"], True, False), 1e3,
                              duration)
    got = aux.download()
    want_v, want_z = rim_dilation(vel, depth, col, duration)
    assert (want_z != depth).sum() >= 20                       # rims moved with their lights
    np.testing.assert_array_equal(got[..., :2], want_v.astype(np.float32))
    np.testing.assert_array_equal(got[..., 2], want_z.astype(np.float32))


@pytest.mark.parametrize("curved", [False, True])
def test_tilemax_takes_the_first_fastest_pixel_and_the_depth_range(rt, rng, curved):
    """TileMax's record is the tile's fastest pixel's (vx, vy, |v|), the first in scan order
    among equal speeds (here many: speeds from 4 values), its backward motion with it
    (CURVED), and each tile's smallest and largest depth; on a width that ends mid-tile and
    mid-quad (the kernel's 4 columns at a time and the columns after), a still tile too."""
    from clfx.fx import motion

    h, w, k = 37, 45, 8
    aux = np.zeros((h, w, 4), np.float32)
    speed = rng.choice(np.array([0.0, 1.0, 2.0, 3.0], np.float32), (h, w))
    angle = rng.uniform(0.0, 2.0 * np.pi, (h, w))
    aux[..., 0], aux[..., 1] = speed * np.cos(angle), speed * np.sin(angle)
    aux[..., 2] = rng.uniform(1.0, 50.0, (h, w))
    aux[..., 3] = speed
    aux[:8, :8, 3] = aux[:8, :8, 0] = aux[:8, :8, 1] = 0.0          # a still tile
    back = rng.uniform(-5.0, 5.0, (h, w, 4)).astype(np.float32)
    defines = motion._defines(motion.LEVELS["final"], True, curved)
    tx, ty, bufs = motion._grid_buffers(rt, w, h, k, curved)
    img = rt.upload(aux)
    motion._tilemax(rt, defines, img, rt.upload(back) if curved else bufs[1], bufs, img.pitch,
                    w, h, 0, tx, ty, 0, ty, k)
    tiles = rt.from_device(bufs[0], np.float32, tx * ty * 4).reshape(ty, tx, 4)
    zr = rt.from_device(bufs[2], np.float32, tx * ty * 2).reshape(ty, tx, 2)
    if curved:
        tb = rt.from_device(bufs[1], np.float32, tx * ty * 2).reshape(ty, tx, 2)
    for j in range(ty):
        for i in range(tx):
            blk = aux[j * k:(j + 1) * k, i * k:(i + 1) * k]
            s = blk[..., 3].ravel()
            first = int(np.argmax(s))              # numpy: the first among equals
            y, x = divmod(first, blk.shape[1])
            want = (blk[y, x, 0], blk[y, x, 1], s[first], 0.0) if s[first] > 0 else (0,) * 4
            np.testing.assert_array_equal(tiles[j, i], np.float32(want), err_msg=(j, i))
            np.testing.assert_array_equal(zr[j, i], (blk[..., 2].min(), blk[..., 2].max()))
            if curved:
                wb = back[j * k + y, i * k + x, :2] if s[first] > 0 else (0.0, 0.0)
                np.testing.assert_array_equal(tb[j, i], wb, err_msg=(j, i))
