"""Thin frames (issue 34): light-spreading effects size their PSFs from the frame's diagonal,
so a 65535x1 frame asked for a 19661^2 PSF (8-21 GB, minutes, SIGTERM unanswered).  The FFT
family keeps only the PSF rows that can carry light into the frame, and what would still
exceed the frame's memory budget is refused in one line before it is built."""
import numpy as np
import pytest

from clfx.core.errors import ClfxError
from clfx.core.rect import Rect
from clfx.fx import fftconv
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


@pytest.mark.parametrize("name", ["glare", "soft_focus"])
def test_a_psf_beyond_the_frames_budget_is_refused_before_it_is_built(rt, name):
    """65535x1: glare's 16385^2 PSF took > 8.3 GB (12 GiB asked)."""
    src = np.full((1, 65535, 4), 0.2, np.float32)
    src[0, ::1000, :3] = 500
    p = E.discover()[name].params()
    with pytest.raises(ClfxError, match=r"PSF .* would take .* GiB; the memory budget of a "
                                        r"65535x1 frame allows") as info:
        E.apply(rt, name, src, p)
    assert "\n" not in str(info.value)


def test_a_device_buffer_over_the_devices_limit_is_one_line(rt):
    """dof on a 65535x1 frame asked for one 8.9 GiB buffer: pyopencl's LogicError
    (INVALID_BUFFER_SIZE) traceback."""
    from clfx.core.errors import DeviceError

    most = min(d.max_mem_alloc_size for d in rt.ctx.devices)
    with pytest.raises(DeviceError, match=r"cannot allocate a device buffer of .* GiB"):
        rt.buffer(most + 16)
    rt.buffer(1024)                                   # the pool still serves
