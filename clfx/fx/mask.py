"""Limiting an effect to a mask on the device (per-object effects; ``kernels/lib/mask.cl``).

A mask is a one-channel :class:`~clfx.device.runtime.DeviceImage` of coverage in [0, 1]
(uploaded once per frame by the look, feathered here).  Two ways to apply it:

``mix(rt, source, effect, mask)``
    ``source + mask * (effect - source)``: the effect's output where the mask is, the source
    elsewhere, blended by coverage (the compositor's "mask" input).
``multiply(rt, source, mask)`` then ``spread(rt, source, masked, effect)``
    For effects that spread light (glare, streaks, flares): the effect renders ``masked =
    source * mask`` (light sources from the masked region only) and the result is
    ``source + (effect(masked) - masked)``: what the effect did to the masked light (the
    light it spread, over the whole frame, and what it took away) added to the untouched
    source.

Images of different windows are first placed in the effect's window (zero outside), so an
effect that grew the frame keeps its light where the mask allows it.
"""
from __future__ import annotations

from clfx.fx.blur import gaussian_blur

KERNEL = "lib/mask.cl"


def feather(rt, mask, sigma_px: float):
    """``mask`` softened by a Gaussian of ``sigma_px`` pixels (edges clamped; a copy);
    ``mask`` itself below 0.3 px."""
    if sigma_px < 0.3:
        return mask
    return gaussian_blur(rt, mask, float(sigma_px), border="clamp")


def _run(rt, name: str, window, *images):
    """Run ``mask_<name>`` over ``window`` on ``images`` placed there (zero outside their
    own windows); returns the new RGBA image it wrote."""
    placed = [rt.reframe(img, window, "zero") for img in images]
    dst = rt.image(window, 4)
    rt.launch(rt.kernel(KERNEL, f"mask_{name}"), (dst.pitch, dst.height), *placed, dst, dst.pitch,
              dst.height)
    return dst


def mix(rt, source, effect, mask):
    """``source + mask * (effect - source)`` over ``effect.window`` (a new image)."""
    return _run(rt, "mix", effect.window, source, effect, mask)


def multiply(rt, source, mask):
    """``source * mask`` over ``source.window`` (a new image)."""
    return _run(rt, "multiply", source.window, source, mask)


def spread(rt, source, masked, effect):
    """``source + (effect - masked)`` over ``effect.window`` (a new image)."""
    return _run(rt, "spread", effect.window, source, masked, effect)
