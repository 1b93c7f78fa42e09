"""clfx: OpenCL-accelerated camera-defect effects for image sequences.

Real cameras are not perfect pinholes.  clfx adds their defects back to rendered frames, from
scene-linear radiance, as post effects: depth of field, defocus, noise and grain, motion blur,
glare, streaks, flares, coronas, vignetting, distortion and chromatic aberration.

The Python API (`clfx.api`; the ``clfx`` command is a thin layer over it):

``load_look(look, set=[...])``
    A look by name, YAML file, dict, or from an output clfx stamped; ``--set`` overrides.
``render_array(rgba, look, depth=, velocity=, channels=, frame=)``
    One image in memory -> ``ArrayResult(rgba, window, report)``.
``render_file(input, output, look, **options)``, ``render_sequence(...)``, ``render(...)``
    Files and sequences -> ``RenderResult(summary, reports, outputs)``.
``runtime(device=None)``
    The OpenCL device everything runs on.
``RenderOptions``, ``PassOptions``, ``Look``, ``FrameReport``
    The typed options and results.

Example::

    import clfx
    look = clfx.load_look("cinema", set=["camera.focus_distance=1001:2.0,1040:5.5"])
    result = clfx.render_sequence("shot.#.exr", "out/shot.#.exr", look,
                                  frames="1001-1040", overwrite=True)
    print(result.summary["fps"], result.reports[0].as_dict()["ran"])

Errors: every error clfx reports is a ``clfx.ClfxError`` (one line naming the file, frame,
channel or key): ``ParamError``, ``ClipError``, ``PresetError``, ``SequenceError``,
``ImageIOError`` (``OutputExistsError``: an output exists and ``overwrite=True`` was not
given), ``KernelBuildError``, ``DeviceError``, ``ClusterError``::

    try:
        clfx.render_file("in.exr", "out.exr", "cinema")
    except clfx.OutputExistsError:
        ...

Names are imported on first use, so ``import clfx`` stays cheap (no OpenCL, no OpenImageIO).
"""
from clfx._version import __version__
from clfx.core.errors import (ClfxError, ClipError, ClusterError, DeviceError, ImageIOError,
                              KernelBuildError, ParamError, PresetError, SequenceError)

_API = ("ArrayResult", "ClusterOptions", "FrameReport", "Look", "PassOptions", "RenderOptions",
        "RenderResult",
        "load_look", "look_from_stamp", "render", "render_array", "render_file",
        "render_sequence", "runtime")
__all__ = ["__version__", *_API,
           "ClfxError", "ClipError", "ClusterError", "DeviceError", "ImageIOError",
           "KernelBuildError", "ParamError", "PresetError", "SequenceError", "OutputExistsError"]


def __getattr__(name: str):
    if name in _API:
        from clfx import api   # lazy: `import clfx` takes 4 ms, clfx.api 1.6 s (device, OIIO)

        return getattr(api, name)
    if name == "OutputExistsError":     # lives with the writer (OpenImageIO): on first use
        from clfx.io.write import OutputExistsError   # lazy: clfx.io.write takes 0.7 s

        return OutputExistsError
    raise AttributeError(f"module 'clfx' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + list(_API) + ["OutputExistsError"])
