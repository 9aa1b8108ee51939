"""The held-contact solve (engine/resting/): the direct cluster solve against plain
projected Gauss–Seidel, on the held contacts of resting stacks."""

from __future__ import annotations

import numpy as np
import pytest

from physdbg.engine.resting import (
    HELD,
    RAPID_HOLD,
    RAPID_TC,
    HeldContacts,
    begin_solve,
    grow_held,
    held_add,
    held_room,
    new_held,
    rapid_holds,
    solve_contacts,
)
from physdbg.engine.resting.solves import _cholesky_solve, _contact_matrix, _gauss_seidel, _relative
from physdbg.events import KIND_PAIR, KIND_WALL

from .conftest import make_state, make_walls, make_world


@pytest.fixture(scope="module")
def pile():
    """Four stacks of eight spheres (r = 0.1 m) on a floor under gravity, settled for half
    a second: 32 held contacts, each stack a chain that Gauss–Seidel converges on slowly
    (rate about cos²(π/9) per sweep)."""
    positions = [[0.5 * s, 0.1 + 0.2 * k, 0.0] for s in range(4) for k in range(8)]
    world, _ = make_world(make_state(positions, radius=0.1, restitution=0.5), make_walls(([0, 1, 0], 0.0, 0.5)),
                          observe=False, gravity=(0.0, -9.81, 0.0))
    for _ in range(30):
        stats = world.step(1 / 60)
    assert world.held_count == 32 and stats.max_overlap <= world.settings.contact_tolerance
    return world


def _solve(world, contact, solver, target=0.05):
    """Ask held contact ``contact`` to separate at ``target`` m/s and solve the velocities
    with ``solver``; returns (velocities (N, 3), the store after, updates done)."""
    h = HeldContacts(*[array.copy() for array in world.held])
    v = world.state.velocities.copy()
    x = world.state.positions.copy()
    a = world.last_step.path_accel.copy()
    sigma = np.zeros(len(v))
    begin_solve(h)
    h.count[2] = 0
    h.target[contact] = target
    seeds = np.array([contact], np.int64)
    ok = solver(h, v, True, seeds, 1, x, v, a, sigma, world.state.inverse_mass, 0.0, world._integrator, world._drag,
                world._k, world.last_step.vtol, 10**9, 0.0)
    assert ok
    return v, h, int(h.count[2])


def test_the_direct_solve_finds_what_gauss_seidel_finds_with_a_fraction_of_the_work(pile):
    held = int(pile.held.count[HELD])
    rng = np.random.default_rng(7)
    direct_work = sweep_work = 0
    for contact in rng.choice(held, size=12, replace=False):
        v_direct, h, work = _solve(pile, contact, solve_contacts)
        v_sweeps, _, work_gs = _solve(pile, contact, _gauss_seidel)
        direct_work += work
        sweep_work += work_gs
        # the velocities that satisfy the contacts are unique; both solves stop within
        # their tolerance of them
        assert np.abs(v_direct - v_sweeps).max() < 1e-10
        # and every held contact the solve visited ends as it promises: pushing only
        # where it is exactly at its target, and approaching by no more than its
        # neighbours' last updates below the tolerance (two neighbours in a stack)
        tol = pile.last_step.vtol
        for c in range(held):
            if h.seen[c] != h.count[1]:
                continue
            rel = _relative(v_direct, h, c, True) - h.target[c]
            assert rel >= -2 * tol
            if h.jv[c] > 0.0:
                assert abs(rel) <= 2 * tol
    assert direct_work * 20 < sweep_work, (direct_work, sweep_work)


def test_a_satisfied_seed_costs_one_update(pile):
    _, _, work = _solve(pile, 0, solve_contacts, target=0.0)
    assert work == 1


def test_the_held_store_grows_only_what_ran_out():
    """The per-sphere lists are (N, K): K doubles only when a sphere's list is full, the
    capacity only when the store is (doubling both at once made K 8 192 wide, 6.5 GB, for
    a 100 000-sphere pile). Full means without room for AT_ONE_INSTANT more contacts: a
    sphere's contacts at one instant are held together."""
    from physdbg.engine.resting import AT_ONE_INSTANT, grow_held, held_add, held_find, held_room, new_held

    room = AT_ONE_INSTANT
    h = new_held(8, capacity=room + 2, per_particle=room + 1)
    held_add(h, KIND_PAIR, 0, 1, 1.0, 0.0, 0.0)
    held_add(h, KIND_PAIR, 2, 3, 0.0, 1.0, 0.0)
    assert held_room(h, 0, 4)
    held_add(h, KIND_PAIR, 4, 5, 0.0, 1.0, 0.0)
    assert not held_room(h, 0, 6)  # the store is full; no sphere is
    h = grow_held(h)
    assert (h.kind.shape[0], h.slots.shape[1]) == (2 * (room + 2), room + 1)
    held_add(h, KIND_PAIR, 0, 2, 0.0, 0.0, 1.0)
    assert not held_room(h, 0, 3)  # sphere 0's list is full; the store is not
    h = grow_held(h)
    assert (h.kind.shape[0], h.slots.shape[1]) == (2 * (room + 2), 2 * (room + 1))
    held_add(h, KIND_PAIR, 0, 3, 1.0, 0.0, 0.0)
    # every contact is still found where it was, with its normal
    for c, (a, b) in enumerate([(0, 1), (2, 3), (4, 5), (0, 2), (0, 3)]):
        assert held_find(h, KIND_PAIR, a, b) == c and held_find(h, KIND_PAIR, b, a) == -1
    assert h.normal[3].tolist() == [0.0, 0.0, 1.0] and h.count[HELD] == 5
    assert h.deg.tolist() == [3, 1, 2, 2, 1, 1, 0, 0]


def _left_looking_cholesky_solve(big, idx, n, ridge, xs):
    """The row-by-row (left-looking) Cholesky solve, in plain Python: the reference the
    compiled right-looking one must match to the bit."""
    chol = np.zeros((n, n))
    for u in range(n):
        for w in range(u + 1):
            s = big[idx[u], idx[w]]
            for t in range(w):
                s -= chol[u, t] * chol[w, t]
            if u == w:
                s += ridge
                if not s > 0.0:
                    return False
                chol[u, u] = np.sqrt(s)
            else:
                chol[u, w] = s / chol[w, w]
    for u in range(n):
        s = xs[idx[u]]
        for t in range(u):
            s -= chol[u, t] * xs[idx[t]]
        xs[idx[u]] = s / chol[u, u]
    for u in range(n - 1, -1, -1):
        s = xs[idx[u]]
        for t in range(u + 1, n):
            s -= chol[t, u] * xs[idx[t]]
        xs[idx[u]] = s / chol[u, u]
    return True


def _random_store(rng, n_spheres=30, n_contacts=70):
    """Held contacts among random spheres (some immovable) and walls, random unit
    normals: (store, inverse masses (N,))."""
    h = new_held(n_spheres)
    inverse_mass = np.where(rng.random(n_spheres) < 0.15, 0.0, rng.uniform(0.5, 2.0, n_spheres))
    pairs = set()
    while len(pairs) < n_contacts:
        a, b = (int(i) for i in rng.integers(0, n_spheres, 2))
        if rng.random() < 0.2:
            pairs.add((KIND_WALL, a, int(rng.integers(0, 3))))
        elif a != b:
            pairs.add((KIND_PAIR, min(a, b), max(a, b)))
    for kind, a, other in sorted(pairs):
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        while not held_room(h, a, other if kind == KIND_PAIR else -1):
            h = grow_held(h)
        held_add(h, kind, a, other, n[0], n[1], n[2])
    return h, inverse_mass


def _movable_spheres(h, c, inverse_mass) -> set[int]:
    spheres = {int(h.a[c])} | ({int(h.other[c])} if h.kind[c] == KIND_PAIR else set())
    return {p for p in spheres if inverse_mass[p] > 0.0}


def _scanned_contact_matrix(h, members, inverse_mass):
    """K = J W Jᵀ by scanning every pair of members (the form the compiled one replaced)."""
    m = len(members)
    big = np.zeros((m, m))
    for r in range(m):
        c = members[r]
        for e in range(2):
            p = h.a[c] if e == 0 else (h.other[c] if h.kind[c] == KIND_PAIR else -1)
            if p < 0 or inverse_mass[p] == 0.0:
                continue
            sr = 1.0 if e == 0 else -1.0
            for q in range(m):
                d = members[q]
                if h.a[d] == p:
                    sd = 1.0
                elif h.kind[d] == KIND_PAIR and h.other[d] == p:
                    sd = -1.0
                else:
                    continue
                big[r, q] += inverse_mass[p] * sr * sd * (h.normal[c, 0] * h.normal[d, 0] + h.normal[c, 1]
                                                          * h.normal[d, 1] + h.normal[c, 2] * h.normal[d, 2])
    return big


@pytest.mark.parametrize("seed", range(4))
def test_the_contact_matrix_is_the_scanned_one_to_the_bit(seed):
    rng = np.random.default_rng(seed)
    h, inverse_mass = _random_store(rng)
    members = rng.permutation(int(h.count[HELD]))[: int(rng.integers(1, h.count[HELD] + 1))].astype(np.int64)
    big, row_start, cols = _contact_matrix(h, members, len(members), inverse_mass)
    expected = _scanned_contact_matrix(h, members, inverse_mass)
    assert big.tobytes() == expected.tobytes()
    for r in range(len(members)):  # each row lists its possible nonzeros in column order, and no others
        listed = cols[row_start[r]:row_start[r + 1]]
        assert np.all(np.diff(listed) > 0)
        assert set(np.flatnonzero(expected[r])) <= set(listed.tolist())
        shared = [q for q in range(len(members))
                  if _movable_spheres(h, members[q], inverse_mass) & _movable_spheres(h, members[r], inverse_mass)]
        assert listed.tolist() == shared
    assert np.all(h.place == -1)  # the spheres' numbering is given back


def _sparse_k(rng, m):
    """A contact matrix K = J W Jᵀ of m contacts among spheres met breadth-first, as a
    cluster grows: sparse, with exact zeros, in a band."""
    n_spheres = m // 2 + 2
    jac = np.zeros((m, 3 * n_spheres))
    for r in range(m):
        a = min(r // 2, n_spheres - 2)
        b = min(a + 1 + int(rng.integers(0, 3)), n_spheres - 1)
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        jac[r, 3 * a:3 * a + 3] = n
        jac[r, 3 * b:3 * b + 3] = -n
    weight = np.repeat(rng.uniform(0.5, 2.0, n_spheres), 3)
    big = (jac * weight) @ jac.T
    big[big == 0.0] = 0.0  # no -0 (the engine's matrix has none)
    return big


@pytest.mark.parametrize("seed", range(10))
def test_the_cholesky_solve_equals_the_row_by_row_form_to_the_bit(seed):
    rng = np.random.default_rng(seed)
    m = int(rng.integers(1, 40)) if seed < 6 else int(rng.integers(20, 120))
    if seed < 6:
        jac = rng.normal(size=(m, m + 3))
        big = jac @ jac.T  # symmetric positive definite, like K = J W Jᵀ
    else:  # sparse, as in a pile: the factorisation visits only the nonzeros
        big = _sparse_k(rng, m)
        assert (big == 0.0).mean() > 0.5
    if seed % 2:  # redundant rows (a sphere touching more than three others): only the ridge keeps it solvable
        big[-1] = big[0]
        big[:, -1] = big[:, 0]
    idx = np.sort(rng.choice(m, size=int(rng.integers(1, m + 1)), replace=False)).astype(np.int64)
    ridge = 1e-13 * big.diagonal().max()
    rhs = rng.normal(size=m)
    expected = rhs.copy()
    got = rhs.copy()
    assert _cholesky_solve(big, idx, idx.shape[0], ridge, np.empty((m, m)), got, np.empty(m, np.int64)) == \
        _left_looking_cholesky_solve(big, idx, idx.shape[0], ridge, expected)
    assert got.tobytes() == expected.tobytes()


def test_the_cholesky_solve_refuses_a_matrix_that_is_not_positive():
    big = np.array([[1.0, 2.0], [2.0, 1.0]])
    assert not _cholesky_solve(big, np.arange(2), 2, 0.0, np.empty((2, 2)), np.ones(2), np.empty(2, np.int64))


def test_the_tc_rule_holds_a_pressed_rapid_contact_only_if_its_press_brings_it_back_within_the_window():
    g, window = 9.81, 1e-4  # the press adds g·window = 0.981 mm/s in the window
    for rule in (RAPID_HOLD, RAPID_TC):
        assert rapid_holds(0.9e-3, -g, window, rule)  # slow and pressed: held under both
        assert not rapid_holds(0.9e-3, 0.0, window, rule)  # nothing presses it: elastic
        assert not rapid_holds(0.9e-3, 2.0, window, rule)  # pulled apart: elastic
    assert rapid_holds(0.5, -g, window, RAPID_HOLD)  # fast: held at any speed under hold,
    assert not rapid_holds(0.5, -g, window, RAPID_TC)  # elastic under tc
    assert rapid_holds(0.5, -5000.0, window, RAPID_TC)  # unless the press is that strong
