"""The plugin host (OpenFX's host side): the render context, the Plugin base class, the
registry decorator.

Effects subclass :class:`Plugin` (``clfx/plugins/<effect>.py``) and describe themselves
with ``clfx.core.plugin`` descriptors; the context gives them the frame on the device, its
passes, the camera and the shared scene analysis (``clfx.fx.analysis``), computed on first
use.  Files an effect reads (kernel images) come through ``ctx.read_image``, which the
pipeline supplies: effects never open files themselves.
"""
from __future__ import annotations

from dataclasses import KW_ONLY, dataclass, field, replace
from typing import Any, ClassVar

import numpy as np

from clfx.core import colour
from clfx.core.camera import Camera
from clfx.core.errors import ClipError, ParamError
from clfx.core.plugin import DEFAULT_QUALITY, QUALITY_LEVELS, Descriptor, Level, Params
from clfx.core.rect import Rect
from clfx.fx.analysis import MID_GREY, analyse


# -- render context ------------------------------------------------------------------------
class _SharedAnalysis:
    """The frame's scene analysis, shared by a look's context and every per-step context
    made from it (:meth:`RenderContext.for_step`), with the seconds spent computing it."""

    __slots__ = ("seconds", "value", "alpha_is_coverage")

    def __init__(self, value=None, alpha_is_coverage=None):
        self.value = value
        self.seconds = 0.0
        self.alpha_is_coverage = alpha_is_coverage
        """The verdict of the frame's first analysis (`RenderContext.alpha_is_coverage`)."""


class _FrameAnalysis(_SharedAnalysis):
    """The analysis box of a tile's context: the whole frame's analysis, never recomputed
    over the tile (an effect that tiles reads only its frame-wide values: counts, peaks,
    the metering level; one that reads its per-tile arrays renders whole)."""

    __slots__ = ()


def _no_reader(what: str, keyword: str):
    """A reader for a context made without one: says so in a ParamError."""
    def read(name):
        raise ParamError(f"no {what} reader in this context to read {name!r} "
                         f"(pass {keyword}= to the render context)")
    return read


@dataclass(frozen=True)
class StepPlan:
    """What one step derives once per frame from its parameters and the frame (openfx-misc's
    per-time params struct, darktable's ``commit_params``): ``is_identity``, the regions, the
    clamp warnings and ``render`` read it instead of deriving it again.  Effects subclass it
    (frozen) with their fields; the base holds nothing (an effect with nothing costly to
    derive).  ``identity``: the reason the step has nothing to do on this frame, or None."""

    identity: str | None = None


def read_only(*arrays):
    """``arrays`` made read-only (a plan's tables: built once on the whole frame, read by
    every band); one array or a tuple of them."""
    for a in arrays:
        a.flags.writeable = False
    return arrays if len(arrays) != 1 else arrays[0]


@dataclass(frozen=True)
class ExposurePlan(StepPlan):
    """The plan of an effect relative to the plate's exposure (grain, sensor noise): its
    middle grey, stated or metered on the whole frame (`clfx.kit.noise.exposure_reference`)
    once per step, so every band of a tiled render uses the frame's."""

    middle_grey: float = MID_GREY


def tile_bands(window: Rect, tile_pixels: int | None) -> list[Rect]:
    """``window`` in full-width bands of at most ``tile_pixels`` pixels (one band, the
    window, without a tile size or when it fits)."""
    rows = max(1, tile_pixels // max(window.width, 1)) if tile_pixels else window.height
    if rows >= window.height:
        return [window]
    return [Rect(window.x0, y, window.x1, min(y + rows, window.y1))
            for y in range(window.y0, window.y1, rows)]


@dataclass(frozen=True)
class Band:
    """One band of a step's tiled render, the one object a band's render receives (on its
    context: `RenderContext.tile`): ``band``, the rows of the step's output window it
    renders; ``roi``, the part of the step's source it reads (its region of interest, cut to
    the source: the tile context's source window); ``whole``, the step's source window (the
    untiled render's), from which effects whose arithmetic depends on the window they render
    over (a warp's coordinates and canvas) compute it, so a band gets the whole render's
    bits; ``plan``, the step's plan (`Plugin.planned`), built on the whole frame before any
    band, which the band reads instead of looking it up."""

    whole: Rect
    band: Rect
    roi: Rect
    plan: StepPlan


@dataclass(frozen=True, eq=False)
class RenderContext:
    """Everything an effect may read while rendering one frame: frozen, derived with
    :func:`dataclasses.replace` (:meth:`for_step`, :meth:`with_source`, :meth:`grown_to`,
    :meth:`over`).

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
        motion then follow the circular arc at a constant turn rate through the previous,
        current and next positions (`clfx.fx.motion.path`).
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
        A lens prescription by name (``presets/lenses/<name>.yaml``) or path, as the plain
        dict ``clfx.fx.optics.Prescription.from_dict`` takes (supplied by the pipeline, which
        resolved and validated it when the look was loaded: `clfx.io.lenses`).
    rgb_to_xyz : ndarray (3, 3), float64
        The working space's RGB -> CIE XYZ (D65) matrix, as data (the pipeline takes it from
        OCIO); default linear Rec.709 (`clfx.core.colour`).  Spectral effects build their
        wavelength -> RGB tables with it, thresholds weigh luminance with its Y row.
    notes, warnings : list of str
        This step's notes for the report and lines said on stderr (a clamp, a guess, a
        skipped request); the lists are shared by the contexts derived within one step.
    tiling : Band or None
        In a tile of a tiled render (`tile`): the band (its rows, what it reads, the step's
        whole source window and plan); None in a whole render.
    tile_pixels : int or None
        The band size (pixels) of this step's tiled render (`tile_bands`; None: whole), set
        before the step plans, so a plan holds what its bands will read (`bands`).
    """

    runtime: Any
    source: Any
    _: KW_ONLY
    depth: Any = None
    velocity: Any = None
    velocity_back: Any = None
    display_window: Rect | None = None
    pixel_aspect: float = 1.0
    frame: int = 0
    seed: int = 0
    camera: Camera | None = None
    quality: str = DEFAULT_QUALITY
    display_referred: bool = False
    output_limit: Rect | None = None
    read_image: Any = field(default=None, repr=False)
    read_lens: Any = field(default=None, repr=False)
    reference_camera: Camera | None = None
    rgb_to_xyz: Any = field(default=None, repr=False)
    notes: list = field(default_factory=list)
    warnings: list = field(default_factory=list)
    shared: _SharedAnalysis = field(default_factory=_SharedAnalysis, repr=False)
    """The frame's scene analysis box (shared by the step contexts of one frame)."""
    plans: dict = field(default_factory=dict, repr=False)
    """This step's plans (`Plugin.planned`), shared by the contexts derived within it."""
    tiling: Band | None = None
    tile_pixels: int | None = None

    def __post_init__(self):
        def put(name, value):
            object.__setattr__(self, name, value)

        put("display_window", self.display_window or self.source.window)
        put("pixel_aspect", float(self.pixel_aspect))
        put("frame", int(self.frame))
        put("seed", int(self.seed))
        put("camera", self.camera or Camera())
        put("reference_camera", self.reference_camera or self.camera)
        put("output_limit", self.output_limit or self.source.window.union(self.display_window))
        put("rgb_to_xyz", colour.rgb_to_xyz_matrix(self.rgb_to_xyz))
        if self.read_image is None:
            put("read_image", _no_reader("image", "read_image"))
        if self.read_lens is None:
            put("read_lens", _no_reader("lens", "read_lens"))

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

    @property
    def analysis(self):
        """The frame's shared scene analysis of the current source: computed on first use,
        and again only if an effect has since changed the source's window (its tiles are
        always those of ``source.window``)."""
        shared = self.shared
        if isinstance(shared, _FrameAnalysis):
            return shared.value
        if shared.value is None or shared.value.window != self.source.window:
            shared.value = analyse(self.runtime, self.source, depth=self.depth,
                                   velocity=self.velocity, camera=self.camera,
                                   display_window=self.display_window,
                                   luminance_defines=self.luminance_defines)
            shared.seconds += shared.value.seconds
            if shared.alpha_is_coverage is None:
                shared.alpha_is_coverage = shared.value.alpha_is_coverage()
        return shared.value

    def alpha_is_coverage(self) -> bool:
        """Whether the frame's alpha reads as coverage (`SceneAnalysis.alpha_is_coverage`:
        no light where alpha <= 0), as the frame's first scene analysis found it: the look's
        input whenever an earlier step read the analysis (every resampling, glare-family,
        blur and motion effect does), not the image after effects that put light where
        alpha is 0 on purpose (chromatic aberration's fringes, glare), which would turn a CG
        element on an empty background into "a matte"."""
        analysis = self.analysis
        verdict = self.shared.alpha_is_coverage
        return analysis.alpha_is_coverage() if verdict is None else verdict

    @property
    def analysis_seconds(self) -> float:
        """Seconds spent computing this frame's analyses so far (this context and every
        per-step context made from it)."""
        return self.shared.seconds

    @property
    def diagonal_px(self) -> float:
        return self.display_window.diagonal

    @property
    def width_px(self) -> int:
        return self.display_window.width

    def size_px(self, fraction_of_diagonal: float) -> float:
        """A resolution-independent size (fraction of the frame diagonal) in pixels."""
        return fraction_of_diagonal * self.diagonal_px

    def over(self, **changes) -> RenderContext:
        """This context with ``changes`` (`dataclasses.replace`): the same step (notes,
        warnings, plans and the frame's analysis shared)."""
        return replace(self, **changes)

    def grown_to(self, window: Rect) -> RenderContext:
        """This context over a larger ``window`` (an effect whose light leaves the data
        window): the source padded with transparent black, depth and velocity extended from
        their edges; notes, plans and the frame's analysis box shared (the analysis is
        recomputed for the new window on first use)."""
        rt = self.runtime

        def clamp(img):
            return None if img is None else rt.reframe(img, window, "clamp")

        return replace(self, source=rt.reframe(self.source, window, "zero"),
                       depth=clamp(self.depth), velocity=clamp(self.velocity),
                       velocity_back=clamp(self.velocity_back))

    def for_step(self, quality: str) -> RenderContext:
        """A context for one effect of a look: this one at ``quality``, with its own
        ``notes``, ``warnings`` and plans and the same scene analysis (one the step computes
        is this frame's)."""
        return replace(self, quality=quality, notes=[], warnings=[], plans={})

    def bands(self, window: Rect) -> list[Rect]:
        """The bands of this step's render of ``window`` (its output window):
        `tile_bands` of its ``tile_pixels`` (``[window]``: a whole render)."""
        return tile_bands(window, self.tile_pixels)

    def tile(self, window: Rect, band: Rect, plan: StepPlan) -> RenderContext:
        """This step's context over the part ``window`` of its source and passes (a tile of a
        tiled render: `clfx.pipeline.look`): `grown_to` the tile, with the same plans and
        notes, and the whole frame's scene analysis (computed now if not yet), not the
        tile's; ``tiling`` is the :class:`Band`: the ``band`` of the output the tile
        renders, ``window`` (its region of interest), the step's whole source window and its
        ``plan`` (the frame's, already built)."""
        frame = _FrameAnalysis(self.analysis, self.alpha_is_coverage())
        whole = self.tiling.whole if self.tiling else self.source.window
        return replace(self.grown_to(window), shared=frame,
                       tiling=Band(whole, band, window, plan))

    def with_source(self, source) -> RenderContext:
        """This context over another source image (a masked copy of the frame): same notes
        and passes, its own scene analysis and plans (the frame's do not describe
        ``source``)."""
        return replace(self, source=source, shared=_SharedAnalysis(), plans={})


# -- plugins -------------------------------------------------------------------------------
class Plugin:
    """Base of every effect.  Subclasses set ``descriptor`` and implement ``render``."""

    descriptor: ClassVar[Descriptor]
    whole_frame: ClassVar[str | None] = "not shown to give the same pixels in tiles"
    """Why the effect renders the whole frame at once (a global FFT, whole-frame statistics),
    or None: it renders in tiles, each from its region of interest, with the same pixels
    (checked for every such effect by tests/contract/test_tiles.py)."""

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

    # the step's plan -----------------------------------------------------------------
    def plan(self, p: Params, ctx: RenderContext) -> StepPlan:
        """What this step derives from ``p`` and the frame that more than one of
        ``is_identity``, the regions, the warnings and ``render`` need (a lens, tile radii, a
        ghost table): built once per step per frame through :meth:`planned`, never called
        directly.  Default: nothing to derive."""
        return StepPlan()

    def planned(self, p: Params, ctx: RenderContext) -> StepPlan:
        """This step's plan for ``p`` on ``ctx``'s frame: built on first use, then the same
        object for every context derived within the step (`RenderContext.over`, `grown_to`,
        the tiles of a tiled render, whose :class:`Band` carries it); `RenderContext.for_step`
        and `with_source` start afresh.  A plan is made for the step's band size
        (``ctx.tile_pixels``): what its bands read is in it before any band renders."""
        if ctx.tiling is not None:     # a band: the frame's plan, built before any band
            return ctx.tiling.plan
        key = (type(self), p, ctx.tile_pixels)
        plan = ctx.plans.get(key)
        if plan is None:
            plan = ctx.plans[key] = self.plan(p, ctx)
        return plan

    def lens_refs(self, p: Params) -> tuple:
        """The lenses ``p`` names, as ``(param, kind, value)``: kind "prescription" (value a
        name in ``presets/lenses`` or a YAML file) or "lensfun" (value ``(maker, model)``).
        The pipeline reads and validates them when the look is loaded (`clfx.io.lenses`), so
        a bad name fails before any frame.  Default: none."""
        return ()

    # cheap questions ------------------------------------------------------------------
    def is_identity(self, p: Params, ctx: RenderContext) -> str | None:
        """A reason (e.g. "amount is 0") if this frame needs nothing from the effect
        (default: the plan's ``identity``)."""
        return self.planned(p, ctx).identity

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

    def passes_after(self, rt, p: Params, ctx: RenderContext, out, later: set) -> dict:
        """Passes realigned with this step's output ``out`` for the steps after it that read
        them (``later``: the clip names they read), by name (``"velocity"``...), each over
        ``out.window``: an effect that moves colour (motion blur's smear) moves what the
        passes say about it, so a later effect (rolling shutter) reads passes that describe
        the image it gets.  The pipeline extends the passes not returned by their edges, as
        for any step that grows the window.  Default: none."""
        return {}

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
