"""timeline.py's event queue, and its step helpers: the pair list a mid-step re-query
grows, and its adjacency; the loop's own re-query."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from physdbg.engine.broadphase.boxes import overlapping
from physdbg.engine.timeline import (COUNTERS, HEAP_SIZE, adjacency_from_pairs, grow_unpartnered, heap_pop,
                                     heap_push, merge_sorted_pairs)


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


@settings(max_examples=200, deadline=None)
@given(times=st.lists(st.sampled_from([0.0, 1e-300, 0.25, 0.5, 0.5000000000000001, 1.0]), max_size=60),
       pops=st.lists(st.integers(0, 3), max_size=60))
def test_the_queue_pops_by_time_then_row_whatever_the_interleaving(times, pops):
    """Pushes and pops interleaved (pops[m] pops after push m, ties in time included): each
    pop is the earliest entry still queued, by time and then by test-log row, the order
    the loop's contacts (and so every golden hash) depend on."""
    toi = np.empty(len(times) + 1)
    data = np.empty((len(times) + 1, 2), dtype=np.int64)
    counters = np.zeros(COUNTERS, dtype=np.int64)
    queued: list[tuple[float, int]] = []
    popped, expected = [], []

    def pop():
        slot = heap_pop(toi, data, counters)
        popped.append((float(toi[slot]), int(data[slot, 0])))
        assert data[slot, 1] == data[slot, 0] + 1  # the entry moved whole (its batch with its row)
        queued.sort()
        expected.append(queued.pop(0))

    for row, t in enumerate(times):
        heap_push(toi, data, counters, t, row, row + 1)
        queued.append((t, row))
        for _ in range(pops[row] if row < len(pops) else 0):
            if queued:
                pop()
    while queued:
        pop()
    assert popped == expected
    assert counters[HEAP_SIZE] == 0


# box bounds from a few values, so that boxes touch, coincide and hold signed zeros and NaN
_BOUND = st.sampled_from([-1.0, -0.5, -0.0, 0.0, 0.25, 0.5, 1.0, float("nan")])


@settings(max_examples=300, deadline=None)
@given(n=st.integers(2, 12), data=st.data())
def test_the_loops_requery_finds_nothing_exactly_when_the_worlds_would(n, data):
    """grow_unpartnered answers the world's re-query (World._refresh_box on a broad phase
    whose query scans every box) where that would find no new partner: it grows the box
    bit for bit as np.minimum and np.maximum do, and leaves everything alone otherwise."""
    lo = np.array(data.draw(st.lists(st.lists(_BOUND, min_size=3, max_size=3), min_size=n, max_size=n)))
    hi = lo + np.array(data.draw(st.lists(st.lists(st.sampled_from([0.0, 0.25, 1.0]), min_size=3, max_size=3),
                                          min_size=n, max_size=n)))
    every = [(i, j) for i in range(n) for j in range(i + 1, n)]
    start, partners = adjacency_from_pairs(_sorted_pairs(data.draw(st.sets(st.sampled_from(every)))), n)
    p = data.draw(st.integers(0, n - 1))
    path_box = np.array(data.draw(st.lists(st.lists(_BOUND, min_size=3, max_size=3), min_size=2, max_size=2)))
    # the world's way: grow, scan every box, drop p and its known partners
    grown_lo, grown_hi = lo.copy(), hi.copy()
    grown_lo[p] = np.minimum(lo[p], path_box[0])
    grown_hi[p] = np.maximum(hi[p], path_box[1])
    found = set(overlapping(grown_lo, grown_hi, grown_lo[p], grown_hi[p]).tolist())
    new = found - {p} - set(partners[start[p]:start[p + 1]].tolist())
    box_lo, box_hi = lo.copy(), hi.copy()
    alone = grow_unpartnered(p, path_box, box_lo, box_hi, start, partners)
    assert alone == (not new)
    want_lo, want_hi = (grown_lo, grown_hi) if alone else (lo, hi)
    assert box_lo.tobytes() == want_lo.tobytes() and box_hi.tobytes() == want_hi.tobytes()
