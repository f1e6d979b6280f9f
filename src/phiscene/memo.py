"""A bounded in-process memory of computed values (least recently used evicted), the one every per-process cache
of the package uses: signed distances, SDF grids, outer shells, mass properties."""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Generic, TypeVar

V = TypeVar("V")


class Memo(Generic[V]):
    """Values by key, at most ``size`` of them; the least recently used is evicted first.

    Parameters
    ----------
    size
        Entries kept.
    """

    def __init__(self, size: int):
        self.size = int(size)
        self._values: OrderedDict[Hashable, V] = OrderedDict()

    def get(self, key: Hashable, compute: Callable[[], V]) -> V:
        """The value remembered for ``key`` (now the most recently used), else ``compute()``, remembered."""
        if key in self._values:
            self._values.move_to_end(key)
            return self._values[key]
        value = compute()
        self._values[key] = value
        if len(self._values) > self.size:
            self._values.popitem(last=False)
        return value

    def clear(self) -> None:
        """Forget every value."""
        self._values.clear()

    def __len__(self) -> int:
        return len(self._values)

    def __contains__(self, key: Hashable) -> bool:
        return key in self._values
