"""One least-recently-used dict by count: what a worker keeps so as to do nothing twice (the settle ends of
worker.trial.settled, the trial ends of worker.trial.continued, the verdicts on bodies of worker.trial.feasibility).
A value is touched when a get returns it."""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Generic, TypeVar

K = TypeVar("K", bound=Hashable)
V = TypeVar("V")


class LRU(Generic[K, V]):
    """Values by key, the `size` most recently used kept (size 0 keeps nothing); `what` names them in errors."""

    def __init__(self, size: int, what: str) -> None:
        self.what = what
        self.size = size
        self._items: OrderedDict[K, V] = OrderedDict()
        self.hits = 0
        self.misses = 0

    @property
    def size(self) -> int:
        return self._size

    @size.setter
    def size(self, size: int) -> None:
        # a smaller size trims at the next put
        if size < 0:
            raise ValueError(f"size of the {self.what} is negative: received {size}, expected >= 0")
        self._size = size

    def __len__(self) -> int:
        return len(self._items)

    def get(self, key: K, usable: Callable[[V], bool] | None = None) -> V | None:
        """The value of `key`, touched, if kept (and `usable` says yes to it); else None, nothing touched."""
        value = self._items.get(key)
        if value is None or (usable is not None and not usable(value)):
            self.misses += 1
            return None
        self._items.move_to_end(key)
        self.hits += 1
        return value

    def put(self, key: K, value: V) -> None:
        self._items[key] = value
        self._items.move_to_end(key)
        while len(self._items) > self._size:
            self._items.popitem(last=False)
