"""Deterministic noise seeds and alpha coverage shared by the noise effects (``grain``,
``sensor_noise``).

Every random number on the device is a hash of (seed, frame, pixel, channel stream)
(``clfx_uniform`` in kernels/lib/common.h, ``clfx_uniform16`` / ``clfx_hash_xy16`` in
kernels/lib/fastmath.h), so a frame rendered alone, in a batch, cropped or on any thread
count gives the same bytes.  The host only derives the kernel's 32-bit seed: from the
effect's ``seed`` parameter, the look's seed and a salt naming the noise stream, so two
effects (or two streams of one effect) with equal seeds stay uncorrelated.

Coverage: on a CG element with a tight data window and an empty, alpha-0 background
(OpenEXR's Beachball) noise over the whole data window draws a visible rectangle around the
element, and the comp adds it on top of the plate's own noise.  Both effects take
``coverage`` (:data:`COVERAGE_PARAM`), resolve it per frame with
`clfx.kit.noise.alpha_is_coverage` and weight their deviation by alpha on the device
(kernels/lib/coverage.h).
"""
from __future__ import annotations

from clfx.core.plugin import ChoiceParam, IntParam

SEED_PARAM = IntParam("seed", 0, min=0, max=2 ** 31 - 1,
                      hint="Noise seed, combined with the look's seed.")
"""The ``seed`` parameter of every noise effect (combined with the look's by
:func:`effect_seed`)."""


def lowbias32(x: int) -> int:
    """The 32-bit integer hash of kernels/lib/common.h (``clfx_hash``), on a Python int."""
    x &= 0xFFFFFFFF
    x ^= x >> 16
    x = (x * 0x7FEB352D) & 0xFFFFFFFF
    x ^= x >> 15
    x = (x * 0x846CA68B) & 0xFFFFFFFF
    x ^= x >> 16
    return x


def effect_seed(param_seed: int, look_seed: int, salt: int) -> int:
    """The kernel's 32-bit seed from the effect's ``seed`` param, the look's seed and a salt
    naming the noise stream (different effects with equal seeds stay uncorrelated)."""
    return lowbias32((param_seed & 0xFFFFFFFF) ^ lowbias32((look_seed & 0xFFFFFFFF) ^ salt))


COVERAGE_PARAM = ChoiceParam(
    "coverage", "auto", choices=("auto", "alpha", "ignore"),
    hint="alpha: the noise weighted by the pixel's alpha, so the transparent part of a CG "
         "element stays empty (no noise rectangle over the data window; the plate it is "
         "comped over has its own noise); ignore: noise over every pixel of the data window; "
         "auto: alpha when no pixel with alpha 0 holds light (premultiplied, empty "
         "background), else ignore (a matte in a photograph's alpha).")
"""The ``coverage`` parameter of every noise effect (resolved by
`clfx.kit.noise.alpha_is_coverage`; applied on the device by ``clfx_cover16`` /
``clfx_cover4`` in kernels/lib/coverage.h)."""
