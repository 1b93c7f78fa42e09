"""The unusual-value images of ``openexr-images/TestImages`` as small frames.

The images are the ones its README lists (``Name.exr`` entries), read by
``clfx.io.read.read_frame``.  ``AllHalfValues`` is used whole (every half value, 256 x 256);
every other image twice: a 64 x 64 crop around its most unusual pixels (the non-finite ones,
else the largest magnitude) and a 64 x 64 nearest-neighbour sample of the whole frame (its
full value range at a bounded cost).
"""
from __future__ import annotations

import functools
import os
import re

import numpy as np

from tests.conftest import EXR_IMAGES, ROOT


def _folder():
    """``$CLFX_SHARED_DATA``'s or ``../shared/data``'s TestImages; from a worktree nested one
    folder deeper (``wt/NAME``), the nearest ancestor's ``shared/data``."""
    candidates = [EXR_IMAGES] + [up / "shared" / "data" / "openexr-images"
                                 for up in ROOT.parents[1:]]
    if "CLFX_SHARED_DATA" in os.environ:
        candidates = candidates[:1]
    return next((c / "TestImages" for c in candidates if (c / "TestImages").is_dir()),
                EXR_IMAGES / "TestImages")


FOLDER = _folder()
SIDE = 64
WHOLE = ("AllHalfValues",)


def names() -> list[str]:
    """Image names (no extension) the folder's README lists, else every EXR in it."""
    readme = FOLDER / "README.rst"
    listed = re.findall(r"``(\w+)\.exr``", readme.read_text()) if readme.is_file() else []
    found = sorted(p.stem for p in FOLDER.glob("*.exr"))
    return [n for n in dict.fromkeys(listed) if n in found] or found


def variants() -> list[str]:
    """Input ids: ``Name`` (whole), ``Name[crop]``, ``Name[sample]``; [] without the folder."""
    if not FOLDER.is_dir():
        return []
    return [v for n in names()
            for v in ([n] if n in WHOLE else [f"{n}[crop]", f"{n}[sample]"])]


@functools.cache
def _read(name: str) -> np.ndarray:
    from clfx.io.read import read_frame

    return read_frame(FOLDER / f"{name}.exr").rgba


def _nearest(n: int) -> np.ndarray:
    return np.linspace(0, n - 1, SIDE).round().astype(int)


def image(variant: str) -> np.ndarray:
    """The float32 RGBA pixels of one input id (a copy)."""
    name, _, kind = variant.partition("[")
    rgba = _read(name)
    h, w = rgba.shape[:2]
    if not kind:
        return rgba.copy()
    if kind == "sample]":
        return np.ascontiguousarray(rgba[_nearest(h)][:, _nearest(w)])
    odd = ~np.isfinite(rgba).all(axis=2)
    if odd.any():
        cy, cx = np.argwhere(odd).mean(axis=0).astype(int)
    else:
        mag = np.abs(rgba[..., :3]).max(axis=2)
        cy, cx = np.unravel_index(mag.argmax(), mag.shape)
    y0 = int(np.clip(cy - SIDE // 2, 0, max(h - SIDE, 0)))
    x0 = int(np.clip(cx - SIDE // 2, 0, max(w - SIDE, 0)))
    return np.ascontiguousarray(rgba[y0:y0 + SIDE, x0:x0 + SIDE])
