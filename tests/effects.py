"""One effect on host arrays through the production render path: a one-step look rendered
by `clfx.pipeline.look.render_frame`, as ``clfx render`` and `clfx.api.render_array` run it
(upload with NaN/Inf sanitised, pass checks, ``is_identity``, the step's plan, the grown
window checked against the pixel limit, `render_tiled` when a tile size is given, masks,
the crop to the output limit, download).  Effect tests render through this, never by
calling a plugin's ``render`` on a context they built, so what they check is what users get.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from clfx.core.camera import Camera
from clfx.core.frame import Frame, crop_to
from clfx.core.rect import Rect
from clfx.pipeline.animation import Animated
from clfx.pipeline.look import Look, Step, render_frame


@dataclass(frozen=True)
class _Lenses:
    """A look's lens data read through ``read`` (`clfx.io.lenses.Lenses`' one method)."""

    read: object


def _look(plugin, p, quality, camera, reference_camera, seed, read_lens, mask) -> Look:
    """A one-step look; a ``camera`` that differs from ``reference_camera`` (the shot's
    first keys) is keyframed to it, as a look file would animate it."""
    reference = reference_camera or camera or Camera()
    moved = ()
    if camera is not None and camera != reference:
        first = reference.as_dict()
        moved = tuple((k, Animated(((0, v),))) for k, v in camera.as_dict().items()
                      if first.get(k) != v)
    step = Step(plugin.descriptor.name, p, quality=quality, plugin=plugin, mask=mask)
    return Look("test", camera=reference, camera_animated=moved, steps=[step], seed=seed,
                lenses=None if read_lens is None else _Lenses(read_lens))


def render_effect(rt, plugin, p, source, *, depth=None, velocity=None, velocity_back=None,
                  quality: str = "final", frame: int = 0, seed: int = 0,
                  camera: Camera | None = None, reference_camera: Camera | None = None,
                  data_window: Rect | None = None, display_window: Rect | None = None,
                  pixel_aspect: float = 1.0, display_referred: bool = False,
                  read_lens=None, working_space: str | None = None,
                  tile_pixels: int | None = None, mask=None, masks=None,
                  keep_rod: bool = False, report: list | None = None):
    """``plugin`` with params ``p`` over ``source`` (RGBA, or a grey (h, w) given alpha 1,
    covering ``data_window``, default at the origin) through `render_frame`.

    ``camera``: this frame's camera; ``reference_camera``: the shot's first keys (default
    ``camera``: nothing animated).  ``read_lens``: the look's lens reader (default the
    pipeline's, `clfx.io.lenses.read_lens`).  ``working_space``: the OCIO space ``source``
    is in (default linear Rec.709).  ``tile_pixels``: render a tiling effect in bands of
    at most this many pixels (default ``CLFX_TILE_PIXELS``, unset: whole).  ``mask``: a
    `clfx.pipeline.masks.MaskSpec` on the step, with ``masks`` its arrays.  ``report``: a
    list the frame's `FrameReport` is appended to (its warnings and notes).

    Returns the output cropped to the data window, or ``(array, window)`` with
    ``keep_rod=True``: the window the effect grew the frame to, within the display and
    data windows.
    """
    src = np.asarray(source, np.float32)
    if src.ndim == 2:
        src = np.stack([src, src, src, np.ones_like(src)], axis=2)
    window = data_window or Rect.from_size(src.shape[1], src.shape[0])

    def host(a):
        return None if a is None else np.asarray(a, np.float32)

    look = _look(plugin, p, quality, camera, reference_camera, seed, read_lens, mask)
    plate = Frame(src, window, display_window or window, pixel_aspect=pixel_aspect,
                  depth=host(depth), velocity=host(velocity), velocity_back=host(velocity_back),
                  encoding="sRGB" if display_referred else "linear",
                  colorspace=working_space or "lin_rec709")
    out, frame_report = render_frame(rt, look, plate, frame_number=frame, quality=quality,
                                     masks=masks, tile_pixels=tile_pixels)
    if report is not None:
        report.append(frame_report)
    if keep_rod:
        return out.rgba, out.data_window
    return crop_to(out.rgba, out.data_window, window)
