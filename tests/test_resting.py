"""The held-contact solve (engine/resting.py): the direct cluster solve against plain
projected Gauss–Seidel, on the held contacts of resting stacks."""

from __future__ import annotations

import numpy as np
import pytest

from physdbg.engine.resting import HeldContacts, _cholesky_solve, _gauss_seidel, _relative, begin_solve, solve_contacts
from physdbg.events import KIND_PAIR

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
                world._k, world.last_step.vtol, 10**9, KIND_PAIR, 0.0)
    assert ok
    return v, h, int(h.count[2])


def test_the_direct_solve_finds_what_gauss_seidel_finds_with_a_fraction_of_the_work(pile):
    held = int(pile.held.count[0])
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
            rel = _relative(v_direct, h, c, KIND_PAIR) - h.target[c]
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
    a 100 000-sphere pile)."""
    from physdbg.engine.resting import grow_held, held_add, held_find, held_room, new_held

    h = new_held(4, capacity=2, per_particle=2)
    held_add(h, KIND_PAIR, 0, 1, 1.0, 0.0, 0.0, KIND_PAIR)
    held_add(h, KIND_PAIR, 2, 3, 0.0, 1.0, 0.0, KIND_PAIR)
    assert not held_room(h, 0, 2)  # the store is full; no sphere is
    h = grow_held(h)
    assert (h.kind.shape[0], h.slots.shape[1]) == (4, 2)
    held_add(h, KIND_PAIR, 0, 2, 0.0, 0.0, 1.0, KIND_PAIR)
    assert not held_room(h, 0, 3)  # sphere 0's list is full; the store is not
    h = grow_held(h)
    assert (h.kind.shape[0], h.slots.shape[1]) == (4, 4)
    held_add(h, KIND_PAIR, 0, 3, 1.0, 0.0, 0.0, KIND_PAIR)
    # every contact is still found where it was, with its normal
    for c, (a, b) in enumerate([(0, 1), (2, 3), (0, 2), (0, 3)]):
        assert held_find(h, KIND_PAIR, a, b) == c and held_find(h, KIND_PAIR, b, a) == -1
    assert h.normal[2].tolist() == [0.0, 0.0, 1.0] and h.count[0] == 4 and h.deg.tolist() == [3, 1, 2, 2]


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


@pytest.mark.parametrize("seed", range(6))
def test_the_cholesky_solve_equals_the_row_by_row_form_to_the_bit(seed):
    rng = np.random.default_rng(seed)
    m = int(rng.integers(1, 40))
    jac = rng.normal(size=(m, m + 3))
    big = jac @ jac.T  # symmetric positive definite, like K = J W Jᵀ
    if seed % 2:  # redundant rows (a sphere touching more than three others): only the ridge keeps it solvable
        big[-1] = big[0]
        big[:, -1] = big[:, 0]
    idx = np.sort(rng.choice(m, size=int(rng.integers(1, m + 1)), replace=False)).astype(np.int64)
    ridge = 1e-13 * big.diagonal().max()
    rhs = rng.normal(size=m)
    expected = rhs.copy()
    got = rhs.copy()
    assert _cholesky_solve(big, idx, idx.shape[0], ridge, np.empty((m, m)), got) == \
        _left_looking_cholesky_solve(big, idx, idx.shape[0], ridge, expected)
    assert got.tobytes() == expected.tobytes()


def test_the_cholesky_solve_refuses_a_matrix_that_is_not_positive():
    big = np.array([[1.0, 2.0], [2.0, 1.0]])
    assert not _cholesky_solve(big, np.arange(2), 2, 0.0, np.empty((2, 2)), np.ones(2))
