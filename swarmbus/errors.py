"""The errors' root, and the one-line error of a bad value: where it is, which field, why."""

from __future__ import annotations


class PlumeswarmError(Exception):
    """The root of every error plumeswarm raises on purpose: ``except PlumeswarmError`` catches
    them all (the CLI prints its message as one line). Each error also derives from the built-in
    it stands for (``ValueError``, ``RuntimeError``, ``TimeoutError``, …)."""


class FieldError(PlumeswarmError, ValueError):
    """``<where>: <field>: <reason>``; ``field`` and ``reason`` are kept for callers to match on.

    A blank field (the whole thing is wrong, not one of its fields) prints as ``blank``.
    """

    def __init__(self, where: str, field: str, reason: str, blank: str = "") -> None:
        self.field = field
        self.reason = reason
        super().__init__(f"{where}: {field or blank}: {reason}")
