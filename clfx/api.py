"""The Python API: looks, and rendering arrays, files and sequences through them.

``import clfx`` exposes these names; the ``clfx`` command line is a thin layer over them.

Conventions (the same as the command line's, docs/pipeline.md, "Conventions"):

- ``rgba``: float32 (h, w, 4) scene-linear, premultiplied, in the working space (linear
  Rec.709 unless told otherwise); (h, w, 3) gets alpha 1, (h, w) is grey.
- ``depth``: float32 (h, w) planar camera z in scene units (metres), background ``+inf``.
- ``velocity``: float32 (h, w, 2) forward displacement in pixels per frame, +x right, +y down.
- Sizes in looks are fractions of the frame diagonal, or physical units through the camera
  block (mm, metres, degrees, stops).

Examples
--------
>>> import numpy as np, clfx
>>> look = clfx.load_look("default", set=["grain.amount=0"])          # doctest: +SKIP
>>> result = clfx.render_array(np.ones((90, 160, 4), np.float32), look)  # doctest: +SKIP
>>> result.rgba.shape, result.report.ran                                # doctest: +SKIP
((90, 160, 4), [...])
"""
from __future__ import annotations

import os
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from typing import Callable, Iterable, Mapping

import numpy as np

from clfx.core.errors import ParamError, PresetError, SequenceError
from clfx.core.frame import Frame
from clfx.core.limits import load_json
from clfx.core.plugin import QUALITY_LEVELS
from clfx.core.rect import Rect
from clfx.device.runtime import Runtime
from clfx.io.channels import beauty_out
from clfx.pipeline.masks import read_masks
from clfx.pipeline.options import ClusterOptions, PassOptions, RenderOptions, resolve_quality
from clfx.pipeline.look import FrameReport, Look, RunStats, render_frame
from clfx.pipeline.presets import (MAX_LOOK_BYTES, apply_overrides, load_look as _load,
                                   look_from_dict)


__all__ = ["Look", "FrameReport", "RenderOptions", "PassOptions", "ClusterOptions", "ArrayResult", "RenderResult",
           "load_look", "runtime", "render_array", "render_file", "render_sequence", "render"]


def runtime(device: str | None = None):
    """The process's OpenCL runtime (created on first use; later calls return it).

    Parameters
    ----------
    device : str, optional
        ``"P:D"`` platform and device indices, or a substring of the device's name; default
        ``$CLFX_DEVICE``, else PoCL's CPU device (``clfx devices`` lists them).

    Raises
    ------
    DeviceError
        No usable OpenCL device (the message says what to install).
    """
    return Runtime.get(device)


def load_look(look: str | os.PathLike | dict | Look = "default", *,
              set: Iterable[str] = ()) -> Look:
    """A validated look.

    Parameters
    ----------
    look : str, path, dict or Look
        A look name (``clfx looks`` lists them), a YAML file, a dict shaped like a look file
        (``{"camera": {...}, "effects": [{"effect": "glare", "params": {...}}]}``, optionally
        ``"base": "cinema"``), an output file stamped by clfx (``.exr`` etc.: its
        ``clfx:lookJSON`` is read back), or a Look (copied).
    set : iterable of str
        Overrides as on the command line: ``"glare.strength=0.2"``,
        ``"camera.focus_distance=1001:2.0,1040:5.5"`` (keyframes), ``"dof.enabled=false"``,
        ``"seed=3"``.

    Returns
    -------
    Look
        ``look.describe()`` is the resolved look, ``look.at(frame)`` its values on a frame.

    Raises
    ------
    PresetError, ParamError
        Unknown look, effect or parameter (with the closest name), a value out of range.
    """
    _check_look(look)
    if isinstance(set, (str, bytes)) or not isinstance(set, Iterable):
        raise TypeError(f"set: {set!r} is not a list of 'key=value' strings")
    if isinstance(look, Look):
        lk = replace(look, steps=list(look.steps))
    elif isinstance(look, dict):
        lk = look_from_dict(look)
    else:
        text = os.fspath(look)
        lk = look_from_stamp(text) if _is_image(text) else _load(text)
    return apply_overrides(lk, list(set))


def _check_look(look) -> None:
    """TypeError unless ``look`` is a name, a path, a dict or a Look."""
    if not isinstance(look, (str, os.PathLike, dict, Look)):
        raise TypeError(f"look: {look!r} ({type(look).__name__}) is not a look name, a file, "
                        f"a dict or a Look")


def _check_quality(quality) -> None:
    """ValueError unless ``quality`` is None or a quality level."""
    if quality is not None and (not isinstance(quality, str) or quality not in QUALITY_LEVELS):
        raise ValueError(f"quality: {quality!r} is not one of {', '.join(QUALITY_LEVELS)} "
                         f"(or None: final)")


def _check_frame(frame) -> int:
    """``frame`` as an int; TypeError unless it is a whole number."""
    if isinstance(frame, bool) or not isinstance(frame, (int, np.integer)):
        raise TypeError(f"frame: {frame!r} ({type(frame).__name__}) is not a whole number")
    return int(frame)


def _float_array(a, name: str) -> np.ndarray:
    """``a`` as float32.  The rule: floating-point arrays (float16, float32, float64) are
    converted to float32; anything else (uint8, bool, complex, int, object) is refused with a
    TypeError, since clfx takes scene-linear values and an 8-bit image is neither linear nor
    scaled (convert it yourself, e.g. ``srgb_uint8 / 255`` then linearise)."""
    arr = np.asarray(a)
    if arr.dtype.kind != "f":
        raise TypeError(f"{name}: dtype {arr.dtype} is not floating point; clfx takes "
                        f"scene-linear float values (float16/32/64), e.g. convert 8-bit sRGB "
                        f"with rgb / 255 and linearise it first")
    return arr.astype(np.float32, copy=False)


def _is_image(path: str) -> bool:
    return os.path.splitext(path)[1].lower() in (".exr", ".tif", ".tiff", ".png", ".jpg",
                                                 ".jpeg", ".dpx", ".hdr")


def look_from_stamp(path: str | os.PathLike, *, relevel: bool = False,
                    level: str | None = None) -> Look:
    """The look an output of clfx was rendered with (its ``clfx:lookJSON`` header
    attribute), to render a shot again from the file alone.

    The stamped look carries every step's quality level as the render resolved it, so it
    renders the same pixels whatever level the render asked for.  ``relevel``: the steps
    that took the render's level (``clfx:quality``) take the next render's instead (``clfx
    render --look-from FILE --quality LEVEL``); steps with their own level keep it.
    ``level``: that stamp when the caller has read it already (`stamped_quality`); None:
    read here.

    Raises
    ------
    PresetError
        The file carries no clfx look (not rendered by clfx, or by a clfx before 0.1.0).
    """
    from clfx.io.probe import header_attribute   # lazy: files cost `import clfx.api` ~0.5 s

    text = header_attribute(path, "clfx:lookJSON")
    if not text:
        raise PresetError(f"{os.fspath(path)}: no clfx:lookJSON attribute (not rendered by clfx "
                          "with a stamped look)")
    data = load_json(text, f"{os.fspath(path)}: clfx:lookJSON", PresetError,
                     max_bytes=MAX_LOOK_BYTES, unique_keys=True)   # as a look file

    look = look_from_dict(data, where=f"{os.fspath(path)} (clfx:lookJSON)")
    if relevel:
        level = level if level is not None else stamped_quality(path)
        look = replace(look, steps=[replace(s, quality=None) if s.quality == level else s
                                    for s in look.steps])
    return replace(look, source=os.fspath(path), files=(os.fspath(path),))


def stamped_quality(path: str | os.PathLike) -> str | None:
    """The quality level an output of clfx was rendered at (its ``clfx:quality``), None
    when it has none (rendered by a clfx before it was stamped) or not a level."""
    from clfx.io.probe import header_attribute   # lazy: as look_from_stamp

    level = header_attribute(path, "clfx:quality")
    return level if level in QUALITY_LEVELS else None


@dataclass
class ArrayResult:
    """What :func:`render_array` returns.

    Attributes
    ----------
    rgba : ndarray
        float32 over ``window`` (the input's window unless ``keep_overscan`` let light spread
        past it), with the input's channels: (h, w, 4) RGBA, (h, w, 3) RGB (the
        premultiplied colour, alpha dropped) or (h, w) grey (BT.709 luminance of the
        rendered RGB; exact where it stayed grey).
    window : Rect
        The pixels ``rgba`` covers, in the input's coordinates ((0, 0) is its top left).
    report : FrameReport
        What ran, what was skipped and why, timings in ms, warnings (``report.as_dict()``).
    """

    rgba: np.ndarray
    window: Rect
    report: FrameReport


def render_array(rgba, look: str | dict | Look = "default", *, depth=None, velocity=None,
                 channels: Mapping[str, np.ndarray] | None = None, frame: int = 0,
                 quality: str | None = None, keep_overscan: bool = False,
                 device: str | None = None, stats: RunStats | None = None,
                 working_space: str | None = None) -> ArrayResult:
    """Render one image held in memory through a look.

    Parameters
    ----------
    rgba : array_like
        (h, w, 4) scene-linear premultiplied RGBA in the working space (linear Rec.709 by
        default, see ``working_space``); (h, w, 3) gets alpha 1; (h, w) is grey.  Floating
        point (float16/32/64, converted to float32); other dtypes (uint8, bool, complex,
        int) are refused with a TypeError, as for ``depth``, ``velocity`` and ``channels``.
    look : str, dict or Look
        See :func:`load_look`.
    depth : array_like, optional
        (h, w) planar z in scene units (metres), ``+inf`` where nothing was hit; needed by
        ``dof``.
    velocity : array_like, optional
        (h, w, 2) forward motion in pixels per frame (+x right, +y down); needed by
        ``motion_blur``.
    channels : mapping of str to array_like, optional
        Named (h, w) channels for masks: a step with ``mask: {channel: ball.A}`` reads
        ``channels["ball.A"]`` (coverage 0..1).
    frame : int
        Frame number: drives keyframed values and noise (deterministic per frame).
    quality : {"draft", "preview", "final", "reference"}, optional
        Level of every step without its own; default ``final``.
    keep_overscan : bool
        Keep light spread past the image (``result.window`` grows).
    device : str, optional
        See :func:`runtime`.
    stats : RunStats, optional
        Share across the frames of one run to estimate what skipping saved.
    working_space : str, optional
        The linear OCIO space ``rgba`` is in (``"ACEScg"``; default linear Rec.709): spectral
        effects and luminance thresholds use its primaries.  Nothing is converted.

    Returns
    -------
    ArrayResult

    Raises
    ------
    ClipError
        A step needs a pass (depth, velocity) or mask channel that was not given.
    ParamError, PresetError
        Bad look or values.
    TypeError, ValueError
        An argument of the wrong type (``look=5``, ``frame="x"``, a uint8 array) or value
        (``quality="ultra"``), naming the argument.
    """
    _check_look(look)
    _check_quality(quality)
    frame = _check_frame(frame)
    arr = _float_array(rgba, "rgba")
    depth = None if depth is None else _float_array(depth, "depth")
    velocity = None if velocity is None else _float_array(velocity, "velocity")
    if channels is not None:
        channels = {k: _float_array(v, f"channels[{k!r}]") for k, v in channels.items()}
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] not in (3, 4)) or arr.size == 0:
        raise ParamError(f"rgba: shape {arr.shape} is not (h, w, 4), (h, w, 3) or (h, w)")
    h, w = arr.shape[:2]
    for name, a, shape in (("depth", depth, (h, w)), ("velocity", velocity, (h, w, 2))):
        if a is not None and np.shape(a) != shape:
            raise ParamError(f"{name}: shape {np.shape(a)} does not match the image's {shape}")
    lk, level = resolve_quality(look if isinstance(look, Look) else load_look(look), quality)
    frm = Frame.from_array(arr, depth=depth, velocity=velocity)
    if working_space is not None:
        from clfx.io import colour   # lazy: OpenImageIO, as look_from_stamp

        frm.colorspace = colour.resolve(working_space, "working space")
        if frm.colorspace == colour.RAW or not colour.is_linear(frm.colorspace):
            raise ParamError(f"working_space {working_space!r} must be a linear colour space "
                             f"(e.g. lin_rec709, ACEScg)")
    masks = read_masks(lk.at(frame), frm, frame, channels=channels) if lk.masks() else None
    out, report = render_frame(runtime(device), lk, frm, frame_number=frame, quality=level,
                               keep_overscan=keep_overscan, stats=stats, masks=masks)

    pixels = beauty_out(out.rgba, arr.shape[2] if arr.ndim == 3 else 1)   # channels in = out
    return ArrayResult(pixels[..., 0] if arr.ndim == 2 else pixels, out.data_window, report)


@dataclass
class RenderResult:
    """What :func:`render_file` and :func:`render_sequence` return.

    Attributes
    ----------
    summary : dict
        ``frames``, ``wall_s`` (seconds), ``fps``, ``device_ms_mean`` (ms per frame on the
        device), ``skipped_existing``, ``saved_ms_estimate``.
    reports : list of FrameReport
        One per rendered frame, in order.
    outputs : list of str
        The files written.
    """

    summary: dict
    reports: list[FrameReport] = field(default_factory=list)
    outputs: list[str] = field(default_factory=list)


def render(input: str | os.PathLike, output: str | os.PathLike,
           look: str | dict | Look = "default", *, set: Iterable[str] = (),
           options: RenderOptions | None = None, verbosity: int = 0,
           on_frame: Callable | None = None, device: str | None = None, runtime=None,
           distributed: ClusterOptions | dict | None = None, **option_values) -> RenderResult:
    """Render a file, a sequence or a raw pipe through a look: :func:`render_file` and
    :func:`render_sequence` are this function (the command line's ``clfx render``).

    Everything is checked before the first frame is read (missing frames, existing outputs,
    inputs that would be overwritten, mask files and channels); frames are read and written
    on I/O threads while the device renders.

    Parameters
    ----------
    input, output : str or path
        Files or patterns (``shot.#.exr``, ``shot.%04d.exr``, ``shot.$F4.exr``); ``"-"``
        for raw frames on stdin (``raw_size="WxH"``) or stdout, ``raw_format`` their layout
        (``"gbrpf32le"``: planes G, B, R; ``"gbrapf32le"``, ``"rgbf32le"``, ``"rgbaf32le"``;
        `clfx.io.raw`).  Either side may be files: raw frames to ``out.#.exr``, or a
        sequence to raw frames.
    look : str, dict or Look
        See :func:`load_look`; ``set`` applies overrides to it.
    options : RenderOptions, optional
        Every option of ``clfx render`` (frames, quality, passes, colour spaces,
        overwrite, ...); or give them as keywords (``frames="1001-1100", overwrite=True``).
    verbosity : int
        0: nothing on stderr but warnings; 1: notices and a summary line (the CLI's
        default); 2: more.
    on_frame : callable(done, total, report), optional
        Called after each frame (progress; ``total`` is None for raw pipes).
    device, runtime
        The OpenCL device (:func:`runtime`'s ``device``), or a runtime (or a Future of
        one) to use.
    distributed : ClusterOptions or dict, optional
        Render on a Dask cluster: ``ClusterOptions(workers=N)`` or
        ``ClusterOptions(scheduler="tcp://...")`` (plus ``chunk``, ``fail_fast``; a dict of
        these is accepted); see ``docs/scaling.md``.

    Returns
    -------
    RenderResult

    Raises
    ------
    SequenceError, ImageIOError, ClipError, PresetError, ParamError, DeviceError
        Each a one-line `ClfxError` naming the file, frame or value.
    """
    if options is None:
        options = _options(option_values)
    elif option_values:
        raise TypeError("give options= or option keywords, not both")
    if not isinstance(options, RenderOptions):
        raise TypeError(f"options: {options!r} is not a clfx.RenderOptions")
    _check_look(look)
    _check_quality(options.quality)
    lk = look if isinstance(look, Look) and not set else load_look(look, set=set)
    # lazy: files (OpenImageIO, fileseq) cost `import clfx.api` ~0.5 s
    from clfx.pipeline.batch import Batch

    batch = Batch(look=lk, input_path=os.fspath(input), output_path=os.fspath(output),
                  options=options, verbosity=verbosity, on_frame=on_frame)
    batch.prepare()
    if distributed:
        # lazy: Dask costs ~0.6 s to import (measured); only a render on a cluster needs it
        from clfx.pipeline.distributed import render_distributed

        summary = render_distributed(batch, ClusterOptions.of(distributed), device=device)
        return RenderResult(summary, batch.reporter.reports, [j.output for j in batch.jobs])
    if runtime is None:
        runtime = runtime_soon(device)
    with batch.reading():   # the first frame is read while the device finishes setting up
        rt = runtime.result() if isinstance(runtime, Future) else runtime
        summary = batch.run(rt)
    reports = summary.pop("reports")
    return RenderResult(summary, reports, [r.output for r in reports])


def render_file(input, output, look: str | dict | Look = "default", **kw) -> RenderResult:
    """Render one image file to another (any format OpenImageIO reads; the output's
    extension picks its format).  Keywords: see :func:`render`."""
    from clfx.io.sequence import Pattern   # lazy: fileseq, as render

    if Pattern.parse(os.fspath(input)).is_sequence:
        raise SequenceError(f"{os.fspath(input)} is a sequence pattern; use render_sequence")
    return render(input, output, look, **kw)


def render_sequence(input, output, look: str | dict | Look = "default", *,
                    frames: str | None = None, **kw) -> RenderResult:
    """Render a frame sequence (``shot.#.exr`` -> ``out/shot.#.exr``), ``frames``
    like ``"1001-1100"`` (default: every frame on disk).  Keywords: see :func:`render`."""
    if frames is not None:
        kw["frames"] = frames
    return render(input, output, look, **kw)


def _options(values: dict) -> RenderOptions:
    """RenderOptions from keywords (pass options, e.g. ``depth_channel``, included)."""
    passes = {k: values.pop(k) for k in list(values) if k in PassOptions.names()}
    try:
        return RenderOptions(passes=PassOptions(**passes), **values)
    except TypeError as exc:
        raise TypeError(f"{exc} (see clfx.RenderOptions)") from None


def runtime_soon(device: str | None = None) -> Future:
    """Start creating the runtime on a thread (OpenCL releases the GIL) so device set-up
    overlaps reading the first frame."""
    pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="clfx-device")
    future = pool.submit(runtime, device)
    pool.shutdown(wait=False)
    return future
