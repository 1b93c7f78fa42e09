"""The look's camera block: one set of physical values that every effect reads.

Lengths on the sensor are in millimetres; distances in the scene are in scene units, metres
by default (the depth pass is read in the same units, see ``clfx.io.files``).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace


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

    RANGES = {
        "focal_length": (0.5, 5000.0), "f_number": (0.5, 128.0), "sensor_width": (0.5, 200.0),
        "focus_distance": (1e-4, 1e9), "shutter_angle": (0.0, 720.0), "iso": (1.0, 1e6),
        "blades": (0, 32), "blade_rotation": (-360.0, 360.0), "sensor_height": (0.5, 200.0),
    }
    CHOICES = {"shutter_offset": ("centered", "opening", "closing")}
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

    def coc_px(self, depth: float, image_width_px: float) -> float:
        """Circle-of-confusion diameter in pixels for a point at planar ``depth`` (thin lens).

        ``c = (f/N) * f/(S - f) * |1 - S/z|`` on the sensor (mm), times px per mm.  Finite
        at z = inf (it tends to the background CoC).
        """
        f = self.focal_length
        s = self.focus_distance * 1000.0  # scene metres -> mm
        z = depth * 1000.0
        if not (z > 0.0):
            return 0.0
        aperture = f / self.f_number
        scale = aperture * f / max(s - f, 1e-6)
        c_mm = scale * abs(1.0 - s / z) if math.isfinite(z) else scale
        return c_mm * image_width_px / self.sensor_width

    def shutter_fraction(self) -> float:
        """Fraction of the frame interval the shutter is open."""
        return self.shutter_angle / 360.0
