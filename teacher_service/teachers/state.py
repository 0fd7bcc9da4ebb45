"""A teacher's state as JSON-ready data and back, declared once per kind instead of written twice.

A kind lists what its snapshot holds beyond the counters as ``StateField``s: the key in the snapshot,
the attribute it comes from, and a codec that turns the attribute's value into plain data and back
(``Teacher._export`` and ``_import`` walk the list). Numbers, numpy arrays of any dtype (``ARRAY``,
for one value per level, say), lists and deques of them, tuples and records have codecs here (a
return scale's is ``performance.RETURN_SCALE``); what no codec fits (a tree of regions, a history
log) a kind adds in its own ``_export``/``_import`` around the declared fields. The codecs write what
each kind wrote by hand before, key for key, so every stored snapshot still loads.

Nothing random is stored: draws are addressed by the seed and a counter (``draws``), so the counters
and these fields are the whole state.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections import Counter, deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np


class Codec(ABC):
    """Turns one attribute's value into JSON-ready data (``dump``) and back (``load``). ``load``
    also gets the value a fresh teacher holds there, for what the data does not say (an array's
    shape, a deque's length limit)."""

    @abstractmethod
    def dump(self, value: Any) -> Any: ...

    @abstractmethod
    def load(self, data: Any, fresh: Any) -> Any: ...


@dataclass(frozen=True)
class Scalar(Codec):
    """An ``int``, ``float``, ``bool`` or ``str``, stored as it is and read back through its type."""

    kind: Callable[[Any], Any]

    def dump(self, value: Any) -> Any:
        return value

    def load(self, data: Any, fresh: Any) -> Any:
        return self.kind(data)


@dataclass(frozen=True)
class Optional(Codec):
    """``None``, or a value of ``inner``."""

    inner: Codec

    def dump(self, value: Any) -> Any:
        return None if value is None else self.inner.dump(value)

    def load(self, data: Any, fresh: Any) -> Any:
        return None if data is None else self.inner.load(data, fresh)


INT, FLOAT, BOOL, STR = Scalar(int), Scalar(float), Scalar(bool), Scalar(str)
OPTIONAL_FLOAT, OPTIONAL_BOOL = Optional(FLOAT), Optional(BOOL)


class Plain(Codec):
    """JSON-ready data kept as it is (a kind's own records, such as the moves it reports)."""

    def dump(self, value: Any) -> Any:
        return value

    def load(self, data: Any, fresh: Any) -> Any:
        return data


PLAIN = Plain()


@dataclass(frozen=True)
class FloatArray(Codec):
    """A float64 array as nested lists. ``rows``: any number of rows as wide as the fresh array's;
    otherwise exactly the fresh array's shape (a bound per dimension), or any shape where a fresh
    teacher holds none."""

    what: str
    rows: bool = False

    def dump(self, value: Any) -> Any:
        return np.asarray(value).tolist()

    def load(self, data: Any, fresh: Any) -> Any:
        array = np.array(data, dtype=np.float64)
        if fresh is None:
            return array
        shape = np.shape(fresh)
        if self.rows:
            return array.reshape(-1, *shape[1:])
        if array.shape != shape:
            raise ValueError(f"{self.what} must have shape {shape}, got {array.shape}")
        return array


@dataclass(frozen=True)
class Array(Codec):
    """A numpy array of any dtype (float scores, bool flags, int64 counters) as nested lists, read
    back with the dtype and shape of the fresh teacher's array: a kind that keeps one value per level
    declares ``StateField("scores", ARRAY)`` and a restored teacher holds the same array. A shape
    other than the fresh one's (a snapshot of another space) is refused."""

    def dump(self, value: Any) -> Any:
        return np.asarray(value).tolist()

    def load(self, data: Any, fresh: Any) -> Any:
        expected = np.asarray(fresh)
        array = np.array(data, dtype=expected.dtype)
        if array.shape != expected.shape:
            raise ValueError(f"an array of shape {expected.shape} was expected, got {array.shape}")
        return array


ARRAY = Array()


@dataclass(frozen=True)
class Items(Codec):
    """A list or a deque of values of ``item``; a deque keeps the fresh one's length limit."""

    item: Codec

    def dump(self, value: Any) -> Any:
        return [self.item.dump(entry) for entry in value]

    def load(self, data: Any, fresh: Any) -> Any:
        loaded = [self.item.load(entry, None) for entry in data]
        return deque(loaded, maxlen=fresh.maxlen) if isinstance(fresh, deque) else loaded


class Counts(Codec):
    """A ``Counter`` of names, stored as a dict of name to count."""

    def dump(self, value: Any) -> Any:
        return dict(value)

    def load(self, data: Any, fresh: Any) -> Any:
        return Counter({str(name): int(count) for name, count in data.items()})


COUNTS = Counts()


@dataclass(frozen=True)
class Pair(Codec):
    """A tuple stored as a list, each place with its own codec."""

    places: tuple[Codec, ...]

    def dump(self, value: Any) -> Any:
        return [codec.dump(entry) for codec, entry in zip(self.places, value, strict=True)]

    def load(self, data: Any, fresh: Any) -> Any:
        return tuple(codec.load(entry, None) for codec, entry in zip(self.places, data, strict=True))


OUTCOMES = Items(Pair((FLOAT, OPTIONAL_BOOL)))
"""Results as (return, success or ``None``) pairs."""


@dataclass(frozen=True)
class Record(Codec):
    """A dict with fixed keys, each with its own codec."""

    fields: Mapping[str, Codec]

    def dump(self, value: Any) -> Any:
        return {key: codec.dump(value[key]) for key, codec in self.fields.items()}

    def load(self, data: Any, fresh: Any) -> Any:
        return {key: codec.load(data[key], None) for key, codec in self.fields.items()}


@dataclass(frozen=True)
class StateField:
    """One entry of a snapshot's ``state``: ``key`` in it, from attribute ``attr`` (the key
    unless given), through ``codec``."""

    key: str
    codec: Codec
    attr: str = ""

    @property
    def attribute(self) -> str:
        return self.attr or self.key


def export_fields(owner: object, fields: Sequence[StateField]) -> dict[str, Any]:
    """The declared fields of ``owner`` as JSON-ready data, keyed as declared."""
    return {field.key: field.codec.dump(getattr(owner, field.attribute)) for field in fields}


def import_fields(owner: object, fields: Sequence[StateField], state: Mapping[str, Any]) -> None:
    """Set the declared fields of a fresh ``owner`` from what ``export_fields`` wrote."""
    for field in fields:
        fresh = getattr(owner, field.attribute)
        try:
            loaded = field.codec.load(state[field.key], fresh)
        except ValueError as error:
            raise ValueError(f"state field {field.key!r}: {error}") from error
        setattr(owner, field.attribute, loaded)
