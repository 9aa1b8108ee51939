"""The textbook mistakes of a contact's impulse, as the effective restitution each gives,
and a step re-simulated with one of them.

A mistake in the impulse j = −(1 + e)·(v_rel·n)/(1/m_a + 1/m_b) (the "1 +" missing, the
sign of e, the impulse applied twice, ...) leaves a contact with another **effective
restitution**: −(normal speed after)/(normal speed before). check-run reads it off one
contact (``restitution_mistake``). In a chain of contacts within one step (a break in
billiards) the speeds around each contact cannot be read off the run's frames, so the
mistake is tried instead: physdbg's step is taken again from the run's state with every
sphere pair's restitution replaced by the mistake's (``step_with_mistake``), and where that
step ends where the run's does, the mistake reproduces the step. A mistake that leaves a
pair approaching would meet it again at the same instant, over and over, in physdbg's loop;
a student's engine that makes it has a guard (each contact once a step), so the step is
re-simulated with the reference loop (engine/reference.py) and that guard. The impulse,
the swept tests and the restitution rule are physdbg's own: only the restitution differs.
"""

from __future__ import annotations

import functools

import numpy as np

# Effective restitutions that name a mistake: (code, the effective e it gives for the scene's e,
# words, what to do). Each is told apart from the scene's own e before it is named.
RESTITUTION_MISTAKES = (
    ("restitution-sign", lambda e: -e, "−e: the impulse uses (1 − e) where (1 + e) belongs, so the bodies keep "
                                       "approaching",
     "j = −(1 + e)·(v_rel·n)/(1/m_a + 1/m_b): with (1 − e) an elastic contact does nothing and every other one "
     "leaves the bodies approaching"),
    ("impulse-sign", lambda e: -(2.0 + e), "−(2 + e): the impulse points the wrong way, adding the closing speed "
                                           "instead of taking it away (energy gained)",
     "the impulse points the wrong way: j = −(1 + e)·(v_rel·n)/(1/m_a + 1/m_b) pushes a along n (from b towards "
     "a) and b against it; check its sign and the normal's direction"),
    ("impulse-doubled", lambda e: 1.0 + 2.0 * e, "1 + 2e: the impulse was applied twice (energy gained)",
     "apply each contact's impulse once: +j·n/m_a to a and −j·n/m_b to b, for each unordered pair (a loop over "
     "ordered pairs meets every pair twice)"),
    ("one-missing", lambda e: e - 1.0, "e − 1: the impulse uses e where (1 + e) belongs (the \"1 +\" is missing), so "
                                       "it takes away only e of the closing speed and the bodies keep approaching",
     "j = −(1 + e)·(v_rel·n)/(1/m_a + 1/m_b): the 1 takes the closing speed away, the e gives it back reversed; "
     "with e alone the bodies still approach after the contact (energy lost, not gained)"),
    ("restitution-squared", lambda e: e * e, "e²: the restitution was applied twice",
     "scale the normal speed by e once: v_n after = −e·v_n before"),
)
RESTITUTION_TOLERANCE = 0.02  # an effective restitution this close to the scene's is right
MISTAKE_SPHERES = 64  # a step is re-simulated with a mistake (O(N²) a contact) in scenes of up to this many spheres


def restitution_mistake(e: float, want: float):
    """(code, words, advice) of the mistake whose effective restitution ``e`` is, for a
    contact whose restitution is ``want``; None when none fits or it cannot be told from
    the right one."""
    best = None
    for code, predicted, words, advice in RESTITUTION_MISTAKES:
        p = predicted(want)
        slack = RESTITUTION_TOLERANCE * max(1.0, abs(p))
        if abs(p - want) <= 2 * slack or abs(e - p) > slack:
            continue
        if best is None or abs(e - p) < best[0]:
            best = (abs(e - p), code, f"{p:.3g} = {words}", advice)
    return best[1:] if best is not None else None


def step_with_mistake(scene, x0: np.ndarray, v0: np.ndarray, time: float, dt: float, predicted, once: bool = True):
    """physdbg's step of ``scene`` from (x0, v0) (N, 3) at ``time`` (s) over ``dt`` (s), with
    every sphere pair's contact made with the effective restitution ``predicted(e)`` of
    its own e (walls keep theirs) and, with ``once``, each contact taken at most once (a
    mistake that leaves pairs approaching needs that guard; one that parts them, such as
    the impulse applied twice, may be made without it): (x, v) (N, 3) at its end, or None
    when the step cannot be taken (a budget). The scene's numbering is kept (space_order
    = "given")."""
    import dataclasses

    from ..engine.state import State
    from ..errors import PhysdbgError, WorldStuck

    st = scene.state
    right = np.asarray(st.restitution, dtype=float)
    state = State(np.array(x0, dtype=float), np.array(v0, dtype=float), st.inverse_mass, st.radius,
                  np.array([predicted(float(e)) for e in right]), st.gravity_scale)
    world = _once_a_step_world()(state, scene.walls, dataclasses.replace(scene.settings, space_order="given"))
    world.once_a_step = once
    world.right_restitution = right
    world.time = float(time)
    try:
        world.step(float(dt))
    except (PhysdbgError, WorldStuck):  # a budget, a stuck world, a non-finite state: not this mistake's step
        return None
    return state.positions.copy(), state.velocities.copy()


@functools.cache
def _once_a_step_world():
    from ..engine.colliders import PARTNER_IS_SPHERE
    from ..engine.reference import ReferenceWorld

    class OnceAStep(ReferenceWorld):
        """The reference loop with a student's guard (each contact once a step), whose
        sphere–wall contacts use the spheres' right restitution (``right_restitution``,
        (N,)): the mistakes tried are those of the pair impulse."""

        once_a_step = True
        right_restitution: np.ndarray

        def _resolve_one(self, ctx, kind, a, other, when):
            if PARTNER_IS_SPHERE[kind]:
                return super()._resolve_one(ctx, kind, a, other, when)
            return self._with_right_restitution(a, super()._resolve_one, ctx, kind, a, other, when)

        def _resolve_at_one_instant(self, ctx, contacts, a, when):  # (immovable partners only)
            return self._with_right_restitution(a, super()._resolve_at_one_instant, ctx, contacts, a, when)

        def _with_right_restitution(self, a, resolve, *args):
            restitution = self._st.restitution  # the array the resolver reads, in place
            mistaken = restitution[a]
            restitution[a] = self.right_restitution[a]
            try:
                return resolve(*args)
            finally:
                restitution[a] = mistaken

    return OnceAStep
