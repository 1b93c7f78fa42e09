"""One exception hierarchy; every message names the object, the value and what was expected."""


class ClfxError(Exception):
    """Base of every error clfx reports to the user as one line (exit code 1)."""

    exit_code = 1


class ParamError(ClfxError):
    """A parameter value has the wrong type or lies outside its hard range."""


class ClipError(ClfxError):
    """A required input clip (depth, velocity) is missing or malformed."""


class PresetError(ClfxError):
    """A look (YAML preset) is malformed: names file, line and key."""


class KernelBuildError(ClfxError):
    """An OpenCL program failed to build; the message carries the build log."""


class DeviceError(ClfxError):
    """No usable OpenCL device."""


class ImageIOError(ClfxError):
    """A frame could not be read or written; names the file."""


class SequenceError(ClfxError):
    """A frame pattern or range is malformed, or frames are missing."""


class ClusterError(ClfxError):
    """A Dask cluster could not be started or reached, or its workers kept dying."""


# -- options named as the caller spells them ------------------------------------------------
_API_NAMES = {
    "--overwrite": "overwrite=True", "--skip-existing": "skip_existing=True",
    "--skip-missing": "skip_missing=True", "--log": "log_path", "--raw": "raw_size",
    "--raw-format": "raw_format", "--set": "set", "--workers": "workers",
    "--scheduler": "scheduler", "--chunk": "chunk", "--colorspace": "colorspace",
    "--out-colorspace": "out_colorspace", "--working-space": "working_space",
    "--depth": "depth_path", "--velocity": "velocity_path", "--depth-zero": "depth_zero",
    "--passes": "passes_mode", "--quality": "quality", "--frames": "frames", "--view": "view",
    "--keep-overscan": "keep_overscan=True",
}
_SPELLING = ["api"]


def speak(spelling: str) -> None:
    """Name options in errors as ``"cli"`` (the ``clfx`` command: ``--overwrite``) or
    ``"api"`` (`clfx.api`'s keywords: ``overwrite=True``, the default).  The command line
    sets ``"cli"`` while it runs and ``"api"`` again when it ends."""
    _SPELLING[0] = spelling


def option(flag: str, value=None) -> str:
    """A render option as the caller spells it: ``option("--overwrite")`` is
    ``--overwrite`` on the command line and ``overwrite=True`` in the API;
    ``option("--raw", "1920x1080")`` is ``--raw 1920x1080`` or ``raw_size='1920x1080'``;
    ``option("--set", "grain.amount=0")`` is ``--set grain.amount=0`` or
    ``set=['grain.amount=0']``.  The one place messages of the layers below the CLI name
    an option (`speak` says whose words)."""
    if _SPELLING[0] == "cli" or flag not in _API_NAMES:
        return flag if value is None else f"{flag} {value}"
    name = _API_NAMES[flag]
    if value is None or "=" in name:
        return name
    return f"set=[{str(value)!r}]" if flag == "--set" else f"{name}={value!r}"
