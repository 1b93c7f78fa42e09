"""Thin frames (issue 34): light-spreading effects size their PSFs from the frame's diagonal,
so a 65535x1 frame asked for a 19661^2 PSF (8-21 GB, minutes, SIGTERM unanswered).  The FFT
family keeps only the PSF rows that can carry light into the frame, and what would still
exceed the frame's memory budget is refused in one line before it is built."""
import numpy as np
import pytest

from clfx.core.errors import ClfxError
from clfx.core.rect import Rect
from clfx.fx import fftconv
from clfx.fx import psf as psflib
from clfx.plugins.halation import halation_psf
from tests.contract import effects as E

SPREADERS = ("glare", "soft_focus", "bleed", "halation")


def test_reachable_drops_only_taps_that_reach_nothing():
    k = np.arange(41 * 41, dtype=np.float64).reshape(41, 41)
    frame = Rect.from_size(300, 2)
    thin = fftconv.reachable(k, frame, frame)
    assert thin.shape == (2 * (1 + fftconv.REACH_MARGIN) + 1, 41)
    assert np.array_equal(thin, k[20 - 3:20 + 4])
    square = Rect.from_size(64, 64)
    assert fftconv.reachable(k, square, square) is k           # everything reaches: the same


@pytest.mark.parametrize("name", SPREADERS)
def test_a_thin_frame_renders_as_with_the_whole_psf(rt, name, monkeypatch):
    """Dropping the rows that reach nothing changes nothing but the FFT's rounding."""
    src = E.scene((2, 700))
    src[0, ::97, :3] = E.HIGHLIGHT
    fftconv.clear_caches(rt)
    thin = E.apply(rt, name, src)
    cropped = []
    real = fftconv.reachable

    def whole(k, support, out_window):
        cropped.append(real(k, support, out_window).shape != k.shape)
        return k

    monkeypatch.setattr(fftconv, "reachable", whole)
    fftconv.clear_caches(rt)
    full = E.apply(rt, name, src)
    assert any(cropped), f"{name}: nothing to drop on a 700x2 frame?"
    np.testing.assert_allclose(thin, full, rtol=1e-4, atol=1e-5 * float(np.abs(full).max()))


def test_a_psf_window_is_normalised_as_the_whole():
    """A large PSF is built over the rows and columns that reach the frame only (a 65535x1
    frame's glare: 5 of its 16385 rows), normalised as the whole (1e-12)."""
    r, reach = 600, (3, 650)
    for build in (lambda **k: psflib.spencer(r, 0.01, **k),
                  lambda **k: psflib.spencer(r, 4e-4, **k),       # a long lens: a wide core
                  lambda **k: psflib.gaussians(r, *psflib.bloom_sigmas(r), **k),
                  lambda **k: psflib.exponentials(r, [r / 12, r / 24, r / 48], [1, 2, 4], **k),
                  lambda **k: psflib.exponential(r, r / 3, **k),
                  lambda **k: halation_psf(r, True, **k),
                  lambda **k: psflib.from_image(np.random.default_rng(2).random((37, 53)), r,
                                                **k)):
        whole = build()
        part = build(reach=reach)
        assert part.shape[:2] == (7, 2 * r + 1)
        np.testing.assert_allclose(part, whole[r - 3:r + 4], rtol=1e-9, atol=1e-12 * whole.max())
    small = psflib.spencer(200, 0.01, reach=(3, 3))     # below WINDOW_MIN_CELLS: the whole
    assert small.shape == (401, 401)


@pytest.mark.parametrize("name", ["glare", "soft_focus", "halation"])
def test_a_thin_frame_renders_with_its_psf_window_as_with_the_whole(rt, name, monkeypatch):
    """The window path (mocked to start at any size) renders what the whole PSF renders."""
    src = E.scene((2, 700))
    src[0, ::97, :3] = E.HIGHLIGHT
    p = E.params(name, radius=0.3) if name == "halation" else E.params(name)
    monkeypatch.setattr(psflib, "WINDOW_MIN_CELLS", 0)
    rt.cache.clear()
    thin = E.apply(rt, name, src, p)
    monkeypatch.setattr(psflib, "windowed", lambda radius, reach: False)
    rt.cache.clear()
    full = E.apply(rt, name, src, p)
    np.testing.assert_allclose(thin, full, rtol=1e-4, atol=1e-5 * float(np.abs(full).max()))


@pytest.mark.parametrize("name", ["glare", "soft_focus"])
def test_a_65535x1_psf_is_built_over_its_reach_within_the_budget(rt, name):
    """65535x1: glare's 16385^2 PSF took > 8.3 GB (12 GiB asked), then was refused; its 5 rows
    that reach the frame are built."""
    src = np.zeros((1, 65535, 4), np.float32)
    ctx = E.context(rt, name, src)
    plugin = E.plugin(name)
    p = E.params(name)
    r = plugin.radius_px(p, ctx)
    k = plugin.psf(p, ctx)
    assert k.shape[:2] == (1 + 2 * fftconv.REACH_MARGIN, 2 * r + 1)
    assert 0.0 < float(k.sum()) < 1.0


def test_a_glare_size_the_docs_allow_is_built_over_the_frame_it_reaches(rt):
    """glare size 2.0 (its documented maximum) on a 960x540 frame: a 4407^2 PSF, refused by
    the frame's budget (as 1080p was past size 0.84); the rows and columns that reach the
    frame are built."""
    ctx = E.context(rt, "glare", np.zeros((540, 960, 4), np.float32))
    p = E.params("glare", size=2.0)
    k = E.plugin("glare").psf(p, ctx)
    reach = 2 * (fftconv.REACH_MARGIN + np.array([539, 959])) + 1
    assert k.shape == tuple(reach)


@pytest.mark.parametrize("name", ["glare", "soft_focus"])
def test_a_psf_beyond_the_frames_budget_is_refused_before_it_is_built(rt, name, monkeypatch):
    """What even the PSF's window would take beyond the frame's budget (mocked to 72 bytes a
    pixel, no pool) is one line before it is built."""
    from clfx.core import limits

    src = np.zeros((1, 65535, 4), np.float32)
    ctx = E.context(rt, name, src)
    monkeypatch.setattr(limits, "DERIVED_MIN_BYTES", 0)
    monkeypatch.setattr(rt.cache, "max_bytes", 0)
    with pytest.raises(ClfxError, match=r"PSF .* would take .* GiB; the memory budget of a "
                                        r"65535x1 frame allows") as info:
        E.plugin(name).psf(E.params(name), ctx)
    assert "\n" not in str(info.value)


def test_a_device_buffer_over_the_devices_limit_is_one_line(rt):
    """dof on a 65535x1 frame asked for one 8.9 GiB buffer: pyopencl's LogicError
    (INVALID_BUFFER_SIZE) traceback."""
    from clfx.core.errors import DeviceError

    most = min(d.max_mem_alloc_size for d in rt.ctx.devices)
    with pytest.raises(DeviceError, match=r"cannot allocate a device buffer of .* GiB"):
        rt.buffer(most + 16)
    rt.buffer(1024)                                   # the pool still serves


def test_an_fft_axis_past_the_longest_is_cut_into_blocks(rt, monkeypatch):
    """soft_focus on a 65535x1 frame asked VkFFT for a 3 x 71442 float64 plan: SIGSEGV on
    PoCL.  An axis past MAX_FFT_AXIS (mocked to 512 on a 700x2 frame) is cut into blocks,
    which render what the one grid renders."""
    src = E.scene((2, 700))
    src[0, ::97, :3] = E.HIGHLIGHT
    fftconv.clear_caches(rt)
    whole = E.apply(rt, "glare", src)
    monkeypatch.setattr(fftconv, "MAX_FFT_AXIS", 512)
    seen = []
    real = fftconv._convolve

    def spy(rt_, img, k, support, out_window, method, precision, *args):
        grid = args[3] if len(args) > 3 and args[3] is not None else fftconv.fft_grid(
            support, out_window.intersect(fftconv.full_region(support, *k.shape[:2])),
            *k.shape[:2])
        seen.append(grid)
        return real(rt_, img, k, support, out_window, method, precision, *args)

    monkeypatch.setattr(fftconv, "_convolve", spy)
    fftconv.clear_caches(rt)
    cut = E.apply(rt, "glare", src)
    assert len(seen) > 1 and max(max(g) for g in seen) <= 512
    np.testing.assert_allclose(cut, whole, rtol=1e-4, atol=1e-5 * float(np.abs(whole).max()))


def test_dof_refuses_padded_planes_past_a_thin_frames_budget(rt, monkeypatch):
    """dof on a 65535x1 frame asked for one 28 GiB buffer (the frame padded by the CoC reach
    above and below); only the device's per-buffer limit stopped it.  Mocked to no pool: a
    600x1 frame's padded planes are refused in one line, a 30x20 frame of as many pixels
    renders."""
    from clfx.core import limits

    monkeypatch.setattr(limits, "DERIVED_MIN_BYTES", 0)
    monkeypatch.setattr(rt.cache, "max_bytes", 0)
    p = E.params("dof", max_coc=0.25)

    import dataclasses

    near = dataclasses.replace(E.CAMERA, focal_length=50.0, focus_distance=0.5)

    def far(shape):                   # everything at infinity: CoC radii at max_coc
        return np.full(shape, np.inf, np.float32)

    with pytest.raises(ClfxError, match=r"dof: its \d+x\d+ padded planes .* would take .*"
                                        r"600x1 frame allows .*lower dof.max_coc") as info:
        E.apply(rt, "dof", E.scene((1, 600)), p, depth=far((1, 600)), camera=near)
    assert "\n" not in str(info.value)
    E.apply(rt, "dof", E.scene((20, 30)), p, depth=far((20, 30)), camera=near)
