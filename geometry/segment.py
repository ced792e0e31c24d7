"""The interface every toolpath segment offers to ``Toolpath`` and ``ArcLengthTable``.

``NurbsSegment`` is one implementation; ``ClothoidSegment`` (exactly
arc-length parameterised Euler spirals, ``geometry/clothoid.py``) another. A
segment is a regular curve C(u), u in ``domain``, in mm; the scheduler sees it
only through these members:

    domain              (u_0, u_1)
    breakpoints         parameters where C''' may jump (both ends included);
                        arc length is integrated piecewise between them
    derivatives(u)      (4, K, 3): C, C', C'', C''' (mm, mm/u, mm/u^2, mm/u^3)
    speed(u)            |C'(u)|, (K,)
    points(u)           C(u), (K, 3)
    split_at_c0_knots() the segment cut where it is only C0 (tangent may break)
    name                field path for error messages
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


class Segment(Protocol):
    """A curve segment that Toolpath can chain, measure and evaluate."""

    @property
    def name(self) -> str: ...

    @property
    def domain(self) -> tuple[float, float]: ...

    @property
    def breakpoints(self) -> FloatArray: ...

    def derivatives(self, u: FloatArray) -> FloatArray: ...

    def speed(self, u: FloatArray) -> FloatArray: ...

    def points(self, u: FloatArray) -> FloatArray: ...

    def split_at_c0_knots(self) -> Sequence[Segment]: ...
