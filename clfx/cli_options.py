"""Options several ``clfx`` commands share, declared once (as rasterio's ``rio.options``).

Each name here is a decorator (``frames_option`` too): ``@pass_options`` adds the options that say how depth and
velocity passes are found and read (``render``, ``apply``, ``probe``), ``@render_options``
everything ``render`` and ``apply`` take besides the look, ``@quality_option`` the quality
level (also ``demo``).
"""
from __future__ import annotations

import math

import click

from clfx.core.errors import SequenceError
from clfx.core.plugin import QUALITY_LEVELS

DEPTH_MODES = ("auto", "z", "inverse", "distance", "normalized")  # clfx.io.channels.DEPTH_MODES


def stack(*decorators):
    """One decorator applying ``decorators``; options are listed in the order given."""
    def apply(f):
        for decorate in reversed(decorators):
            f = decorate(f)
        return f
    return apply


def _positive(ctx, param, value):
    if not (value > 0 and math.isfinite(value)):
        raise click.BadParameter(f"{value} must be a positive number")
    return value


def _names(ctx, param, value):
    return tuple(value.split(",")) if value else None


def _channel_pair(ctx, param, value):
    """``U,V``: two channel names (a usage error otherwise)."""
    names = _names(ctx, param, value)
    if names is not None and (len(names) != 2 or not all(n.strip() for n in names)):
        raise click.BadParameter(f"{value!r} is not two channel names U,V (e.g. "
                                 f"forward.u,forward.v)")
    return names


def check_frames(ctx, param, value):
    """A bad frame range is a usage error (exit 2), said before anything is read."""
    if value is None:
        return None
    from clfx.io.sequence import parse_frames   # lazy: fileseq is 40-120 ms at start-up

    try:
        parse_frames(value)
    except SequenceError as exc:
        raise click.BadParameter(str(exc)) from None
    return value


def check_raw_size(ctx, param, value):
    """A --raw value that is not WxH is a usage error (exit 2); its size limit is checked
    with the render (exit 1)."""
    if value is None:
        return None
    from clfx.io.raw import parse_wxh   # lazy: with OpenImageIO, ~0.27 s at start-up

    try:
        parse_wxh(value)
    except SequenceError:
        raise click.BadParameter(f"{value!r} is not WxH (two positive whole numbers)") from None
    return value


quality_option = click.option(
    "--quality", type=click.Choice(QUALITY_LEVELS), default=None,
    help="Quality level of every effect without its own override.")

pass_options = stack(
    click.option("--depth-channel", default=None, help="Depth channel name (overrides detection)."),
    click.option("--depth-mode", type=click.Choice(DEPTH_MODES), default="auto",
                 help="How depth is stored: planar z, 1/z, radial distance, 0-1."),
    click.option("--depth-scale", type=float, default=1.0, callback=_positive,
                 help="Multiply depth (e.g. 0.01 for cm to m)."),
    click.option("--depth-zero", type=click.Choice(["auto", "far", "invalid"]), default="auto",
                 help="Depth 0: far = no hit (infinitely far), invalid = kept (in focus); "
                      "auto decides from its share and alpha."),
    click.option("--depth-far-threshold", type=float, default=1e9, metavar="Z",
                 help="Depths of at least this magnitude are no hit (inf keeps them)."),
    click.option("--focal-length-px", type=float, default=None,
                 help="For --depth-mode distance: focal length in pixels (default: from the "
                      "look's camera block and the frame width)."),
    click.option("--velocity-channels", default=None, metavar="U,V", callback=_channel_pair,
                 help="Velocity channel names."),
    click.option("--velocity-y-up/--velocity-y-down", default=None,
                 help="Direction of +v in the velocity pass (overrides detection)."),
    click.option("--velocity-scale", type=float, default=1.0, callback=_positive,
                 help="Multiply velocity."),
)

colour_options = stack(
    click.option("--colorspace", default=None,
                 help="Colour space of the input (OCIO name or alias, 'raw'); default: the "
                      "file's tag or chromaticities, else sRGB for 8/16-bit, linear Rec.709."),
    click.option("--working-space", default=None, metavar="SPACE",
                 help="Linear space effects work in: lin_rec709 (default), ACEScg, ..."),
    click.option("--view", default=None, metavar="NAME",
                 help="Multi-view EXR input: render view NAME only, the others copied "
                      "through.  Default: every view renders (an EXR output with --passes "
                      "keep; other outputs: the hero view); --explain, --json and the "
                      "summary name the views."),
)

render_options = stack(
    click.option("--frames", default=None, metavar="SPEC", callback=check_frames,
                 help="Frames to render: 1-100, 1-100x2, 1,5,10-20, farm a-b:n. Default: all on disk."),
    quality_option,
    click.option("--depth", "depth_path", default=None, metavar="PATTERN",
                 help="Depth pass from separate files (pattern like the input)."),
    click.option("--velocity", "velocity_path", default=None, metavar="PATTERN",
                 help="Velocity pass from separate files."),
    pass_options,
    colour_options,
    click.option("--out-colorspace", default=None,
                 help="Colour space to write the output in (default: the input's)."),
    click.option("--passes", "passes_mode", type=click.Choice(["keep", "drop"]), default="keep",
                 help="keep: write every other channel and part of the input through "
                      "unchanged (EXR); drop: the beauty only."),
    click.option("--float", "as_float", is_flag=True,
                 help="Write the EXR beauty as 32-bit float (default: the input's type)."),
    click.option("--compression", default=None,
                 help="EXR compression: zip, piz, dwaa, none, ... (default: an EXR input's, else zips)."),
    click.option("-y", "--overwrite", is_flag=True, help="Replace existing outputs."),
    click.option("--skip-existing", is_flag=True,
                 help="Skip frames whose output exists (resume a batch)."),
    click.option("--skip-missing", is_flag=True, help="Skip missing input frames instead of failing."),
    click.option("--keep-overscan", is_flag=True, help="Keep light spread past the display window."),
    click.option("--raw", "raw_size", default=None, metavar="WxH", callback=check_raw_size,
                 help="'-' as INPUT: raw frames of this size on stdin (ffmpeg -f rawvideo), "
                      "to '-' (stdout) or to files (OUT.#.exr, numbered from --frames, "
                      "default 1).  '-' as OUTPUT alone: files to raw frames on stdout, "
                      "sized as the first input's display window (--raw must match it)."),
    click.option("--raw-format", "raw_format", default=None,
                 type=click.Choice(["gbrpf32le", "gbrapf32le", "rgbf32le", "rgbaf32le"]),
                 help="Layout of raw frames (ffmpeg -pix_fmt; little-endian float32): "
                      "gbrpf32le (default) planar G, B, R: planes in that order, not R, G, B; "
                      "gbrapf32le planar G, B, R, A; rgbf32le packed R, G, B per pixel; "
                      "rgbaf32le packed R, G, B, A.  Without alpha: alpha 1 in, "
                      "premultiplied colour out."),
    click.option("--explain", is_flag=True,
                 help="Per frame: which effects ran, which were skipped and why."),
    click.option("--json", "as_json", is_flag=True,
                 help="One JSON line per frame and a summary on stdout."),
    click.option("--log", "log_path", default=None, metavar="FILE",
                 help="Also write each frame's report, the warnings and the summary to FILE "
                      "(JSON lines if it ends in .json/.jsonl)."),
)
