"""The look's camera block: one set of physical values that every effect reads, and the
camera physics every layer shares (one copy each): the thin-lens circle of confusion and the
open shutter interval.

Lengths on the sensor are in millimetres; distances in the scene are in scene units, metres
by default (the depth pass is read in the same units, see ``clfx.io.read``).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace

import numpy as np

SHUTTER_OFFSETS = ("centered", "opening", "closing")
"""Where the open shutter sits relative to the frame time."""


# -- thin lens -------------------------------------------------------------------------------
def coc_signed(depth, scale_px: float, focus: float):
    """Signed thin-lens circle of confusion of planar depths (float64 NumPy).

    Thin lens (Potmesil & Chakravarty 1981): a point at planar depth ``z`` seen through a lens
    focused at ``S`` blurs into ``scale_px * (1 - S / z)``, where ``scale_px`` is the CoC at
    infinity (:meth:`Camera.coc_scale_px` for a diameter; half of it gives a radius).  The
    sign tells the side of the focus plane: > 0 behind it, < 0 in front.

    Parameters
    ----------
    depth : array_like
        Planar depths in scene units; ``+inf`` gives ``scale_px``.
    scale_px : float
        The CoC at infinity in pixels.
    focus : float
        Focus distance ``S``, same units as ``depth``.

    Returns
    -------
    np.ndarray
        float64, same shape; invalid depths (NaN, 0, negative) give 0 (in focus).
    """
    z = np.asarray(depth, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        c = np.where(np.isposinf(z), scale_px, scale_px * (1.0 - focus / z))
    return np.where(z > 0, c, 0.0)


def image_distance(focal_length_mm: float, focus: float) -> float:
    """Thin-lens image distance ``v = f S / (S - f)`` in mm of a lens of focal length ``f``
    (mm) focused at ``S`` (scene units, metres): how far behind the lens the sharp image
    forms.  A unit-focusing lens moves by ``v - f`` to focus, so the frame it images scales
    with ``v`` (lens breathing, ``clfx.plugins.breathing``).  Undefined at or inside the
    focal length (no real image): callers clamp first."""
    s = focus * 1000.0  # scene metres -> mm
    return focal_length_mm * s / (s - focal_length_mm)


def camera_rotation(yaw: float, pitch: float, roll: float = 0.0) -> np.ndarray:
    """``C = R_y(yaw) R_x(pitch) R_z(roll)`` (radians): a turned camera's axes (columns) in
    the frame of the unturned one (image axes: +x right, +y down, +z forward; yaw turns +z
    towards +x, a positive pitch turns it upwards, roll turns +x towards +y)."""
    cy, sy = math.cos(yaw), math.sin(yaw)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cr, sr = math.cos(roll), math.sin(roll)
    ry = np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cp, -sp], [0.0, sp, cp]])
    rz = np.array([[cr, -sr, 0.0], [sr, cr, 0.0], [0.0, 0.0, 1.0]])
    return ry @ rx @ rz


def first_blade_angle(rotation_deg: float = 0.0) -> float:
    """Direction (radians, image coordinates: x right, y down) of the aperture polygon's first
    vertex: up (-y), turned ``rotation_deg`` degrees clockwise on screen."""
    return -0.5 * math.pi + math.radians(rotation_deg)


NO_POLYGON = (1, 2)
"""Blade counts that make no polygon: refused (they used to render round without a word)."""
BLADES_WHY = "1 or 2 blades make no polygon: 0 is a round aperture, 3 to 32 a polygon"


def aperture_radius(phi, blades: int, first: float = -0.5 * math.pi, roundness: float = 0.0):
    """Boundary radius (circumradius 1) of the aperture in direction ``phi`` (radians, image
    coordinates), i.e. the shape of the bokeh: ``blades`` < 3 is a disk; otherwise a regular
    polygon inscribed in the unit circle with its first vertex at angle ``first``
    (:func:`first_blade_angle`), blended toward the disk by ``roundness``."""
    phi = np.asarray(phi, np.float64)
    if blades < 3:
        return np.ones_like(phi)
    sector = 2.0 * math.pi / blades
    rel = np.mod(phi - first, sector) - 0.5 * sector
    poly = math.cos(0.5 * sector) / np.cos(rel)
    return poly + (1.0 - poly) * roundness


def vignetted_fraction(d, barrel: float = 1.0):
    """Fraction of a round aperture (radius 1) left open by a barrel circle of radius
    ``barrel`` whose centre is ``d`` away (optical vignetting; the lens-shaped intersection
    of two circles over the aperture's area).  1 for ``d <= barrel - 1``, 0 once the circles
    part."""
    d = np.asarray(d, np.float64)
    r, b = 1.0, float(barrel)
    with np.errstate(divide="ignore", invalid="ignore"):
        dd = np.maximum(d, 1e-300)
        a1 = np.arccos(np.clip((dd * dd + r * r - b * b) / (2 * dd * r), -1.0, 1.0))
        a2 = np.arccos(np.clip((dd * dd + b * b - r * r) / (2 * dd * b), -1.0, 1.0))
        k = np.sqrt(np.maximum((-dd + r + b) * (dd + r - b) * (dd - r + b) * (dd + r + b), 0.0))
        lens = (r * r * a1 + b * b * a2 - 0.5 * k) / (math.pi * r * r)
    inside = d <= abs(b - r)
    full = min(b * b, r * r) / (r * r)
    return np.where(inside, full, np.where(d >= r + b, 0.0, lens))


def optical_vignetting_centre(x, y, *, strength: float, centre: tuple, half_diagonal: float,
                              pixel_aspect: float = 1.0):
    """Centre of the barrel circle, in aperture radii, for image positions ``(x, y)`` (px,
    pixel centres at ``i + 0.5``): ``strength * (position - optical centre) / half
    diagonal``, measured in x pixels (y divided by the pixel aspect).  0 at the optical
    centre; at the frame's corner ``strength`` (the barrel's offset there)."""
    cx = strength * (np.asarray(x, np.float64) - centre[0]) / half_diagonal
    cy = strength * (np.asarray(y, np.float64) - centre[1]) / (pixel_aspect * half_diagonal)
    return cx, cy


# -- shutter ---------------------------------------------------------------------------------
def shutter_interval(angle_deg: float, offset: str) -> tuple[float, float]:
    """(t0, t1): the open shutter in frames relative to the frame time.

    With ``s = angle / 360`` of a frame: ``centered`` is ``[-s/2, s/2]``, ``opening``
    ``[0, s]`` (the shutter opens at the frame time), ``closing`` ``[-s, 0]``.
    """
    s = angle_deg / 360.0
    if offset == "opening":
        return 0.0, s
    if offset == "closing":
        return -s, 0.0
    return -0.5 * s, 0.5 * s


@dataclass(frozen=True)
class Camera:
    focal_length: float = 35.0     # mm
    f_number: float = 2.8          # N = focal length / aperture diameter
    sensor_width: float = 36.0     # mm (full-frame 35 mm still; Super 35 is 24.89)
    focus_distance: float = 5.0    # scene units (m), planar distance to the focus plane
    shutter_angle: float = 180.0   # degrees of the frame interval the shutter is open
    shutter_offset: str = "centered"  # centered | opening | closing
    iso: float = 400.0
    blades: int = 0                # aperture blades; 0 = round aperture
    blade_rotation: float = 0.0    # degrees
    sensor_height: float | None = None  # mm; None = from the frame's aspect
    breathing: float = 0.0         # lens breathing: 0 none, 1 unit-focusing thin lens
    optical_vignetting: float = 0.0  # barrel offset at the frame corner, aperture radii (cat-eye)
    optical_vignetting_front: float = 0.0  # front rim's offset at the corner (towards the centre)
    anamorphic_squeeze: float = 1.0  # 1 = spherical; 1.33, 1.8, 2: oval bokeh (height / width)
    axial_ca_red: float = 0.0      # um: focus of red behind green (longitudinal CA), sensor side
    axial_ca_blue: float = 0.0     # um: focus of blue behind green

    RANGES = {
        "focal_length": (0.5, 5000.0), "f_number": (0.5, 128.0), "sensor_width": (0.5, 200.0),
        "focus_distance": (1e-4, 1e9), "shutter_angle": (0.0, 720.0), "iso": (1.0, 1e6),
        "blades": (0, 32), "blade_rotation": (-360.0, 360.0), "sensor_height": (0.5, 200.0),
        "breathing": (-2.0, 2.0),
        "optical_vignetting": (0.0, 2.0), "optical_vignetting_front": (0.0, 2.0),
        "anamorphic_squeeze": (1.0, 3.0),
        "axial_ca_red": (-1000.0, 1000.0), "axial_ca_blue": (-1000.0, 1000.0),
    }
    CHOICES = {"shutter_offset": SHUTTER_OFFSETS}
    INTEGERS = ("blades",)

    @classmethod
    def validate(cls, name: str, value):
        """``value`` checked for the field ``name``: one of its CHOICES, or a number within
        its RANGES (a whole number for INTEGERS; 6.0 is 6, 3.5 is refused).

        Raises TypeError or ValueError saying what was expected (the caller names the file
        or option).
        """
        if name in cls.CHOICES:
            if value not in cls.CHOICES[name]:
                raise ValueError(f"{value!r} is not one of {', '.join(cls.CHOICES[name])}")
            return value
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise TypeError(f"{value!r} is not a number")
        shown = f"{value:g}" if isinstance(value, float) else repr(value)
        if name in cls.INTEGERS and not float(value).is_integer():
            raise ValueError(f"{shown} is not a whole number")
        lo, hi = cls.RANGES[name]
        if not lo <= value <= hi:
            raise ValueError(f"{shown} is outside the allowed range [{lo:g}, {hi:g}]")
        if name == "blades" and value in NO_POLYGON:
            raise ValueError(f"{shown} is not allowed ({BLADES_WHY})")
        return int(value) if name in cls.INTEGERS else float(value)

    def as_dict(self) -> dict:
        d = asdict(self)
        return {k: v for k, v in d.items() if v is not None}

    @classmethod
    def field_names(cls) -> list[str]:
        return [f.name for f in fields(cls)]

    def updated(self, **kw) -> "Camera":
        return replace(self, **kw)

    def focal_length_px(self, image_width_px: float) -> float:
        """Focal length in pixels for an image ``image_width_px`` wide (square pixels)."""
        return self.focal_length * image_width_px / self.sensor_width

    # -- thin lens ---------------------------------------------------------------------
    def coc_scale_px(self, image_width_px: float) -> float:
        """``K``: the CoC diameter in pixels of a point at infinity.

        ``K = A f / (S - f)`` on the sensor (mm; aperture ``A = f / N``, focus ``S``), times
        pixels per mm.  A point at planar depth ``z`` blurs into ``|K (1 - S / z)|``.
        """
        f = self.focal_length
        s = self.focus_distance * 1000.0  # scene metres -> mm
        return (f / self.f_number) * f / max(s - f, 1e-6) * image_width_px / self.sensor_width

    def axial_ca_px(self, image_width_px: float) -> tuple[float, float]:
        """Signed CoC diameter offsets (px) of red and blue against green from the axial
        (longitudinal) chromatic aberration.

        A channel focusing ``delta`` mm further behind the lens than green (``axial_ca_*``
        in um) meets the sensor with a cone of slope ``1/N``: its signed CoC diameter (> 0
        behind the focus plane) is green's minus ``delta / N`` on the sensor, at every
        depth.  An achromat has red and blue together behind green: their bokeh is smaller
        behind the focus plane (green rims) and larger in front of it (magenta rims).
        """
        px_per_mm = image_width_px / self.sensor_width
        return tuple(-(ca * 1e-3) / self.f_number * px_per_mm
                     for ca in (self.axial_ca_red, self.axial_ca_blue))

    def coc_signed_px(self, depth, image_width_px: float):
        """Signed CoC diameters in pixels of planar depths (:func:`coc_signed` with ``K``)."""
        return coc_signed(depth, self.coc_scale_px(image_width_px), self.focus_distance)

    def coc_px(self, depth: float, image_width_px: float) -> float:
        """Circle-of-confusion diameter in pixels for a point at planar ``depth`` (thin lens).

        ``c = (f/N) * f/(S - f) * |1 - S/z|`` on the sensor (mm), times px per mm.  Finite
        at z = inf (it tends to the background CoC); 0 for an invalid depth.
        """
        return abs(float(self.coc_signed_px(depth, image_width_px)))

    def image_distance(self, focus: float | None = None) -> float:
        """:func:`image_distance` of this lens focused at ``focus`` (default the camera's
        ``focus_distance``), in mm."""
        return image_distance(self.focal_length,
                              self.focus_distance if focus is None else focus)

    # -- shutter -----------------------------------------------------------------------
    def shutter_fraction(self) -> float:
        """Fraction of the frame interval the shutter is open."""
        return self.shutter_angle / 360.0

    def shutter_interval(self) -> tuple[float, float]:
        """(t0, t1): the open shutter in frames relative to the frame time
        (:func:`shutter_interval` of this camera's angle and offset)."""
        return shutter_interval(self.shutter_angle, self.shutter_offset)
