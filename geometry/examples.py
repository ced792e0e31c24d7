"""Reference toolpaths used by tests, benchmarks and the service's examples.

All are exact NURBS (line, rational-quadratic circle) or NURBS fitted to an
analytic curve (flower, 3-D wave) by cubic interpolation.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import make_interp_spline

from geometry.nurbs import FloatArray, NurbsSegment
from geometry.toolpath import Toolpath

FLOWER_R0 = 40.0
FLOWER_A = 15.0
FLOWER_LOBES = 5


def line(start: tuple[float, float, float], end: tuple[float, float, float]) -> NurbsSegment:
    """Straight line as a degree-1 NURBS."""
    return NurbsSegment.create(1, [0, 0, 1, 1], [start, end], [1.0, 1.0], name="line")


def circle(radius: float, center: tuple[float, float] = (0.0, 0.0)) -> NurbsSegment:
    """Exact full circle in XY: rational quadratic, 9 control points (Piegl & Tiller)."""
    w = np.sqrt(0.5)
    cx, cy = center
    unit = [(1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1), (1, 0)]
    P = [(cx + radius * x, cy + radius * y, 0.0) for x, y in unit]
    W = [1, w, 1, w, 1, w, 1, w, 1]
    U = [0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1]
    return NurbsSegment.create(2, U, P, W, name="circle")


def flower_xyz(theta: FloatArray) -> FloatArray:
    """Points on r = 40 + 15 cos(5 theta) mm, starting at theta = 0 (x = 55)."""
    r = FLOWER_R0 + FLOWER_A * np.cos(FLOWER_LOBES * theta)
    return np.column_stack([r * np.cos(theta), r * np.sin(theta), np.zeros_like(theta)])


def _fit(points: FloatArray, name: str, periodic: bool) -> NurbsSegment:
    """Cubic interpolation through points (chord-length parameters) as a NURBS, weights 1."""
    chord = np.linalg.norm(np.diff(points, axis=0), axis=1)
    u = np.concatenate([[0.0], np.cumsum(chord)])
    u /= u[-1]
    spl = make_interp_spline(u, points, k=3, bc_type="periodic" if periodic else "not-a-knot")
    c = np.asarray(spl.c)
    t = np.asarray(spl.t)
    n = t.size - 4
    return NurbsSegment.create(3, t, c[:n], np.ones(n), name=name)


def flower_segment(points_per_loop: int = 720) -> NurbsSegment:
    """One closed flower loop (407.7 mm), cubic NURBS fitted through ``points_per_loop`` points."""
    theta = np.linspace(0.0, 2.0 * np.pi, points_per_loop + 1)
    pts = flower_xyz(theta)
    pts[-1] = pts[0]
    return _fit(pts, "flower", periodic=True)


def flower(loops: int = 1, points_per_loop: int = 720) -> Toolpath:
    """The flower loop chained ``loops`` times (each loop one segment)."""
    seg = flower_segment(points_per_loop)
    return Toolpath([seg] * loops)


def wave3d(points: int = 400) -> NurbsSegment:
    """A 3-D path: an ellipse in XY with Z rising and waving, about 330 mm long."""
    th = np.linspace(0.0, 2.0 * np.pi, points)
    pts = np.column_stack([50 * np.cos(th), 30 * np.sin(th), 10 * th + 5 * np.sin(3 * th)])
    return _fit(pts, "wave3d", periodic=False)


def square_corner(size: float = 50.0) -> Toolpath:
    """Two lines meeting at a 90 degree corner."""
    return Toolpath([line((0, 0, 0), (size, 0, 0)), line((size, 0, 0), (size, size, 0))])
