"""The state codec of behaviour plug-ins: what a checkpoint saves of a behaviour, bit for bit.

A behaviour (and each helper it keeps, such as
:class:`agents.behaviors.steering.CrosswindSweep`) derives from :class:`SavesState` and lists
its state attributes in ``state_attributes``; its ``checkpoint()`` / ``restore(data)`` save and
put back exactly those (numpy arrays and generators bit for bit), never its configuration or
the callables it was built with (a wind reader), so a restarted autopilot's behaviour flies on
with the same bits. :mod:`agents.checkpoint` stores the data with the rest of the autopilot.
"""

from __future__ import annotations

import dataclasses
from collections import deque
from collections.abc import Callable
from typing import Any, ClassVar

import numpy as np

from agents.behavior import SourceEstimate


class SavesState:
    """``checkpoint()`` / ``restore(data)`` over the attributes named in ``state_attributes``.

    The data is plain msgpack-encodable values; tuples, deques, numpy arrays (dtype, shape
    and bytes), generators (their ``bit_generator.state``), :class:`SourceEstimate` and
    nested :class:`SavesState` objects are tagged so that restoring gives back the same types
    and bits. A nested object or generator is restored into the one the fresh behaviour built
    (which keeps its configuration).
    """

    state_attributes: ClassVar[tuple[str, ...]] = ()

    def checkpoint(self) -> dict[str, Any]:
        return {name: encode_state(getattr(self, name)) for name in self.state_attributes}

    def restore(self, data: dict[str, Any]) -> None:
        for name in self.state_attributes:
            if name not in data:
                raise ValueError(f"{type(self).__name__} checkpoint: no {name!r} in it")
            setattr(self, name, decode_state(data[name], getattr(self, name)))


def _encode_int(value: int) -> Any:
    # msgpack holds 64 bits; a generator's 128-bit words go as decimal text
    return value if -(2**63) <= value < 2**64 else {"$": "int", "v": str(value)}


def _tagged(tag: str, value: Any) -> dict[str, Any]:
    return {"$": tag, "v": value}


#: How each kind of value is saved, in the order the kinds are tried (bool before int).
_ENCODERS: tuple[tuple[type | tuple[type, ...], Callable[[Any], Any]], ...] = (
    ((bool, str, float, type(None)), lambda v: v),
    (int, _encode_int),
    (SavesState, lambda v: _tagged("state", v.checkpoint())),
    (np.ndarray, lambda v: _tagged("ndarray", [v.dtype.str, list(v.shape), v.tobytes()])),
    (np.random.Generator, lambda v: _tagged("generator", encode_state(v.bit_generator.state))),
    (SourceEstimate, lambda v: _tagged("estimate", encode_state(dataclasses.asdict(v)))),
    (tuple, lambda v: _tagged("tuple", [encode_state(x) for x in v])),
    (deque, lambda v: _tagged("deque", [encode_state(x) for x in v])),
    (list, lambda v: [encode_state(x) for x in v]),
)


def encode_state(value: Any) -> Any:
    """``value`` as msgpack-encodable data that :func:`decode_state` turns back exactly."""
    for kind, encode in _ENCODERS:
        if isinstance(value, kind):
            return encode(value)
    if isinstance(value, dict) and all(isinstance(k, str) for k in value):
        return _tagged("dict", {k: encode_state(v) for k, v in value.items()})
    raise TypeError(f"cannot save a {type(value).__name__} as behaviour state")


def _restore_into(current: Any, v: Any) -> Any:
    current.restore(v)
    return current


def _generator_into(current: Any, v: Any) -> Any:
    current.bit_generator.state = decode_state(v)
    return current


def _ndarray(v: Any) -> Any:
    dtype, shape, raw = v
    return np.frombuffer(raw, dtype=np.dtype(dtype)).reshape(shape).copy()


#: The tagged kinds: tag -> (saved value, the fresh attribute) -> value.
_DECODERS: dict[str, Callable[[Any, Any], Any]] = {
    "int": lambda v, current: int(v),
    "state": lambda v, current: _restore_into(current, v),
    "ndarray": lambda v, current: _ndarray(v),
    "generator": lambda v, current: _generator_into(current, v),
    "estimate": lambda v, current: SourceEstimate(**decode_state(v)),
    "tuple": lambda v, current: tuple(decode_state(x) for x in v),
    "deque": lambda v, current: deque(decode_state(x) for x in v),
    "dict": lambda v, current: {k: decode_state(x) for k, x in v.items()},
}


def decode_state(data: Any, current: Any = None) -> Any:
    """The value :func:`encode_state` saved; ``current`` (the fresh attribute) receives a
    nested state or a generator's state in place."""
    if isinstance(data, list):
        return [decode_state(v) for v in data]
    if not isinstance(data, dict):
        return data
    tag, v = data["$"], data["v"]
    decoder = _DECODERS.get(tag)
    if decoder is None:
        raise ValueError(f"behaviour checkpoint: unknown value kind {tag!r}")
    return decoder(v, current)
