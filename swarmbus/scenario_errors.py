"""A scenario's validation error in the user's words: the key, the bad value and the valid values.

msgspec says ``Invalid enum value 'turbulent'`` or ``Object contains unknown field `sped` ``;
:func:`explain` turns that into ``wind.model``, ``invalid choice, got 'turbulent'; valid:
field, meander, steady`` (the choices read from the schema's type annotations: a ``Literal``,
an ``Enum``, or a pattern of alternatives ``^(a|b)$``) and a ``did you mean 'speed_m_s'?`` for
a key or a choice close to a valid one. Any msgspec-typed file can use it (scenarios, hosts
files).
"""

from __future__ import annotations

import difflib
import enum
import re

import msgspec
import msgspec.inspect as mi

from swarmbus.codec import split_validation_error

__all__ = ["did_you_mean", "explain", "toml_value"]

# msgspec's type names in the words of a TOML file
_TOML_TYPES = {
    "str": "string",
    "int": "integer",
    "float": "float",
    "bool": "boolean",
    "object": "table",
    "array": "array",
}


def did_you_mean(word: str, candidates: list[str]) -> str:
    """`` (did you mean 'x'?)`` for the closest of ``candidates``, else ``""``."""
    close = difflib.get_close_matches(word, candidates, n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def toml_value(value: object) -> str:
    """``value`` as a TOML file spells it (``true``, ``'fast'``, ``3.5``), a table or a long
    array by its kind."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, dict):
        return "a table"
    text = repr(value)
    if isinstance(value, list) and len(text) > 60:
        return f"an array of {len(value)}"
    return text


def _unwrap(t: mi.Type) -> mi.Type:
    while isinstance(t, mi.Metadata):
        t = t.type
    return t


def _members(t: mi.Type) -> list[mi.Type]:
    """The types a value at ``t`` may have (a union's members, None left out)."""
    t = _unwrap(t)
    if isinstance(t, mi.UnionType):
        return [m for member in t.types for m in _members(member)]
    return [] if isinstance(t, mi.NoneType) else [t]


def _type_at(root: type, path: str) -> mi.Type | None:
    """The declared type at a msgspec error path (``plume.sources[0].model``), or None."""
    t: mi.Type | None = mi.type_info(root)
    for name, index in re.findall(r"([^.\[\]]+)|\[(\d+)\]", path):
        if t is None:
            return None
        nxt: mi.Type | None = None
        for member in _members(t):
            if name and isinstance(member, mi.StructType):
                nxt = next((f.type for f in member.fields if f.encode_name == name), None)
            elif index and isinstance(member, mi.ListType):
                nxt = member.item_type
            elif index and isinstance(member, mi.TupleType) and int(index) < len(member.item_types):
                nxt = member.item_types[int(index)]
            if nxt is not None:
                break
        t = nxt
    return t


def _choices(t: mi.Type | None) -> list[str]:
    """The valid values of a Literal or an Enum type (or a union of them), as TOML spells them."""
    out: list[str] = []
    for member in [] if t is None else _members(t):
        if isinstance(member, mi.LiteralType):
            out += [str(v) for v in member.values]
        elif isinstance(member, mi.EnumType) and issubclass(member.cls, enum.Enum):
            out += [str(m.value) for m in member.cls]
    return out


def _keys(t: mi.Type | None) -> list[str]:
    """The keys of the table (struct) at ``t``."""
    for member in [] if t is None else _members(t):
        if isinstance(member, mi.StructType):
            return [f.encode_name for f in member.fields]
    return []


def _value_at(raw: object, field: str) -> tuple[bool, object]:
    """The raw TOML value at a msgspec error path (``a.b[0].c``): ``(found, value)``."""
    node = raw
    for name, index in re.findall(r"([^.\[\]]+)|\[(\d+)\]", field):
        if name and isinstance(node, dict) and name in node:
            node = node[name]
        elif index and isinstance(node, list) and int(index) < len(node):
            node = node[int(index)]
        else:
            return False, None
    return bool(field), node


def _expected(spec: str) -> str:
    """msgspec's ``float | null`` as ``float`` (a TOML file has no null), ``str`` as ``string``."""
    words = [_TOML_TYPES.get(w.strip(), w.strip()) for w in spec.split("|")]
    return " or ".join(w for w in words if w != "null")


def explain(exc: msgspec.ValidationError, raw: object, root: type) -> tuple[str, str]:
    """``(key, reason)`` of ``exc``, raised converting ``raw`` to ``root``: the reason says the
    bad value (``got ...``) once, and the valid values of an enum or the keys of a table."""
    field, reason = split_validation_error(exc)
    prefix = f"{field}." if field else ""
    if m := re.fullmatch(r"Object contains unknown field `(.+)`", reason):
        keys = _keys(_type_at(root, field))
        hint = did_you_mean(m[1], keys)
        return prefix + m[1], f"unknown key{hint}; valid: {', '.join(keys)}"
    if m := re.fullmatch(r"Object missing required field `(.+)`", reason):
        return prefix + m[1], "required, missing"
    found, value = _value_at(raw, field)
    choices = _choices(_type_at(root, field))
    got = f", got {toml_value(value)}" if found else ""
    if m := re.fullmatch(r"Expected `str` matching regex '\^\(([\w|-]+)\)\$'", reason):
        choices = m[1].split("|")  # a pattern of alternatives is a choice too
        reason = "Invalid enum value"
    if reason.startswith("Invalid enum value"):
        hint = did_you_mean(str(value), choices) if found else ""
        return field, f"invalid choice{got}{hint}; valid: {', '.join(choices)}"
    if m := re.fullmatch(r"Expected `([^`]+)`(.*?)(?:, got (`[^`]+`|.+))?", reason):
        rest = m[2]
        if not found and m[3]:  # only msgspec knows what it got
            got = f", got {_expected(m[3].strip('`'))}"
        reason = f"expected {_expected(m[1])}{rest}{got}"
    elif found and toml_value(value) not in reason:
        reason = f"{reason}{got}"
    if choices:
        reason += f"; valid: {', '.join(choices)}"
    return field, reason
