"""tests.effects.render_effect, the effect tests' way in, is the production path: it tiles
when given a tile size, sanitises the upload, animates the camera from the reference camera,
keeps the grown window when asked and masks the step, as `render_frame` does."""
import numpy as np

from clfx.core.camera import Camera
from clfx.core.rect import Rect
from clfx.pipeline.masks import MaskSpec
from clfx.plugins import discover
from tests.effects import render_effect


def frame(h=24, w=32):
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    src = np.empty((h, w, 4), np.float32)
    src[..., 0], src[..., 1], src[..., 2] = x / w, y / h, 0.5
    src[..., 3] = 1.0
    return src


def test_a_tile_size_renders_in_bands_with_the_whole_pixels(rt, monkeypatch):
    vignette = discover()["vignette"]()
    p = vignette.params(amount=0.5)
    whole = render_effect(rt, vignette, p, frame())
    bands = []
    real = type(vignette).render
    monkeypatch.setattr(vignette, "render",
                        lambda rt_, p_, ctx: bands.append(ctx.tiling) or real(vignette, rt_, p_, ctx))
    tiled = render_effect(rt, vignette, p, frame(), tile_pixels=32 * 5)
    assert len(bands) == 5 and all(b is not None for b in bands)
    assert np.array_equal(tiled, whole)


def test_the_upload_is_sanitised_and_said(rt):
    glare = discover()["glare"]()
    src = frame()
    src[3, 4, 0], src[10, 20, 2] = np.nan, np.inf
    report = []
    out = render_effect(rt, glare, glare.params(strength=0.2), src, report=report)
    assert np.isfinite(out).all()
    assert any("2 pixel(s) with NaN" in w for w in report[0].frame_warnings)


def test_the_camera_is_keyframed_from_the_reference_camera(rt):
    """Breathing responds to the focus pulled from the shot's first keys: the same frame
    camera breathes with another reference camera and not with its own."""
    breathing = discover()["breathing"]()
    p = breathing.params(amount=1.0)
    setup, pulled = Camera(focus_distance=10.0), Camera(focus_distance=0.5)
    src = frame()
    assert np.array_equal(render_effect(rt, breathing, p, src, camera=pulled), src)
    moved = render_effect(rt, breathing, p, src, camera=pulled, reference_camera=setup)
    assert not np.array_equal(moved, src)


def test_the_grown_window_and_a_mask(rt):
    glare = discover()["glare"]()
    p = glare.params(strength=0.5, threshold=0.5)
    src = frame()
    src[12, 16, :3] = 50.0
    out, window = render_effect(rt, glare, p, src, data_window=Rect(4, 4, 36, 28),
                                display_window=Rect(0, 0, 40, 32), keep_rod=True)
    assert window == Rect(0, 0, 40, 32) and out.shape == (32, 40, 4)
    spec = MaskSpec(channel="m")
    report = []
    none = np.zeros(src.shape[:2], np.float32)
    kept = render_effect(rt, glare, p, src, mask=spec, masks={spec: none}, report=report)
    assert np.array_equal(kept, src) and "selects nothing" in report[0].steps[0].reason
    every = render_effect(rt, glare, p, src, mask=spec, masks={spec: none + 1.0})
    np.testing.assert_allclose(every, render_effect(rt, glare, p, src), rtol=1e-6, atol=1e-7)
