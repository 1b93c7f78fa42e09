"""Warps fill to the frame's edge (issue 32): no border row or column darker than the
interior, at each warp's defaults and through the cinema look.

Before the fix, distortion read points past the plate as transparent black by default
(``border: black``, ``fit: none``): cinema's k1 = -0.02 barrel left column 0 of CandleGlass
at ~0 and column 1 at 44 % of the interior (a 1-2 px black frame, failing delivery QC)."""
import numpy as np
import pytest

import clfx
from clfx.core.rect import Rect
from clfx.plugins import discover
from tests.contract.effects import CAMERA
from tests.effects import render_effect

GREY = 0.5
SHAPE = (36, 64)

WARPS = {
    # each warp at its defaults, plus what makes it move pixels past the frame's edge
    "distortion barrel": ("distortion", {"k1": -2.0}),
    "distortion amount": ("distortion", {"amount": -0.2}),
    "distortion pincushion": ("distortion", {"k1": 0.1}),
    "distortion tangential": ("distortion", {"k1": -1.0, "p1": 0.01}),
    "chromatic_aberration +": ("chromatic_aberration", {"amount": 0.01, "spectral": False}),
    "chromatic_aberration -": ("chromatic_aberration", {"amount": -0.01, "spectral": False}),
    "lens": ("lens", {"maker": "Canon", "model": "Canon EF 24-70mm f/2.8L II USM",
                      "vignetting": False}),
    "breathing widens": ("breathing", {"amount": 1.0, "reference_focus": 0.5}),
}


def flat(shape=SHAPE):
    src = np.full(shape + (4,), GREY, np.float32)
    src[..., 3] = 1.0
    return src


def borders(img, n=3):
    """The first and last ``n`` rows and columns (mean RGB of each): 4n values."""
    lum = img[..., :3].mean(axis=-1)
    return np.concatenate([lum[:n].mean(1), lum[-n:].mean(1), lum[:, :n].mean(0),
                           lum[:, -n:].mean(0)])


@pytest.mark.parametrize("case", sorted(WARPS))
def test_warp_of_a_flat_plate_keeps_its_border(rt, case):
    name, settings = WARPS[case]
    cls = discover()[name]
    # the camera's focus at 2 m: breathing from a reference of 0.5 m widens the frame 5.6 %
    got = render_effect(rt, cls(), cls.params(**settings), flat(), camera=CAMERA)
    assert got.shape == SHAPE + (4,)
    # interpolating filters on a constant plate: the constant wherever the plate is read
    np.testing.assert_allclose(borders(got), GREY, rtol=2e-3)
    np.testing.assert_allclose(got[..., 3], 1.0, atol=2e-3)


def test_explicit_black_border_still_darkens(rt):
    # the old behaviour stays available when asked for (outside the frame is transparent)
    cls = discover()["distortion"]
    got = render_effect(rt, cls(), cls.params(k1=-2.0, fit="none", border="black"), flat(),
                        camera=CAMERA)
    assert borders(got).min() < 0.9 * GREY


def test_cinema_look_has_no_dark_border(rt):
    look = clfx.load_look("cinema", set=["grain.amount=0"])
    got = clfx.render_array(flat((54, 96)), look).rgba
    lum = got[..., :3].mean(axis=-1)
    # the vignette darkens towards the edges, smoothly: each border's profile (the mean of
    # each of the outer rows / columns) stays within 1 % of the line through the next two in
    # (the black rim was -50 % and more)
    for profile in (lum[:5].mean(1), lum[::-1][:5].mean(1), lum[:, :5].mean(0),
                    lum[:, ::-1][:, :5].mean(0)):
        for k in (2, 1, 0):
            line = 2 * profile[k + 1] - profile[k + 2]
            assert profile[k] > 0.99 * line, (k, profile)


def test_crop_uses_the_plates_overscan_before_scaling(rt):
    from clfx.plugins.distortion import build_map

    cls = discover()["distortion"]
    display = Rect(0, 0, 64, 36)
    p = cls.params(k1=-2.0)
    # no overscan: scaled up just enough that the display window reads inside the plate
    sx, sy, info = build_map(p, CAMERA, display, display, 1.0)
    assert info["fit_scale"] < 1.0
    assert sx.min() >= 0.0 and sx.max() <= 64.0 and sy.min() >= 0.0 and sy.max() <= 36.0
    assert min(sx.min(), sy.min(), 64 - sx.max(), 36 - sy.max()) < 0.6   # no more than that
    # 8 px of overscan cover the barrel's reach: nothing is scaled
    _, _, info = build_map(p, CAMERA, display, display.grown(8), 1.0)
    assert info["fit_scale"] == 1.0
    # a pincushion reads inside the plate anyway
    _, _, info = build_map(cls.params(k1=0.1), CAMERA, display, display, 1.0)
    assert info["fit_scale"] == 1.0


def test_lens_crop_scales_a_barrel_lens_and_uses_overscan(rt):
    from clfx.fx import lensdb
    from clfx.plugins.lens import simulation_geometry

    w, h = 120, 80
    lens = lensdb.get_lens("Canon", "Canon EF 24-70mm f/2.8L II USM", 1.0)
    cal = lensdb.calibration(lens, 24.0, 2.8, 1000.0)       # a barrel at 24 mm
    norm = lensdb.Normalisation.for_image(cal, 1.0, w, h)
    win = Rect(0, 0, w, h)
    gx, gy, info = simulation_geometry(cal, norm, win, win, "crop", plate=win)
    assert info["fit_scale"] < 1.0
    assert gx.min() >= -1e-3 and gx.max() <= w + 1e-3 and gy.min() >= -1e-3 and gy.max() <= h + 1e-3
    _, _, info = simulation_geometry(cal, norm, win, win, "crop", plate=win.grown(10))
    assert info["fit_scale"] == 1.0
