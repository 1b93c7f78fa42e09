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
