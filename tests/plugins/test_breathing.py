"""Lens breathing: the scale follows the thin lens and the keyframed focus, every level
matches its float64 oracle, a static focus is an identity, widening past the rendered pixels
warns (and uses the overscan where there is one)."""
import numpy as np
import pytest

import clfx
from clfx.core.camera import Camera
from clfx.core.frame import Frame
from clfx.core.rect import Rect
from clfx.pipeline.look import render_frame
from clfx.plugins.breathing import Breathing, thin_lens_scale
from tests.conftest import hard_shapes
from tests.plugins.test_distortion import (built_with_streaming, nonfinite_image,
                                           plain_and_streamed, render_with_notes, smooth_image)
from tests.reference import breathing as ref
from tests.effects import render_effect

LENS = Camera(focal_length=50.0, focus_distance=0.6, breathing=1.0)
SETUP = Camera(focal_length=50.0, focus_distance=5.0)
"""A 50 mm lens racked from 5 m (the shot's first key) to 0.6 m: the view narrows 8%."""

QUALITIES = ("draft", "preview", "final", "reference")
TOL = {"draft": 2e-5, "preview": 2e-5, "final": 2e-5, "reference": 1e-6}
"""float32 positions (a few ulps of 64 px, ~1e-5 px), weights and sums over up to 64 taps per
sub-footprint of values <= 1: ~1e-5; the reference sums in float64 and stores float32 (ulp
6e-8), its positions in float64."""


def m_of(camera=LENS, setup=SETUP, amount=None):
    return ref.scale(camera.focus_distance, setup.focus_distance, camera.focal_length,
                     camera.breathing if amount is None else amount)


def run(rt, src, quality="final", camera=LENS, setup=SETUP, **kw):
    p = Breathing.params(**kw)
    return render_effect(rt, Breathing(), p, src, quality=quality, camera=camera,
                         reference_camera=setup)


def test_scale_is_the_thin_lens_image_distance_ratio():
    # v(0.6 m) = 50 * 600 / 550, v(5 m) = 50 * 5000 / 4950
    want = (50 * 600 / 550) / (50 * 5000 / 4950)
    assert thin_lens_scale(0.6, 5.0, 50.0, 1.0)[0] == pytest.approx(want, rel=1e-14)
    assert thin_lens_scale(0.6, 5.0, 50.0, 0.5)[0] == pytest.approx(1 + 0.5 * (want - 1))
    assert thin_lens_scale(0.6, 5.0, 50.0, -1.0)[0] < 1.0          # widens focusing close
    assert thin_lens_scale(5.0, 5.0, 50.0, 1.0) == (1.0, [])
    lens = Camera(focal_length=50.0, focus_distance=0.6)
    assert lens.image_distance() == pytest.approx(50 * 600 / 550)


def test_closer_than_macro_is_clamped_with_a_warning():
    m, warnings = thin_lens_scale(0.03, 5.0, 50.0, 1.0)      # inside the focal length
    assert m == pytest.approx(thin_lens_scale(0.1, 5.0, 50.0, 1.0)[0])   # 2 f = 0.1 m
    assert len(warnings) == 1 and "1:1 macro" in warnings[0]
    m, warnings = thin_lens_scale(0.1, 1e9, 50.0, -2.0)       # 1 - 2 (2 - 1) < 0: floored
    assert m == 0.25 and "raised to 0.25" in warnings[-1]


@pytest.mark.parametrize("shape", hard_shapes())
def test_matches_reference_hard_shapes(rt, rng, shape):
    src = rng.uniform(0.0, 1.0, shape + (4,)).astype(np.float32)
    got = run(rt, src)
    want = ref.breathing(src, m=m_of())
    np.testing.assert_allclose(got, want, rtol=0, atol=TOL["final"])


@pytest.mark.parametrize("quality", QUALITIES)
@pytest.mark.parametrize("amount", [1.0, -1.0, -2.0])    # narrows 8%, widens 8%, widens 16%
def test_each_quality_matches_its_oracle(rt, rng, quality, amount):
    src = smooth_image(rng, 40, 64)
    camera = LENS.updated(breathing=amount)
    got = run(rt, src, quality, camera=camera)
    want = ref.breathing(src, m=m_of(camera), quality=quality)
    np.testing.assert_allclose(got, want, rtol=0, atol=TOL[quality])


@pytest.mark.parametrize("quality", QUALITIES)
def test_strong_minification_splits_the_footprint(rt, rng, quality):
    """m = 0.25 (amount -2 at 2 f vs far): 4x minification needs sub-footprints."""
    src = rng.uniform(0.0, 1.0, (24, 40, 4)).astype(np.float32)
    camera = Camera(focal_length=50.0, focus_distance=0.1, breathing=-2.0)
    setup = Camera(focal_length=50.0, focus_distance=1e9)
    got = run(rt, src, quality, camera=camera, setup=setup)
    want = ref.breathing(src, m=0.25, quality=quality)
    np.testing.assert_allclose(got, want, rtol=0, atol=TOL[quality])
    # an area average: far flatter than the input
    assert got[8:16, 12:28, :3].std() < 0.5 * src[..., :3].std()


def test_param_overrides_camera_and_centre_and_reference_focus(rt, rng):
    src = smooth_image(rng, 30, 50)
    got = run(rt, src, camera=LENS.updated(breathing=0.0), setup=LENS, amount=0.7,
              reference_focus=2.0, center=(0.3, -0.5))
    want = ref.breathing(src, m=ref.scale(0.6, 2.0, 50.0, 0.7), center=(0.3, -0.5))
    np.testing.assert_allclose(got, want, rtol=0, atol=TOL["final"])


def test_static_focus_is_an_identity_with_a_reason(rt, rng):
    src = rng.uniform(0.0, 1.0, (9, 13, 4)).astype(np.float32)
    plugin = Breathing()
    from clfx.host import RenderContext

    ctx = RenderContext(rt, rt.upload(src), camera=LENS)       # reference camera = camera
    reason = plugin.is_identity(Breathing.params(), ctx)
    assert reason and "does not change" in reason
    ctx = RenderContext(rt, rt.upload(src), camera=SETUP, reference_camera=SETUP)
    assert "amount is 0" in plugin.is_identity(Breathing.params(), ctx)
    assert run(rt, src, camera=LENS, setup=LENS).tobytes() == src.tobytes()


def rack_look(**params):
    return clfx.load_look({
        "name": "rack", "schema": 1,
        "camera": {"focal_length": 50.0, "focus_distance": {1: 5.0, 9: 0.6}, "breathing": 1.0},
        "effects": [{"effect": "breathing", "params": params}]})


def test_keyframed_focus_scale_follows_the_keys(rt, rng):
    """Over a rack focus the scale is m(S(frame)) from the first key's focus: 1 at the first
    key and before it, the thin-lens ratio at the last key and after it."""
    src = smooth_image(rng, 32, 48)
    look = rack_look()
    for frame in (0, 1, 3, 5, 9, 12):
        s = look.at(frame).camera.focus_distance
        out, report = render_frame(rt, look, Frame.from_array(src), frame_number=frame)
        step = report.steps[0]
        if frame <= 1:
            assert not step.ran and "does not change" in step.reason
            np.testing.assert_array_equal(out.rgba, src)
            continue
        m = ref.scale(s, 5.0, 50.0, 1.0)
        assert step.ran and f"scale {m:.6f}" in step.notes[0]
        np.testing.assert_allclose(out.rgba, ref.breathing(src, m=m), rtol=0, atol=2e-5)
        assert report.values == {"camera.focus_distance": pytest.approx(s)}


def test_static_focus_in_a_look_is_skipped(rt, rng):
    src = smooth_image(rng, 16, 24)
    look = clfx.load_look({"name": "still", "schema": 1,
                           "camera": {"focus_distance": 0.6, "breathing": 1.0},
                           "effects": [{"effect": "breathing"}]})
    out, report = render_frame(rt, look, Frame.from_array(src), frame_number=5)
    assert not report.steps[0].ran and "does not change" in report.steps[0].reason
    np.testing.assert_array_equal(out.rgba, src)


def test_widening_without_overscan_warns_once(rt, rng):
    src = smooth_image(rng, 32, 48)
    look = clfx.load_look({
        "name": "widen", "schema": 1,
        "camera": {"focal_length": 50.0, "focus_distance": {1: 0.6, 9: 5.0}, "breathing": 1.0},
        "effects": [{"effect": "breathing"}]})
    out, report = render_frame(rt, look, Frame.from_array(src), frame_number=9)
    m = ref.scale(5.0, 0.6, 50.0, 1.0)
    assert m < 1
    warnings = report.steps[0].warnings
    assert len(warnings) == 1, warnings
    assert f"widens the frame by {100 * (1 / m - 1):.2f}%" in warnings[0]
    assert "past the rendered pixels" in warnings[0]
    assert report.warnings()[0].startswith("clfx: warning: frame 9: breathing: ")
    np.testing.assert_allclose(out.rgba, ref.breathing(src, m=m), rtol=0, atol=2e-5)
    # narrowing reads inside the frame: no warning
    _, report = render_frame(rt, rack_look(), Frame.from_array(src), frame_number=9)
    assert report.steps[0].warnings == []


def test_widening_reads_the_overscan_and_does_not_warn(rt, rng):
    """With a data window 6 px beyond the display window on every side, an 8% widening of a
    48 x 32 frame (2 px per side) reads real pixels: same as the oracle on the whole data
    window, no warning."""
    display = Rect(0, 0, 48, 32)
    data = display.grown(6)
    src = smooth_image(rng, data.height, data.width)
    camera, setup = SETUP.updated(breathing=1.0), LENS
    m = m_of(camera, setup)
    p = Breathing.params()
    out = render_effect(rt, Breathing(), p, src, camera=camera, reference_camera=setup,
                        data_window=data, display_window=display)
    want = ref.breathing(src, m=m, data_window=(-6, -6, 54, 38), display_window=(0, 0, 48, 32))
    np.testing.assert_allclose(out, want, rtol=0, atol=2e-5)
    from clfx.host import RenderContext

    ctx = RenderContext(rt, rt.upload(src, data), display_window=display, camera=camera,
                        reference_camera=setup)
    Breathing().render(rt, p, ctx)
    assert ctx.warnings == []


@pytest.mark.parametrize("amount", [1.0, -1.0])
def test_element_inside_the_display_window(rt, rng, amount):
    """A data window inside the display window (an element's bounding box): outside it the
    frame is transparent black, read as 0 (no warning); scaling up grows the window."""
    display, data = Rect(0, 0, 64, 48), Rect(20, 10, 50, 30)
    src = smooth_image(rng, data.height, data.width)
    camera = LENS.updated(breathing=amount)
    m = m_of(camera)
    p = Breathing.params()
    from clfx.host import RenderContext

    ctx = RenderContext(rt, rt.upload(src, data), display_window=display, camera=camera,
                        reference_camera=SETUP)
    img = Breathing().render(rt, p, ctx)
    assert ctx.warnings == []
    assert img.window.contains(data) and display.contains(img.window)
    # zooming in grows the window; zooming out only by the filter's reach (its tails read
    # the element's edge texels from a few pixels out)
    assert img.window != data if m > 1 else data.grown(5).contains(img.window)
    got = rt.download(img)
    want = ref.breathing(np.pad(src, ((data.y0 - img.window.y0, img.window.y1 - data.y1),
                                      (data.x0 - img.window.x0, img.window.x1 - data.x1),
                                      (0, 0))),
                         m=m, data_window=(img.window.x0, img.window.y0, img.window.x1,
                                           img.window.y1),
                         display_window=(0, 0, 64, 48))
    np.testing.assert_allclose(got, want, rtol=0, atol=2e-5)
    # the content scaled away from the element's edge leaves transparent black
    assert np.abs(got[0, :, 3]).max() < 1e-6


def test_only_the_beauty_changes(rt, rng):
    src = smooth_image(rng, 16, 24)
    depth = np.linspace(1.0, 9.0, 16 * 24, dtype=np.float32).reshape(16, 24)
    frame = Frame.from_array(src, depth=depth)
    out, _ = render_frame(rt, rack_look(), frame, frame_number=9)
    assert not np.allclose(out.rgba, src)
    np.testing.assert_array_equal(out.depth, depth)


@pytest.mark.parametrize("quality", QUALITIES)
def test_nan_and_inf_read_as_zero_and_are_noted(rt, rng, quality):
    src = nonfinite_image(rng)
    p = Breathing.params()
    got, notes = render_with_notes(rt, Breathing(), p, src, quality=quality, camera=LENS,
                                   reference_camera=SETUP)
    assert np.isfinite(got).all()
    assert any("4 non-finite pixel(s) read as 0" in n for n in notes)
    clean = np.nan_to_num(src, nan=0.0, posinf=0.0, neginf=0.0)
    np.testing.assert_array_equal(got, run(rt, clean, quality))


def test_hdr_point_is_not_rung_and_alpha_kept(rt):
    src = np.full((21, 21, 4), 0.01, np.float32)
    src[..., 3] = 1.0
    src[10, 10, :3] = 1e5
    for quality in QUALITIES:
        got = run(rt, src, quality, camera=LENS.updated(breathing=-2.0))
        assert (got[..., :3] >= 0.01 - 1e-6).all(), quality      # clamped: no negative lobes
        np.testing.assert_allclose(got[..., 3], 1.0, atol=1e-6)


def test_keyframed_cli_render(rt, rng, tmp_path):
    """`clfx render in.#.exr out.#.exr --look X --set camera.focus_distance=1:2.0,8:5.5
    --set camera.breathing=1`: each frame scaled by its focus, one warning line per widened
    frame without overscan, the values stamped."""
    import json

    from click.testing import CliRunner

    from clfx.cli import cli
    from clfx.io.read import read_frame
    from clfx.io.write import write_frame

    frames = {f: smooth_image(rng, 24, 40) for f in (1, 4, 8)}
    for f, a in frames.items():
        write_frame(Frame.from_array(a), tmp_path / f"in.{f:04d}.exr", bit_depth="float")
    (tmp_path / "rack.yaml").write_text("name: rack\nschema: 1\ncamera: {focal_length: 50}\n"
                                        "effects:\n  - effect: breathing\n")
    r = CliRunner().invoke(cli, ["render", str(tmp_path / "in.#.exr"),
                                 str(tmp_path / "out.#.exr"), "--look",
                                 str(tmp_path / "rack.yaml"), "--float",
                                 "--set", "camera.focus_distance=1:2.0,8:5.5",
                                 "--set", "camera.breathing=1"], catch_exceptions=False)
    assert r.exit_code == 0, (r.output, r.stderr)
    warned = [line for line in r.stderr.splitlines() if "breathing:" in line]
    assert [line.split(":")[2].strip() for line in warned] == ["frame 4", "frame 8"]
    for f, a in frames.items():
        out = read_frame(tmp_path / f"out.{f:04d}.exr")
        s = 2.0 + 3.5 * (f - 1) / 7
        values = json.loads(out.metadata["clfx:values"])
        assert values == {"camera.focus_distance": pytest.approx(s)}
        np.testing.assert_allclose(out.rgba, ref.breathing(a, m=ref.scale(s, 2.0, 50.0, 1.0)),
                                   rtol=0, atol=2e-5)


@pytest.mark.parametrize("quality", ["draft", "preview", "final"])
@pytest.mark.parametrize("camera", [LENS, Camera(focal_length=50.0, focus_distance=0.1,
                                                 breathing=-2.0)])
def test_streaming_stores_give_the_same_pixels(rt, rng, monkeypatch, quality, camera):
    """Outputs at least half the device's cache are written with streaming stores
    (Runtime.streams_stores); forced on a small frame, with fast quads and checked ones (the
    edge, the minifying lens's sub-footprints), every pixel is what plain stores write."""
    src = smooth_image(rng, 37, 58)
    plain, streamed, asked = plain_and_streamed(
        rt, monkeypatch, lambda: run(rt, src, quality, camera=camera))
    assert asked and asked[-1] >= src.nbytes
    assert np.array_equal(streamed, plain)
    assert built_with_streaming(rt, "breathing.cl")


@pytest.mark.parametrize("amount", [1.0, -1.0])
def test_tight_window_gives_the_full_frame_pixels(rt, rng, amount):
    """An element in its own data window gives the pixels it gives placed in a full-frame
    window (zooming in grows the window; out keeps it)."""
    from tests.plugins.windows import element, tight_and_full

    display, data = Rect(0, 0, 96, 64), Rect(50, 30, 90, 60)
    camera, setup = Camera(focal_length=50.0, focus_distance=0.6), Camera(focal_length=50.0,
                                                                           focus_distance=3.0)
    p = Breathing.params(amount=amount)
    tight, full, window = tight_and_full(rt, Breathing(), p, element(rng, data), data,
                                         display, camera=camera, reference_camera=setup,
                                         quality="final")
    # the same affine map from other window origins: float32 positions (x * inv_m + a) differ
    # by ~1e-6 px, times gradients up to ~4 per px at the disc's edge: measured 2.3e-5
    np.testing.assert_allclose(tight, full, rtol=0, atol=1e-4)
    # zooming out carries the element towards the centre, past its box's left and top
    assert window.contains(data) and window != data
