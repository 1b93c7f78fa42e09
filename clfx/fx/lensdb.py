"""Real lens profiles from the lensfun database (bundled with the ``lensfunpy`` package).

Looks up lenses by maker/model, reads their calibration (distortion, transverse chromatic
aberration, vignetting) interpolated at a focal length, aperture and focus distance, and
describes lensfun's coordinate systems so ``clfx.plugins.lens`` can apply the models itself.

Interpolation between calibration points is lensfun's own (``lfLens::InterpolateDistortion``
/ ``InterpolateTCA`` / ``InterpolateVignetting``, reached through ``lensfunpy.Lens
.interpolate_*``), so clfx's coefficients are exactly those lensfun uses.  The models and
the maps are clfx's (``clfx/plugins/lens.py``); lensfunpy's ``Modifier`` is used only by
the tests, as a cross-check.

Coordinates (lensfun 0.3.x, ``lfModifier::lfModifier``), for an image of W x H pixels with
pixel centres at integers (0 .. W-1):

    W' = W - 1, H' = H - 1, size = min(W', H'), a_img = max(W', H') / size
    c = crop_cal / crop * sqrt(a_cal^2 + 1) / sqrt(a_img^2 + 1)
    x = px * (2 c / size) - (W' / size * c + lens.center_x)     (same for y)

so r = 1 is half the short side of the calibration sensor's frame (``crop_cal`` and aspect
``a_cal``, default 3:2), mapped onto this image by the ratio of crop factors (diagonals).
Vignetting uses r / sqrt(a_cal^2 + 1) (1 = the calibration frame's corner).

The database and the table of calibration aspect ratios are host data read once per process
(``functools.lru_cache``: lensfunpy's bundled files, no device memory); the maps and tables
derived from them live in the runtime's cache (``clfx.plugins.lens``).
"""
from __future__ import annotations

import difflib
import functools
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from clfx.core.errors import ParamError

FULL_FRAME_DIAGONAL_MM = math.hypot(36.0, 24.0)
DEFAULT_ASPECT = 1.5


@functools.lru_cache(maxsize=1)
def database():
    """The lensfun database bundled with lensfunpy (loaded once per process)."""
    try:
        # lazy: lensfunpy is ~0.1 s; listing the effects (discover) loads this module, not it
        import lensfunpy
    except ImportError as exc:  # pragma: no cover - dependency missing
        raise ParamError(f"lens profiles need the lensfunpy package ({exc})") from exc
    return lensfunpy.Database()


@functools.lru_cache(maxsize=1)
def _aspect_ratios() -> dict:
    """(maker, model) -> calibration aspect ratio, read from the bundled XML files.

    lensfunpy does not expose ``lfLens::AspectRatio``; lensfun's default is 3:2.
    """
    import lensfunpy  # lazy: as database()

    out = {}
    folder = Path(lensfunpy.__file__).parent / "db_files"
    for path in sorted(folder.glob("*.xml")):
        try:
            root = ET.parse(path).getroot()
        except ET.ParseError:
            continue
        for lens in root.iter("lens"):
            ar = lens.find("aspect-ratio")
            if ar is None or not (ar.text or "").strip():
                continue
            text = ar.text.strip()
            try:
                value = (float(text.split(":")[0]) / float(text.split(":")[1])
                         if ":" in text else float(text))
            except (ValueError, ZeroDivisionError):
                continue
            maker = (lens.findtext("maker") or "").strip()
            for model in lens.findall("model"):
                if model.get("lang") is None:
                    out[(maker.lower(), (model.text or "").strip().lower())] = value
    return out


def aspect_ratio(lens) -> float:
    """Aspect ratio (long / short side) of the sensor the lens was calibrated on."""
    a = _aspect_ratios().get((lens.maker.lower(), lens.model.lower()), DEFAULT_ASPECT)
    return a if a >= 1 else 1.0 / a


def _rounded(v, digits=3):
    return None if v is None else round(float(v), digits)


def describe(lens) -> dict:
    """A JSON-friendly summary of one lens (for ``clfx lenses``)."""
    return {
        "maker": lens.maker, "model": lens.model,
        "focal_range": [_rounded(lens.min_focal), _rounded(lens.max_focal)],
        "max_aperture": _rounded(lens.min_aperture), "crop_factor": _rounded(lens.crop_factor, 4),
        "type": str(lens.type).split(".")[-1].lower(), "mounts": list(lens.mounts),
        "distortion": bool(lens.calib_distortion), "tca": bool(lens.calib_tca),
        "vignetting": bool(lens.calib_vignetting),
    }


def _tokens(text: str) -> list[str]:
    return [t for t in text.lower().replace("/", " ").split() if t]


def find_lenses(query: str, limit: int = 50) -> list[dict]:
    """Lenses whose maker + model contain every word of ``query`` (case-insensitive).

    Results are sorted by maker and model; an empty query lists the first ``limit``.
    Each entry: maker, model, focal_range (mm), max_aperture (f-number), crop_factor, type,
    mounts and which calibrations it has (distortion, tca, vignetting).
    """
    words = _tokens(query or "")
    hits = []
    for lens in database().lenses:
        hay = f"{lens.maker} {lens.model}".lower()
        if all(w in hay for w in words):
            hits.append(lens)
    hits.sort(key=lambda l: (l.maker.lower(), l.model.lower()))
    return [describe(l) for l in hits[:max(int(limit), 0)]]


def get_lens(maker: str, model: str, crop: float | None = None):
    """The lensfunpy Lens named ``model`` (exact, case-insensitive; maker may be empty).

    When the database lists the model several times (per mount or calibration sensor), the
    entry whose crop factor is closest to ``crop`` without exceeding it wins.  Raises
    ParamError naming the closest models when none match, or when makers conflict.
    """
    lenses = database().lenses
    m = model.strip().lower()
    k = maker.strip().lower()
    exact = [l for l in lenses if l.model.lower() == m and (not k or l.maker.lower() == k)]
    makers = sorted({l.maker for l in exact})
    if len(makers) > 1:
        raise ParamError(f"lens: model {model!r} is made by several makers "
                         f"({', '.join(makers)}); set maker")
    if exact:
        # the same lens may be listed once per mount or calibration sensor: prefer the
        # calibration whose crop factor is closest to (and not above) the camera's
        return min(exact, key=lambda l: (crop is not None and l.crop_factor > crop * 1.01,
                                         abs(math.log(l.crop_factor / crop)) if crop else 0.0))
    sub = [l for l in lenses if m and m in l.model.lower() and (not k or l.maker.lower() == k)]
    if len(sub) == 1:
        return sub[0]
    names = [l.model for l in lenses]
    close = sub[:5] and [l.model for l in sub[:5]] or difflib.get_close_matches(model, names, n=3)
    hint = f"; did you mean {', '.join(repr(c) for c in close)}?" if close else ""
    raise ParamError(f"lens: no lens {model!r}{' by ' + repr(maker) if maker else ''} in the "
                     f"lensfun database{hint} (search with `clfx lenses WORDS`)")


@dataclass(frozen=True)
class Calibration:
    """Interpolated calibration of one lens at one focal length / aperture / distance.

    ``distortion``: (model, terms) with model in poly3, poly5, ptlens, or None.
    ``tca``: (model, terms) with model in linear ([kr, kb]) or poly3 ([vr, vb, cr, cb, br, bb]).
    ``vignetting``: (model, terms) with model pa ([k1, k2, k3]).
    """

    distortion: tuple | None
    tca: tuple | None
    vignetting: tuple | None
    crop_factor: float
    aspect_ratio: float
    center_x: float
    center_y: float


def _model_name(m) -> str:
    return str(m).split(".")[-1].lower()


def calibration(lens, focal: float, aperture: float, distance: float) -> Calibration:
    """Lensfun's interpolation of the lens's calibration at (focal mm, f-number, metres)."""
    def pick(cal, allowed):
        if cal is None:
            return None
        name = _model_name(cal.model)
        return (name, tuple(float(t) for t in cal.terms)) if name in allowed else None

    dist = pick(lens.interpolate_distortion(focal) if lens.calib_distortion else None,
                ("poly3", "poly5", "ptlens"))
    tca = pick(lens.interpolate_tca(focal) if lens.calib_tca else None, ("linear", "poly3"))
    vig = pick(lens.interpolate_vignetting(focal, aperture, distance)
               if lens.calib_vignetting else None, ("pa",))
    return Calibration(dist, tca, vig, float(lens.crop_factor), aspect_ratio(lens),
                       float(lens.center_x), float(lens.center_y))


def crop_factor(camera, width: int, height: int, pixel_aspect: float = 1.0) -> float:
    """The camera block's crop factor: full-frame diagonal / sensor diagonal."""
    sw = camera.sensor_width
    sh = camera.sensor_height or sw * height / max(width * pixel_aspect, 1e-9)
    return FULL_FRAME_DIAGONAL_MM / math.hypot(sw, sh)


@dataclass(frozen=True)
class Normalisation:
    """lensfun's pixel <-> normalised coordinates for a W x H image (see module notes)."""

    scale: float        # normalised units per pixel
    center_x: float     # optical centre, pixel-index coordinates (centres at integers)
    center_y: float
    vignetting_unit: float   # divide normalised r by this for the vignetting radius

    @classmethod
    def for_image(cls, cal: Calibration, crop: float, width: int, height: int):
        wp = float(width - 1 if width >= 2 else 1)
        hp = float(height - 1 if height >= 2 else 1)
        size = min(wp, hp)
        a_img = max(wp, hp) / size
        arc = math.sqrt(cal.aspect_ratio ** 2 + 1)
        c = cal.crop_factor / crop * arc / math.sqrt(a_img ** 2 + 1)
        scale = 2.0 * c / size
        cx_norm = wp / size * c + cal.center_x
        cy_norm = hp / size * c + cal.center_y
        return cls(scale, cx_norm / scale, cy_norm / scale, arc)
