"""Role options: the ``--set KEY=VALUE`` settings the launcher and the CLI give a role process.

A role declares its options as one :class:`RoleOptions` struct: names, types, defaults, and
ranges as ``msgspec.Meta`` constraints, each field documented where it is declared (a role whose
defaults come from the scenario overrides :meth:`RoleOptions.defaults`). Its ``main`` reads them
with :func:`role_options`, which raises :class:`OptionError` naming the option and the bad value,
or is made by :func:`role_main`, which reads them and hands them to the role's code::

    class ViewerOptions(RoleOptions, frozen=True, kw_only=True):
        rate_hz: Annotated[float, msgspec.Meta(gt=0.0, le=25.0)] = 25.0

    opts = role_options(ViewerOptions, ctx)  # ctx.options == {"rate_hz": "10"}

    @role_main(ViewerOptions, "viewer")  # a bad option: logged in one line, exit code 2
    def main(ctx: NodeContext, opts: ViewerOptions) -> int: ...

Values are read as msgspec reads text in lax mode (``"1.5"`` a float, ``"3"`` an int); a
``bool`` also takes on/off and yes/no; a tuple or list takes comma-separated items; a ``dict``
field ``rate`` takes ``rate.<KEY>=VALUE`` per entry. An option not declared is refused with the
list of the known ones.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable, Mapping
from typing import TYPE_CHECKING, Any, Self, TypeVar

import msgspec
from msgspec import inspect as mi

from swarmbus.errors import PlumeswarmError
from swarmbus.scenario_errors import did_you_mean

if TYPE_CHECKING:  # the node runtime opens Zenoh; a role's options need not
    from swarmbus.node import NodeContext
    from swarmbus.scenario import Scenario

log = logging.getLogger(__name__)

_TRUE = ("true", "on", "yes", "1")
_FALSE = ("false", "off", "no", "0")


class OptionError(PlumeswarmError, ValueError):
    """A role option that is malformed, out of range or unknown (the message names it)."""


class RoleOptions(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Base of every role's options; each field needs a default."""

    @classmethod
    def defaults(cls, scenario: Scenario) -> Self:
        """The options before any ``--set``: the declared defaults (a role whose defaults come
        from ``scenario`` overrides this)."""
        del scenario
        return cls()


T = TypeVar("T", bound=RoleOptions)


def role_options(spec: type[T], ctx: NodeContext) -> T:
    """A role's options: ``ctx.options`` over ``spec.defaults(ctx.scenario)``, or
    :class:`OptionError`."""
    return parse_options(spec, ctx.options, spec.defaults(ctx.scenario))


def role_main(
    spec: type[T], role: str
) -> Callable[[Callable[[NodeContext, T], int]], Callable[[NodeContext], int]]:
    """A role's entry point ``main(ctx)`` made of ``run(ctx, options)``: the options read with
    :func:`role_options`; a bad one is logged as ``<role>: <what is wrong>`` and the exit code
    is 2, before the role joins the bus."""

    def wrap(run: Callable[[NodeContext, T], int]) -> Callable[[NodeContext], int]:
        def main(ctx: NodeContext) -> int:
            try:
                options = role_options(spec, ctx)
            except OptionError as exc:
                log.error("%s: %s", role, exc)
                return 2
            return run(ctx, options)

        main.__doc__ = run.__doc__
        return main

    return wrap


def split_settings(items: Iterable[str]) -> dict[str, str]:
    """``["k=v", ...]`` as a dict (a later setting of a key wins), or :class:`OptionError`."""
    settings: dict[str, str] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise OptionError(f"--set expects KEY=VALUE, got {item!r}")
        settings[key.strip()] = value
    return settings


def parse_options(
    spec: type[T], settings: Mapping[str, str] | Iterable[str], defaults: T | None = None
) -> T:
    """``settings`` (a dict, or ``KEY=VALUE`` items) over ``defaults`` (``spec()`` when None)."""
    pairs = settings if isinstance(settings, Mapping) else split_settings(settings)
    base = spec() if defaults is None else defaults
    fields = _fields(spec)
    values: dict[str, Any] = {}
    for key, text in pairs.items():
        name, dot, entry = key.partition(".")
        field = fields.get(name)
        is_map = field is not None and isinstance(_inner(field.type), mi.DictType)
        if field is None or bool(dot) != is_map or (is_map and not entry):
            known = known_names(spec)
            if is_map:  # rate=5 or rate.=5: a map's setting names its entry
                hint = f" (did you mean '{name}.<KEY>'?)"
            else:
                hint = did_you_mean(key, [n for n in known.split(", ") if n != key])
            raise OptionError(f"--set {key}={text}: unknown option{hint}; known: {known}")
        try:
            value = _convert(spec, field, entry if is_map else None, text)
        except msgspec.ValidationError:
            wanted = describe(_value_type(field.type))
            raise OptionError(f"--set {key}={text}: expected {wanted}") from None
        if is_map:
            value = {**values.get(field.name, getattr(base, field.name)), **value}
        values[field.name] = value
    return msgspec.structs.replace(base, **values)


def known_names(spec: type[RoleOptions]) -> str:
    """The option names of ``spec`` for a message (``rate.<KEY>`` for a dict field)."""
    names = [
        f"{name}.<KEY>" if isinstance(_inner(f.type), mi.DictType) else name
        for name, f in _fields(spec).items()
    ]
    return ", ".join(sorted(names)) or "none"


def describe(t: mi.Type) -> str:
    """What a value of type ``t`` must be, in words (``a number in [0, 25]``)."""
    if isinstance(t, mi.UnionType):
        return " or ".join(describe(u) for u in t.types if not isinstance(u, mi.NoneType))
    if isinstance(t, mi.BoolType):
        return "true or false"
    if isinstance(t, mi.IntType | mi.FloatType):
        what = "an integer" if isinstance(t, mi.IntType) else "a number"
        return what + _range(t.ge, t.gt, t.le, t.lt)
    if isinstance(t, mi.EnumType):
        return "one of " + ", ".join(str(m.value) for m in t.cls)
    if isinstance(t, mi.LiteralType):
        return "one of " + ", ".join(str(v) for v in t.values)
    if isinstance(t, mi.ListType | mi.VarTupleType):
        return f"comma-separated values, each {describe(t.item_type)}"
    if isinstance(t, mi.StrType) and t.pattern:
        return f"text matching {t.pattern}"
    return "text"


def _range(ge: float | None, gt: float | None, le: float | None, lt: float | None) -> str:
    if (ge is not None or gt is not None) and (le is not None or lt is not None):
        low = f"[{ge:g}" if ge is not None else f"({gt:g}"
        high = f"{le:g}]" if le is not None else f"{lt:g})"
        return f" in {low}, {high}"
    for sign, bound in ((">=", ge), (">", gt), ("<=", le), ("<", lt)):
        if bound is not None:
            return f" {sign} {bound:g}"
    return ""


def _fields(spec: type[RoleOptions]) -> dict[str, mi.Field]:
    """The fields of ``spec`` by option name (a field's ``msgspec.field(name=...)``)."""
    info = mi.type_info(spec)
    assert isinstance(info, mi.StructType)
    return {f.encode_name: f for f in info.fields}


def _inner(t: mi.Type) -> mi.Type:
    """``t`` without ``| None``."""
    if isinstance(t, mi.UnionType):
        rest = [u for u in t.types if not isinstance(u, mi.NoneType)]
        return rest[0] if len(rest) == 1 else t
    return t


def _value_type(t: mi.Type) -> mi.Type:
    inner = _inner(t)
    return inner.value_type if isinstance(inner, mi.DictType) else t


def _convert(spec: type[T], field: mi.Field, entry: str | None, text: str) -> Any:
    """One option's value, checked by msgspec against the whole struct's declaration."""
    raw = _raw(_value_type(field.type), text)
    payload = {field.encode_name: raw if entry is None else {entry: raw}}
    return getattr(msgspec.convert(payload, spec, strict=False), field.name)


def _raw(t: mi.Type, text: str) -> Any:
    """``text`` as msgspec's lax conversion takes it for type ``t``."""
    inner = _inner(t)
    if isinstance(t, mi.UnionType) and inner is not t and not text.strip():
        return None  # an empty value of an optional option: unset
    if isinstance(inner, mi.BoolType):
        word = text.strip().lower()
        return True if word in _TRUE else False if word in _FALSE else text
    if isinstance(inner, mi.ListType | mi.VarTupleType):
        return [_raw(inner.item_type, part) for part in text.split(",") if part.strip()]
    if isinstance(inner, mi.IntType | mi.FloatType):
        return text.strip()
    return text
