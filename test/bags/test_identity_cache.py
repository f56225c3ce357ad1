"""model/identity_cache.py: values by object identity, never handed to another object."""

import numpy as np
import pytest

from balance_calib.model.identity_cache import IdentityCache


class _Unhashable:
    __hash__ = None  # like a dataclass holding arrays

    def __init__(self, values):
        self.values = np.asarray(values)


def test_a_value_is_returned_for_the_same_object_only():
    cache = IdentityCache(limit=4)
    a, b = _Unhashable([1.0]), _Unhashable([1.0])  # equal values, different objects
    assert cache.put(a, 'for a') == 'for a'
    assert cache.get(a) == 'for a'
    assert cache.get(b) is None


def test_a_reused_id_is_not_answered_with_the_old_value():
    cache = IdentityCache(limit=4)
    cache.put(_Unhashable([1.0]), 'stale')  # the object dies; its id may be reused
    # the cache holds the object itself, so its id cannot be reused while cached
    fresh = [_Unhashable([2.0]) for _ in range(50)]
    assert all(cache.get(f) is None for f in fresh)


def test_the_cache_is_emptied_at_its_limit_and_bad_limits_are_refused():
    cache = IdentityCache(limit=2)
    a, b, c = _Unhashable([1]), _Unhashable([2]), _Unhashable([3])
    cache.put(a, 1)
    cache.put(b, 2)
    cache.put(a, 11)  # an object already there does not empty it
    assert len(cache) == 2 and cache.get(a) == 11
    cache.put(c, 3)
    assert len(cache) == 1 and cache.get(c) == 3 and cache.get(a) is None
    with pytest.raises(ValueError, match='limit'):
        IdentityCache(limit=0)
