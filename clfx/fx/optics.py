"""Lens prescriptions and their two-reflection ghosts by paraxial ray-transfer matrices.

A lens is a sequence of spherical surfaces (:class:`Prescription`), read from a plain dict
(the pipeline loads the YAML files in ``presets/lenses/``).  :func:`ghosts` enumerates every
ghost that two reflections make (light reflected back by surface ``i``, then forward again by
an earlier surface ``j < i``) and returns, per ghost and per wavelength, what the lens-flare
kernel needs to draw it: where its centre lies on the line through the optical centre and
the light, how large it is, and how much of the light it carries.

Notes
-----
**Model.**  Paraxial optics with 2x2 ray-transfer matrices acting on ``(y, u)``: the ray's
height ``y`` (mm) at a surface's vertex plane and its slope ``u = dy/dz``.  Translation by
``d`` is ``[[1, d], [0, 1]]``; refraction from index ``n1`` into ``n2`` at a surface of
radius ``R`` (positive when the centre of curvature lies towards the image) is
``[[1, 0], [(n1 - n2) / (R n2), n1 / n2]]``; reflection is ``[[1, 0], [2 / R, 1]]``.  After a
reflection the path is *unfolded*: the axis is flipped, so the surfaces met on the way back
are refractions with radius ``-R`` and media swapped, and the second reflection uses ``-R``
too (Lee & Eisemann 2013, sec. 3; Hullin et al. 2011, sec. 3).  The determinant of a whole
path is ``n_object / n_image = 1`` (a check the tests make).

**A ghost.**  A distant point light at field slope ``u`` sends a parallel beam; a ray
entering the first vertex plane at height ``y0`` reaches surface crossing ``k`` at
``y_k = A_k y0 + B_k u`` and the image plane at ``y_s = A_s y0 + B_s u``.  Each crossing
(every surface on every pass, the stop included) passes only ``|y_k| <= a_k`` (its clear
semi-aperture), i.e. a disc of entrance heights of radius ``a_k / |A_k|`` centred on
``-B_k u / A_k``; the surviving beam is the intersection of these discs.  On the axis they
are concentric and the smallest one, the *limiting aperture* ``L`` (usually the stop: the
ghost is the image of the aperture polygon; otherwise a lens rim: a round ghost), is the
ghost.  Its image on the sensor is a copy of that aperture scaled by ``A_s a_L / A_L``
(negative: inverted) centred at ``(B_s - A_s B_L / A_L) u``.  Dividing by the light's own
image height ``h = (B_p - A_p B_stop / A_stop) u`` (the primary, no-reflection path at
the reference wavelength) gives the ghost's *centre factor* ``c``: with the light imaged
at ``x`` from the optical centre, the ghost is centred at ``c x`` (ghosts lie on the line
through the centre and the light, L&E sec. 3).  ``c`` and the radius do not depend on
``u``.  Every other crossing's disc maps the same way (centre ``c_k x``, radius
``|A_s| a_k / |A_k|``); off the axis they slide apart along that line, cut into the ghost
(cat's-eye ghosts) or hide it.  Since all centres lie on one line, their intersection is
exactly known along it: :meth:`GhostTable.for_light` keeps the two discs that cut deepest
from either side and says which ghosts are hidden (Hullin et al. 2011 trace the same
clipping per ray).

**Energy.**  Fresnel reflectance at normal incidence (the paraxial limit): uncoated
``((n1 - n2) / (n1 + n2))**2``, 4 % for ``n = 1.5`` in air; a single-layer coating of
index ``n_c`` and quarter-wave optical thickness at ``lambda0`` (``n_c d = lambda0 / 4``)
has the Airy reflectance ``R = (r1^2 + r2^2 + 2 r1 r2 cos d) / (1 + r1^2 r2^2 + 2 r1 r2
cos d)`` with ``r1 = (n1 - n_c) / (n1 + n_c)``, ``r2 = (n_c - n2) / (n_c + n2)`` and
``d = pi lambda0 / lambda``, minimal at ``lambda0`` where it is ``((n1 n2 - n_c^2) /
(n1 n2 + n_c^2))**2`` (Born & Wolf, sec. 1.6.4; Hullin et al. 2011, sec. 4.2).  A stack of
films (``Coating.layers``: the V-coats and three-layer broadband designs of multi-coated
lenses, ``MULTILAYER_DESIGNS``) by the transfer-matrix method, :func:`thin_film_reflectance`
(Macleod ch. 2): its residual reflectance has one or two minima and humps between them, so
ghosts take green, magenta, amber or blue tints from the product of their two surfaces'
curves (checked against the closed forms above, textbook quarter-wave stacks and the
reference's film-by-film recursion, ``tests/fx/test_optics.py``).  Glass-air
surfaces carry the lens's coating unless a surface says otherwise; cemented (glass-glass)
surfaces are bare.  A ghost's *transmission* is ``R_i R_j`` times ``(1 - R_k)`` of every
other crossing on its path.  Its *energy* is the fraction of the light entering the
entrance pupil that lands in it: transmission times ``(r_in / r_EP)**2``, the ghost beam's
entrance area over the pupil's.  Its irradiance relative to the light's over the pupil is
``transmission / A_s**2`` (*intensity*; ``energy * r_EP**2 / radius**2`` on the axis), the
same however far clip discs cut it.  Coated two-reflection ghosts carry 1e-4 to 1e-6 of the
light: their dimness is physics, not a fudge factor.

**Dispersion.**  ``n(lambda) = A + B / lambda**2`` (Cauchy), fitted through ``n_d`` at the
helium d line (587.56 nm) with the principal dispersion ``n_F - n_C = (n_d - 1) / V_d``
(F 486.13 nm, C 656.27 nm): the Abbe number's definition (Schott TIE-29).  Air is 1.  Each
wavelength gets its own matrices, so ghost sizes and positions differ per colour channel:
the coloured fringes of real ghosts.

**Accuracy.**  Against an exact float64 ray tracer (``tests/fx/test_optics.py``): near the
axis at f/16, ghosts whose largest paraxial incidence angle (``incidence_rad``) is at most
0.14 rad agree to 2-3 % in centre, radius and energy; beyond 0.2 rad aberrations shift,
resize and dim real ghosts by tens of percent (their centre factor can be off by 1-3).
Errors grow off the axis (median centre error 0.002 at 1 degree, 0.03 at 10 degrees).
Wide open, rim rays of a fast lens meet surfaces far from normal incidence, some reflect
totally inside the glass, and those ghosts are several times brighter than the table says.

Not modelled: the sensor/cover-glass reflections, aspheres, diffraction (starbursts and
the ring structure of an out-of-focus aperture; the kernel's business), and reflectance
at oblique incidence.  Every array is float64 on the host; for a 12-element lens (21
reflecting surfaces, 210 ghosts, three wavelengths) :func:`ghosts` takes about 5 ms and
:meth:`GhostTable.for_light` about 5 ms for 8 lights (one core).  The plugin should keep the
table in ``rt.cache`` under the prescription, f-number and wavelengths; nothing here keeps
state.

References
----------
.. [1] S. Lee and E. Eisemann, "Practical real-time lens-flare rendering", Computer
   Graphics Forum 32(4) (EGSR 2013), pp. 1-6.
.. [2] M. Hullin, E. Eisemann, H.-P. Seidel and S. Lee, "Physically-based real-time lens
   flare rendering", ACM Trans. Graph. 30(4), 108 (SIGGRAPH 2011).
.. [3] M. Born and E. Wolf, "Principles of Optics", 7th ed., Cambridge 1999, sec. 1.6
   (stratified media, a single film) and 4.4 (paraxial imaging).
.. [4] W. J. Smith, "Modern Optical Engineering", 4th ed., McGraw-Hill 2008, ch. 2-3 and
   "Modern Lens Design", 2nd ed., McGraw-Hill 2005 (prescriptions, sign conventions).
.. [5] SCHOTT, "TIE-29: Refractive index and dispersion", 2016 (Abbe number, d/F/C lines).

Examples
--------
>>> p = Prescription.from_dict({"name": "singlet", "surfaces": [
...     {"stop": True, "thickness": 5.0, "semi_aperture": 6.25},
...     [51.68, 4.0, 1.5168, 64.17, 10.0], [0, 97.36, 1, 0, 10.0]]}, "singlet")
>>> round(p.efl(), 2), round(p.f_number_paraxial(), 2)
(100.0, 8.0)
>>> table = ghosts(p)
>>> table.pairs.tolist()        # the two reflecting surfaces: the back, then the front
[[2, 1]]
"""
from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, field, replace

import numpy as np

from clfx.core.errors import ParamError

D_LINE_NM = 587.56
F_LINE_NM = 486.13
C_LINE_NM = 656.27
RGB_WAVELENGTHS_NM = (610.0, 550.0, 465.0)
"""Representative wavelengths of the Rec.709 red, green and blue primaries (their dominant
wavelengths, rounded): the default sampling, one wavelength per channel."""

MGF2_INDEX = 1.38


def cauchy_index(nd: float, vd: float, wavelength_nm) -> np.ndarray:
    """Refractive index of a glass given ``n_d`` and Abbe number ``V_d`` (Cauchy fit).

    Parameters
    ----------
    nd : float
        Index at the helium d line, 587.56 nm.  ``nd == 1`` is air (no dispersion).
    vd : float
        Abbe number ``(n_d - 1) / (n_F - n_C)``; ignored for air.
    wavelength_nm : array_like
        Wavelengths in nanometres.

    Returns
    -------
    ndarray
        ``A + B / lambda**2`` with ``n(587.56) = nd`` and ``n(486.13) - n(656.27) =
        (nd - 1) / vd`` exactly.
    """
    lam = np.asarray(wavelength_nm, np.float64)
    if nd == 1.0:
        return np.ones_like(lam)
    b = ((nd - 1.0) / vd) / (F_LINE_NM ** -2 - C_LINE_NM ** -2)
    return nd + b * (lam ** -2 - D_LINE_NM ** -2)


def fresnel_reflectance(n1, n2) -> np.ndarray:
    """Reflectance of a bare interface at normal incidence, ``((n1 - n2) / (n1 + n2))**2``."""
    n1 = np.asarray(n1, np.float64)
    n2 = np.asarray(n2, np.float64)
    return ((n1 - n2) / (n1 + n2)) ** 2


def quarter_wave_reflectance(n1, n2, coating_index: float, design_nm: float,
                             wavelength_nm) -> np.ndarray:
    """Reflectance at normal incidence of a single-layer quarter-wave coating.

    Parameters
    ----------
    n1, n2 : array_like
        Indices of the media on either side (the result is the same from either side).
    coating_index : float
        Index of the film (MgF2: 1.38).
    design_nm : float
        Wavelength at which the film's optical thickness is a quarter wave.
    wavelength_nm : array_like
        Wavelengths in nanometres.

    Returns
    -------
    ndarray
        Airy reflectance of the film (Born & Wolf sec. 1.6.4), minimal at ``design_nm``.
    """
    n1 = np.asarray(n1, np.float64)
    n2 = np.asarray(n2, np.float64)
    lam = np.asarray(wavelength_nm, np.float64)
    r1 = (n1 - coating_index) / (n1 + coating_index)
    r2 = (coating_index - n2) / (coating_index + n2)
    cos_d = np.cos(np.pi * design_nm / lam)   # phase 4 pi n_c d / lambda, n_c d = l0 / 4
    num = r1 * r1 + r2 * r2 + 2.0 * r1 * r2 * cos_d
    return num / (1.0 + (r1 * r2) ** 2 + 2.0 * r1 * r2 * cos_d)


def thin_film_reflectance(n1, n2, layers, design_nm: float, wavelength_nm) -> np.ndarray:
    """Reflectance at normal incidence of a stack of thin films (transfer-matrix method).

    Parameters
    ----------
    n1, n2 : array_like
        Indices of the media on either side.  The stack faces the lower-index one (a lens's
        films face the air): ``layers[0]`` touches it, ``layers[-1]`` the other (the glass).
        A lossless stack reflects alike from either side, so which side the light comes
        from does not matter.
    layers : sequence of (index, quarter_waves)
        Each film's index and optical thickness ``n d`` in quarter waves of ``design_nm``
        (1: a quarter wave, 2: a half wave, which is *absent* at ``design_nm``).
    design_nm : float
        The wavelength the optical thicknesses are quarter waves of (nm).
    wavelength_nm : array_like
        Wavelengths in nanometres.

    Returns
    -------
    ndarray
        ``|r|^2`` with ``r = (eta0 B - C) / (eta0 B + C)`` and ``(B, C) = M_1 ... M_k (1,
        eta_s)``, each film's characteristic matrix ``M = [[cos d, i sin d / n], [i n sin d,
        cos d]]``, phase ``d = 2 pi n d / lambda = (pi / 2) q design / lambda`` (Macleod,
        *Thin-Film Optical Filters*, ch. 2; Born & Wolf sec. 1.6.2).  Film indices are taken
        constant over the visible (their dispersion shifts the curve by a few nm).
    """
    n1, n2, lam = np.broadcast_arrays(np.asarray(n1, np.float64), np.asarray(n2, np.float64),
                                      np.asarray(wavelength_nm, np.float64))
    n0, ns = np.minimum(n1, n2), np.maximum(n1, n2)    # the films face the lower index
    m11 = np.ones(lam.shape, np.complex128)
    m12 = np.zeros(lam.shape, np.complex128)
    m21 = np.zeros(lam.shape, np.complex128)
    m22 = np.ones(lam.shape, np.complex128)
    for n, q in layers:
        d = 0.5 * np.pi * q * design_nm / lam
        c, s = np.cos(d), 1j * np.sin(d)
        m11, m12, m21, m22 = (m11 * c + m12 * n * s, m11 * s / n + m12 * c,
                              m21 * c + m22 * n * s, m21 * s / n + m22 * c)
    b = m11 + m12 * ns
    c = m21 + m22 * ns
    return np.abs((n0 * b - c) / (n0 * b + c)) ** 2


MULTILAYER_DESIGNS = {
    "mgf2": ((MGF2_INDEX, 1.0),),
    "v-coat": ((MGF2_INDEX, 1.0), (1.63, 1.0)),
    "broadband": ((MGF2_INDEX, 1.0), (2.05, 2.0), (1.63, 1.0)),
    "broadband-hi": ((MGF2_INDEX, 1.0), (2.10, 2.0), (1.70, 1.0)),
}
"""Classic anti-reflection stacks, films from the air side as (index, quarter waves):
``mgf2`` one quarter wave of MgF2 (1.38); ``v-coat`` quarter-quarter MgF2 / Al2O3 (1.63): a
V-shaped curve, zero where ``n_H / n_L = sqrt(n_s)`` at the design wavelength, rising
steeply either side (purple-magenta residual when tuned to the green); ``broadband``
quarter-half-quarter MgF2 / ZrO2 (2.05) / Al2O3 (1.63), the three-layer design of most
multi-coated camera lenses: a W-shaped curve with two minima either side of the design
wavelength and a hump between them, so tuned to 500-540 nm it reflects green (the green
reflections and ghosts of real multi-coated lenses); ``broadband-hi`` the same with
ZrO2 2.10 / a 1.70 middle-index film (after Macleod ch. 4; H. A. Macleod, *Thin-Film Optical
Filters*, 4th ed., CRC 2010)."""


@dataclass(frozen=True)
class Coating:
    """An anti-reflection coating tuned to ``wavelength_nm``: one quarter-wave film of
    ``index`` (``layers`` empty, the default), or a stack ``layers`` of ``(index,
    quarter_waves)`` from the air side (:func:`thin_film_reflectance`)."""

    index: float = MGF2_INDEX
    wavelength_nm: float = 550.0
    layers: tuple[tuple[float, float], ...] = ()

    def reflectance(self, n1, n2, wavelength_nm) -> np.ndarray:
        if not self.layers:
            return quarter_wave_reflectance(n1, n2, self.index, self.wavelength_nm,
                                            wavelength_nm)
        return thin_film_reflectance(n1, n2, self.layers, self.wavelength_nm, wavelength_nm)


@dataclass(frozen=True)
class Surface:
    """One spherical surface and the medium behind it.

    ``radius`` in mm (``inf`` = flat; positive = centre of curvature towards the image),
    ``thickness`` to the next surface (the last surface's: to the image plane), ``nd`` and
    ``vd`` of the medium behind it (air: 1 and 0), ``semi_aperture`` the clear radius (mm),
    ``stop`` marks the aperture stop (a flat surface in air), ``coating`` ``None`` = bare.
    """

    radius: float
    thickness: float
    nd: float = 1.0
    vd: float = 0.0
    semi_aperture: float = math.inf
    stop: bool = False
    coating: Coating | None = None

    @property
    def curvature(self) -> float:
        return 0.0 if math.isinf(self.radius) else 1.0 / self.radius


_TOP_KEYS = ("name", "description", "source", "focal_length", "f_number", "coating",
             "scale", "surfaces")
_SURFACE_KEYS = ("radius", "thickness", "nd", "vd", "semi_aperture", "stop", "coating")
_ROW = ("radius", "thickness", "nd", "vd", "semi_aperture")


def _unknown(where, key, valid):
    close = difflib.get_close_matches(str(key), valid, n=1)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    raise ParamError(f"{where}: unknown key {key!r}{hint}; expected one of {', '.join(valid)}")


def _number(where, value, *, lo=-math.inf, hi=math.inf, what="a number", lo_open=False):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParamError(f"{where}: {value!r} is not {what}")
    v = float(value)
    if math.isnan(v) or v < lo or v > hi or (lo_open and v == lo):
        raise ParamError(f"{where}: {value!r} is not {what}")
    return v


_COATING_KEYS = ("index", "wavelength", "layers", "design")


def _coating(where, value, default):
    if value is None or value == "none" or value is False:
        return None
    if value == "default":
        return default
    if not isinstance(value, dict):
        raise ParamError(f"{where}: {value!r} is not a coating ({{index: 1.38, wavelength: "
                         f"550}}, {{design: broadband, wavelength: 520}}, {{layers: [[1.38, 1], "
                         f"[1.63, 1]], wavelength: 510}} or none)")
    for k in value:
        if k not in _COATING_KEYS:
            _unknown(where, k, _COATING_KEYS)
    design_nm = _number(f"{where}.wavelength", value.get("wavelength", 550.0), lo=300.0,
                        hi=1100.0, what="a design wavelength in [300, 1100] nm")
    if "design" in value and "layers" in value:
        raise ParamError(f"{where}: give either design or layers, not both")
    layers = value.get("layers")
    if "design" in value:
        name = value["design"]
        if name not in MULTILAYER_DESIGNS:
            _unknown(f"{where}.design", name, tuple(MULTILAYER_DESIGNS))
        layers = MULTILAYER_DESIGNS[name]
    elif layers is not None:
        if not isinstance(layers, (list, tuple)) or not 1 <= len(layers) <= 16:
            raise ParamError(f"{where}.layers: {layers!r} is not a list of 1 to 16 films "
                             f"[index, quarter waves]")
        out = []
        for k, film in enumerate(layers):
            w = f"{where}.layers[{k}]"
            if not isinstance(film, (list, tuple)) or len(film) != 2:
                raise ParamError(f"{w}: {film!r} is not a film [index, quarter waves]")
            out.append((_number(f"{w}[0]", film[0], lo=1.0, hi=3.0,
                                what="a film index in [1, 3]"),
                        _number(f"{w}[1]", film[1], lo=0.0, hi=20.0, lo_open=True,
                                what="an optical thickness in (0, 20] quarter waves")))
        layers = tuple(out)
    if layers is not None:
        if "index" in value:
            raise ParamError(f"{where}.index: a stack's films carry their own indices")
        return Coating(index=layers[0][0], wavelength_nm=design_nm, layers=tuple(layers))
    return Coating(
        index=_number(f"{where}.index", value.get("index", MGF2_INDEX), lo=1.0, hi=3.0,
                      what="a coating index in [1, 3]"),
        wavelength_nm=design_nm)


@dataclass(frozen=True)
class Prescription:
    """A rotationally symmetric lens: spherical surfaces from the object side to the image.

    Build one with :meth:`from_dict`.  ``focal_length`` and ``f_number`` are the published
    values (``None`` if unknown); :meth:`efl` and :meth:`f_number_paraxial` compute them.
    """

    name: str
    surfaces: tuple[Surface, ...]
    focal_length: float | None = None
    f_number: float | None = None
    description: str = ""
    source: str = ""
    coating: Coating | None = field(default=Coating())

    # -- construction ---------------------------------------------------------------------
    @classmethod
    def from_dict(cls, d, where: str = "lens") -> Prescription:
        """Validate a plain dict (a parsed YAML file) and build the prescription.

        Parameters
        ----------
        d : dict
            ``name``; ``surfaces``: a list, each a row ``[radius, thickness, nd, vd,
            semi_aperture]`` or a mapping with those keys plus ``stop: true`` and
            ``coating``; optional ``description``, ``source``, ``focal_length`` and
            ``f_number`` (published values, after scaling), ``coating`` (lens default for
            glass-air surfaces: ``{index: 1.38, wavelength: 550}``, the default, a stack
            ``{design: broadband, wavelength: 520}`` (``MULTILAYER_DESIGNS``) or ``{layers:
            [[1.38, 1], [1.63, 1]], wavelength: 510}`` (films from the air side: index,
            quarter waves), or ``none``), ``scale`` (multiplies every length of the table, so a patent's
            ``f = 100`` table can be listed as printed).  ``radius: 0`` (or ``.inf``) is
            flat; ``nd: 1`` is air.  Adjacent surfaces must not cross inside their clear
            apertures.
        where : str
            Names the source in error messages (the file path).

        Raises
        ------
        ParamError
            Naming ``where``, the key (``surfaces[3].thickness``), the value and what was
            expected.
        """
        if not isinstance(d, dict):
            raise ParamError(f"{where}: a lens prescription is a mapping, not {type(d).__name__}")
        for k in d:
            if k not in _TOP_KEYS:
                _unknown(where, k, _TOP_KEYS)
        name = d.get("name")
        if not isinstance(name, str) or not name:
            raise ParamError(f"{where}.name: {name!r} is not a non-empty string")
        for k in ("description", "source"):
            if not isinstance(d.get(k, ""), str):
                raise ParamError(f"{where}.{k}: {d[k]!r} is not a string")
        focal = d.get("focal_length")
        if focal is not None:
            focal = _number(f"{where}.focal_length", focal, lo=0.0, lo_open=True,
                            what="a positive focal length (mm)")
        fno = d.get("f_number")
        if fno is not None:
            fno = _number(f"{where}.f_number", fno, lo=0.1, hi=1000.0,
                          what="an f-number in [0.1, 1000]")
        scale = _number(f"{where}.scale", d.get("scale", 1.0), lo=0.0, hi=1e4, lo_open=True,
                        what="a positive scale factor")
        default_coating = _coating(f"{where}.coating", d.get("coating", "default"), Coating())
        rows = d.get("surfaces")
        if not isinstance(rows, list) or len(rows) < 2:
            raise ParamError(f"{where}.surfaces: {rows!r} is not a list of at least two "
                             f"surfaces")
        surfaces = []
        n_before = 1.0
        for idx, row in enumerate(rows):
            w = f"{where}.surfaces[{idx}]"
            if isinstance(row, (list, tuple)):
                if len(row) != len(_ROW):
                    raise ParamError(f"{w}: {row!r} is not a row [{', '.join(_ROW)}]")
                row = dict(zip(_ROW, row))
            if not isinstance(row, dict):
                raise ParamError(f"{w}: {row!r} is not a row [{', '.join(_ROW)}] or a mapping")
            for k in row:
                if k not in _SURFACE_KEYS:
                    _unknown(w, k, _SURFACE_KEYS)
            stop = row.get("stop", False)
            if not isinstance(stop, bool):
                raise ParamError(f"{w}.stop: {stop!r} is not true or false")
            r = row.get("radius", 0.0)
            r = _number(f"{w}.radius", r, what="a radius of curvature (mm; 0 = flat)")
            radius = math.inf if r == 0.0 or math.isinf(r) else r
            if "thickness" not in row:
                raise ParamError(f"{w}.thickness: missing (mm to the next surface)")
            last = idx == len(rows) - 1
            thickness = _number(f"{w}.thickness", row["thickness"], lo=0.0, hi=1e5,
                                lo_open=last,
                                what="a positive distance to the image plane (mm)" if last
                                else "a thickness >= 0 (mm)")
            nd = row.get("nd")
            nd = _number(f"{w}.nd", 1.0 if nd is None else nd, lo=1.0, hi=3.0,
                         what="a refractive index n_d in [1, 3]")
            vd = row.get("vd")
            if nd > 1.0:
                vd = _number(f"{w}.vd", vd, lo=5.0, hi=150.0,
                             what="an Abbe number V_d in [5, 150] for glass")
            else:
                vd = 0.0
            if "semi_aperture" not in row:
                raise ParamError(f"{w}.semi_aperture: missing (clear radius, mm)")
            semi = _number(f"{w}.semi_aperture", row["semi_aperture"], lo=0.0, hi=1e4,
                           lo_open=True, what="a positive clear semi-aperture (mm)")
            if semi > abs(radius):
                raise ParamError(f"{w}.semi_aperture: {semi!r} is larger than the radius of "
                                 f"curvature {abs(radius):g} mm (a sphere has no such rim)")
            if stop and (not math.isinf(radius) or nd != n_before or nd != 1.0):
                raise ParamError(f"{w}.stop: the aperture stop must be a flat surface in air "
                                 f"(radius 0, nd 1 on both sides)")
            glass_air = (nd == 1.0) != (n_before == 1.0)
            coating = _coating(f"{w}.coating", row["coating"], default_coating) \
                if "coating" in row else (default_coating if glass_air else None)
            surfaces.append(Surface(radius=radius * scale, thickness=thickness * scale, nd=nd,
                                    vd=vd, semi_aperture=semi * scale, stop=stop,
                                    coating=coating))
            n_before = nd
        stops = [i for i, s in enumerate(surfaces) if s.stop]
        if len(stops) != 1:
            raise ParamError(f"{where}.surfaces: {len(stops)} surfaces marked stop: true; "
                             f"expected exactly one aperture stop")
        for k in range(len(surfaces) - 1):
            a, b = surfaces[k], surfaces[k + 1]
            rim = min(a.semi_aperture, b.semi_aperture)
            edge = a.thickness + _sag(b.radius, rim) - _sag(a.radius, rim)
            if edge < -1e-9 * max(1.0, a.thickness):
                raise ParamError(f"{where}.surfaces[{k}].thickness: {a.thickness / scale!r}; "
                                 f"surfaces {k} and {k + 1} cross inside their clear "
                                 f"apertures (edge thickness {edge:.3g} mm at r = {rim:g} mm)")
        if surfaces[-1].nd != 1.0:
            raise ParamError(f"{where}.surfaces[{len(rows) - 1}].nd: {surfaces[-1].nd!r}; the "
                             f"image side must be air (nd 1)")
        return cls(name=name, surfaces=tuple(surfaces), focal_length=focal, f_number=fno,
                   description=d.get("description", ""), source=d.get("source", ""),
                   coating=default_coating)

    # -- basic optics ---------------------------------------------------------------------
    @property
    def stop_index(self) -> int:
        return next(i for i, s in enumerate(self.surfaces) if s.stop)

    def media(self, wavelength_nm) -> np.ndarray:
        """Indices ``(N + 1, W)``: row ``k`` before surface ``k``, row ``k + 1`` after it."""
        lam = np.atleast_1d(np.asarray(wavelength_nm, np.float64))
        rows = [np.ones_like(lam)]
        rows += [cauchy_index(s.nd, s.vd, lam) for s in self.surfaces]
        return np.stack(rows)

    def reflectances(self, wavelength_nm) -> np.ndarray:
        """Normal-incidence reflectance ``(N, W)`` of every surface (coated or bare)."""
        n = self.media(wavelength_nm)
        lam = np.atleast_1d(np.asarray(wavelength_nm, np.float64))
        out = np.empty((len(self.surfaces), lam.size))
        for k, s in enumerate(self.surfaces):
            if s.coating is not None:
                out[k] = s.coating.reflectance(n[k], n[k + 1], lam)
            else:
                out[k] = fresnel_reflectance(n[k], n[k + 1])
        return out

    def reflecting_surfaces(self) -> list[int]:
        """Surfaces with an index step (the stop and dummy planes reflect nothing)."""
        out, before = [], 1.0
        for k, s in enumerate(self.surfaces):
            if s.nd != before:
                out.append(k)
            before = s.nd
        return out

    def system_matrix(self, wavelength_nm=D_LINE_NM) -> np.ndarray:
        """Ray-transfer matrix ``(W, 2, 2)`` from the first vertex to the last surface's
        exit side (the last thickness excluded)."""
        trace = _Trace(self, wavelength_nm)
        m = trace.identity()
        for k in range(len(self.surfaces)):
            m = trace.refract(k, m)
            if k < len(self.surfaces) - 1:
                m = trace.translate(self.surfaces[k].thickness, m)
        return m

    def efl(self, wavelength_nm=D_LINE_NM) -> float:
        """Effective focal length (mm) at one wavelength, ``-1 / C`` of the system matrix."""
        return float(-1.0 / self.system_matrix(wavelength_nm)[0, 1, 0])

    def back_focal_length(self, wavelength_nm=D_LINE_NM) -> float:
        """Paraxial distance (mm) from the last surface to the focus of a parallel beam."""
        m = self.system_matrix(wavelength_nm)[0]
        return float(-m[0, 0] / m[1, 0])

    def entrance_pupil_radius(self, wavelength_nm=D_LINE_NM) -> float:
        """Radius (mm) of the axial beam the lens accepts (the most limiting aperture)."""
        steps = _Trace(self, wavelength_nm).primary()
        return float(steps.entrance_radius()[0])

    def f_number_paraxial(self, wavelength_nm=D_LINE_NM) -> float:
        return self.efl(wavelength_nm) / (2.0 * self.entrance_pupil_radius(wavelength_nm))

    def at_f_number(self, f_number: float) -> Prescription:
        """The same lens with the stop's semi-aperture set for ``f_number`` (paraxial, d
        line).  Other rims still clip: opening beyond the design aperture does not help."""
        f_number = _number("f_number", f_number, lo=0.1, hi=1000.0,
                           what="an f-number in [0.1, 1000]")
        trace = _Trace(self, D_LINE_NM).primary()
        a_stop = abs(trace.crossing_a(self.stop_index)[0])
        semi = a_stop * self.efl() / (2.0 * f_number)
        surfaces = list(self.surfaces)
        k = self.stop_index
        surfaces[k] = replace(surfaces[k], semi_aperture=semi)
        return replace(self, surfaces=tuple(surfaces))


def _sag(radius: float, r: float) -> float:
    """Axial depth (mm) of a sphere at height ``r`` from its vertex (positive: towards the
    image)."""
    if math.isinf(radius):
        return 0.0
    return radius - math.copysign(math.sqrt(radius * radius - r * r), radius)


class _Trace:
    """Cumulative ray-transfer matrices along one path, vectorised over wavelengths.

    ``crossings`` records, for every surface crossing, the matrix from the entrance plane
    (the first vertex) to that surface's vertex plane: its ``[0, 0]`` and ``[0, 1]`` are the
    ``A_k, B_k`` of ``y_k = A_k y0 + B_k u``.
    """

    def __init__(self, lens: Prescription, wavelength_nm):
        self.lens = lens
        self.lam = np.atleast_1d(np.asarray(wavelength_nm, np.float64))
        self.n = lens.media(self.lam)
        self.crossings: list[tuple[int, np.ndarray]] = []
        self.matrix = None

    def identity(self):
        return np.broadcast_to(np.eye(2), (self.lam.size, 2, 2)).copy()

    @staticmethod
    def _apply(op, m):
        return np.einsum("wij,wjk->wik", op, m)

    def translate(self, d, m):
        out = m.copy()
        out[:, 0, :] += d * m[:, 1, :]
        return out

    def refract(self, k, m, backward=False):
        """Refraction at surface ``k`` (forward: medium k -> k+1; backward, unfolded:
        k+1 -> k with the radius negated)."""
        c = self.lens.surfaces[k].curvature
        n1, n2 = (self.n[k + 1], self.n[k]) if backward else (self.n[k], self.n[k + 1])
        if backward:
            c = -c
        out = np.empty_like(m)
        out[:, 0, :] = m[:, 0, :]
        out[:, 1, :] = ((n1 - n2) * c / n2)[:, None] * m[:, 0, :] + (n1 / n2)[:, None] * m[:, 1, :]
        return out

    def reflect(self, k, m, backward=False):
        c = -self.lens.surfaces[k].curvature if backward else self.lens.surfaces[k].curvature
        out = m.copy()
        out[:, 1, :] += 2.0 * c * m[:, 0, :]
        return out

    def cross(self, k, m):
        self.crossings.append((k, m))

    def crossing_a(self, k):
        return next(m[:, 0, 0] for kk, m in self.crossings if kk == k)

    def primary(self) -> _Trace:
        s = self.lens.surfaces
        m = self.identity()
        for k in range(len(s)):
            self.cross(k, m)
            m = self.translate(s[k].thickness, self.refract(k, m))
        self.matrix = m
        return self

    def limits(self):
        """Per crossing and wavelength: entrance radius ``a_k / |A_k|`` and ``B_k / A_k``."""
        a = np.array([self.lens.surfaces[k].semi_aperture for k, _ in self.crossings])
        A = np.stack([m[:, 0, 0] for _, m in self.crossings])            # (K, W)
        B = np.stack([m[:, 0, 1] for _, m in self.crossings])
        with np.errstate(divide="ignore", invalid="ignore"):
            radius = np.where(A != 0.0, a[:, None] / np.abs(A), np.inf)
            shift = np.where(A != 0.0, B / A, 0.0)
        return radius, shift

    def entrance_radius(self):
        return self.limits()[0].min(axis=0)


class _GhostBatch:
    """All two-reflection paths at once: the rays ``(y0, u) = (1, 0)`` and ``(0, 1)``
    traced through every ghost ``(i, j)`` and wavelength as arrays ``(G, W, 2)``.

    Three sweeps over the surfaces: forward to ``i`` (reflect there), backward to ``j``
    (reflect there), forward to the image plane; a ghost takes part in a step only where
    its path does.  Each crossing records the entrance disc it allows (radius
    ``a_k / |A_k|``, centre ``-B_k u / A_k``; ``inf`` where the ghost does not cross) and
    its surface; the Fresnel factors multiply into the transmission ``t``.  ``y`` ends as
    the image-plane ``(A_s, B_s)``.
    """

    def __init__(self, lens: Prescription, lam: np.ndarray, pairs: np.ndarray,
                 refl: np.ndarray):
        s = lens.surfaces
        n = lens.media(lam)                                 # (N + 1, W)
        g, nw = len(pairs), lam.size
        i, j = pairs[:, 0], pairs[:, 1]
        self.y = np.zeros((g, nw, 2))
        self.y[..., 0] = 1.0
        self.u = np.zeros((g, nw, 2))
        self.u[..., 1] = 1.0
        self.t = np.ones((g, nw))
        self.radius, self.shift, self.surface = [], [], []   # per crossing event
        self.incidence = []
        self._s, self._n, self._refl = s, n, refl
        for k in range(len(s)):                             # forward to i
            self._refract(k, k < i, forward=True)
            self._reflect(k, k == i, forward=True)
        for k in range(len(s) - 1, -1, -1):                 # backward to j
            self._refract(k, (j < k) & (k < i), forward=False)
            self._reflect(k, k == j, forward=False)
        for k in range(len(s)):                             # forward to the image
            self._refract(k, k > j, forward=True)
        self.radius = np.stack(self.radius)                 # (E, G, W)
        self.shift = np.stack(self.shift)
        self.surface = np.array(self.surface, np.int64)     # (E,)
        self.incidence = np.stack(self.incidence)

    def _cross(self, k, mask, c):
        a, b = self.y[..., 0], self.y[..., 1]
        # paraxial incidence angle of the ray (y0, u) = (1, 0): slope plus height / radius
        self.incidence.append(np.abs(self.u[..., 0] + a * c))
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.where(mask[:, None] & (a != 0.0), self._s[k].semi_aperture / np.abs(a),
                         np.inf)
            self.shift.append(np.where(a != 0.0, b / a, 0.0))
        self.radius.append(r)
        self.surface.append(k)

    def _translate(self, d, mask):
        self.y = np.where(mask[:, None, None], self.y + d * self.u, self.y)

    def _refract(self, k, mask, forward):
        if not mask.any():
            return
        c = self._s[k].curvature
        n1, n2 = (self._n[k], self._n[k + 1]) if forward else (self._n[k + 1], self._n[k])
        if not forward:
            c = -c                                          # unfolded: the radius negated
        self._cross(k, mask, c)
        u = ((n1 - n2) * c / n2)[:, None] * self.y + (n1 / n2)[:, None] * self.u
        self.u = np.where(mask[:, None, None], u, self.u)
        self.t = np.where(mask[:, None], self.t * (1.0 - self._refl[k]), self.t)
        self._translate(self._s[k].thickness if forward else self._s[k - 1].thickness, mask)

    def _reflect(self, k, mask, forward):
        if not mask.any():
            return
        c = self._s[k].curvature if forward else -self._s[k].curvature
        self._cross(k, mask, c)
        self.u = np.where(mask[:, None, None], self.u + 2.0 * c * self.y, self.u)
        self.t = np.where(mask[:, None], self.t * self._refl[k], self.t)
        # after i: back to the surface before it; after j: on to the one behind it
        self._translate(self._s[k - 1].thickness if forward else self._s[k].thickness, mask)

    def discs(self, h_per_u: float):
        """Every crossing's entrance disc on the sensor, and which one limits the ghost.

        The entrance disc of crossing ``q`` maps to a sensor disc of radius ``|A_s| r_q``
        centred at ``c_q x`` (``c_q = (B_s - A_s B_q / A_q) / h``, ``x`` the light's image
        position); the smallest is the limiting aperture's image, the ghost.
        """
        a_s, b_s = self.y[..., 0], self.y[..., 1]
        e = np.argmin(self.radius, axis=0)                  # (G, W) limiting event
        gi, wi = np.indices(e.shape)
        r_in = self.radius[e, gi, wi]
        centres = (b_s - a_s * self.shift) / h_per_u        # (E, G, W)
        radii = np.abs(a_s) * self.radius
        # the largest paraxial incidence angle of the (axial) beam's rim rays
        angle = np.where(np.isfinite(self.radius), self.incidence * r_in, 0.0)
        c_l = centres[e, gi, wi]
        # pack each ghost's crossings first along the last axis, drop the empty tail
        centres, radii = np.moveaxis(centres, 0, -1), np.moveaxis(radii, 0, -1)
        order = np.argsort(~np.isfinite(radii), axis=-1, kind="stable")
        keep = max(int(np.isfinite(radii).sum(axis=-1).max(initial=0)), 1)
        order = order[..., :keep]
        lim = np.argmax(order == e[..., None], axis=-1)
        return (r_in, self.surface[e], lim, c_l,
                np.take_along_axis(centres, order, -1), np.take_along_axis(radii, order, -1),
                angle.max(axis=0))


def _lens_area(r1, r2, d):
    """Area of the intersection of two discs (radii ``r1``, ``r2``, centres ``d`` apart)."""
    r1, r2, d = np.broadcast_arrays(*(np.asarray(v, np.float64) for v in (r1, r2, d)))
    out = np.where(d >= r1 + r2, 0.0, np.pi * np.minimum(r1, r2) ** 2)
    part = (d < r1 + r2) & (d > np.abs(r1 - r2))
    if part.any():
        a, b, c = r1[part], r2[part], d[part]
        alpha = np.arccos(np.clip((c * c + a * a - b * b) / (2.0 * c * a), -1.0, 1.0))
        beta = np.arccos(np.clip((c * c + b * b - a * a) / (2.0 * c * b), -1.0, 1.0))
        out[part] = (a * a * (alpha - np.sin(2.0 * alpha) / 2.0)
                     + b * b * (beta - np.sin(2.0 * beta) / 2.0))
    return out


@dataclass(frozen=True)
class GhostLayout:
    """The ghosts of lights at distances ``x_mm`` from the optical centre (on the sensor).

    All centres lie on the line from the optical centre through the light; a signed
    coordinate along it (mm, positive towards the light) places each disc.  A ghost is the
    limiting aperture's image (``centre_mm``, ``radius_mm`` of the table) intersected with
    up to two clip discs: ``inner`` cuts the side towards smaller coordinates, ``outer`` the
    side towards larger ones (``inf`` radius: no cut).  Arrays are ``(L, G, W)``.

    Attributes
    ----------
    centre_mm : ndarray
    inner_centre_mm, inner_radius_mm, outer_centre_mm, outer_radius_mm : ndarray
    visible : ndarray of bool
        False where some aperture hides the ghost completely at this light position.
    area_fraction : ndarray
        The part of the limiting aperture's image left by the two clip discs (circles; an
        approximation where both cut deep); multiplies the table's ``energy``.
    """

    centre_mm: np.ndarray
    inner_centre_mm: np.ndarray
    inner_radius_mm: np.ndarray
    outer_centre_mm: np.ndarray
    outer_radius_mm: np.ndarray
    visible: np.ndarray
    area_fraction: np.ndarray


@dataclass(frozen=True)
class GhostTable:
    """Every two-reflection ghost of a lens, per wavelength: plain NumPy, float64.

    Attributes
    ----------
    lens : str
        The prescription's name.
    wavelengths_nm : ndarray (W,)
    pairs : ndarray (G, 2) int
        ``(i, j)``: the light reflects back at surface ``i``, then forward at ``j < i``.
    centre : ndarray (G, W)
        Centre factor: with the light imaged at ``x`` (relative to the optical centre,
        any units), the ghost is centred at ``centre * x``.  Negative: across the centre.
    radius_mm : ndarray (G, W)
        Radius on the sensor (mm) of the image of the limiting aperture (for the stop: the
        circumradius of the aperture polygon).  Pixels: ``radius_mm * width_px /
        sensor_width_mm``.
    orientation : ndarray (G, W)
        +1 upright, -1 inverted (rotate the aperture polygon by 180 degrees).
    limiter : ndarray (G,) int
        The surface whose rim limits the ghost: the stop (draw the aperture polygon) or a
        lens (draw a disc).  Taken at the reference (middle) wavelength.
    disc_centre, disc_radius_mm : ndarray (G, W, E)
        The image on the sensor of every aperture crossing on the ghost's path (centre
        factor as ``centre``, radius in mm; ``inf`` radius where a ghost has fewer
        crossings).  The ghost is the intersection of all of them; off the axis they slide
        apart along the line through the light and some cut into the limiting one
        (cat's-eye ghosts) or hide it: :meth:`for_light` picks the two that cut deepest.
    limiting_disc : ndarray (G, W) int
        Index into the last axis of ``disc_*``: the limiting aperture's image.
    transmission : ndarray (G, W)
        ``R_i R_j`` times ``1 - R_k`` of every other crossing (normal incidence).
    energy : ndarray (G, W)
        Fraction of the light entering the entrance pupil that lands in the ghost.
    intensity : ndarray (G, W)
        Irradiance of the ghost relative to the light's irradiance over the entrance pupil,
        ``transmission / A_s**2`` (``A_s``: the ghost's magnification from the entrance
        plane to the sensor); ``energy * entrance_pupil_mm**2 / radius_mm**2`` on the axis.
        It does not change when clip discs cut the ghost: draw the clipped shape at this
        irradiance.  In pixel values: a light whose pixels sum to ``P`` gives the
        ghost ``P * intensity / (pi * entrance_pupil_mm**2 * primary_transmission)`` per
        mm**2 of sensor.
    incidence_rad : ndarray (G, W)
        The paraxial model's small parameter: the largest paraxial angle of incidence
        ``|u_k + y_k / R_k|`` of the axial ghost beam's rim rays over its surface crossings.
        Aberrations, which the matrices leave out, grow with it (third order: its square
        relative to the first-order terms): above about 0.2 rad the real ghost is visibly
        softer, shifted and dimmer than the table says (``tests/fx/test_optics.py``).
    primary_transmission : ndarray (W,)
        Fraction of the entering light in the primary image (``prod(1 - R_k)``);
        a ghost's power relative to the imaged light is ``energy / primary_transmission``.
    entrance_pupil_mm : ndarray (W,)
        Entrance pupil radius of the primary path (mm).
    edge_bm_mm : ndarray (G, W)
        ``|B m|`` (mm) of the limiting aperture's rim imaged onto the sensor: ``B`` of the
        ray-transfer matrix from that aperture to the sensor, ``m = A_s / A_L`` the rim's
        magnification along the ghost beam (``B m = c_L h A_s``).  A rim diffracts into
        Fresnel fringes ``sqrt(lambda |B m| / 2)`` wide on the sensor (the Collins integral
        near a straight edge: Fresnel's ``xi = d / sqrt(lambda B m / 2)``; exact for an
        aperture in air, such as the stop).
    image_height_per_slope_mm : float
        The light's paraxial image height per unit field slope ``tan(angle)`` (mm): the
        effective focal length for a lens focused at infinity.
    """

    lens: str
    wavelengths_nm: np.ndarray
    pairs: np.ndarray
    centre: np.ndarray
    radius_mm: np.ndarray
    orientation: np.ndarray
    limiter: np.ndarray
    disc_centre: np.ndarray
    disc_radius_mm: np.ndarray
    limiting_disc: np.ndarray
    transmission: np.ndarray
    energy: np.ndarray
    intensity: np.ndarray
    incidence_rad: np.ndarray
    primary_transmission: np.ndarray
    entrance_pupil_mm: np.ndarray
    edge_bm_mm: np.ndarray
    image_height_per_slope_mm: float

    PER_GHOST = ("pairs", "centre", "radius_mm", "orientation", "limiter", "disc_centre",
                 "disc_radius_mm", "limiting_disc", "transmission", "energy", "intensity",
                 "incidence_rad", "edge_bm_mm")
    """The fields with one row per ghost (:meth:`subset` selects rows of these)."""

    def __len__(self) -> int:
        return len(self.pairs)

    PER_WAVELENGTH = ("centre", "radius_mm", "orientation", "disc_centre", "disc_radius_mm",
                      "limiting_disc", "transmission", "energy", "intensity", "incidence_rad",
                      "edge_bm_mm")
    """The per-ghost fields with a wavelength axis (the second)."""

    def at_wavelength(self, index: int) -> GhostTable:
        """The table at one of its wavelengths (its layouts cost 1 / W of the full one)."""
        k = slice(index, index + 1)
        return replace(self, wavelengths_nm=self.wavelengths_nm[k],
                       primary_transmission=self.primary_transmission[k],
                       entrance_pupil_mm=self.entrance_pupil_mm[k],
                       **{f: getattr(self, f)[:, k] for f in self.PER_WAVELENGTH})

    def subset(self, keep) -> GhostTable:
        """The table of the ghosts ``keep`` selects (a boolean mask or indices)."""
        return replace(self, **{k: getattr(self, k)[keep] for k in self.PER_GHOST})

    def for_light(self, x_mm) -> GhostLayout:
        """Where the ghosts of lights imaged ``x_mm`` from the optical centre fall.

        Parameters
        ----------
        x_mm : float or array_like (L,)
            The lights' distances from the optical centre on the sensor (mm).

        Returns
        -------
        GhostLayout
            Arrays ``(L, G, W)``.  Along the line through the light the intersection of all
            the ghost's discs is the interval from the largest left edge to the smallest
            right edge; the discs giving those edges, where they cut into the limiting one,
            are the inner and outer clip discs.  An empty interval hides the ghost.
        """
        x = np.atleast_1d(np.asarray(x_mm, np.float64))[:, None, None, None]   # (L,1,1,1)
        centres = self.disc_centre[None] * x                 # (L, G, W, E)
        radii = np.broadcast_to(self.disc_radius_mm[None], centres.shape)
        finite = np.isfinite(radii)
        left = np.where(finite, centres - radii, -np.inf)
        right = np.where(finite, centres + radii, np.inf)
        lim = np.broadcast_to(self.limiting_disc[None, ..., None], centres.shape[:-1] + (1,))
        c0 = np.take_along_axis(centres, lim, -1)[..., 0]
        r0 = self.radius_mm[None] + np.zeros_like(c0)
        inner = np.argmax(left, axis=-1)[..., None]
        outer = np.argmin(right, axis=-1)[..., None]
        lo = np.take_along_axis(left, inner, -1)[..., 0]
        hi = np.take_along_axis(right, outer, -1)[..., 0]
        cuts_in = lo > c0 - r0
        cuts_out = hi < c0 + r0
        inf = np.full_like(c0, np.inf)
        ic = np.take_along_axis(centres, inner, -1)[..., 0]
        ir = np.where(cuts_in, np.take_along_axis(radii, inner, -1)[..., 0], inf)
        oc = np.take_along_axis(centres, outer, -1)[..., 0]
        orr = np.where(cuts_out, np.take_along_axis(radii, outer, -1)[..., 0], inf)
        visible = lo <= hi
        area = np.pi * r0 ** 2
        with np.errstate(invalid="ignore", divide="ignore"):
            kept = np.ones_like(c0)
            same = inner[..., 0] == outer[..., 0]          # one small disc cutting both sides
            for cc, rr, cut in ((ic, ir, cuts_in), (oc, orr, cuts_out & ~(same & cuts_in))):
                lens = _lens_area(r0, np.where(cut, rr, 0.0), np.abs(cc - c0))
                kept = kept - np.where(cut, 1.0 - lens / area, 0.0)
            kept = np.where(area > 0.0, kept, 1.0)
        return GhostLayout(centre_mm=c0, inner_centre_mm=ic, inner_radius_mm=ir,
                           outer_centre_mm=oc, outer_radius_mm=orr, visible=visible,
                           area_fraction=np.where(visible, np.clip(kept, 0.0, 1.0), 0.0))


def ghosts(lens: Prescription, wavelengths_nm=RGB_WAVELENGTHS_NM, *,
           reference_nm: float | None = None, min_energy: float = 0.0) -> GhostTable:
    """Every two-reflection ghost of ``lens`` by paraxial ray-transfer matrices.

    Parameters
    ----------
    lens : Prescription
    wavelengths_nm : sequence of float
        Wavelengths (nm) to evaluate, e.g. one per colour channel.
    reference_nm : float, optional
        Wavelength whose primary image defines the light's image height (the centre factor's
        denominator).  Default: the middle entry of ``wavelengths_nm``.
    min_energy : float
        Drop ghosts whose energy stays below this at every wavelength.

    Returns
    -------
    GhostTable
        One row per ghost ``(i, j)``, ``i > j`` over the reflecting surfaces (the stop and
        index-matched planes reflect nothing), in lexicographic order of ``(i, j)``.
    """
    lam = np.atleast_1d(np.asarray(wavelengths_nm, np.float64))
    if lam.ndim != 1 or lam.size == 0 or not np.all((lam > 200.0) & (lam < 2000.0)):
        raise ParamError(f"wavelengths_nm: {wavelengths_nm!r} is not a list of wavelengths "
                         f"in (200, 2000) nm")
    ref = float(lam[lam.size // 2]) if reference_nm is None else float(reference_nm)
    refl = lens.reflectances(lam)                      # (N, W)
    trans = 1.0 - refl
    stop = lens.stop_index

    primary = _Trace(lens, lam).primary()
    p_radius, _ = primary.limits()
    r_ep = p_radius.min(axis=0)
    primary_transmission = np.prod(trans, axis=0)
    # the light's image height per unit slope at the reference wavelength (through the stop)
    pr = _Trace(lens, [ref]).primary()
    a_stop = pr.crossing_a(stop)[0]
    b_stop = next(m[0, 0, 1] for k, m in pr.crossings if k == stop)
    h_per_u = pr.matrix[0, 0, 1] - pr.matrix[0, 0, 0] * b_stop / a_stop

    reflecting = lens.reflecting_surfaces()
    pairs = np.array([(i, j) for i in reflecting for j in reflecting if j < i],
                     np.int64).reshape(-1, 2)
    g = len(pairs)
    b = _GhostBatch(lens, lam, pairs, refl)
    r_in, limiter, lim_event, centre, disc_centre, disc_radius, angle = b.discs(h_per_u)
    a_s = b.y[..., 0]
    size = a_s * r_in                           # (G, W) signed image of the limiting rim
    energy = b.t * (r_in / r_ep) ** 2
    with np.errstate(divide="ignore"):
        intensity = b.t / a_s ** 2
    mid = lam.size // 2
    table = GhostTable(
        lens=lens.name, wavelengths_nm=lam, pairs=pairs, centre=centre,
        radius_mm=np.abs(size), orientation=np.where(size < 0.0, -1.0, 1.0),
        limiter=limiter[:, mid] if g else np.zeros(0, np.int64),
        disc_centre=disc_centre, disc_radius_mm=disc_radius, limiting_disc=lim_event,
        transmission=b.t, energy=energy, intensity=intensity, incidence_rad=angle,
        primary_transmission=primary_transmission, entrance_pupil_mm=r_ep,
        edge_bm_mm=np.abs(centre * h_per_u * a_s), image_height_per_slope_mm=float(h_per_u))
    if min_energy > 0.0 and g:
        table = table.subset(table.energy.max(axis=1) >= min_energy)
    return table
