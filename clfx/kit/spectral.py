"""A spectral effect rendered in the reference basis (linear Rec.709) whatever the working
space: corona, lens_flare and chromatic_aberration define their spectral model once
(`clfx.fx.spectral`), and this carries the frame into that basis and back.
"""
from __future__ import annotations

import numpy as np

from clfx.core import colour
from clfx.fx.spectral import rgb_matrix


def in_reference_basis(rt, ctx, render):
    """``render(ctx)`` (a spectral effect's device render, returning an RGBA image) in the
    reference basis, linear Rec.709, whatever the working space.

    Rec.709 (``ctx.rgb_to_xyz`` the default): ``render(ctx)``, pixels untouched.  Any other
    space: the source is carried into the reference basis by ``B = XYZ_TO_REC709 @
    ctx.rgb_to_xyz`` (a 3x3 per pixel on the device, alpha kept, negative components kept),
    rendered in a context whose matrix is Rec.709's (tables, luminance thresholds and the
    scene analysis of the converted pixels: the luminance row ``Y_709 B`` is the working
    space's own, to 1e-4), and the output carried back by ``B^-1``.  Every step of the effect,
    non-linear ones included (per-channel anti-ringing clamps, thresholds), then sees the same
    numbers as for the same light given in Rec.709.
    """
    b = colour.to_reference(ctx.rgb_to_xyz)
    if b is None:
        return render(ctx)
    ref = ctx.with_source(rgb_matrix(rt, ctx.source, b)).over(rgb_to_xyz=colour.REC709_TO_XYZ)
    return rgb_matrix(rt, render(ref), np.linalg.inv(b))
