"""A small cache of values computed per object, for objects that are not hashable by value.

A `BalanceModel` is a frozen dataclass holding arrays: hashing it by value would cost as much as
what is cached. The cache keys by `id()` and checks identity on the way out, so a new object that
reuses a freed id is never answered with the old object's value; it holds a reference to each
object it answers for, and is emptied when it reaches its size limit.
"""

from __future__ import annotations

from typing import Generic, TypeVar

V = TypeVar('V')


class IdentityCache(Generic[V]):
    """Values by object identity, at most `limit` objects (then emptied)."""

    def __init__(self, limit: int = 64):
        if limit < 1:
            raise ValueError(f'IdentityCache limit must be at least 1, got {limit}')
        self.limit = limit
        self._items: dict[int, tuple[object, V]] = {}

    def get(self, obj: object) -> V | None:
        """The value stored for this very object, or None."""
        item = self._items.get(id(obj))
        return item[1] if item is not None and item[0] is obj else None

    def put(self, obj: object, value: V) -> V:
        """Store value for obj and return it."""
        if len(self._items) >= self.limit and id(obj) not in self._items:
            self._items.clear()
        self._items[id(obj)] = (obj, value)
        return value

    def __len__(self) -> int:
        return len(self._items)
