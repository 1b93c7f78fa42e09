"""The plugin host (OpenFX's host side): the render context, the Plugin base class, the
registry decorator.

Effects subclass :class:`Plugin` (``clfx/plugins/<effect>.py``) and describe themselves
with ``clfx.core.plugin`` descriptors; the context gives them the frame on the device, its
passes, the camera and the shared scene analysis (``clfx.fx.analysis``), computed on first
use.  Files an effect reads (kernel images) come through ``ctx.read_image``, which the
pipeline supplies: effects never open files themselves.
"""
from __future__ import annotations

from typing import ClassVar

import numpy as np

from clfx.core import colour
from clfx.core.camera import Camera
from clfx.core.errors import ClipError, ParamError
from clfx.core.frame import crop_to
from clfx.core.plugin import DEFAULT_QUALITY, QUALITY_LEVELS, Descriptor, Level, Params
from clfx.core.rect import Rect
from clfx.fx.analysis import analyse


# -- render context ------------------------------------------------------------------------
class _SharedAnalysis:
    """The frame's scene analysis, shared by a look's context and every per-step context
    made from it (:meth:`RenderContext.for_step`), with the seconds spent computing it."""

    __slots__ = ("seconds", "value")

    def __init__(self, value=None):
        self.value = value
        self.seconds = 0.0


class RenderContext:
    """Everything an effect may read while rendering one frame.

    Attributes
    ----------
    runtime : Runtime
    source : DeviceImage
        The current RGBA image (the previous effect's output), scene-linear.
    depth, velocity : DeviceImage or None
        Passes in clfx's conventions (planar z in scene units; forward px/frame, +y down),
        covering ``source.window`` (the look re-frames them when an effect grows the window).
    velocity_back : DeviceImage or None
        The other half of the vector pass where the renderer writes both (Blender's XY):
        backward motion, current - previous position in px/frame, +y down.  The blurs of
        motion then follow the quadratic through the previous, current and next positions.
    display_window : Rect
        The frame's display window; resolution-independent sizes refer to its diagonal.
    pixel_aspect : float
        Pixel width / height.
    frame : int
        Frame number (drives noise; effects are deterministic per frame).
    seed : int
        The look's seed.
    camera : Camera
        The camera of this frame (keyframed values resolved at ``frame``).
    reference_camera : Camera
        The camera the shot is set up with: every keyframed camera value at its first key
        (``camera`` itself when nothing is keyframed).  Effects that respond to a change over
        the shot measure it from here (lens breathing: the focus pulled away from the first
        key's), so a static camera never changes anything.
    quality : str
        One of ``QUALITY_LEVELS``.
    display_referred : bool
        The input was an 8/16-bit display-referred file (linearised on read).
    read_image : callable(path) -> ndarray
        Reads a file a :class:`~clfx.core.plugin.PathParam` names (supplied by the pipeline).
    read_lens : callable(name) -> dict
        Reads a lens prescription by name (``presets/lenses/<name>.yaml``) or path, as the
        plain dict ``clfx.fx.optics.Prescription.from_dict`` takes (supplied by the pipeline).
    rgb_to_xyz : ndarray (3, 3), float64
        The working space's RGB -> CIE XYZ (D65) matrix, as data (the pipeline takes it from
        OCIO); default linear Rec.709 (`clfx.core.colour`).  Spectral effects build their
        wavelength -> RGB tables with it, thresholds weigh luminance with its Y row.
    """

    def __init__(self, runtime, source, *, depth=None, velocity=None, velocity_back=None,
                 display_window=None,
                 pixel_aspect=1.0, frame=0, seed=0, camera=None, quality=DEFAULT_QUALITY,
                 display_referred=False, analysis=None, output_limit=None, read_image=None,
                 read_lens=None, reference_camera=None, rgb_to_xyz=None):
        self.runtime = runtime
        self.source = source
        self.depth = depth
        self.velocity = velocity
        self.velocity_back = velocity_back
        self.display_window = display_window or source.window
        self.pixel_aspect = float(pixel_aspect)
        self.frame = int(frame)
        self.seed = int(seed)
        self.camera = camera or Camera()
        self.reference_camera = reference_camera or self.camera
        self.quality = quality
        self.display_referred = display_referred
        self._analysis = _SharedAnalysis(analysis)
        self.output_limit = output_limit or source.window.union(self.display_window)
        self.notes: list[str] = []
        self.warnings: list[str] = []  # said on stderr: a clamp, a guess, a skipped request
        self._read_image = read_image
        self._read_lens = read_lens
        self.rgb_to_xyz = colour.rgb_to_xyz_matrix(rgb_to_xyz)
        self._handoff: dict = {}

    @property
    def luminance(self) -> np.ndarray:
        """Luminance weights of the working space's R, G, B (the Y row of ``rgb_to_xyz``;
        Rec.709: 0.2126, 0.7152, 0.0722)."""
        return colour.luminance_weights(self.rgb_to_xyz)

    @property
    def luminance_defines(self) -> dict:
        """Build defines giving kernels' ``clfx_luminance`` the working space's weights
        (none for Rec.709); pass them to ``rt.kernel`` wherever a kernel weighs luminance."""
        return colour.luminance_defines(self.rgb_to_xyz)

    @property
    def colour_key(self) -> tuple:
        """The working space's matrix as a cache key (() for Rec.709)."""
        return colour.matrix_key(self.rgb_to_xyz)

    def read_image(self, path: str) -> np.ndarray:
        """The RGB(A) pixels of an image file a parameter names (a :class:`PathParam`), read
        by the pipeline's reader (effects never open files)."""
        if self._read_image is None:
            raise ParamError(f"no image reader in this context to read {path!r} "
                             f"(pass read_image= to the render context)")
        return self._read_image(path)

    def read_lens(self, name: str) -> dict:
        """A lens prescription (a shipped name or a file) as a plain dict, read by the
        pipeline's reader (effects never open files or parse YAML)."""
        if self._read_lens is None:
            raise ParamError(f"no lens reader in this context to read {name!r} "
                             f"(pass read_lens= to the render context)")
        return self._read_lens(name)

    @property
    def analysis(self):
        """The frame's shared scene analysis of the current source: computed on first use,
        and again only if an effect has since changed the source's window (its tiles are
        always those of ``source.window``)."""
        shared = self._analysis
        if shared.value is None or shared.value.window != self.source.window:
            shared.value = analyse(self.runtime, self.source, depth=self.depth,
                                   velocity=self.velocity, camera=self.camera,
                                   display_window=self.display_window,
                                   luminance_defines=self.luminance_defines)
            shared.seconds += shared.value.seconds
        return shared.value

    @property
    def analysis_seconds(self) -> float:
        """Seconds spent computing this frame's analyses so far (this context and every
        per-step context made from it)."""
        return self._analysis.seconds

    @property
    def diagonal_px(self) -> float:
        return self.display_window.diagonal

    @property
    def width_px(self) -> int:
        return self.display_window.width

    def size_px(self, fraction_of_diagonal: float) -> float:
        """A resolution-independent size (fraction of the frame diagonal) in pixels."""
        return fraction_of_diagonal * self.diagonal_px

    def grown_to(self, window: Rect) -> RenderContext:
        """This context over a larger ``window`` (an effect whose light leaves the data
        window): the source padded with transparent black, depth and velocity extended from
        their edges; notes and the frame's analysis box shared (the analysis is recomputed
        for the new window on first use)."""
        ctx = RenderContext.__new__(RenderContext)
        ctx.__dict__.update(self.__dict__)
        rt = self.runtime
        ctx.source = rt.reframe(self.source, window, "zero")
        ctx.depth = None if self.depth is None else rt.reframe(self.depth, window, "clamp")
        ctx.velocity = None if self.velocity is None else rt.reframe(self.velocity, window, "clamp")
        ctx.velocity_back = (None if self.velocity_back is None
                             else rt.reframe(self.velocity_back, window, "clamp"))
        return ctx

    def for_step(self, quality: str) -> RenderContext:
        """A context for one effect of a look: this one at ``quality``, with its own
        ``notes`` and the same scene analysis (one the step computes is this frame's)."""
        ctx = RenderContext.__new__(RenderContext)
        ctx.__dict__.update(self.__dict__)  # shares the analysis
        ctx.quality = quality
        ctx.notes = []
        ctx.warnings = []
        ctx._handoff = {}
        return ctx

    def with_source(self, source) -> RenderContext:
        """This context over another source image (a masked copy of the frame): same notes
        and passes, its own scene analysis (the frame's does not describe ``source``)."""
        ctx = RenderContext.__new__(RenderContext)
        ctx.__dict__.update(self.__dict__)
        ctx.source = source
        ctx._analysis = _SharedAnalysis()
        ctx._handoff = {}
        return ctx

    def remember(self, key, build):
        """``build()``, kept for this step's next `recall` of ``key``: what an effect's
        ``is_identity`` has to compute to answer and its ``render`` needs again (lens_flare's
        ghost plan) is computed once per frame."""
        value = build()
        self._handoff[key] = (self.source, value)
        return value

    def recall(self, key, build):
        """What `remember` kept for ``key`` over this same source (taken: the next call
        builds afresh, so a context rendered twice, as the bench does, pays every time), else
        ``build()``."""
        kept = self._handoff.pop(key, None)
        if kept is not None and kept[0] is self.source:
            return kept[1]
        return build()


# -- plugins -------------------------------------------------------------------------------
class Plugin:
    """Base of every effect.  Subclasses set ``descriptor`` and implement ``render``."""

    descriptor: ClassVar[Descriptor]

    @classmethod
    def params(cls, _where: str = "", **values) -> Params:
        """Validated parameters: defaults overridden by ``values``; raises ParamError."""
        d = cls.descriptor
        out = {p.name: p.default for p in d.params}
        for name, value in values.items():
            where = f"{_where or d.name}.{name}"
            out[name] = d.param(name, _where or d.name).validate(value, where)
        return Params(d.name, out)

    def level(self, ctx: "RenderContext") -> Level:
        """This effect's declared settings for ``ctx.quality``."""
        return self.descriptor.level(ctx.quality)

    # cheap questions ------------------------------------------------------------------
    def is_identity(self, p: Params, ctx: RenderContext) -> str | None:
        """A reason (e.g. "amount is 0") if this frame needs nothing from the effect."""
        return None

    def region_of_definition(self, p: Params, ctx: RenderContext) -> Rect:
        """Where the output can be non-zero: the source window grown by the light spread."""
        return ctx.source.window

    def region_of_interest(self, p: Params, ctx: RenderContext, window: Rect) -> Rect:
        """The input area needed to render ``window``."""
        return window

    def output_window(self, p: Params, ctx: RenderContext) -> Rect:
        """The window to render: the source window, grown to the region of definition as far
        as anything will be kept (``ctx.output_limit``: display and data windows, or more with
        --keep-overscan)."""
        rod = self.region_of_definition(p, ctx).intersect(ctx.output_limit)
        return ctx.source.window.union(rod)

    def render(self, rt, p: Params, ctx: RenderContext):
        """Enqueue the effect; return a DeviceImage (the source itself must not be changed)."""
        raise NotImplementedError

    def prepare(self, rt, p: Params, ctx: RenderContext) -> None:
        """Build, through ``rt.cache``, what ``render`` will ask the cache for and that depends
        only on the parameters and the frame's geometry (maps, tables), so a sequence's first
        frame does not wait for it: a look calls this on a thread while the first frame is read
        and the steps before this one render (`clfx.pipeline.look.prepare`).  ``ctx.source``
        may be a stand-in with a window and row pitch but no pixels.  Default: nothing."""

    # conveniences ---------------------------------------------------------------------
    def check_clips(self, ctx: RenderContext) -> None:
        for clip in self.descriptor.clips:
            if clip.name != "source" and not clip.optional and getattr(ctx, clip.name) is None:
                raise ClipError(f"effect {self.descriptor.name!r} needs a {clip.name} pass "
                                f"and the frame has none (see `clfx probe`, --depth/--velocity)")

    def apply(self, rt, p: Params, source: np.ndarray, *, depth=None, velocity=None,
              velocity_back=None, quality: str = DEFAULT_QUALITY, frame: int = 0, seed: int = 0, camera=None,
              data_window: Rect | None = None, display_window: Rect | None = None,
              pixel_aspect: float = 1.0, display_referred: bool = False,
              keep_rod: bool = False, read_image=None, read_lens=None, reference_camera=None,
              rgb_to_xyz=None):
        """Run the effect on host arrays: upload, identity check, render, download.

        ``source`` is in the working space whose RGB -> XYZ matrix is ``rgb_to_xyz`` (default
        linear Rec.709).

        Returns the output cropped to the source window, or ``(array, window)`` with
        ``keep_rod=True``.  ``reference_camera`` is the camera at the shot's first keys
        (default ``camera``: nothing animated).  An identity returns a copy of ``source`` with NaN and infinities set to 0 (as a look does on
        upload).
        """
        src = np.asarray(source, np.float32)
        if src.ndim == 2:
            src = np.stack([src, src, src, np.ones_like(src)], axis=2)
        window = data_window or Rect.from_size(src.shape[1], src.shape[0])
        ctx = RenderContext(
            rt, rt.upload(src, window),
            depth=None if depth is None else rt.upload(np.asarray(depth, np.float32), window),
            velocity=None if velocity is None else rt.upload(np.asarray(velocity, np.float32), window),
            velocity_back=(None if velocity_back is None
                           else rt.upload(np.asarray(velocity_back, np.float32), window)),
            display_window=display_window or window, pixel_aspect=pixel_aspect, frame=frame,
            seed=seed, camera=camera, quality=quality, display_referred=display_referred,
            read_image=read_image, read_lens=read_lens, reference_camera=reference_camera,
            rgb_to_xyz=rgb_to_xyz)
        self.check_clips(ctx)
        if self.is_identity(p, ctx):  # as in a look, whose upload sanitises: NaN/Inf -> 0
            out, out_window = np.nan_to_num(src, nan=0.0, posinf=0.0, neginf=0.0), window
        else:
            img = self.render(rt, p, ctx)
            out, out_window = rt.download(img), img.window
        if keep_rod:
            return out, out_window
        return crop_to(out, out_window, window)


_REGISTRY: dict[str, type[Plugin]] = {}


def register(cls: type[Plugin]) -> type[Plugin]:
    """Class decorator: add a plugin to the registry (checks its descriptor)."""
    d = cls.descriptor
    missing = [lvl for lvl in QUALITY_LEVELS if lvl not in d.quality]
    if missing:
        raise TypeError(f"plugin {d.name} does not say what quality levels {missing} mean")
    names = [p.name for p in d.params]
    if len(set(names)) != len(names):
        raise TypeError(f"plugin {d.name} has duplicate parameter names")
    for p in d.params:
        p.validate(p.default, f"{d.name}.{p.name} (default)")
    _REGISTRY[d.name] = cls
    return cls


def registry() -> dict[str, type[Plugin]]:
    """The plugins registered so far (``clfx.plugins.discover`` imports them all)."""
    return dict(sorted(_REGISTRY.items()))
