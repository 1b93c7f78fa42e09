"""Unusual pixel values through every effect at every quality level.

- NaN, +Inf, -Inf, +-1e38 and 65504 (half's largest) in a few pixels give finite output
  everywhere: non-finite input is sanitised, finite input never overflows.
- Non-finite values count as 0 (in their channel or over their whole pixel): they change
  nothing beyond what a 0 there would (they do not spread).
- Alpha 0 (transparent holes, emission without coverage) and fractional alpha render finite,
  and alpha stays within the input's range.
- A non-finite alpha leaves colour finite, and is either kept bit for bit (effects that keep
  alpha) or sanitised.
"""
import numpy as np
import pytest

from tests.contract import effects as E
from tests.contract.known import param


def where(bad: np.ndarray) -> str:
    """How many pixels of an (h, w[, c]) mask are set, and the first few (y, x)."""
    bad = bad.any(axis=2) if bad.ndim == 3 else bad
    pts = ", ".join(str(tuple(int(i) for i in p)) for p in np.argwhere(bad)[:6])
    return f"{int(bad.sum())} pixels, e.g. (y, x) {pts}"


def assert_finite(out: np.ndarray, what: str):
    bad = ~np.isfinite(out)
    if bad.any():
        pytest.fail(f"{what}: non-finite output at {where(bad)}")


@pytest.mark.parametrize("name,quality,value", [
    param("test_unusual_values_give_finite_output", n, q, v, id=f"{n}-{q}-{v}")
    for n in E.EFFECTS for q in E.QUALITIES for v in E.HARD_VALUES])
def test_unusual_values_give_finite_output(rt, name, quality, value):
    src = E.with_value(E.HARD_VALUES[value])
    out = E.apply(rt, name, src, quality=quality)
    assert out.shape == src.shape
    assert_finite(out, f"{name} ({quality}) with {value} pixels")


@pytest.mark.parametrize("name,quality", [
    param("test_nonfinite_values_count_as_zero", n, q, id=f"{n}-{q}")
    for n in E.EFFECTS for q in E.QUALITIES])
def test_nonfinite_values_count_as_zero(rt, name, quality):
    src = E.with_value(E.NONFINITE)
    out = E.apply(rt, name, src, quality=quality)
    assert_finite(out, f"{name} ({quality}) with NaN and Inf pixels")
    channel = np.where(np.isfinite(src), src, np.float32(0))
    pixel = np.where(np.isfinite(src).all(axis=2, keepdims=True), src, np.float32(0))
    # the same arithmetic on the same finite values: equal up to float32 rounding
    close = [np.isclose(out, E.apply(rt, name, zeroed, quality=quality), rtol=1e-5, atol=1e-6)
             for zeroed in (channel, pixel)]
    assert any(c.all() for c in close), (
        f"{name} ({quality}): NaN/Inf pixels change the output unlike a 0 in their channel "
        f"({where(~close[0])}) or pixel ({where(~close[1])})")


@pytest.mark.parametrize("name,quality", [
    param("test_alpha_zero_and_fractional", n, q, id=f"{n}-{q}")
    for n in E.EFFECTS for q in E.QUALITIES])
def test_alpha_zero_and_fractional(rt, name, quality):
    for label, src in (("holes", E.transparent_scene()),
                       ("all alpha 0", E.scene() * np.float32([1, 1, 1, 0]))):
        out = E.apply(rt, name, src, quality=quality)
        assert out.shape == src.shape
        assert_finite(out, f"{name} ({quality}), {label}")
        lo, hi = src[..., 3].min(), src[..., 3].max()
        # kept, or filtered (resampled, blurred): within the input's range up to rounding
        assert lo - 1e-4 <= out[..., 3].min() and out[..., 3].max() <= hi + 1e-4, \
            f"{name} ({quality}), {label}: alpha leaves [{lo}, {hi}]"


@pytest.mark.parametrize("name", [
    param("test_nonfinite_alpha_is_sanitised_or_kept", n, id=n) for n in E.EFFECTS])
def test_nonfinite_alpha_is_sanitised_or_kept(rt, name):
    src = E.with_value(E.NONFINITE, alpha=True)
    odd = ~np.isfinite(src[..., 3])
    for quality in E.QUALITIES:
        out = E.apply(rt, name, src, quality=quality)
        assert_finite(out[..., :3], f"{name} ({quality}) with NaN and Inf (in alpha too)")
        alpha = out[..., 3]
        assert_finite(np.where(odd, 0, alpha), f"{name} ({quality}): alpha off the odd pixels")
        # effects that keep alpha keep it bit for bit (grain, sensor_noise); others sanitise
        kept = alpha[odd].tobytes() == src[..., 3][odd].tobytes()
        assert kept or np.isfinite(alpha[odd]).all(), \
            f"{name} ({quality}): a non-finite alpha neither kept nor sanitised"


PASS_VALUES = {"depth": (np.nan, np.inf, -np.inf, 0.0, -3.0, 1e38, 1e-30),
               "velocity": (np.nan, np.inf, -np.inf, 1e38, -1e38, 65504.0)}
"""Unusual pass values: depth's invalid ones (NaN, 0, negative) and extremes; velocity's."""

PASS_EFFECTS = [n for n in E.EFFECTS if E.clip_names(n)]


@pytest.mark.parametrize("name,quality", [
    param("test_unusual_pass_values_give_finite_output", n, q, id=f"{n}-{q}")
    for n in PASS_EFFECTS for q in E.QUALITIES])
def test_unusual_pass_values_give_finite_output(rt, name, quality):
    src = E.scene()
    passes = E.passes(name, src.shape[:2])
    for clip, values in PASS_VALUES.items():
        if clip in passes:
            flat = passes[clip].reshape(-1, *passes[clip].shape[2:])
            flat[:: 97][: len(values)] = np.asarray(values, np.float32).reshape(
                -1, *(1,) * (flat.ndim - 1))
    out = E.apply(rt, name, src, quality=quality, **passes)
    assert_finite(out, f"{name} ({quality}) with NaN, Inf, 0 and huge pass values")
