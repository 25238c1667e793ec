"""The one-line error of a bad value: where it is, which field, why."""

from __future__ import annotations


class FieldError(ValueError):
    """``<where>: <field>: <reason>``; ``field`` and ``reason`` are kept for callers to match on.

    A blank field (the whole thing is wrong, not one of its fields) prints as ``blank``.
    """

    def __init__(self, where: str, field: str, reason: str, blank: str = "") -> None:
        self.field = field
        self.reason = reason
        super().__init__(f"{where}: {field or blank}: {reason}")
