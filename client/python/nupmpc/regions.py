"""Keep-out regions in the plane of two outputs (proto KeepOutRegion)."""

from __future__ import annotations

from dataclasses import dataclass

from nupmpc._proto import pb
from nupmpc.arrays import ArrayLike, vector
from nupmpc.errors import ShapeError


@dataclass
class Ellipse:
    """A keep-out ellipse (a circle when b is None) in the plane of two outputs."""
    centre: ArrayLike
    a: float
    b: float | None = None
    rotation: float = 0.0
    margin: float = 0.0
    slope: float = 0.0  # 0: hard

    def _shape(self) -> pb.KeepOutRegion.Shape:
        return pb.KeepOutRegion.SHAPE_ELLIPSE

    def to_proto(self) -> pb.KeepOutRegion:
        centre = vector(self.centre, "centre", 2)
        if not self.a > 0 or (self.b is not None and not self.b > 0):
            raise ShapeError("half_axis", "must be > 0")
        return pb.KeepOutRegion(shape=self._shape(), centre_x=centre[0], centre_y=centre[1], half_axis_a=self.a,
                                half_axis_b=self.b or 0.0, rotation_rad=self.rotation, margin=self.margin,
                                slope=self.slope)


@dataclass
class Rectangle(Ellipse):
    """A keep-out rectangle of half-width a and half-height b (a square when b is None)."""

    def _shape(self) -> pb.KeepOutRegion.Shape:
        return pb.KeepOutRegion.SHAPE_RECTANGLE
