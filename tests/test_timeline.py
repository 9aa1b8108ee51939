"""timeline.py's step helpers: the pair list a mid-step re-query grows, and its adjacency."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from physdbg.engine.timeline import adjacency_from_pairs, merge_sorted_pairs


def _sorted_pairs(pairs: set[tuple[int, int]]) -> np.ndarray:
    return np.array(sorted(pairs), dtype=np.int64).reshape(-1, 2)


@settings(max_examples=200, deadline=None)
@given(n=st.integers(2, 30), data=st.data())
def test_merging_new_pairs_gives_what_sorting_the_whole_list_gives(n, data):
    every = [(i, j) for i in range(n) for j in range(i + 1, n)]
    chosen = data.draw(st.sets(st.sampled_from(every)))
    new = data.draw(st.sets(st.sampled_from(every)).map(lambda s: s - chosen))
    pairs, extra = _sorted_pairs(chosen), _sorted_pairs(new)
    merged = merge_sorted_pairs(pairs, extra)
    together = np.concatenate((pairs, extra))
    np.testing.assert_array_equal(merged, together[np.lexsort((together[:, 1], together[:, 0]))])
    assert merged.dtype == np.int64
    # and the adjacency built from it lists each sphere's partners in order
    start, partners = adjacency_from_pairs(merged, n)
    for i in range(n):
        expected = sorted([j for a, j in chosen | new if a == i] + [a for a, j in chosen | new if j == i])
        assert partners[start[i]:start[i + 1]].tolist() == expected
