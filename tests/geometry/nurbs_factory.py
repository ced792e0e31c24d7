"""Random valid NURBS for the geometry tests (shared by several test modules)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from geometry.nurbs import NurbsSegment


@dataclass(frozen=True)
class RawNurbs:
    """Raw NURBS data as a client would send it."""

    degree: int
    knots: np.ndarray
    control_points: np.ndarray
    weights: np.ndarray

    def segment(self, name: str = "segment") -> NurbsSegment:
        return NurbsSegment.create(self.degree, self.knots, self.control_points, self.weights, name=name)


def clamped_knots(
    degree: int,
    interior: np.ndarray,
    multiplicities: np.ndarray,
    lo: float = 0.0,
    hi: float = 1.0,
) -> np.ndarray:
    """Clamped knot vector on [lo, hi] with the given distinct interior knots and multiplicities."""
    inner = np.repeat(np.asarray(interior, dtype=np.float64), np.asarray(multiplicities, dtype=int))
    return np.concatenate([np.full(degree + 1, lo), inner, np.full(degree + 1, hi)])


def random_nurbs(
    rng: np.random.Generator,
    degree: int,
    n_interior: int,
    lo: float = 0.0,
    hi: float = 1.0,
    weight_range: tuple[float, float] = (0.3, 3.0),
    extent_mm: float = 50.0,
) -> RawNurbs:
    """Random 3-D NURBS: clamped knots, interior knots of multiplicity 1..degree-1
    (well separated: every span is at least 30 % of the mean span), weights != 1."""
    spans = rng.uniform(0.3, 1.0, n_interior + 1)
    cuts = np.cumsum(spans)[:-1] / spans.sum()
    interior = lo + (hi - lo) * cuts
    mults = rng.integers(1, max(degree, 2), n_interior)  # 1 .. degree-1
    knots = clamped_knots(degree, interior, mults, lo, hi)
    n = knots.size - degree - 1
    points = rng.uniform(-extent_mm, extent_mm, (n, 3))
    weights = rng.uniform(*weight_range, n)
    return RawNurbs(degree, knots, points, weights)
