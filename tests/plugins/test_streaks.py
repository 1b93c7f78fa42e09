import math

import numpy as np
import pytest

from clfx.core.camera import Camera
from clfx.plugins.streaks import Streaks, streak_angles
from clfx.core.rect import Rect
from tests.conftest import hard_shapes
from tests.reference.streaks import angles_of, line_kernel_streaks, streaks as reference
from tests.effects import render_effect

PARAMS = dict(threshold=1.0, intensity=0.5, length=0.6, angle=30.0, color_shift=0.4,
              tint=(1.0, 0.9, 0.8))


def scene(rng, shape, hot=1e4):
    src = rng.uniform(0.0, 0.5, shape + (4,)).astype(np.float32)
    h, w = shape
    src[h // 3, w // 2, :3] = hot
    src[(2 * h) // 3, w // 5, :3] = (40.0, 20.0, 5.0)
    return src


def run(rt, src, quality="final", **kw):
    p = Streaks.params(**{**PARAMS, **kw})
    return render_effect(rt, Streaks(), p, src, quality=quality), p


@pytest.mark.parametrize("shape", hard_shapes())
def test_streaks_match_reference(rt, rng, shape):
    src = scene(rng, shape)
    got, p = run(rt, src, "reference")
    want = reference(src, **p.as_dict())
    # float32 buffers between at most 4 passes of 4 taps: ~20 roundings of the largest value
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=2e-6 * np.abs(want).max())


@pytest.mark.parametrize("shape", [(17, 31), (48, 64)])
def test_anamorphic_matches_reference(rt, rng, shape):
    # two exponentials per ray, the coating's colour, the (L / peak)^3 weighting
    src = scene(rng, shape)
    got, p = run(rt, src, "reference", mode="anamorphic", angle=10.0, core=0.3,
                 source_color=0.0)
    want = reference(src, **p.as_dict())
    # as above: float32 buffers between the passes of each chain
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=2e-6 * np.abs(want).max())


def test_final_matches_reference_every_tap_interpolated(rt, rng):
    # final once rounded the taps of passes stepping >= 16 px to whole pixels: a staircase
    # along a thin ray; now it is the reference's kernel in float32
    src = scene(rng, (48, 64))
    got, p = run(rt, src, "final", length=1.0)     # 80 px: passes step 1, 4, 16, 64
    want = reference(src, **p.as_dict())
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=2e-6 * np.abs(want).max())


def test_error_falls_with_quality(rt, rng):
    src = scene(rng, (40, 56))
    p = Streaks.params(**PARAMS)
    want = reference(src, **p.as_dict())
    errs = [np.abs(render_effect(rt, Streaks(), p, src, quality=q) - want).max()
            for q in ("draft", "preview", "final", "reference")]
    assert errs[0] >= errs[1] >= errs[2] >= errs[3] - 1e-9 * want.max(), errs


@pytest.mark.parametrize("case", ["star30", "star75", "anamorphic", "extended"])
def test_draft_and_preview_match_reference(rt, rng, case):
    # draft and preview run each ray on a grid reduced along its major axis only (x-major
    # at 30 degrees, y-major at 75); the oracle computes that grid, its passes and the
    # upsampling along the ray in float64
    src = bright_pane(rng) if case == "extended" else scene(rng, (48, 64))
    kw = {"star30": {}, "star75": dict(angle=75.0, streaks=5),
          "anamorphic": dict(mode="anamorphic", angle=10.0, core=0.3, source_color=0.0),
          "extended": dict(core=0.5, angle=15.0, streaks=4, length=0.3)}[case]
    for quality in ("draft", "preview"):
        got, p = run(rt, src, quality, **kw)
        want = reference(src, **p.as_dict(), factor=Streaks.descriptor.level(quality).factor)
        # measured 6e-8 of the largest value
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=2e-6 * np.abs(want).max())


def test_draft_and_preview_beat_the_input_on_thin_rays(rt):
    # the bench's case at 480 x 270: 12 compact lights, each a point streaking 4 thin rays
    # at 45 degrees.  Passes at 1/4 and 1/2 resolution in both axes drew a ray 4-8 px wide
    # at a fraction of its amplitude, worse in log-PSNR than no ray at all: draft 23.0,
    # preview 24.1 dB against the unchanged input's 26.9.  Reduced along each ray only
    # (8 and 4 times), they keep it a pixel wide (measured 50.2 and 56.9 dB)
    from clfx.bench.cases.streaks import make
    from clfx.bench.metrics import psnr_log

    case = make(480, 270, np.random.default_rng(0))
    p = Streaks.params(**case["params"])
    src, camera = case["source"], case["camera"]
    want = render_effect(rt, Streaks(), p, src, quality="reference", camera=camera)
    floor = psnr_log(src, want)
    for quality in ("draft", "preview"):
        got = psnr_log(render_effect(rt, Streaks(), p, src, quality=quality, camera=camera), want)
        assert got > floor + 20.0, (quality, got, floor)


def test_axis_aligned_kawase_equals_exact_line_kernel():
    # integer taps: the base-4 passes compose to the exponential line kernel exactly
    src = np.zeros((20, 70, 4))
    src[10, 60, :3] = 100.0
    kw = dict(Streaks.params(**{**PARAMS, "angle": 0.0, "streaks": 2}).as_dict())
    np.testing.assert_allclose(reference(src, **kw), line_kernel_streaks(src, **kw),
                               rtol=1e-12, atol=1e-12)


def test_diagonal_kawase_vs_line_kernel_same_energy_slightly_wider():
    # stated error of the algorithm (module docstring): same energy, a little wider
    src = np.zeros((160, 160, 4))
    src[80, 80, :3] = 1e4                    # rays (64 px support) stay inside the frame
    kw = dict(Streaks.params(**{**PARAMS, "angle": 30.0, "length": 0.265}).as_dict())
    k = reference(src, **kw)[..., 1] - src[..., 1]
    e = line_kernel_streaks(src, **kw)[..., 1] - src[..., 1]
    assert abs(k.sum() / e.sum() - 1) < 1e-6
    assert np.abs(k - e).sum() / e.sum() < 0.35   # measured 0.25 (docstring)


def test_aperture_spike_counts():
    assert len(streak_angles("aperture", 0, 0.0, 6, 0.0)) == 6     # even N: N spikes
    assert len(streak_angles("aperture", 0, 0.0, 5, 0.0)) == 10    # odd N: 2N spikes
    assert streak_angles("aperture", 0, 0.0, 0, 0.0) == []          # round: none


@pytest.mark.parametrize("mode", ["star", "anamorphic", "aperture"])
def test_ray_directions_follow_the_optics(mode):
    """Every mode's rays point where the descriptor's optics put them (the oracle derives
    them on its own: an aperture's spikes perpendicular to its polygon's edges, a star's
    evenly around, an anamorphic line through ``angle``), as sets of directions mod 360."""
    def directions(angles):
        return sorted(round(a % 360.0, 6) % 360.0 for a in angles)

    for blades, rotation, angle, streaks in [(3, 0.0, 0.0, 4), (5, 10.0, 0.0, 6),
                                             (6, 0.0, 15.0, 5), (7, -33.0, 40.0, 8),
                                             (8, 22.5, 0.0, 3), (9, 90.0, 200.0, 1)]:
        want = directions(angles_of(mode, streaks, angle, blades, rotation))
        assert directions(streak_angles(mode, streaks, angle, blades, rotation)) == want


def test_aperture_mode_uses_camera_blades(rt, rng):
    src = scene(rng, (33, 41))
    p = Streaks.params(**{**PARAMS, "mode": "aperture", "blades": 0})
    got = render_effect(rt, Streaks(), p, src, quality="reference",
                        camera=Camera(blades=5, blade_rotation=10.0))
    want = reference(src, **p.as_dict() | {"blades": 5}, blade_rotation=10.0)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=2e-6 * want.max())
    same = render_effect(rt, Streaks(), p, src, camera=Camera(blades=0))       # round: identity
    assert np.array_equal(same, src)


def test_identities(rt, rng):
    src = rng.uniform(0.0, 0.9, (9, 13, 4)).astype(np.float32)
    for kw in ({"intensity": 0.0}, {}):
        got, _ = run(rt, src, **kw)
        assert np.array_equal(got, src)     # nothing above threshold 1.0 / intensity 0


def test_nan_inf_do_not_spread_and_are_counted(rt, rng):
    clean = scene(rng, (31, 45))
    bad = clean.copy()
    bad[3, 3, 0], bad[20, 40, 2], bad[5, 30, :] = np.nan, np.inf, -np.inf
    p = Streaks.params(**PARAMS)
    got = render_effect(rt, Streaks(), p, bad)
    assert np.isfinite(got).all()
    ref = reference(bad, **p.as_dict())
    np.testing.assert_allclose(got, ref, rtol=1e-5, atol=2e-6 * ref.max())
    from clfx.host import RenderContext
    ctx = RenderContext(rt, rt.upload(bad))
    Streaks().render(rt, p, ctx)
    assert any("3 non-finite" in n for n in ctx.notes)


def test_hdr_point_energy_and_no_negatives(rt):
    src = np.zeros((64, 64, 4), np.float32)
    src[32, 32, :3] = 1e5
    p = Streaks.params(**{**PARAMS, "length": 0.1, "color_shift": 0.0, "tint": (1, 1, 1)})
    got = render_effect(rt, Streaks(), p, src)
    assert got.min() >= 0.0
    bright = 1e5 * (1 - 0.5)                 # lum - core x peak: the pixel is its own peak
    added = (got.astype(np.float64) - src)[..., :3].sum(axis=(0, 1))
    # 9 px rays, 16 px support, stay inside the frame: energy = intensity * highlight
    np.testing.assert_allclose(added, 0.5 * bright, rtol=1e-5)


def test_alpha_kept(rt, rng):
    src = scene(rng, (17, 23))
    src[..., 3] = rng.uniform(0, 1, (17, 23))
    got, _ = run(rt, src)
    np.testing.assert_array_equal(got[..., 3], src[..., 3])


def test_rod_grows_and_light_reaches_overscan(rt):
    src = np.zeros((16, 16, 4), np.float32)
    src[8, 1, :3] = 1e3                          # near the left edge of the data window
    data, display = Rect(20, 20, 36, 36), Rect(0, 0, 60, 60)
    p = Streaks.params(**{**PARAMS, "angle": 0.0, "streaks": 2, "length": 0.2})
    out, win = render_effect(rt, Streaks(), p, src, data_window=data, display_window=display,
                             keep_rod=True)
    assert win == display                        # grown by the spread, clipped to the limit
    row = out[8 + data.y0, :data.x0, 1]
    assert row.max() > 0.0                       # the left-going ray continues outside
    want = reference(src, **p.as_dict(), diagonal=display.diagonal, pad=20)  # frame [0, 56)
    np.testing.assert_allclose(out[:56, :56, :3], want[..., :3], rtol=1e-5,
                               atol=2e-6 * want.max())


def test_huge_length_and_tiny_images(rt):
    for shape in ((1, 1), (1, 9), (5, 3)):
        src = np.full(shape + (4,), 50.0, np.float32)
        got, _ = run(rt, src, length=2.0, intensity=100.0)
        assert np.isfinite(got).all() and got.min() >= 0.0


@pytest.mark.parametrize("quality", ["draft", "preview"])
def test_bounds_tested_taps_match_reference(rt, rng, monkeypatch, quality):
    # draft's and preview's grids: very long rays skip the zero margin and test every tap's
    # bounds instead (final's and reference's passes always do)
    import clfx.plugins.streaks as mod
    monkeypatch.setattr(mod, "MAX_MARGIN", 0)
    src = scene(rng, (31, 45))
    got, p = run(rt, src, quality)
    want = reference(src, **p.as_dict(), factor=Streaks.descriptor.level(quality).factor)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=2e-6 * np.abs(want).max())


def test_final_passes_take_frame_sized_buffers(rt, rng, monkeypatch):
    # final's pass buffers are the frame's size (taps test their bounds, no zero margin), so
    # the pool holds them from one frame to the next: with margins, each was a size of its
    # own (2312 x 1472 px at 1080p), four fresh 52 MiB buffers a frame, paged in and
    # zero-filled; and no pass buffer is copied or filled whole but the total the rays add to
    import pyopencl as cl
    from clfx.plugins.streaks import MAX_SEEDS
    src = scene(rng, (90, 160))
    frame_bytes = 160 * 90 * 16
    taken, filled, copied = [], [], []
    take = rt.cache.take
    monkeypatch.setattr(rt.cache, "take", lambda n: taken.append(n) or take(n))
    fill, copy = cl.enqueue_fill_buffer, cl.enqueue_copy
    monkeypatch.setattr(cl, "enqueue_fill_buffer",
                        lambda q, b, pat, off, size, *a, **k: filled.append(size)
                        or fill(q, b, pat, off, size, *a, **k))
    monkeypatch.setattr(cl, "enqueue_copy", lambda q, dst, src_, **k: copied.append(
        (type(dst).__name__, type(src_).__name__)) or copy(q, dst, src_, **k))
    got, p = run(rt, src, "final", streaks=4, length=0.3)
    assert {n for n in taken if n > frame_bytes} <= {MAX_SEEDS * 32}   # but the seeds' list
    assert [n for n in filled if n >= frame_bytes] == [frame_bytes]     # the total alone
    assert ("Buffer", "Buffer") not in copied
    want = reference(src, **p.as_dict())
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=2e-6 * np.abs(want).max())


def lights(rng, shape):
    """``scene`` with an extended light (a 12 x 20 px pane) and a light at the corner."""
    src = scene(rng, shape)
    h, w = shape
    src[h // 2:h // 2 + 12, 3 * w // 4:3 * w // 4 + 20, :3] = 6.0
    src[2, 3, :3] = 300.0
    return src


@pytest.mark.parametrize("quality", ["draft", "preview", "final", "reference"])
@pytest.mark.parametrize("kw", [dict(angle=30.0, length=0.3), dict(angle=-60.0, length=0.3),
                                dict(mode="anamorphic", angle=10.0),
                                dict(mode="aperture", blades=5, length=0.2),
                                dict(streaks=6, angle=17.0, length=1.5)],
                         ids=["30", "-60", "anamorphic", "aperture", "long"])
def test_streamed_passes_give_the_whole_passes_bits(rt, rng, monkeypatch, quality, kw):
    # a large frame streams through the passes in chunks of rows, each pass's input held as
    # a ring of the rows the later passes still read: every pixel takes the same floats
    import clfx.plugins.streaks as mod
    src = lights(rng, (61, 133))
    p = Streaks.params(**{**PARAMS, **kw})
    cam = Camera(blades=5)
    whole = render_effect(rt, Streaks(), p, src, quality=quality, camera=cam)
    monkeypatch.setattr(mod, "streams", lambda *a: True)
    for chunk_rows in (1, 5):
        monkeypatch.setattr(mod, "CHUNK_PIXELS", chunk_rows * 136)
        got = render_effect(rt, Streaks(), p, src, quality=quality, camera=cam)
        assert np.array_equal(got.view(np.uint32), whole.view(np.uint32)), chunk_rows


def test_an_8k_frame_streams_in_a_fraction_of_the_whole_passes_memory():
    # cinema's streaks at 8K UHD final: 4 rays of 440 px; the held rows and the chunk's sum
    # are about 3000 rows of the frame's width, the whole passes' three buffers 3 x 4320
    import clfx.plugins.streaks as mod
    lengths = mod.channel_lengths(0.05 * math.hypot(7680, 4320), 0.0)
    rays = []
    for a in mod.streak_angles("star", 4, 45.0, 0, 0.0):
        sx, sy, step = mod.grid_step(a)
        passes, top = mod.pass_plan(float(lengths.max()) / step)
        rays.append(mod.Ray(sx, sy, passes, top, []))
    chunk = mod.CHUNK_PIXELS // 7680
    rings = mod.ring_rows(rays, chunk, 4320)
    assert mod.streams(7680, 4320, rings, chunk)
    assert sum(rings) + chunk < 0.25 * 3 * 4320
    assert not mod.streams(960, 540, mod.ring_rows(rays, 1092, 540), 1092)


def test_many_lights_read_after_the_first_wait(rt, rng, monkeypatch):
    # the count and the first SEEDS_READ points come in one wait; more lights, a second read
    import clfx.plugins.streaks as mod
    src = lights(rng, (48, 64))
    src[5:45:8, 4:60:9, :3] = 500.0
    p = Streaks.params(**PARAMS)
    want = render_effect(rt, Streaks(), p, src)
    monkeypatch.setattr(mod, "SEEDS_READ", 2)
    got = render_effect(rt, Streaks(), p, src)
    assert np.array_equal(got.view(np.uint32), want.view(np.uint32))


@pytest.mark.parametrize("shape,radius", [((1, 1), 1), ((1, 37), 3), ((31, 17), 5),
                                          ((40, 70), 13), ((9, 6), 40)])
def test_dilate_grows_flags_by_a_line_in_x_then_y(rt, rng, shape, radius):
    """streaks_dilate (a running count per row, then per column) against the plain
    definition: 1 where a flag lies within ``radius`` pixels along the line."""
    h, w = shape
    flags = (rng.uniform(size=shape) < 0.03).astype(np.uint8)
    flags[rng.integers(h), rng.integers(w)] = 1
    want = flags.astype(bool)
    for axis in (1, 0):
        n = want.shape[axis]
        grown = np.zeros_like(want)
        for k in range(-radius, radius + 1):
            lo, hi = max(0, -k), min(n, n - k)
            if lo < hi:
                idx = [slice(None)] * 2
                src = [slice(None)] * 2
                idx[axis], src[axis] = slice(lo, hi), slice(lo + k, hi + k)
                grown[tuple(idx)] |= want[tuple(src)]
        want = grown
    bufs = [rt.to_device(flags.ravel()), rt.buffer(flags.size)]
    knl = rt.kernel("streaks.cl", "streaks_dilate")
    for a, b, sx, sy in ((0, 1, 1, 0), (1, 0, 0, 1)):
        rt.launch(knl, (h if sx else w,), bufs[a], bufs[b], np.int32(w), np.int32(h),
                  np.int32(radius), np.int32(sx), np.int32(sy))
    got = rt.from_device(bufs[0], np.uint8, flags.size).reshape(shape)
    assert np.array_equal(got, want.astype(np.uint8))


def test_a_frame_without_seeds_grows_no_flags(rt, rng, monkeypatch):
    # issue 37: the dilation is the streaks' fixed cost per frame; no seed, nothing to grow
    launched = []
    real = rt.launch

    def spy(knl, *a, **kw):
        launched.append(knl.function_name)
        return real(knl, *a, **kw)

    monkeypatch.setattr(rt, "launch", spy)
    src = rng.uniform(0.0, 0.5, (32, 48, 4)).astype(np.float32)
    src[4:28, 4:44, :3] = 50.0           # one extended light: no compact light to seed
    p = Streaks.params(**PARAMS)
    render_effect(rt, Streaks(), p, src)
    assert "streaks_seeds" in launched and "streaks_dilate" not in launched


def test_the_rays_share_one_extraction_of_the_bright_pixels(rt, rng, monkeypatch):
    # issue 37: 4 rays extracted the same bright pixels 4 times; now once, copied per ray
    launched = []
    real = rt.launch
    monkeypatch.setattr(rt, "launch", lambda knl, *a, **kw: launched.append(knl.function_name)
                        or real(knl, *a, **kw))
    src = lights(rng, (48, 64))
    p = Streaks.params(**{**PARAMS, "streaks": 4})
    render_effect(rt, Streaks(), p, src)     # its pixels: test_streaks_match_reference and the rest
    assert launched.count("streaks_bright") == 1 and launched.count("streaks_pass") > 4


def test_a_band_composes_from_the_plan_it_carries(rt, rng, monkeypatch):
    """A band of a tiled render composes its rows from the frame's streak sum that its Band
    carries (the plan, made on the whole frame before any band): it never plans (a band
    that came first once raised "the plan is the whole frame's"), and its rows are the
    whole render's."""
    from clfx.host import RenderContext
    ctx = RenderContext(rt, rt.upload(scene(rng, (20, 30))))
    fx, p = Streaks(), Streaks.params(**PARAMS)
    plan = fx.planned(p, ctx)
    assert plan.identity is None and plan.total is not None
    whole = fx.render(rt, p, ctx)
    monkeypatch.setattr(Streaks, "plan", lambda *a: pytest.fail("a band planned"))
    win = whole.window
    band = Rect(win.x0, win.y0 + 5, win.x1, win.y0 + 12)
    part = fx.render(rt, p, ctx.tile(ctx.source.window, band, plan))
    assert part.window == band
    rows = rt.download(whole)[5:12]
    assert np.array_equal(rt.download(part).view(np.uint32), rows.view(np.uint32))


# -- what a user sees -------------------------------------------------------------------------
def flame(h=270, w=480, glow=40.0, core=3000.0):
    """A synthetic flame: a small very bright core (6 x 6 px) in a large dim glow (an ellipse
    50 x 120 px, orange, far above the threshold but far below the core)."""
    src = np.zeros((h, w, 4), np.float32)              # black: exact in a half-float output
    src[..., 3] = 1.0
    ys, xs = np.mgrid[0:h, 0:w] + 0.5
    cx, cy = w / 2, h / 2
    inside = ((xs - cx) / 25) ** 2 + ((ys - cy) / 60) ** 2 <= 1
    src[inside, :3] = np.array([1.6, 1.0, 0.4]) * glow
    src[int(cy) - 3:int(cy) + 3, int(cx) - 3:int(cx) + 3, :3] = (core, 0.8 * core, 0.5 * core)
    return src


def width_at(profile, frac=0.05):
    """Number of samples at or above ``frac`` of the profile's peak."""
    return int((profile >= frac * profile.max()).sum())


def cli(tmp_path, src, *argv):
    """Render ``src`` through ``clfx ARGV... in.exr out.exr`` (argv holds "{in}", "{out}")."""
    from click.testing import CliRunner

    from clfx.cli import cli as clfx_cli
    from clfx.core.frame import Frame
    from clfx.io.read import read_frame
    from clfx.io.write import write_frame

    write_frame(Frame.from_array(src), tmp_path / "in.exr", overwrite=True, bit_depth="float")
    args = [str(tmp_path / "in.exr") if a == "{in}" else str(tmp_path / "out.exr")
            if a == "{out}" else a for a in argv]
    result = CliRunner().invoke(clfx_cli, args + ["--overwrite"], catch_exceptions=False)
    assert result.exit_code == 0, (result.output, result.stderr)
    return read_frame(tmp_path / "out.exr").rgba.astype(np.float64), result


def test_streak_width_follows_the_bright_core_not_the_flame(tmp_path):
    src = flame()
    h, w = src.shape[:2]
    out, _ = cli(tmp_path, src, "apply", "streaks", "{in}", "{out}", "angle=0", "streaks=2",
                 "length=0.4")
    streak = out[..., :3] - src[..., :3]
    lum = streak @ [0.2126, 0.7152, 0.0722]
    for dx in (40, 90, 150):                    # beyond the glow (25 px half-width)
        col = lum[:, w // 2 + dx]
        assert width_at(col) <= 3, (dx, width_at(col))          # a line, not 120 px


def test_default_star_x_is_not_wide_near_a_flame(tmp_path):
    # the default star filter: 4 rays at 45 degrees; across an arm just outside the glow
    # the streak is about as wide as the core's diagonal, not the glow's
    src = flame()
    h, w = src.shape[:2]
    out, _ = cli(tmp_path, src, "apply", "streaks", "{in}", "{out}")
    lum = (out[..., :3] - src[..., :3]) @ [0.2126, 0.7152, 0.0722]
    cx, cy = w / 2, h / 2
    t = np.linspace(-40, 40, 161)                            # across the 45-degree arm
    for d in (45.0, 80.0):
        px = cx + d / math.sqrt(2) + t / math.sqrt(2)
        py = cy - d / math.sqrt(2) + t / math.sqrt(2)
        prof = lum[py.astype(int), px.astype(int)]
        assert width_at(prof) * (t[1] - t[0]) <= 14, (d, width_at(prof))


def test_anamorphic_night_streaks_are_blue(tmp_path):
    # an orange flame through the look: its streak is blue (the look's tint and its
    # source_color 0: the anamorphic coating colours the streak), along its whole length
    src = flame()
    h, w = src.shape[:2]
    out, _ = cli(tmp_path, src, "render", "{in}", "{out}", "--look", "anamorphic-night")
    added = out[..., :3] - src[..., :3]
    row = added[h // 2 - 3:h // 2 + 3].mean(axis=0)           # the streak through the core
    for dx in (40, 80, 150, 220):
        for x in (w // 2 + dx, w // 2 - dx):
            r, g, b = row[x]
            assert b > 1.2 * r and b > 0, (dx, row[x])
    # blue-cyan, not violet (issue 25): the hue of the added light along the streak is between
    # 195 and 225 degrees (the V-coat at 740 nm: 213; the former single MgF2 layer: 232)
    import colorsys

    for dx in (40, 80, 150, 220):
        rgb = np.maximum(row[w // 2 + dx], 0.0)
        hue = 360.0 * colorsys.rgb_to_hsv(*(rgb / rgb.max()))[0]
        assert 195.0 <= hue <= 225.0, (dx, hue, rgb)


def test_aperture_mode_with_a_round_aperture_warns_on_stderr(tmp_path):
    src = flame(64, 96)
    out, result = cli(tmp_path, src, "apply", "streaks", "{in}", "{out}", "mode=aperture")
    assert "clfx: warning: frame" in result.stderr and "round aperture" in result.stderr
    assert np.array_equal(out.astype(np.float32), src)        # nothing drawn, but said so
    _, quiet = cli(tmp_path, src, "apply", "streaks", "{in}", "{out}", "mode=aperture",
                   "camera.blades=6")
    assert "round aperture" not in quiet.stderr


@pytest.mark.parametrize("mode,kw", [
    ("star", {}),                                      # the default 4-ray star, 45 degrees
    # a horizontal pair whose 1 % length (60 px) sat just under the former 4^3 = 64 px
    # support: it stopped at 0.7 % of its start
    ("star", dict(streaks=2, angle=0.0, length=60.0 / math.hypot(480, 320))),
    ("anamorphic", dict(length=0.1, angle=0.0)),
])
def test_point_light_streak_fades_smoothly_before_its_support_ends(rt, mode, kw):
    # issue 25: along a ray the streak is monotone, has no step above 1e-4 of its start and
    # is below that before its support ends
    from clfx.plugins.streaks import grid_step, support_steps
    from tests.light_profile import assert_smooth_tail, point_light, ray

    src = point_light(320, 480)
    h, w = src.shape[:2]
    p = Streaks.params(mode=mode, **kw)
    out = render_effect(rt, Streaks(), p, src)
    step = grid_step(p.angle)[2]
    support = support_steps(p.length * math.hypot(w, h) / step)     # in samples of the ray
    dx, dy = (1, -1) if p.angle == 45.0 else (1, 0)
    n = h // 2 if dy else w // 2
    assert support < n - 2
    assert_smooth_tail(ray(out, h // 2, w // 2, dx, dy, n), support, start=2,
                       what=f"streaks {mode} {kw}")


def spot(h=180, w=320, sigma=3.0, peak=1e4):
    """A round light with a bright centre (Gaussian, sigma px) on black."""
    src = np.zeros((h, w, 4), np.float32)
    src[..., 3] = 1.0
    y, x = np.mgrid[0:h, 0:w]
    g = peak * np.exp(-((x - w // 2) ** 2 + (y - h // 2) ** 2) / (2 * sigma ** 2))
    src[..., :3] = g[..., None]
    return src


def fwhm(col):
    """Width (px) of the samples above half the maximum."""
    return int((col >= 0.5 * col.max()).sum())


def test_anamorphic_streak_thin_core_falls_off_and_is_blue_cyan(rt):
    # issue 25: not a constant-width, constant-brightness white bar
    src = spot()
    h, w = src.shape[:2]
    ana = Streaks.params(mode="anamorphic", angle=0.0, length=0.35, core=0.3, source_color=0.0)
    out = render_effect(rt, Streaks(), ana, src).astype(np.float64)
    added = out[..., :3] - src[..., :3]
    lum = added @ [0.2126, 0.7152, 0.0722]
    # thin: the streak is a line (1 px at half maximum on a horizontal ray), not as wide as
    # the light (7 px at half maximum)
    for dx in (30, 80, 140):
        assert fwhm(lum[:, w // 2 + dx]) <= 2, (dx, fwhm(lum[:, w // 2 + dx]))
    # falls off with distance: a bright part near the light, a long faint one beyond
    row = lum[h // 2]
    assert row[w // 2 + 10] > 2.0 * row[w // 2 + 60] > 0
    assert row[w // 2 + 60] > 1.5 * row[w // 2 + 150] > 0
    assert row[w // 2 - 60] == pytest.approx(row[w // 2 + 60], rel=1e-3)   # both ways
    # blue-cyan from the coating: blue over green over red, everywhere along it
    for dx in (10, 60, 150):
        r, g, b = added[h // 2, w // 2 + dx]
        assert b > 2.0 * r and g > 1.2 * r, (dx, r, g, b)
    # the coating's design sets the colour: one designed in the blue gives a warmer streak
    warm = render_effect(rt, Streaks(), Streaks.params(**{**ana.as_dict(), "coating_nm": 450.0}),
                         src)
    r, g, b = warm[h // 2, w // 2 + 60, :3] - src[h // 2, w // 2 + 60, :3]
    assert r > b


@pytest.mark.parametrize("shape", [(17, 31), (48, 64)])
def test_aperture_spikes_match_reference(rt, rng, shape):
    # three exponentials per spike, channel lengths in proportion to their wavelengths
    src = scene(rng, shape)
    got, p = run(rt, src, "reference", mode="aperture", blades=7, angle=5.0, core=0.3,
                 core_power=2.0)
    want = reference(src, **p.as_dict())
    # as above: float32 buffers between the passes of each chain
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=2e-6 * np.abs(want).max())


def test_aperture_spike_tapers_as_diffraction_and_reddens(rt):
    """Issue 25 (sunny-flare's spikes were heavy white bars of even brightness): along a
    spike a point light's brightness follows the far field of a straight edge, 1 / (1 + 9 r /
    L)^2, within 20 % out to 0.5 L (then faster: 0.2-0.4 % of the root at L), and fades to
    below 1e-4 before its support ends; red reaches further than blue (the diffraction angle
    scales with wavelength).  A ray along +x: the passes compose the line kernel exactly."""
    from clfx.plugins.streaks import APERTURE_PARTS, grid_step, support_steps
    from tests.light_profile import assert_smooth_tail, point_light

    h, w, L = 9, 560, 150.0
    src = point_light(h, 2 * w)
    diag = math.hypot(2 * w, h)
    p = Streaks.params(mode="aperture", blades=4, angle=45.0, length=L / diag,
                       threshold=1.0, intensity=1.0, core=0.0)
    got = render_effect(rt, Streaks(), p, src, quality="reference", camera=Camera(blades=4))
    prof = (got[h // 2, w:, :3] - src[h // 2, w:, :3]).astype(np.float64)
    # the kernel in closed form: each part's exponential, normalised over its support
    k = np.arange(w)
    want = np.zeros((w, 3))
    for frac, share in APERTURE_PARTS:
        lc = frac * L * np.array([610.0, 550.0, 465.0]) / 550.0
        a = 0.01 ** (1.0 / lc)
        support = support_steps(lc.max())
        want += share * np.where(k[:, None] < support, a ** k[:, None], 0.0) * (1 - a) / (
            1 - a ** support)
    want *= (1e4 - 1.0) / 4.0             # the light above threshold; 4 spikes share it
    np.testing.assert_allclose(prof[1:], want[1:], rtol=1e-4, atol=1e-7 * want.max())
    r = np.arange(2, int(0.5 * L))
    law = (1.0 + 9.0 / L) ** 2 / (1.0 + 9.0 * r / L) ** 2
    assert np.abs(prof[r, 1] / prof[1, 1] / law - 1.0).max() < 0.2
    assert 2e-3 < prof[int(L), 1] / prof[1, 1] < 4e-3
    assert prof[int(L), 0] > 1.5 * prof[int(L), 2]                 # red tips
    support = support_steps(L * 610.0 / 550.0 / grid_step(0.0)[2])
    assert_smooth_tail(prof[:, 0], support, start=2, what="aperture spike (red)")


def streak_fwhm(lum, cx, cy, angle_deg, r):
    """FWHM (px) across a ray at ``r`` px from (cx, cy), from a bilinear profile sampled every
    0.1 px perpendicular to it."""
    from scipy import ndimage

    t = math.radians(angle_deg)
    ux, uy = math.cos(t), -math.sin(t)
    s = np.arange(-12.0, 12.0, 0.1)
    v = ndimage.map_coordinates(lum, [cy + r * uy + s * ux, cx + r * ux - s * uy], order=1)
    above = s[v >= 0.5 * v.max()]
    return above.max() - above.min() + 0.1


@pytest.mark.parametrize("quality", ["draft", "preview", "final"])
@pytest.mark.parametrize("mode,angle", [("star", 15.0), ("star", 45.0), ("anamorphic", 0.0)])
def test_streak_width_does_not_follow_the_light_size(rt, mode, angle, quality):
    # issue 25: a star filter's ray is a diffraction line; spreading every pixel of a light
    # drew it as wide as the light (a candle's flame: a bar).  Lights of sigma 1, 3 and 6 px
    # at 640 x 360: the ray's width near the light is the same thin line (measured 1.1-2.2
    # px; the light of sigma 6 px spread pixel by pixel was wider by 5 px or more).  Draft
    # and preview too: their grids are reduced along each ray only (at 1/4 and 1/2 in both
    # axes a ray was 4-8 px wide)
    p = Streaks.params(mode=mode, streaks=4, angle=angle, length=0.3, threshold=1.0)
    widths = []
    for sigma in (1.0, 3.0, 6.0):
        src = spot(h=360, w=640, sigma=sigma)
        h, w = src.shape[:2]
        out = render_effect(rt, Streaks(), p, src, quality=quality).astype(np.float64)
        lum = (out[..., :3] - src[..., :3]) @ [0.2126, 0.7152, 0.0722]
        widths.append([streak_fwhm(lum, w // 2, h // 2, angle, r) for r in (40, 80)])
    widths = np.array(widths)
    assert widths.max() <= 2.5, widths
    assert widths.max() - widths.min() <= 0.6, widths


def test_thin_ray_has_no_staircase(rt):
    # issue 25: taps rounded to whole pixels in the long passes made a thin ray at 15 degrees
    # wander by up to half a pixel per pass (a staircase along it); every tap interpolated,
    # the ray's centre stays on the straight line within 0.25 px along its length, at every
    # level (draft was allowed 1 px when it ran at 1/4 resolution in both axes; on its
    # ray-aligned grid measured 0.06 px, preview 0.07, final 0.08)
    from scipy import ndimage

    src = spot(h=240, w=480, sigma=1.0)
    h, w = src.shape[:2]
    angle = 15.0
    for quality in ("draft", "preview", "final"):
        p = Streaks.params(mode="star", streaks=1, angle=angle, length=0.6, threshold=1.0)
        out = render_effect(rt, Streaks(), p, src, quality=quality).astype(np.float64)
        lum = (out[..., :3] - src[..., :3]) @ [0.2126, 0.7152, 0.0722]
        t = math.radians(angle)
        ux, uy = math.cos(t), -math.sin(t)
        s = np.arange(-6.0, 6.0, 0.05)
        off = []
        for r in range(-20, -200, -3):          # a ray reaches from the light along -d
            v = ndimage.map_coordinates(lum, [h // 2 + r * uy + s * ux,
                                              w // 2 + r * ux - s * uy], order=1)
            off.append((v * s).sum() / v.sum())
        off = np.array(off)
        assert np.abs(off - off.mean()).max() <= 0.25, (quality, np.round(off, 2))


def bright_pane(rng, h=90, w=200):
    """A noisy bright pane (30 x 50 px, 50 +- 5 %) and, two analysis tiles away (a light of
    its own), a compact one (sigma 1 px)."""
    src = rng.uniform(0.0, 0.5, (h, w, 4)).astype(np.float32)
    src[20:50, 20:70, :3] = rng.uniform(47.5, 52.5, (30, 50, 1)).astype(np.float32)
    y, x = np.mgrid[0:h, 0:w]
    src[..., :3] += (500.0 * np.exp(-((x - 175) ** 2 + (y - 75) ** 2) / 2.0))[..., None]
    return src


def test_extended_light_matches_reference(rt, rng):
    # the pane streaks pixel by pixel, the compact light from its point
    src = bright_pane(rng)
    got, p = run(rt, src, "reference", core=0.5, angle=15.0, streaks=4, length=0.3)
    want = reference(src, **p.as_dict())
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=2e-6 * np.abs(want).max())


def test_extended_light_streaks_as_a_band_not_a_hatch(rt, rng):
    # issue 25: gathered into points, a noisy bright pane streaked from its noise's local
    # maxima, a hatch of parallel thin lines; an extended light streaks as a band as wide as
    # it is, smooth across (Desk.exr's window through the star filter)
    src = bright_pane(rng)
    p = Streaks.params(mode="star", streaks=2, angle=0.0, length=0.5, threshold=1.0, core=0.5)
    out = render_effect(rt, Streaks(), p, src).astype(np.float64)
    lum = (out[..., :3] - src[..., :3]) @ [0.2126, 0.7152, 0.0722]
    col = lum[15:55, 100]                    # 30 px right of the pane, away from the light
    band = col[7:33]                         # the rows the pane covers (22..47)
    assert width_at(col, 0.5) >= 25, np.round(col, 3)
    assert band.min() > 0.5 * band.max(), np.round(band, 3)


def test_star_filter_spikes_do_not_fan_out_the_star_rays():
    # issue 25: the star-filter look's spikes step read its lights from the frame's analysis
    # but its pixels from the star step's output: the star's rays, in no light's tile, passed
    # the threshold and streaked again pixel by pixel, lines swept into wedges of light
    # between the rays around the gallery's sun.  Light in no light's tile does not streak
    # (with a core rule): on circles 15 and 25 px from the sun, light is added on the rays
    # only (measured: 17 % of the circles above 1e-3 of their brightest; the wedges: 36 %)
    from clfx.api import render_array
    from clfx.gallery import sun_scene

    src = sun_scene(640, 360).rgba.astype(np.float32)
    out = render_array(src, "star-filter").rgba.astype(np.float64)
    added = (out[..., :3] - src[..., :3]) @ [0.2126, 0.7152, 0.0722]
    lum = src[..., :3] @ [0.2126, 0.7152, 0.0722]
    cy, cx = np.unravel_index(lum.argmax(), lum.shape)
    ring = [added[int(round(cy - r * math.sin(math.radians(a)))),
                  int(round(cx + r * math.cos(math.radians(a))))]
            for r in (15, 25) for a in range(360)]
    lit = np.mean(np.array(ring) > 1e-3 * np.max(ring))
    assert lit < 0.25, lit


# -- issue 37: final's passes over the spans within each ray's reach ---------------------------
def test_final_passes_run_only_within_the_rays_reach_of_the_lights(rt, monkeypatch):
    # a small light in a 256 x 192 frame: the rays' passes (and the bright pixels, the seeds)
    # run over row spans near it, not over the frame's rows; the streaks the same bits as the
    # whole rows' (streamed below), and the oracle's
    import clfx.plugins.streaks as mod
    src = np.zeros((192, 256, 4), np.float32)
    src[..., 3] = 1.0
    src[150:153, 40:43, :3] = 900.0
    p = Streaks.params(**{**PARAMS, "length": 0.1, "streaks": 4})
    launched = []
    real = rt.launch

    def spy(knl, size, *a, **kw):
        launched.append((knl.function_name, int(np.prod(size)) * (4 if knl.function_name in (
            "streaks_pass", "streaks_clear") else 1)))
        return real(knl, size, *a, **kw)

    monkeypatch.setattr(rt, "launch", spy)
    got = render_effect(rt, Streaks(), p, src)
    px = {name: max(n for k, n in launched if k == name) for name, _ in launched}
    assert px["streaks_pass"] < 0.15 * 256 * 192      # the whole rows: 256 x 192 per pass
    assert px["streaks_bright"] < 0.02 * 256 * 192 and px["streaks_seeds"] <= 32 * 32
    assert "streaks_dilate" not in px                  # the host draws the seeds' windows
    monkeypatch.setattr(rt, "launch", real)
    monkeypatch.setattr(mod, "streams", lambda *a: True)
    whole = render_effect(rt, Streaks(), p, src)
    assert np.array_equal(got.view(np.uint32), whole.view(np.uint32))
    want = reference(src, **p.as_dict())
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=2e-6 * np.abs(want).max())


@pytest.mark.parametrize("kw", [dict(core=0.0, angle=17.0, length=0.3),
                                dict(core=0.0, mode="aperture", blades=7, length=0.2),
                                dict(angle=100.0, length=0.5, streaks=3)],
                         ids=["core0", "core0-aperture", "steep"])
def test_spans_give_the_whole_rows_bits_after_another_frame(rt, rng, monkeypatch, kw):
    # what a ray's passes read outside its spans is cleared first: a frame after one with
    # lights elsewhere (the pool's buffers hold its streaks) has the bits of the whole rows;
    # core 0: the seeds run over the whole frame and mark the blocks with light
    import clfx.plugins.streaks as mod
    p = Streaks.params(**{**PARAMS, **kw})
    cam = Camera(blades=7)
    other = lights(rng, (61, 133))[::-1, ::-1].copy()
    src = lights(rng, (61, 133))
    src[40:44, 100:103, :3] = -5.0                     # negatives and a NaN near a light
    src[41, 101, 1] = np.nan
    render_effect(rt, Streaks(), p, other, camera=cam)
    got = render_effect(rt, Streaks(), p, src, camera=cam)
    monkeypatch.setattr(mod, "streams", lambda *a: True)
    whole = render_effect(rt, Streaks(), p, src, camera=cam)
    assert np.array_equal(got.view(np.uint32), whole.view(np.uint32))


def test_pass_spans_cover_each_rays_streak():
    # the row spans of a ray hold every pixel its streak can reach: a box swept along the
    # ray, row by row (a diagonal band, not its bounding box)
    import clfx.plugins.streaks as mod
    iv = mod.raster(64, 48, np.array([[10.0, 30.0, 11.0, 31.0]]), (1.0, -1.0), (0.0, 20.0))
    cover = np.zeros((48, 16), bool)
    for y, q0, q1 in iv:
        cover[y, q0:q1] = True
    for k in range(21):                                 # the box's pixels, k steps on
        for x, y in ((10, 30), (11, 31), (10, 31), (11, 30)):
            assert cover[y - k, (x + k) // 4]
    assert cover.sum() < 0.2 * cover.size
    spans = mod.row_spans(iv, 64)
    assert (spans[:, 0] % 4 == 0).all() and (spans[:, 2] - spans[:, 0] <= mod.SPAN).all()
    assert (np.diff(spans[:, 1]) >= 0).all()           # row order


def test_job_spans_are_each_jobs_own_row_spans(rng):
    # issue 37: final's plan rasters a ray's passes at once (`job_spans`); each job's spans
    # are the ones its parts give alone, joined: the same spans, so the same pixels
    import clfx.plugins.streaks as mod
    boxes = np.floor(rng.uniform(-20.0, 120.0, (9, 2)))
    boxes = np.concatenate([boxes, boxes + rng.integers(0, 12, (9, 2))], axis=1)
    parts = [(0, boxes, (0.0, 0.0), (0.0, 0.0)),
             (2, boxes[:4] + [-1.5, -0.5, 1.5, 0.5], (1.0, -0.5), (0.0, 63.0)),
             (1, boxes, (0.0, 1.0), (-15.0, 15.0)),
             (2, boxes[4:], (-0.75, 1.0), (-3.0, 40.0)),
             (3, boxes[:0], (1.0, 0.0), (0.0, 5.0))]           # no box: no span
    got = mod.job_spans(128, 100, parts, 5)
    assert len(got) == 5 and got[4].shape == (0, 4)
    for job, spans in enumerate(got):
        alone = [mod.raster(128, 100, b, u, t) for j, b, u, t in parts if j == job]
        want = mod.row_spans(np.concatenate(alone) if alone else np.zeros((0, 3), np.int64),
                             128)
        assert spans.dtype == want.dtype == np.int32
        np.testing.assert_array_equal(spans, want)
    assert all(len(got[j]) for j in (0, 1, 2))
