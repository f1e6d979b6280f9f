"""phiscene.memo.Memo. Oracle: functools.lru_cache, the standard library's least-recently-used memory, fed the
same sequence of keys, computes for the same keys."""

from __future__ import annotations

import functools

from phiscene.memo import Memo


def test_memo_computes_and_evicts_as_lru_cache_does():
    keys = [1, 2, 3, 1, 4, 2, 5, 1, 3, 3, 6, 2, 4, 1]
    computed, reference = [], []

    @functools.lru_cache(maxsize=3)
    def oracle(k):
        reference.append(k)
        return k * 10

    memo = Memo(3)
    for k in keys:
        assert memo.get(k, lambda k=k: computed.append(k) or k * 10) == oracle(k)
    assert computed == reference
    assert len(memo) == 3 and 1 in memo and 5 not in memo
    memo.clear()
    assert len(memo) == 0
