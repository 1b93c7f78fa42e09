"""shake: the blur of a camera's seeded random turns, against the exact turns' average
(tests/reference/shake.py), through the production render path."""
import numpy as np
import pytest

from clfx.core.camera import Camera
from clfx.plugins.shake import Shake
from tests.effects import render_effect
from tests.plugins.test_motion_blur import smooth_texture
from tests.reference.motion_blur import bilinear
from tests.reference.shake import angles, velocity
from tests.reference.shake import shake as reference

CAM = Camera(focal_length=35.0, sensor_width=12.0, shutter_angle=180.0,
             shutter_offset="centered")
"""A 35 mm lens on a 12 mm sensor: 187 px/rad on a 64 px frame, so a degree is 3.3 px."""

INNER = (slice(8, -8), slice(8, -8))
"""Away from the frame's edge, where the effect and the oracle both clamp their reads but
the gather's tiles see the edge differently."""


def run(rt, src, quality="final", frame=5, camera=CAM, **kw):
    return render_effect(rt, Shake(), Shake.params(**kw), src, camera=camera, frame=frame,
                         quality=quality)


def rmse(a, b):
    return float(np.sqrt(np.mean((a - b)[INNER][..., :3] ** 2)))


def tangent_blur(src, vel, t0, t1, n=256):
    """Each pixel averaged along the straight line of its velocity at the frame time."""
    ys, xs = np.mgrid[0:src.shape[0], 0:src.shape[1]] + 0.5
    ts = t0 + (np.arange(n) + 0.5) / n * (t1 - t0)
    return sum(bilinear(src, xs - vel[..., 0] * t, ys - vel[..., 1] * t) for t in ts) / n


# Measured at final on smooth_texture 64x96, frame 5 (interior RMSE, [0, 1] range): the
# turns a sway makes (yaw 4, pitch 3 deg RMS at 2 Hz) 0.0073 (the unblurred input 0.0772);
# a fast shake with a strong roll (2, 2, 6 deg at 4 Hz, seed 7) 0.0063 (input 0.0752); a
# roll alone (10 deg RMS) 0.0039 (input 0.0053).  The limits are 1.5x those.
@pytest.mark.parametrize("kw, limit", [
    (dict(yaw=4.0, pitch=3.0, roll=0.0), 0.011),
    (dict(yaw=2.0, pitch=2.0, roll=6.0, frequency=4.0, seed=7), 0.0095),
    (dict(yaw=0.0, pitch=0.0, roll=10.0), 0.006),
])
def test_shake_follows_the_exact_turns(rt, rng, kw, limit):
    src = smooth_texture(rng, 64, 96)
    want = reference(src, camera=CAM, frame=5, n=256, **kw)
    got = run(rt, src, **kw)
    assert rmse(got, want) < limit, rmse(got, want)
    assert rmse(got, want) < 0.15 * rmse(src, want) or kw["roll"] == 10.0


def test_shake_is_as_close_as_each_pixels_own_line(rt, rng):
    """The gather of the chord field is as close to the exact turns as the plain per-pixel
    line blur along each pixel's exact velocity at the frame time, 256 samples each
    (measured 0.0063 against 0.0055 on a fast shake with a strong roll), and far closer than
    the input."""
    kw = dict(yaw=2.0, pitch=2.0, roll=6.0, frequency=4.0, seed=7)
    src = smooth_texture(rng, 64, 96).astype(np.float64)
    want = reference(src, camera=CAM, frame=5, n=256, **kw)
    naive = tangent_blur(src, velocity(src, camera=CAM, frame=5, **kw), -0.25, 0.25)
    got = run(rt, src.astype(np.float32), **kw)
    assert rmse(got, want) < 1.25 * rmse(naive, want), (rmse(got, want), rmse(naive, want))
    assert rmse(got, want) < 0.15 * rmse(src, want)


def test_the_same_seed_and_frame_give_the_same_shake(rt, rng):
    src = smooth_texture(rng, 40, 56)
    a = run(rt, src, seed=3, frame=12)
    np.testing.assert_array_equal(a, run(rt, src, seed=3, frame=12))
    assert np.abs(a - run(rt, src, seed=3, frame=13)).max() > 1e-3    # the shake moves on
    assert np.abs(a - run(rt, src, seed=4, frame=12)).max() > 1e-3    # another hand


def test_the_shake_runs_on_between_frames():
    """The angle signal is one continuous function of time, the same for every frame: at 3 Hz
    (sines up to 5.2 Hz) and 1 deg RMS it turns at most ~0.3 deg per tenth of a frame."""
    kw = dict(yaw=1.0, pitch=1.0, roll=1.0, frequency=3.0, seed=9)
    steps = np.diff([angles(s / 240, **kw) for s in range(0, 2400)], axis=0)
    assert np.abs(steps).max() < np.radians(0.3)


def test_no_turn_is_the_identity(rt, rng):
    src = smooth_texture(rng, 24, 40)
    src[3, 5, 0] = 1e4
    np.testing.assert_array_equal(run(rt, src, yaw=0.0, pitch=0.0, roll=0.0), src)


def test_a_flat_field_stays_flat(rt):
    src = np.full((40, 56, 4), 0.25, np.float32)
    got = run(rt, src, yaw=3.0, pitch=3.0, roll=5.0)
    np.testing.assert_allclose(got, 0.25, rtol=1e-5)


def test_tiles_give_the_whole_render(rt, rng):
    src = smooth_texture(rng, 70, 90)
    p = dict(yaw=3.0, pitch=1.0, roll=4.0)
    whole = run(rt, src, **p)
    tiled = render_effect(rt, Shake(), Shake.params(**p), src, camera=CAM, frame=5,
                          quality="final", tile_pixels=900)
    np.testing.assert_array_equal(whole, tiled)
