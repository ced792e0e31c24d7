"""Toolpath geometry: NURBS segments, arc length, geometric derivatives, corners."""

from geometry.arclength import ArcLengthTable
from geometry.errors import GeometryError
from geometry.nurbs import NurbsSegment
from geometry.toolpath import Corner, PathSamples, Piece, Toolpath, arc_length_derivatives

__all__ = [
    "ArcLengthTable",
    "Corner",
    "GeometryError",
    "NurbsSegment",
    "PathSamples",
    "Piece",
    "Toolpath",
    "arc_length_derivatives",
]
