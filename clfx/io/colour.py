"""Colour spaces from the OpenColorIO config that OpenImageIO uses (its built-in config, or the
one ``$OCIO`` names): the working space, the spaces of inputs and outputs, conversions,
chromaticities and RGB -> XYZ matrices.

Spaces
------
A space is named as OCIO knows it, by name or alias (``"lin_rec709"``, ``"ACEScg"``,
``"sRGB"``, ``"Linear Rec.2020"``, ``"ACEScct"``; ``"linear"`` is OpenImageIO's alias for
linear Rec.709), or, for an EXR whose ``chromaticities`` match no linear space of the config,
as ``"chromaticities:rx,ry,gx,gy,bx,by,wx,wy"`` (linear, converted by matrices; white points
adapted with Bradford).  ``"raw"`` (OCIO's data space) means: no conversion.

- The **working space** (`DEFAULT_WORKING`: scene-linear Rec.709, OIIO ``"lin_rec709"``;
  ``--working-space ACEScg`` supported) is the space effects see.  Trap: the ``scene_linear``
  role of OpenImageIO's built-in config is ACEScg, not clfx's default.
- An input's space: ``--colorspace``, else the file's ``oiio:ColorSpace`` (EXR
  ``colorInteropID``, PNG/JPEG/HDR tags), else an EXR's ``chromaticities``, else the format's
  default (sRGB for integer PNG/JPEG/TIFF/DPX, linear Rec.709 otherwise).  `input_space`.
- An output's space: ``--out-colorspace``, else the input's space when the output is of the
  same kind (scene-linear EXR/HDR/float TIFF from a linear space, display-referred PNG/JPEG/
  DPX/integer TIFF from an encoded one), else sRGB for display-referred outputs and the
  working space for linear ones.  `output_space`.
"""
from __future__ import annotations

import difflib
import functools
import math
import os
import stat

import numpy as np
import OpenImageIO as oiio

from clfx.core.colour import REC709_TO_XYZ
from clfx.core.errors import ImageIOError
from clfx.io._oiio import fail, geterror

DEFAULT_WORKING = "lin_rec709"
RAW = "raw"
XYZ_D65 = "lin_ciexyzd65_scene"      # the built-in config's scene-referred CIE XYZ (D65)
CHROMA_PREFIX = "chromaticities:"
CHROMA_MATCH_TOL = 2e-4              # EXR chromaticities are floats written from decimals

_BRADFORD = np.array([[0.8951, 0.2664, -0.1614],
                      [-0.7502, 1.7135, 0.0367],
                      [0.0389, -0.0685, 1.0296]])
_D65 = (0.3127, 0.3290)


def config_file() -> str | None:
    """The OCIO config file ``$OCIO`` names (None when unset, empty or an ``ocio://`` URI):
    an input of every render."""
    path = os.environ.get("OCIO", "")
    return path if path and not path.startswith("ocio://") else None


_CHECKED: set[str] = set()


def check_config() -> None:
    """Raise `ImageIOError` in one line if ``$OCIO`` names anything but a readable, valid
    OCIO config: a FIFO or device would block the OCIO library forever (it is never
    opened), and a broken config would silently be replaced by the built-in one."""
    path = config_file()
    if path is None or path in _CHECKED:
        return

    try:
        mode = os.stat(path).st_mode
    except OSError as exc:
        raise ImageIOError(f"$OCIO {path}: cannot read the OCIO config: {exc.strerror} "
                           f"(unset OCIO for the built-in config)") from None
    if not stat.S_ISREG(mode):
        kind = "a folder" if stat.S_ISDIR(mode) else \
            "a FIFO" if stat.S_ISFIFO(mode) else "a special file"
        raise ImageIOError(f"$OCIO {path}: the OCIO config must be a regular file, not {kind}")
    cfg = oiio.ColorConfig(path)            # (OpenImageIO's shared config left alone)
    if cfg.configname() == "built-in":      # OpenImageIO fell back: the config did not load
        why = " ".join((cfg.geterror() or "").split()) or "it did not load"
        raise ImageIOError(f"$OCIO {path}: not a usable OCIO config ({why}); fix it or unset "
                           f"OCIO for the built-in config")
    _CHECKED.add(path)


def config():
    """OpenImageIO's colour configuration ($OCIO, else its built-in OCIO config); a broken
    ``$OCIO`` is an error (`check_config`), never silently the built-in config."""
    check_config()
    return oiio.ColorConfig.default_colorconfig()


def is_raw(space: str | None) -> bool:
    return space is None or space.lower() == RAW or (
        not space.startswith(CHROMA_PREFIX) and config().getColorSpaceIndex(space) >= 0
        and config().isData(space))


def resolve(name: str, what: str = "colour space") -> str:
    """The config's name for ``name`` (an alias or role allowed); ``"raw"`` stays ``"raw"``.

    Raises
    ------
    ImageIOError
        Unknown to the config: the message lists the closest names.
    """
    if name is None:
        raise ImageIOError(f"no {what} given")
    if name.startswith(CHROMA_PREFIX):
        _parse_chromaticities(name)
        return name
    if name.lower() == RAW:
        return RAW
    cfg = config()
    if cfg.getColorSpaceIndex(name) < 0:
        names = list(cfg.getColorSpaceNames())
        for n in list(names):
            names += list(cfg.getAliases(n))
        close = difflib.get_close_matches(name, names, n=3, cutoff=0.4)
        hint = f"; did you mean {', '.join(repr(c) for c in close)}?" if close else ""
        raise ImageIOError(f"{what} {name!r} is not in the OCIO config "
                           f"({cfg.configname() or 'built-in'}){hint}")
    return cfg.resolve(name)


def is_linear(space: str) -> bool:
    """Scene-linear (or display-linear) values: conversions between such spaces are 3x3."""
    if space.startswith(CHROMA_PREFIX) or space == RAW:
        return True
    return bool(config().isColorSpaceLinear(resolve(space)))


def same(a: str | None, b: str | None) -> bool:
    """Whether converting from ``a`` to ``b`` changes nothing."""
    if is_raw(a) or is_raw(b) or a == b:
        return True
    if a.startswith(CHROMA_PREFIX) or b.startswith(CHROMA_PREFIX):
        return np.allclose(rgb_to_xyz(a), rgb_to_xyz(b), atol=1e-7)
    return bool(config().equivalent(a, b))


def chromaticities(space: str) -> tuple[float, ...] | None:
    """(rx, ry, gx, gy, bx, by, wx, wy) of a linear space, None for non-linear or data ones."""
    if space.startswith(CHROMA_PREFIX):
        return _parse_chromaticities(space)
    if space == RAW or not is_linear(space):
        return None
    c = config().get_chromaticities(resolve(space))
    return tuple(float(v) for v in c) if c else None


def _parse_chromaticities(space: str) -> tuple[float, ...]:
    try:
        vals = tuple(float(v) for v in space[len(CHROMA_PREFIX):].split(","))
    except ValueError:
        vals = ()
    if len(vals) != 8 or not all(math.isfinite(v) for v in vals):
        raise ImageIOError(f"colour space {space!r}: expected {CHROMA_PREFIX} and 8 numbers")
    return vals


def from_chromaticities(chroma) -> str:
    """The config's linear space with these chromaticities, else a ``chromaticities:`` space."""
    chroma = tuple(float(v) for v in chroma)
    if len(chroma) != 8 or not all(math.isfinite(v) for v in chroma):
        raise ImageIOError(f"chromaticities {chroma!r} are not 8 numbers")
    cfg = config()
    for name in cfg.getColorSpaceNames():
        if cfg.isData(name) or not cfg.isColorSpaceLinear(name):
            continue
        c = cfg.get_chromaticities(name)
        if c and max(abs(a - b) for a, b in zip(c, chroma)) <= CHROMA_MATCH_TOL and \
                "display" not in name.lower():
            return cfg.resolve(name)
    return CHROMA_PREFIX + ",".join(f"{v:.6g}" for v in chroma)


# --------------------------------------------------------------------------------------------
# Matrices

def _xy_to_xyz(x: float, y: float) -> np.ndarray:
    return np.array([x / y, 1.0, (1.0 - x - y) / y])


def _npm(chroma) -> np.ndarray:
    """RGB -> XYZ of a linear space from its chromaticities (SMPTE RP 177), own white."""
    rx, ry, gx, gy, bx, by, wx, wy = chroma
    prim = np.stack([_xy_to_xyz(rx, ry), _xy_to_xyz(gx, gy), _xy_to_xyz(bx, by)], axis=1)
    return prim * np.linalg.solve(prim, _xy_to_xyz(wx, wy))[None, :]


def _bradford(src_white, dst_white) -> np.ndarray:
    s, d = _BRADFORD @ _xy_to_xyz(*src_white), _BRADFORD @ _xy_to_xyz(*dst_white)
    return np.linalg.inv(_BRADFORD) @ np.diag(d / s) @ _BRADFORD


def _ocio_matrix(src: str, dst: str) -> np.ndarray:
    """The 3x3 matrix OCIO applies between two linear spaces (from the three primaries)."""
    px = np.array([[[1, 0, 0, 1], [0, 1, 0, 1], [0, 0, 1, 1]]], np.float32)
    out = oiio.ImageBufAlgo.colorconvert(oiio.ImageBuf(px), src, dst, False)
    if out.has_error or not out.initialized:
        raise ImageIOError(f"cannot convert colour {src!r} -> {dst!r}: {geterror(out)}")
    return np.asarray(out.get_pixels(oiio.FLOAT), np.float64).reshape(3, 4)[:, :3].T


def rgb_to_xyz(space: str) -> np.ndarray:
    """The 3x3 matrix from a linear space's RGB to CIE XYZ (D65 white, Y = luminance).

    For config spaces, the matrix OCIO applies (its chromatic adaptation included, e.g.
    ACEScg's D60 white to D65); for ``chromaticities:`` spaces, the RP 177 matrix followed by
    a Bradford adaptation to D65.  This is what spectral effects need for the working space
    (`clfx.core.frame.Frame.colorspace` names it).

    Raises
    ------
    ImageIOError
        A non-linear or data space, or one unknown to the config.
    """
    if space.startswith(CHROMA_PREFIX):
        chroma = _parse_chromaticities(space)
        return _bradford(chroma[6:], _D65) @ _npm(chroma)
    name = resolve(space)
    if name == RAW or not is_linear(name):
        raise ImageIOError(f"colour space {space!r} is not linear: no RGB -> XYZ matrix")
    if config().getColorSpaceIndex(XYZ_D65) >= 0:
        return _ocio_matrix(name, XYZ_D65)
    chroma = chromaticities(name)
    if chroma is None:
        raise ImageIOError(f"colour space {space!r} has no chromaticities in the OCIO config")
    return _bradford(chroma[6:], _D65) @ _npm(chroma)


@functools.lru_cache(maxsize=32)
def _working_matrix(space: str) -> np.ndarray:
    if same(space, DEFAULT_WORKING):
        return REC709_TO_XYZ
    m = rgb_to_xyz(space)
    m.setflags(write=False)
    return m


def working_rgb_to_xyz(space: str | None) -> np.ndarray:
    """The RGB -> XYZ matrix effects get for a working space (``ctx.rgb_to_xyz``): OCIO's
    (`rgb_to_xyz`), except for linear Rec.709 (None, raw, or a space equivalent to
    `DEFAULT_WORKING`), which gets `clfx.core.colour.REC709_TO_XYZ`, the IEC 61966-2-1
    matrix the effects' Rec.709 tables are built with (2e-4 from OCIO's), so Rec.709 renders
    keep their pixels."""
    if space is None or is_raw(space):
        return REC709_TO_XYZ
    return _working_matrix(resolve(space))


# --------------------------------------------------------------------------------------------
# Converting pixels

def convert(rgba: np.ndarray, src: str | None, dst: str | None, path) -> np.ndarray:
    """Convert premultiplied float32 RGBA from ``src`` to ``dst`` (alpha kept).

    Linear -> linear conversions are 3x3 matrices on the premultiplied colour; others go
    through OCIO with alpha divided out around the transfer functions.  ``raw``/None on either
    side, or equivalent spaces, return ``rgba`` unchanged.
    """
    if same(src, dst):
        return rgba
    rgba = np.asarray(rgba, np.float32)
    if is_linear(src) and is_linear(dst):
        if src.startswith(CHROMA_PREFIX) or dst.startswith(CHROMA_PREFIX):
            m = np.linalg.solve(rgb_to_xyz(dst), rgb_to_xyz(src))
        else:
            m = _ocio_matrix(src, dst)
        out = rgba.copy()       # float32 products: 1e-7 relative, no float64 copy of a frame
        out[..., :3] = rgba[..., :3] @ m.T.astype(np.float32)
        return out
    if src.startswith(CHROMA_PREFIX):         # via OCIO's XYZ: matrix in, OCIO out
        return convert(convert(rgba, src, XYZ_D65, path), XYZ_D65, dst, path)
    if dst.startswith(CHROMA_PREFIX):
        return convert(convert(rgba, src, XYZ_D65, path), XYZ_D65, dst, path)
    buf = oiio.ImageBuf(np.ascontiguousarray(rgba))
    out = oiio.ImageBufAlgo.colorconvert(buf, src, dst, True)
    if out.has_error or not out.initialized:
        raise fail(path, f"cannot convert colour {src!r} -> {dst!r} for", geterror(out))
    return np.asarray(out.get_pixels(oiio.FLOAT), np.float32).reshape(rgba.shape)


# --------------------------------------------------------------------------------------------
# Which space: inputs and outputs

def input_space(colorspace: str | None, *, file_space: str | None, chroma, display: bool
                ) -> tuple[str, str]:
    """(space of an input's stored values, why).

    Parameters
    ----------
    colorspace : str, optional
        ``--colorspace``: wins over everything; ``"raw"`` = no conversion.
    file_space : str, optional
        The file's ``oiio:ColorSpace``; ignored (with a reason) if unknown to the config.
    chroma : sequence of 8 floats, optional
        The file's ``chromaticities`` attribute (EXR).
    display : bool
        Integer non-EXR/HDR file: sRGB by default.
    """
    if colorspace:
        return resolve(colorspace, "--colorspace"), "--colorspace"
    why = ""
    if file_space:
        try:
            return resolve(file_space), f"file's oiio:ColorSpace {file_space!r}"
        except ImageIOError:
            why = f"file's oiio:ColorSpace {file_space!r} unknown to the OCIO config; "
    if chroma is not None and not display:
        try:
            return from_chromaticities(chroma), "file's chromaticities"
        except ImageIOError:
            why += "file's chromaticities unusable; "
    if display:
        return resolve("sRGB"), why + "integer file: sRGB"
    return resolve(DEFAULT_WORKING), why + "float file: linear Rec.709"


def output_space(colorspace: str | None, *, source: str | None, working: str,
                 display: bool) -> str:
    """Space to write an output in (see the module docstring); ``"raw"`` = as they are."""
    if colorspace:
        return resolve(colorspace, "--out-colorspace")
    if source and source != RAW and (is_linear(source) != display):
        return source
    return resolve("sRGB") if display else working
