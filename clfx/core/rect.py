"""Integer pixel rectangles in OpenImageIO's coordinate system.

A ``Rect`` is half-open: it covers pixels ``x0 <= x < x1`` and ``y0 <= y < y1``.  Coordinates
are those of the image's full coordinate system (EXR data and display windows), +x right,
+y down (image rows).
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Rect:
    x0: int
    y0: int
    x1: int
    y1: int

    @classmethod
    def from_size(cls, width: int, height: int, x: int = 0, y: int = 0) -> "Rect":
        return cls(x, y, x + width, y + height)

    @property
    def width(self) -> int:
        return max(0, self.x1 - self.x0)

    @property
    def height(self) -> int:
        return max(0, self.y1 - self.y0)

    @property
    def shape(self) -> tuple[int, int]:
        """(height, width), NumPy order."""
        return (self.height, self.width)

    @property
    def empty(self) -> bool:
        return self.width == 0 or self.height == 0

    @property
    def center(self) -> tuple[float, float]:
        """Centre in continuous pixel coordinates (pixel centres at +0.5)."""
        return ((self.x0 + self.x1) * 0.5, (self.y0 + self.y1) * 0.5)

    @property
    def diagonal(self) -> float:
        return (self.width ** 2 + self.height ** 2) ** 0.5

    def grown(self, dx: int, dy: int | None = None) -> "Rect":
        dy = dx if dy is None else dy
        return Rect(self.x0 - dx, self.y0 - dy, self.x1 + dx, self.y1 + dy)

    def intersect(self, other: "Rect") -> "Rect":
        r = Rect(max(self.x0, other.x0), max(self.y0, other.y0),
                 min(self.x1, other.x1), min(self.y1, other.y1))
        return r if not r.empty else Rect(r.x0, r.y0, r.x0, r.y0)

    def union(self, other: "Rect") -> "Rect":
        if self.empty:
            return other
        if other.empty:
            return self
        return Rect(min(self.x0, other.x0), min(self.y0, other.y0),
                    max(self.x1, other.x1), max(self.y1, other.y1))

    def contains(self, other: "Rect") -> bool:
        return (self.x0 <= other.x0 and self.y0 <= other.y0
                and self.x1 >= other.x1 and self.y1 >= other.y1)

    def offset_in(self, outer: "Rect") -> tuple[int, int]:
        """(dx, dy) of this rectangle's origin inside ``outer``."""
        return (self.x0 - outer.x0, self.y0 - outer.y0)

    def __str__(self) -> str:
        return f"({self.x0},{self.y0})-({self.x1},{self.y1}) {self.width}x{self.height}"
