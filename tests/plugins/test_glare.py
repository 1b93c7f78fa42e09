import math

import numpy as np
import pytest

from clfx.host import RenderContext
from clfx.plugins.glare import Glare
from clfx.core.rect import Rect
from tests.conftest import hard_shapes
from tests.fx.blocks import assert_blocks_match
from tests.reference.glare import glare as reference
from tests.effects import render_effect

LEVELS = ("draft", "preview", "final", "reference")


def psf_for(p, window, display=None):
    """The PSF the plugin builds for a frame (host code under test in test_psf_*)."""
    g = Glare()

    class Ctx:  # the few attributes build_psf/radius_px read
        pass
    ctx = Ctx()
    disp = display or window
    ctx.diagonal_px, ctx.width_px = disp.diagonal, disp.width
    from clfx.core.camera import Camera
    ctx.camera = Camera()
    return g.build_psf(p, ctx, g.radius_px(p, ctx))


def oracle(src, p, window=None, out=None, display=None, boost=0.0):
    window = window or Rect.from_size(src.shape[1], src.shape[0])
    out = out or window
    return reference(src, psf_for(p, window, display), strength=p.strength,
                     threshold=p.threshold, knee=p.knee, tint=p.tint, boost=boost,
                     data_window=(window.x0, window.y0, window.x1, window.y1),
                     out_window=(out.x0, out.y0, out.x1, out.y1))


def scene(rng, h=48, w=64, sun=1e5):
    src = np.zeros((h, w, 4), np.float32)
    src[..., :3] = rng.uniform(0.005, 0.02, (h, w, 3))
    src[..., 3] = 1.0
    src[20:22, 30:32, :3] = sun
    src[8, 10, :3] = (3.0, 2.0, 1.0)
    src[40, 50, :3] = 1.2
    return src


@pytest.mark.parametrize("shape", hard_shapes())
def test_glare_matches_reference_on_hard_shapes(rt, rng, shape):
    src = rng.uniform(0.0, 4.0, shape + (4,)).astype(np.float32)
    p = Glare.params(strength=0.3, size=0.5, threshold=1.0, tint=(1.0, 0.9, 0.8))
    got = render_effect(rt, Glare(), p, src, quality="final")
    want = oracle(src, p)
    # float32 image values ~4, float64 FFT: error is float32 rounding of the sums
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6 * max(want.max(), 1))


@pytest.mark.parametrize("psf", ["spencer", "gaussians"])
def test_glare_levels_error_falls_monotonically(rt, rng, psf):
    src = scene(rng)
    p = Glare.params(strength=0.1, size=0.4, psf=psf)
    want = oracle(src, p)
    errs = [np.abs(render_effect(rt, Glare(), p, src, quality=q) - want).max() for q in LEVELS]
    assert all(a >= b for a, b in zip(errs, errs[1:])), errs
    assert errs[-1] <= 1e-6 * want.max()


@pytest.mark.parametrize("quality", ["preview", "final", "reference"])
def test_glare_hdr_shadows(rt, rng, quality):
    src = scene(rng, 64, 96)
    p = Glare.params(strength=0.1, size=0.5)
    got = render_effect(rt, Glare(), p, src, quality=quality).astype(np.float64)[..., :3]
    want = oracle(src, p)[..., :3]
    m = want >= 1e-3
    assert (np.abs(got - want)[m] / want[m]).max() <= 1e-4   # hard-cases.md case 1
    assert got.min() >= -1e-6 * want.max()


def test_glare_nonfinite_sanitised_and_counted(rt, rng):
    src = scene(rng)
    clean = src.copy()
    src[5, 5, 1], src[30, 60, :] = np.nan, np.inf
    clean[5, 5], clean[30, 60] = 0.0, 0.0
    p = Glare.params(strength=0.1, size=0.3)
    ctx = RenderContext(rt, rt.upload(src))
    out = Glare().render(rt, p, ctx).download()
    assert np.isfinite(out).all()
    assert any("2 non-finite" in n for n in ctx.notes), ctx.notes
    np.testing.assert_array_equal(out, render_effect(rt, Glare(), p, clean))


def test_glare_conserves_energy_away_from_borders(rt):
    src = np.zeros((64, 64, 4), np.float32)
    src[30:34, 30:34, :3] = 1e4
    p = Glare.params(strength=0.5, size=0.3)     # radius 27 px: stays inside
    for q in LEVELS:
        out = render_effect(rt, Glare(), p, src, quality=q)
        assert abs(out[..., :3].sum() / src[..., :3].sum() - 1) <= 1e-5, q  # case 15


def test_glare_identity_without_highlights(rt, rng):
    src = rng.uniform(0.0, 0.4, (16, 20, 4)).astype(np.float32)
    p = Glare.params()
    ctx = RenderContext(rt, rt.upload(src))
    assert Glare().is_identity(p, ctx) == "no pixel above threshold"
    assert Glare().is_identity(Glare.params(strength=0.0), ctx) == "strength is 0"
    assert np.array_equal(render_effect(rt, Glare(), p, src), src)


def test_glare_overscan_contributes(rt, rng):
    # data window larger than the display window; the light sits in the overscan
    data, display = Rect(-16, -16, 80, 64), Rect(0, 0, 64, 48)
    src = np.full((data.height, data.width, 4), 0.01, np.float32)
    src[4:6, 4:6, :3] = 1e4            # frame (-12, -12): outside the display window
    p = Glare.params(strength=0.2, size=0.4)
    got = render_effect(rt, Glare(), p, src, data_window=data, display_window=display)
    want = oracle(src, p, data, data, display)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6 * want.max())
    inside = got[16:, 16:, 0]
    assert inside[0, 0] > 0.05          # light from the overscan reached the display window


def test_glare_rod_grows(rt):
    data, display = Rect(20, 10, 40, 30), Rect(0, 0, 64, 48)
    src = np.zeros((20, 20, 4), np.float32)
    src[10, 10, :3] = 1e3
    p = Glare.params(strength=0.2, size=0.2)
    ctx = RenderContext(rt, rt.upload(src, data), display_window=display)
    r = math.floor(0.2 * display.diagonal + 0.5)
    assert Glare().region_of_definition(p, ctx) == data.grown(r)
    out, win = render_effect(rt, Glare(), p, src, data_window=data, display_window=display,
                             keep_rod=True)
    assert win.contains(data) and win != data
    want = oracle(src, p, data, win, display)
    np.testing.assert_allclose(out, want, rtol=1e-5, atol=1e-6 * want.max())
    assert out[20, 18, 0] > 1e-3        # light left of the source window (frame x = 18)
    assert out.min() >= 0


def test_glare_display_referred_isolates_and_boosts(rt, rng):
    src = rng.uniform(0.0, 0.3, (32, 40, 4)).astype(np.float32)
    src[16, 20, :3] = 1.0
    p = Glare.params(strength=0.1, size=0.3)
    ctx = RenderContext(rt, rt.upload(src), display_referred=True)
    assert Glare().is_identity(p, ctx) is None
    got = render_effect(rt, Glare(), p, src, display_referred=True)
    want = oracle(src, p, boost=p.display_boost)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)
    assert got[16, 24, 0] > src[16, 24, 0]          # glare reads as glare
    linear = render_effect(rt, Glare(), p, src)
    assert got[16, 24, 0] - src[16, 24, 0] > 2 * (linear[16, 24, 0] - src[16, 24, 0])


def test_glare_huge_size_and_extreme_params(rt, rng):
    src = rng.uniform(0.0, 3.0, (12, 9, 4)).astype(np.float32)
    src[5, 4, :3] = 1e5
    p = Glare.params(strength=1.0, size=2.0, threshold=0.0, knee=0.0, psf="gaussians")
    got = render_effect(rt, Glare(), p, src)
    want = oracle(src, p)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6 * want.max())
    np.testing.assert_array_equal(got[..., 3], src[..., 3])   # alpha preserved


def test_psf_spencer_normalised_and_monotonic():
    from clfx.fx import psf
    k = psf.spencer(40, 0.03)
    assert k.shape == (81, 81) and abs(k.sum() - 1) < 1e-12
    row = k[40, 40:]
    assert (np.diff(row[:40]) < 0).all()
    assert psf.spencer_value(0.0) > psf.spencer_value(1.0) > 0


def test_psf_kernel_image_resample():
    from clfx.fx import psf
    img = np.zeros((21, 31, 3))
    img[10, 15] = (1, 2, 3)
    img[10, 25] = (1, 1, 1)
    k = psf.resample_kernel(img, 15)
    assert k.shape == (31, 31, 3)
    np.testing.assert_allclose(k.sum(axis=(0, 1)), 1.0)
    assert k[15, 15, 2] > k[15, 15, 0] * 0.5    # centre of the image lands on the centre tap


def test_glare_kernel_image_comes_from_the_context_reader(rt, rng, monkeypatch):
    from clfx.core.errors import ParamError
    from clfx.fx import psf
    from clfx.pipeline import look

    assert Glare.descriptor.param("kernel_path").kind == "path"   # an input of the render
    src = scene(rng)
    kimg = np.zeros((21, 31, 4), np.float32)
    kimg[10, 15], kimg[4, 25] = (1.0, 2.0, 3.0, 1.0), (1.0, 1.0, 1.0, 1.0)
    reads = []

    def read_image(path):
        reads.append(path)
        return kimg

    monkeypatch.setattr(look, "read_image_rgba", read_image)   # the pipeline's reader
    p = Glare.params(strength=0.2, size=0.3, psf="image",
                     kernel_path="test_glare_kernel_image.exr")
    got = render_effect(rt, Glare(), p, src)
    assert reads == ["test_glare_kernel_image.exr"]     # effects never open files
    window = Rect.from_size(src.shape[1], src.shape[0])
    k = psf.from_image(kimg, int(round(0.3 * window.diagonal)))
    want = reference(src, k, strength=p.strength, threshold=p.threshold, knee=p.knee,
                     tint=p.tint, boost=0.0, data_window=(0, 0, window.x1, window.y1),
                     out_window=(0, 0, window.x1, window.y1))
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6 * want.max())
    with pytest.raises(ParamError, match="glare.kernel_path: psf 'image' needs a kernel image"):
        render_effect(rt, Glare(), Glare.params(psf="image", size=0.3), src)


@pytest.mark.parametrize("psf", ["spencer", "gaussians"])
@pytest.mark.parametrize("size", [0.05, 0.15])
def test_point_light_glare_fades_smoothly_before_its_support_ends(rt, psf, size):
    # issue 25: the radial profile of a 1e4 point is monotone, has no step above 1e-4 of its
    # peak and is below that before the PSF's support ends (size 0.05 on 320 px: the former
    # taper started at 1e-3 and ended the tail in a shoulder)
    from tests.light_profile import assert_smooth_tail, point_light, ray

    src = point_light()
    h, w = src.shape[:2]
    out = render_effect(rt, Glare(), Glare.params(psf=psf, size=size), src)
    support = round(size * math.hypot(w, h))
    assert_smooth_tail(ray(out, h // 2, w // 2, 1, 0, w // 2), support,
                       what=f"glare {psf} size {size}")


def test_glare_of_a_flame_in_a_dark_room_fades_without_a_rim(rt):
    # issue 25: anamorphic-night's glare (Spencer, size 0.2) around a 200-nit flame, exposed
    # for the dark room as the gallery exposes it: the raised-cosine taper over the support's
    # outer tenth cut a tail ten times the room's level to nothing within a few pixels, an
    # orange disc with a rim.  The displayed profile must fade ever more gently (convex): the
    # per-pixel drop (5 px mean) never grows beyond 0.3 x the radius (the outer-tenth taper:
    # +2.6e-4 of display white per px; the taper from half the radius: none)
    from clfx.demo import tonemap_preview
    from clfx.gallery import exposure_for
    from tests.light_profile import flame_in_a_dark_room

    h, w = 260, 480
    src = flame_in_a_dark_room(h, w, 4e-4, 8.0, 32.0)
    p = Glare.params(strength=0.04, threshold=2.0, knee=1.0, size=0.2, psf="spencer")
    out = render_effect(rt, Glare(), p, src).astype(np.float64)
    radius = p.size * math.hypot(w, h)
    row = tonemap_preview(out, exposure_for(src))[h // 2, w // 2:, 1].astype(np.float64)
    drop = np.convolve(-np.diff(row), np.ones(5) / 5, mode="valid")
    seg = drop[int(0.3 * radius):int(radius) + 2]
    assert np.diff(seg).max() <= 2e-5, np.round(seg * 1e3, 2)
    assert row[int(0.3 * radius)] > row[-1] + 0.05        # and the glow shows


@pytest.mark.parametrize("quality", LEVELS)
def test_glare_in_blocks_is_the_one_grid_glare(rt, rng, monkeypatch, quality):
    """8K's path on a small frame: output blocks (overlap-save) give the one-grid glare up to
    FFT rounding at every level, and the float64 levels still match the oracle."""
    src = scene(rng, 64, 96)
    p = Glare.params(strength=0.1, size=0.5)
    got = assert_blocks_match(rt, monkeypatch, Glare(), p, src, quality, cells=1500)
    if quality in ("final", "reference"):
        want = oracle(src, p)
        assert np.abs(got - want).max() <= 1e-6 * want.max()
        m = want[..., :3] >= 1e-3                 # hard-cases.md case 1, as one grid
        assert (np.abs(got - want)[..., :3][m] / want[..., :3][m]).max() <= 1e-4


# -- issue 37: glare's CPU per frame ----------------------------------------------------------
def test_glare_final_copies_no_highlights_and_unpacks_nothing(rt, rng, monkeypatch):
    # the support's highlights come straight from the source (no reframed copy), the host's
    # float64 transforms write the output themselves (no unpacking kernel) through one
    # complex plane the cache keeps from one frame to the next
    from clfx.fx import fftconv
    src = scene(rng, 64, 96)
    p = Glare.params(strength=0.2, size=0.3)
    fftconv.clear_caches(rt)
    launched = []
    real = rt.launch
    monkeypatch.setattr(rt, "launch", lambda knl, *a, **kw: launched.append(
        knl.function_name) or real(knl, *a, **kw))
    got = render_effect(rt, Glare(), p, src, quality="final")
    assert "glare_highlights_at" in launched
    assert not {"image_reframe", "fftconv_unpack", "fftconv_pack"} & set(launched)
    assert rt.cache.stats()["owners"].get("fftconv.host_plane", 0) > 0
    again = render_effect(rt, Glare(), p, src, quality="final")
    assert np.array_equal(got.view(np.uint32), again.view(np.uint32))
    want = oracle(src, p)
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-5 * np.abs(want).max())


@pytest.mark.parametrize("rect", [Rect(3, 2, 21, 13), Rect(-5, -3, 14, 9), Rect(20, 10, 40, 30)])
def test_highlights_at_are_a_reframed_copys_highlights(rt, rng, rect):
    # <effect>_highlights_at over a part of the source (past its edges too) gives the bits
    # of the highlights taken in place of a reframed copy of that part
    src = rng.uniform(-1.0, 6.0, (17, 29, 4)).astype(np.float32)
    src[4, 5, 1], src[6, 7, 0] = np.nan, np.inf
    img = rt.upload(src)
    args = (1.0, 0.5, 0.0)
    sub = rt.reframe(img, rect)
    hl = rt.kernel("glare.cl", "glare_highlights")
    rt.launch(hl, (sub.pitch // 4, sub.height), sub, sub, sub.pitch, sub.height, *args)
    h = rt.image(rect, 4)
    dx, dy = rect.offset_in(img.window)
    rt.launch(rt.kernel("glare.cl", "glare_highlights_at"), (h.pitch // 4, h.height), img,
              img.pitch, img.width, img.height, dx, dy, h, h.pitch, h.width, h.height, *args)
    want = rt.from_device(sub, np.float32, sub.pitch * sub.height * 4)
    got = rt.from_device(h, np.float32, h.pitch * h.height * 4)
    assert np.array_equal(got.view(np.uint32), want.view(np.uint32))


@pytest.mark.parametrize("quality", ["final", "draft"])
def test_glare_spectra_follow_the_psf_and_are_not_rehashed_each_frame(rt, rng, monkeypatch,
                                                                    quality):
    """Issue 37: glare's PSF spectra are found by the PSF's cache key (its bytes hashed
    once, not every frame: 3 ms at 1080p); a frame whose PSF changes (size, shape, field of
    view) renders as a cold cache would, and a frame whose PSF does not (strength) reuses
    the spectra."""
    from clfx.fx import fftconv

    hashed = []
    digest = fftconv.psf_digest
    monkeypatch.setattr(fftconv, "psf_digest", lambda k: hashed.append(k.shape) or digest(k))
    src = scene(rng)
    frames = [Glare.params(strength=0.2, size=0.3), Glare.params(strength=0.2, size=0.4),
              Glare.params(strength=0.2, size=0.4, psf="gaussians"),
              Glare.params(strength=0.2, size=0.4, fov=30.0),
              Glare.params(strength=0.5, size=0.4, fov=30.0)]
    cold = []
    for p in frames:
        fftconv.clear_caches(rt)
        rt.cache.clear("glare.psf")
        cold.append(render_effect(rt, Glare(), p, src, quality=quality))
    for p, want in zip(frames, cold):           # one warm cache from frame to frame
        np.testing.assert_array_equal(render_effect(rt, Glare(), p, src, quality=quality), want)
    assert not np.array_equal(cold[0], cold[1]) and not np.array_equal(cold[1], cold[2])
    assert not np.array_equal(cold[2], cold[3])
    del hashed[:]
    spectra = rt.cache.misses
    for p, want in zip(frames, cold):           # again: nothing hashed, nothing built
        np.testing.assert_array_equal(render_effect(rt, Glare(), p, src, quality=quality), want)
    assert hashed == [] and rt.cache.misses == spectra
