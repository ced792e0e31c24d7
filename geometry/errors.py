"""Typed errors of the geometry package.

Every error names the offending field (a JSON-style path such as
``segments[2].knots``), the value seen and the rule it breaks, so the service
can map it to an RFC 9457 problem document without parsing messages.
"""

from __future__ import annotations

from typing import Any


class GeometryError(ValueError):
    """Invalid or unschedulable toolpath geometry.

    Attributes:
        field: path of the offending input, e.g. ``segments[1].weights[3]``.
        value: the offending value (short repr-able summary).
        rule: the rule that was broken, in words.
        segment: index of the segment in the input chain, when known.
    """

    def __init__(self, field: str, value: Any, rule: str, segment: int | None = None) -> None:
        self.field = field
        self.value = value
        self.rule = rule
        self.segment = segment
        super().__init__(f"{field}: {rule} (got {_short(value)})")


def _short(value: Any, limit: int = 120) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."
