"""What a render is asked to do, as the command line and the API say it: the option classes
(`PassOptions`, `IOOptions`, `RenderOptions`, its `RenderSettings`, `ClusterOptions`) and the
one place a batch resolves the quality level (`resolve_quality`).  Plain frozen data; the
batch (`clfx.pipeline.batch`) checks them before any frame is read."""
from __future__ import annotations

from dataclasses import dataclass, field, fields

from clfx.core import limits
from clfx.pipeline.look import DEFAULT_QUALITY, Look
from clfx.pipeline.report import ReportOptions

RAW = "-"
"""INPUT or OUTPUT ``-``: raw frames on stdin or stdout (`clfx.io.raw`)."""


@dataclass(frozen=True)
class PassOptions:
    """How depth and velocity passes are found and read (``--depth-channel`` ...).

    The fields of :class:`clfx.io.read.PassSpec` that the command line sets; ``spec`` makes
    the PassSpec once the focal length for radial depth is known.

    Attributes
    ----------
    depth_channel : str or None
        Exact depth channel name; None: the documented search order.
    depth_mode : {"auto", "z", "inverse", "distance", "normalized"}
        How depth is stored.
    depth_scale : float
        Multiplies depth (scene-unit conversion, e.g. 0.01 for cm to m).
    focal_length_px : float or None
        Focal length in pixels for ``depth_mode="distance"``; None: from the look's camera
        block and the first frame's width.
    velocity_channels : (str, str) or None
        Exact (u, v) channel names; None: the search order.
    velocity_y_up : bool or None
        Whether stored +v points up; None: from the detected convention.
    velocity_scale : float
        Multiplies velocity.
    depth_zero : {"auto", "far", "invalid"}
        Depth 0: no hit (infinitely far), invalid (in focus), or decided from its share and
        alpha (said on stderr once per sequence).
    depth_far_threshold : float
        Depths of at least this magnitude are no hit.
    """

    depth_channel: str | None = None
    depth_mode: str = "auto"
    depth_scale: float = 1.0
    focal_length_px: float | None = None
    velocity_channels: tuple[str, ...] | None = None
    velocity_y_up: bool | None = None
    velocity_scale: float = 1.0
    depth_zero: str = "auto"
    depth_far_threshold: float = 1e9

    @classmethod
    def names(cls) -> tuple[str, ...]:
        return tuple(f.name for f in fields(cls))

    def spec(self, focal_length_px: float | None = None):
        """The :class:`~clfx.io.read.PassSpec` (``focal_length_px`` fills in a missing one)."""
        from clfx.io.read import PassSpec   # lazy: OpenImageIO; `import clfx.api` skips it

        return PassSpec(depth_channel=self.depth_channel, depth_mode=self.depth_mode,
                        depth_scale=self.depth_scale, velocity_channels=self.velocity_channels,
                        velocity_y_up=self.velocity_y_up, velocity_scale=self.velocity_scale,
                        focal_length_px=self.focal_length_px or focal_length_px,
                        depth_zero=self.depth_zero, depth_far_threshold=self.depth_far_threshold)


@dataclass(frozen=True)
class RenderSettings:
    """What the device does with each frame besides the quality level (resolved once against
    the look: `BatchPlan.quality`): whether light spread past the display window is kept,
    and the band size of tiled steps (``CLFX_TILE_PIXELS``, read once when the plan is made
    and shipped with it; 0: whole frames)."""

    keep_overscan: bool = False
    tile_pixels: int = 0


@dataclass(frozen=True)
class IOOptions:
    """What a render reads and writes, and how (the fields of `RenderOptions` of the same
    names: frames, passes, colour spaces, the output's encoding, overwrites)."""

    frames: str | None = None
    depth_path: str | None = None
    velocity_path: str | None = None
    passes: PassOptions = field(default_factory=PassOptions)
    colorspace: str | None = None
    out_colorspace: str | None = None
    working_space: str | None = None
    view: str | None = None
    passes_mode: str = "keep"
    as_float: bool = False
    bit_depth: str | None = None
    compression: str | None = None
    overwrite: bool = False
    skip_existing: bool = False
    skip_missing: bool = False
    raw_size: str | None = None
    raw_format: str = "gbrpf32le"
    command: str | None = None

    def out_bit_depth(self) -> str | None:
        """The output beauty's bit depth: float with ``as_float``, else ``bit_depth``
        (None: the input's type)."""
        return "float" if self.as_float else self.bit_depth


@dataclass(frozen=True)
class RenderOptions(IOOptions):
    """Everything ``clfx render`` and ``clfx apply`` set besides the look (the CLI builds it),
    as keywords: the `IOOptions`, the ``quality`` a plan resolves against the look
    (`BatchPlan.of`), and the fields a render splits off into its `RenderSettings`
    (``keep_overscan``) and its `clfx.pipeline.report.ReportOptions` (``explain``,
    ``as_json``, ``log_path``).

    Attributes
    ----------
    frames : str or None
        Frame spec (``1-100``, ``1-100x2``, ``1,5,10-20``, ``a-b:n``); None: all on disk.
    quality : str or None
        Quality level of every step without its own; None: ``final``.
    depth_path, velocity_path : str or None
        Passes from separate files (a pattern like the input, or one file for all frames).
    passes : PassOptions
        How the passes are found and read.
    colorspace, out_colorspace : str or None
        Colour space of the input (None: the file's tag or chromaticities, else its type's
        default) / to write the output in (None: the input's).
    working_space : str or None
        Linear space effects work in (None: lin_rec709).
    view : str or None
        Multi-view input: render this view only (None: every view an EXR output can hold).
    passes_mode : {"keep", "drop"}
        keep: every other channel and part of the input written through unchanged (EXR).
    as_float : bool
        Write the EXR beauty as 32-bit float (default: the input's type).
    bit_depth : str or None
        The output beauty's bit depth when not ``as_float`` (``"half"``: what `clfx demo`
        writes from its float scene); None: the input's type.
    compression : str or None
        EXR compression; None: an EXR input's, else zips (`clfx.io.write`).
    overwrite : bool
        Replace existing outputs.
    skip_existing : bool
        Skip frames whose output exists (resume a batch).
    skip_missing : bool
        Skip missing input frames instead of failing.
    keep_overscan : bool
        Keep light spread past the display window.
    raw_size : str or None
        ``WxH`` of the raw frames on stdin when INPUT is ``-``; with only OUTPUT ``-``
        (files to a raw stream), optional: the display window every frame must have.
    raw_format : str
        Layout of raw frames (ffmpeg's ``-pix_fmt``, `clfx.io.raw.FORMATS`): gbrpf32le
        (planar G, B, R), gbrapf32le (planar G, B, R, A), rgbf32le (packed R, G, B),
        rgbaf32le (packed R, G, B, A).
    explain : bool
        Per frame, say on stderr which effects ran and why others were skipped.
    as_json : bool
        One JSON line per frame and a summary on stdout.
    log_path : str or None
        Also write every frame's report, the warnings and notices and the summary to this
        file (JSON lines when it ends in ``.json``/``.jsonl``, else the ``--explain`` text).
    command : str or None
        The command line, stamped into outputs as ``clfx:commandLine``.
    """

    quality: str | None = None
    keep_overscan: bool = False
    explain: bool = False
    as_json: bool = False
    log_path: str | None = None

    def render_settings(self) -> RenderSettings:
        """What the device does with each frame (the quality level resolved apart, once,
        against the look: `BatchPlan.of`); ``CLFX_TILE_PIXELS`` read here, once."""
        return RenderSettings(keep_overscan=self.keep_overscan,
                              tile_pixels=limits.tile_pixels() or 0)

    def io_options(self) -> IOOptions:
        """What is read and written, and how."""
        return IOOptions(**{f.name: getattr(self, f.name) for f in fields(IOOptions)})

    def report_options(self, verbosity: int = 1):
        """What the render says (`clfx.pipeline.report.ReportOptions`)."""
        return ReportOptions(explain=self.explain, as_json=self.as_json,
                             log_path=self.log_path, verbosity=verbosity)


@dataclass(frozen=True)
class ClusterOptions:
    """Where a render runs when not in this process (``--workers``, ``--scheduler``).

    Attributes
    ----------
    workers : int or None
        A local Dask cluster of this many processes.
    scheduler : str or None
        An existing Dask cluster's scheduler address (``tcp://host:8786``).
    chunk : int
        Frames per task.
    fail_fast : bool
        Stop at the first failed frame (default: the other frames go on).
    """

    workers: int | None = None
    scheduler: str | None = None
    chunk: int = 1
    fail_fast: bool = False

    @classmethod
    def of(cls, value) -> ClusterOptions:
        """``value`` as ClusterOptions (a mapping of its fields is accepted)."""
        if isinstance(value, cls):
            return value
        try:
            return cls(**dict(value))
        except TypeError as exc:
            raise TypeError(f"distributed: {exc} (see clfx.ClusterOptions)") from None



def resolve_quality(look: Look, quality: str | None) -> tuple[Look, str]:
    """The render's quality level (``quality``, else ``final``) and ``look`` with every
    step's level resolved (its own override, else the render's): the one place a batch
    resolves it, so the stamped look (``clfx:lookJSON``) renders the same pixels again."""
    level = quality or DEFAULT_QUALITY
    return look.at_quality(level), level
