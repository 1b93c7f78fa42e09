"""The noise effects' per-frame questions: what grain and sensor_noise take as middle grey
(stated, or metered on the frame's analysis: `clfx.fx.analysis.meter`) and whether the
frame's alpha weights their noise (`clfx.fx.noise.COVERAGE_PARAM`).  Both add a note for
``--explain`` when they decide from the frame.
"""
from __future__ import annotations

import math

import numpy as np

from clfx.fx.analysis import EXPOSURE_MIN, MID_GREY, meter


def exposure_reference(p, ctx, effect: str) -> float:
    """The scene-linear value an exposure-relative effect (grain, sensor noise) takes as
    middle grey: its ``middle_grey`` param, or (0, "auto") `meter` on the frame's analysis
    (the whole frame's, in bands too); at least `EXPOSURE_MIN`.  Metered, a note for
    ``--explain`` says the value used, so a shot whose light changes can pin it
    (``middle_grey: <that value>``).

    Parameters
    ----------
    p : Params
        Has ``middle_grey``.
    ctx : RenderContext
        Its analysis is metered; its ``notes`` get the metered value.
    effect : str
        The effect's name, for the note.
    """
    if p.middle_grey > 0.0:
        return max(float(p.middle_grey), EXPOSURE_MIN)
    analysis = ctx.analysis
    grey = max(meter(analysis.mean_lum), EXPOSURE_MIN)
    lit = bool(np.any(np.asarray(analysis.mean_lum) > 0.0))
    ctx.notes.append(f"{effect}: middle grey metered at {grey:.4g} "
                     f"({math.log2(grey / MID_GREY):+.1f} stops from 0.18)" if lit else
                     f"{effect}: no light to meter: middle grey {MID_GREY}")
    return grey



def alpha_is_coverage(coverage: str, ctx, effect: str) -> bool:
    """A noise effect's ``coverage`` resolved for this frame.

    Parameters
    ----------
    coverage : {"auto", "alpha", "ignore"}
        The effect's ``coverage`` param.
    ctx : RenderContext
        "auto" reads ``ctx.alpha_is_coverage()`` (no light where alpha <= 0 in the frame's
        first scene analysis: the look's input where an earlier step read it) and, when that
        says no, adds a line to ``ctx.notes``.
    effect : str
        The effect's name, for that note.

    Returns
    -------
    bool
        True: the deviation is weighted by alpha clamped to [0, 1], ``out = v + alpha
        (noisy - v)`` (pixels with alpha >= 1 get the full deviation bit for bit).
    """
    if coverage != "auto":
        return coverage == "alpha"
    if ctx.alpha_is_coverage():
        return True
    ctx.notes.append(f"{effect}: light where alpha is 0 (a matte, not coverage): "
                     "noise over the whole data window")
    return False
