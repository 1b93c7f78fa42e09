"""The shared scene analysis against its float64 oracle, and its hard cases."""
import numpy as np
import pytest

from clfx.fx.analysis import TILE, analyse
from clfx.core.camera import Camera
from clfx.core.rect import Rect
from tests.conftest import hard_shapes
from tests.reference.analysis import tile_stats


def run(rt, rgba, depth=None, velocity=None, display=None):
    img = rt.upload(rgba)
    return analyse(rt, img, depth=None if depth is None else rt.upload(depth),
                   velocity=None if velocity is None else rt.upload(velocity),
                   display_window=display)


@pytest.mark.parametrize("shape", hard_shapes() + [(33, 65), (70, 100)])
def test_tile_stats_match_reference(rt, rng, shape):
    h, w = shape
    rgba = rng.uniform(0, 10, (h, w, 4)).astype(np.float32)
    depth = rng.uniform(0.5, 50, (h, w)).astype(np.float32)
    vel = rng.normal(0, 5, (h, w, 2)).astype(np.float32)
    if h * w > 4:
        rgba[0, 0, 1] = np.nan
        rgba[-1, -1, 2] = np.inf
        depth[0, -1] = 0.0
        depth[-1, 0] = np.nan
        depth[h // 2, w // 2] = np.inf
        vel[0, 0] = np.nan
    a = run(rt, rgba, depth, vel)
    want = tile_stats(rgba, depth, vel, TILE)
    # luminance is 3 float32 products and 2 sums (<= 3 ulp); min/max/counts of stored values
    # are exact; the mean is a float32 sum of <= 1024 values (rel 1e-5)
    np.testing.assert_allclose(a.max_lum, want[..., 0], rtol=4e-7)
    np.testing.assert_allclose(a.mean_lum, want[..., 1], rtol=1e-5)
    np.testing.assert_array_equal(a.nonfinite, want[..., 2])
    np.testing.assert_allclose(a.max_speed, want[..., 3], rtol=1e-6)
    np.testing.assert_array_equal(a.min_depth, want[..., 4].astype(np.float32))
    np.testing.assert_array_equal(a.max_depth, want[..., 5].astype(np.float32))
    np.testing.assert_array_equal(a.bad_depth, want[..., 6])


def test_highlights_and_light_sources(rt):
    rgba = np.full((96, 160, 4), 0.05, np.float32)
    rgba[10:14, 20:24, :3] = 1e5
    rgba[70, 150, :3] = 50.0
    a = run(rt, rgba)
    assert a.any_above(1.0) and not a.any_above(1e6)
    assert a.peak_luminance == pytest.approx(1e5, rel=1e-6)
    sources = a.light_sources(10.0)
    assert len(sources) == 2 and sources[0].peak > sources[1].peak
    assert sources[0].bbox.contains(Rect(20, 10, 24, 14))
    assert a.light_sources(1e6) == []


def test_light_source_just_outside_the_display_window(rt):
    rgba = np.zeros((64, 128, 4), np.float32)
    rgba[30, 120, :3] = 1e3  # overscan pixel, outside a display window ending at x=96
    display = Rect(0, 0, 96, 64)
    a = run(rt, rgba, display=display)
    near = a.light_sources(1.0, margin_px=64)
    assert len(near) == 1 and not near[0].in_view
    assert a.light_sources(1.0, margin_px=0) == []


def test_coc_tiles_bracket_the_focus_plane(rt):
    cam = Camera(focal_length=50, f_number=2, focus_distance=3.0)
    depth = np.full((32, 64), 3.0, np.float32)
    depth[:, 32:] = 30.0
    a = run(rt, np.ones((32, 64, 4), np.float32), depth=depth)
    lo, hi = a.coc_tiles(cam, 64)
    assert lo[0, 0] == 0 and hi[0, 0] == pytest.approx(0.0, abs=1e-9)
    assert hi[0, 1] == pytest.approx(cam.coc_px(30.0, 64)) and lo[0, 1] > 0


def test_static_frame_has_no_moving_tiles(rt):
    a = run(rt, np.ones((40, 40, 4), np.float32), velocity=np.zeros((40, 40, 2), np.float32))
    assert not a.moving_tiles().any() and a.peak_speed == 0.0


def test_meter_ignores_lights_and_black_and_is_stable(rt, rng):
    """The metered middle grey (shared by grain and sensor noise) of a plate at 0.05 is 0.05
    with a 1e3 light over a few tiles and a black letterbox (before: 0.079, the log-average
    counting both), it scales with the plate, and the plate's own noise moves it
    by < 0.1 % from frame to frame (no flicker on a static shot)."""
    from clfx.fx.analysis import meter

    src = np.full((256, 320, 4), 0.05, np.float32)
    src[..., 3] = 1
    src[100:140, 150:200, :3] = 1e3
    src[:32, :, :3] = 0.0
    src[-32:, :, :3] = 0.0
    got = meter(analyse(rt, rt.upload(src, Rect(0, 0, 320, 256))).mean_lum)
    assert got == pytest.approx(0.05, rel=1e-6)
    for k in (1e-3, 40.0):
        scaled = src.copy()
        scaled[..., :3] *= k
        assert meter(analyse(rt, rt.upload(scaled, Rect(0, 0, 320, 256))).mean_lum) == \
            pytest.approx(0.05 * k, rel=1e-5)
    plate = np.full((256, 320, 4), 1.0, np.float32)
    plate[..., :3] = rng.uniform(0.01, 0.3, (1, 320, 3))     # vertical stripes of colour
    metered = []
    for _ in range(4):
        frame = plate.copy()
        frame[..., :3] *= 1 + 0.05 * rng.standard_normal((256, 320, 3))
        metered.append(meter(analyse(rt, rt.upload(frame, Rect(0, 0, 320, 256))).mean_lum))
    assert max(metered) / min(metered) - 1 < 1e-3, metered
    assert meter(np.zeros((4, 5))) == 0.18
