"""A frame on the host: beauty RGBA plus optional depth and velocity passes, with its windows.

Conventions inside clfx (the I/O layer converts every renderer's convention to these):

- ``rgba``: float32 (h, w, 4), scene-linear RGB in the working space's primaries
  (``colorspace``; linear Rec.709 by default), premultiplied alpha as EXR stores it; covers
  ``data_window``.
- ``depth``: float32 (h, w), planar camera-space z in scene units (metres by default);
  background / no hit = +inf.  NaN, 0 and negatives are invalid and sanitised by effects.
- ``velocity``: float32 (h, w, 2), forward screen-space displacement in pixels per frame
  (where the point will be one frame later minus where it is now), +x right, +y down.
- ``data_window`` and ``display_window`` are OpenImageIO rectangles (see ``clfx.core.rect``);
  overscan (data larger than display) carries light from outside the frame.
- ``pixel_aspect``: width / height of one pixel (EXR ``pixelAspectRatio``).
- ``encoding``: ``"linear"`` for scene-linear files (EXR, HDR, float TIFF) or ``"sRGB"`` for
  display-referred 8/16-bit files that were linearised on read and are encoded back on write.
- ``colorspace``: the OCIO name of the space ``rgba`` is in, the *working space* (default
  scene-linear Rec.709, ``"lin_rec709"``; ``clfx.io.colour.rgb_to_xyz(frame.colorspace)`` gives
  its RGB -> XYZ matrix, which the pipeline hands to effects as ``ctx.rgb_to_xyz``); ``source_colorspace``: the space the file stored (outputs are
  written back in it unless told otherwise), None when unknown or raw.
- ``layout``: the parts and channels of the file the frame was read from, so that outputs
  keep every channel the effects do not change (``clfx.io.write``); None for frames made in
  memory.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from clfx.core.rect import Rect


@dataclass(frozen=True)
class SourcePart:
    """One part (subimage) of the file a frame was read from: what to write back."""

    index: int                       # subimage index in the source file
    name: str                        # part name ("" for single-part files)
    view: str | None                 # the part's ``view`` attribute
    channels: tuple[str, ...]        # every channel, file order
    formats: tuple[str, ...]         # per channel, as OpenImageIO names it: half, float, uint
    data_window: Rect
    attributes: dict = field(default_factory=dict, compare=False)   # header, plain values


@dataclass(frozen=True)
class Layout:
    """Where a frame's beauty came from: the source file's parts, and which channels of which
    part hold the beauty (the channels an output replaces; everything else is copied)."""

    path: str
    parts: tuple[SourcePart, ...]
    beauty_part: int                 # index into ``parts``
    beauty: tuple[str, ...]          # channel names as stored: R, G, B[, A] (or one grey)
    view: str | None = None          # the beauty's view (multi-view files)
    # channels already decoded by the reader, as stored (float32), by part index: the writer
    # copies these instead of decoding the file again (frames up to 4K UHD only:
    # clfx.io.read.KEEP_MAX_PIXELS)
    stored: dict = field(default_factory=dict, compare=False, repr=False)


@dataclass
class Frame:
    rgba: np.ndarray
    data_window: Rect
    display_window: Rect
    pixel_aspect: float = 1.0
    depth: np.ndarray | None = None
    velocity: np.ndarray | None = None
    metadata: dict = field(default_factory=dict)
    encoding: str = "linear"
    source: str = ""
    bit_depth: str = "half"
    colorspace: str = "lin_rec709"
    source_colorspace: str | None = None
    layout: Layout | None = None
    velocity_back: np.ndarray | None = None
    """The other half of the vector pass where the renderer writes both (Blender's Vector
    XY beside ZW): backward motion, current - previous position, px/frame, +y down."""
    channels: int | None = None
    """Beauty channels of a source without a file layout (a raw stream: 3 RGB, 4 RGBA), what
    an output of it holds; None: the layout's beauty, else RGBA."""

    def __post_init__(self):
        h, w = self.data_window.shape
        if self.rgba.shape != (h, w, 4):
            raise ValueError(f"rgba shape {self.rgba.shape} does not match data window {self.data_window}")
        if self.depth is not None and self.depth.shape != (h, w):
            raise ValueError(f"depth shape {self.depth.shape} does not match data window {self.data_window}")
        if self.velocity is not None and self.velocity.shape != (h, w, 2):
            raise ValueError(f"velocity shape {self.velocity.shape} does not match data window {self.data_window}")
        if self.velocity_back is not None and self.velocity_back.shape != (h, w, 2):
            raise ValueError(f"velocity_back shape {self.velocity_back.shape} does not match "
                             f"data window {self.data_window}")

    @property
    def display_referred(self) -> bool:
        return self.encoding.lower() != "linear"

    def with_rgba(self, rgba: np.ndarray, data_window: Rect | None = None) -> "Frame":
        """A copy with new beauty pixels (passes dropped if the window changes)."""
        window = data_window or self.data_window
        same = window == self.data_window
        return replace(self, rgba=rgba, data_window=window,
                       depth=self.depth if same else None,
                       velocity=self.velocity if same else None,
                       velocity_back=self.velocity_back if same else None,
                       metadata=dict(self.metadata))

    @classmethod
    def from_array(cls, rgba: np.ndarray, *, depth=None, velocity=None,
                   pixel_aspect: float = 1.0, encoding: str = "linear") -> "Frame":
        """A frame whose data and display windows are both (0, 0)-(w, h)."""
        rgba = np.asarray(rgba, np.float32)
        if rgba.ndim == 2:
            rgba = np.repeat(rgba[..., None], 4, axis=2)
            rgba[..., 3] = 1.0
        if rgba.shape[2] == 3:
            rgba = np.concatenate([rgba, np.ones(rgba.shape[:2] + (1,), np.float32)], axis=2)
        h, w = rgba.shape[:2]
        win = Rect.from_size(w, h)
        return cls(np.ascontiguousarray(rgba), win, win, pixel_aspect,
                   None if depth is None else np.asarray(depth, np.float32),
                   None if velocity is None else np.asarray(velocity, np.float32),
                   encoding=encoding)


def crop_to(array: np.ndarray, window: Rect, target: Rect, fill: float = 0.0) -> np.ndarray:
    """``array`` (covering ``window``) cut or padded with ``fill`` to cover ``target``."""
    if window == target:
        return array
    shape = (target.height, target.width) + array.shape[2:]
    out = np.full(shape, fill, array.dtype)
    common = window.intersect(target)
    if not common.empty:
        sx, sy = common.offset_in(window)
        tx, ty = common.offset_in(target)
        out[ty:ty + common.height, tx:tx + common.width] = \
            array[sy:sy + common.height, sx:sx + common.width]
    return out
