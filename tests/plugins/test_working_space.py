"""Spectral effects in another working space (issue 13): the same scene rendered in linear
Rec.709 and in ACEScg gives the same chromatic aberration, corona and lens flare once the
ACEScg result is converted back to Rec.709, to float32 precision.

Each spectral effect's model is defined once, in linear Rec.709 (the reference basis); in
another working space the frame is carried into it by ``B = XYZ_TO_REC709 @ ctx.rgb_to_xyz``
and back by ``B^-1`` (``clfx.kit.spectral.in_reference_basis``).  Every step, the non-linear
ones included (per-channel anti-ringing clamps, luminance thresholds), then sees the numbers
it sees for the same light given in Rec.709, negative components (ACEScg colours outside
Rec.709) included.  What is left is float32 rounding: the test's two conversions and the
effect's two, a few ulps of each pixel's largest channel (4e-3 beside a 2e4 light), plus the
effect's own float32 sums.

Tolerance: per pixel, the difference minus ``ROUNDING`` ulps of the pixel's largest value
(``excess``) stays below 1e-4 of the largest change, and its L1 per channel below 1e-4 of
the change's L1.  Measured (printed with -s): corona L1 <= 2.4e-9, 1.9e-8 per pixel (2.2e-7
before the allowance); chromatic aberration 0 (2e-6 before it); lens flare, physical model,
L1 <= 1.4e-6 and 2.3e-5 per pixel (its float32 ghost sums; 1.8e-2 before the allowance, all
of it at the 2e4 light's 9 pixels).  The
previous approach (tables from each space's primaries, negative lobes clipped per space) was
1.4 / 0.2 / 0.2 % (corona), 45 / 18 / 16 % (CA) and 2.1 / 17 / 8.5 % (flare) L1 per channel.
"""
import numpy as np
import pytest

import clfx
from clfx.io import colour
from tests.effects import render_effect

H, W = 96, 128


def scene():
    """HDR lights (white, orange, blue) on a dim gradient, linear Rec.709."""
    src = np.full((H, W, 4), 0.02, np.float32)
    src[..., 3] = 1.0
    yy, xx = np.mgrid[0:H, 0:W]
    src[..., 0] += 0.02 * xx / W
    src[..., 2] += 0.02 * yy / H
    src[29:32, 39:42, :3] = 2e4
    src[60:62, 90:92, :3] = (400.0, 150.0, 30.0)
    src[20, 100, :3] = (20.0, 60.0, 300.0)
    return src


def to_acescg(rgba):
    return colour.convert(rgba, colour.resolve("lin_rec709"), colour.resolve("ACEScg"), None)


def to_rec709(rgba):
    back = colour.convert(rgba, colour.resolve("ACEScg"), colour.resolve("lin_rec709"), None)
    return back.astype(np.float64)


ROUNDING = 8      # float32 ulps of a pixel's largest channel: four 3x3 products on it


def differences(effect, params, working_space):
    """(L1 per channel, per-pixel bound) of the ACEScg render (converted back) against the
    Rec.709 render, after the float32 rounding allowance, relative to the Rec.709 render's
    change; and the raw per-pixel bound."""
    look = {"effects": [{"effect": effect, "params": params}]}
    src = scene()
    ref = clfx.render_array(src, look).rgba.astype(np.float64)
    cg = clfx.render_array(to_acescg(src), look, working_space=working_space).rgba
    back = to_rec709(cg)
    d709 = ref[..., :3] - src[..., :3]
    err = np.abs(back[..., :3] - ref[..., :3])
    ulp = np.finfo(np.float32).eps * np.abs(ref[..., :3]).max(axis=-1, keepdims=True)
    excess = np.maximum(err - ROUNDING * ulp, 0.0)
    l1 = excess.sum(axis=(0, 1)) / np.abs(d709).sum(axis=(0, 1))
    return l1, excess.max() / np.abs(d709).max(), err.max() / np.abs(d709).max()


CASES = {
    "corona": ("corona", {"threshold": 2.0, "intensity": 0.5, "size": 0.05, "extent": 4.0}),
    "chromatic_aberration": ("chromatic_aberration", {"amount": 0.01}),
    "lens_flare": ("lens_flare", {"threshold": 5.0}),      # the physical model
}
TOL = 1e-4


@pytest.mark.parametrize("case", CASES)
def test_acescg_and_rec709_agree_once_converted(rt, case):
    effect, params = CASES[case]
    l1, px, raw = differences(effect, params, "ACEScg")
    print(f"{effect}: relative L1 per channel {l1}, per pixel {px:.3g} (before the rounding "
          f"allowance {raw:.3g})")
    assert (l1 < TOL).all() and px < TOL, (l1, px)
    # the effect on ACEScg pixels as if they were Rec.709 (no conversion) is far off: the
    # conversion is what makes them agree
    wrong_l1, wrong_px, _ = differences(effect, params, "lin_rec709")
    print(f"{effect} without the conversion: {np.round(wrong_l1, 4)}, {wrong_px:.4f}")
    assert wrong_l1.max() > 100 * TOL and wrong_px > 100 * TOL


def test_matrices_as_data():
    from clfx.core import colour as primaries

    # Rec.709 (None, the constant, or OCIO's lin_rec709 through the pipeline) keeps the
    # classic constants, so Rec.709 renders keep their pixels
    for m in (None, primaries.REC709_TO_XYZ, colour.working_rgb_to_xyz("lin_rec709"),
              colour.working_rgb_to_xyz("linear"), colour.working_rgb_to_xyz(None)):
        assert primaries.is_rec709(m) and primaries.luminance_defines(m) == {}
        np.testing.assert_array_equal(primaries.luminance_weights(m), [0.2126, 0.7152, 0.0722])
        np.testing.assert_array_equal(primaries.xyz_to_rgb(m), primaries.XYZ_TO_REC709)
    aces = colour.working_rgb_to_xyz("ACEScg")
    np.testing.assert_array_equal(aces, colour.rgb_to_xyz("ACEScg"))
    np.testing.assert_allclose(primaries.luminance_weights(aces), [0.2677, 0.6743, 0.0580],
                               atol=1e-4)
    assert primaries.luminance_defines(aces)["CLFX_LUMA_R"].startswith("0.2676")
    assert primaries.matrix_key(aces) != primaries.matrix_key(None) == ()
    for bad in (np.eye(2), np.full((3, 3), np.nan), np.zeros((3, 3)), -np.eye(3)):
        with pytest.raises(ValueError, match="rgb_to_xyz"):
            primaries.rgb_to_xyz_matrix(bad)
    from clfx.core.errors import ParamError

    with pytest.raises(ParamError, match="must be a linear"):
        clfx.render_array(np.zeros((4, 4, 4), np.float32), {"effects": []}, working_space="sRGB")


@pytest.mark.parametrize("effect", ["glare", "streaks", "halation"])
def test_thresholds_weigh_the_working_space_luminance(rt, effect):
    """A blue light of luminance 2.17 in Rec.709 is 1.74 in ACEScg: above a threshold of 2
    in one, below it in the other (kernels get the Y row as build defines)."""
    from clfx.plugins import get_plugin

    plugin = get_plugin(effect)()
    src = np.full((32, 32, 4), 0.01, np.float32)
    src[..., 3] = 1.0
    src[14:17, 14:17, :3] = (0.0, 0.0, 30.0)
    knee = {"knee": 0.0} if any(q.name == "knee" for q in plugin.descriptor.params) else {}
    p = plugin.params(threshold=2.0, **knee)
    aces = colour.rgb_to_xyz("ACEScg")
    rec709 = render_effect(rt, plugin, p, src)
    acescg = render_effect(rt, plugin, p, src, working_space="ACEScg")
    assert np.abs(rec709 - src).max() > 1e-4
    np.testing.assert_array_equal(acescg, src)
