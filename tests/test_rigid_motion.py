"""engine/mesh/rigid_motion.py: a kinematic mesh's motion in its two forms, numpy (the
scene, the analysis, the views) and numba (the compiled loop), held to each other."""

from __future__ import annotations

import numpy as np
import pytest

from physdbg import api
from physdbg.engine.mesh import rigid_motion as rm

rng = np.random.default_rng(11)
MOTIONS = [(rng.normal(0, 1, 3), rng.normal(0, 1, 3), w) for w in
           (np.zeros(3), np.array([0.0, 2.0, 0.0]), rng.normal(0, 3, 3), np.array([1e-9, 0.0, 0.0]))]


@pytest.mark.parametrize("pivot, velocity, angular_velocity", MOTIONS)
def test_in_body_frame_undoes_the_motion_that_places_a_point(pivot, velocity, angular_velocity):
    """A run-time-0 point placed at time t (numpy ``placed``, ``transform``) and carried back
    into the body's frame (numba ``in_body_frame``, the motion counted from run time 0)
    is the point again; transform and placed agree."""
    motion = np.concatenate([pivot, velocity, angular_velocity])
    for c, t in zip(rng.normal(0, 2, (20, 3)), rng.uniform(0, 3, 20), strict=True):
        x = rm.placed(c[None], pivot, velocity, angular_velocity, t)[0]
        turn, shift = rm.transform(pivot, velocity, angular_velocity, t)
        assert np.allclose(turn @ c + shift, x, rtol=1e-13, atol=1e-13)
        back = np.array(rm.in_body_frame(*x, 0.0, 0.0, 0.0, motion, t)[:3])
        assert np.allclose(back, c, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("pivot, velocity, angular_velocity", MOTIONS)
def test_the_compiled_turn_is_the_numpy_rotation(pivot, velocity, angular_velocity):
    """turned_with (a direction fixed in the body, as it points at τ) is rotation_about's
    R(ω τ) applied to it."""
    motion = np.concatenate([pivot, velocity, angular_velocity])
    for d, t in zip(rng.normal(0, 1, (20, 3)), rng.uniform(0, 3, 20), strict=True):
        assert np.allclose(rm.turned_with(*d, motion, t), rm.rotation_about(angular_velocity, t) @ d,
                           rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize("pivot, velocity, angular_velocity", MOTIONS)
def test_surface_velocity_and_acceleration_are_the_derivatives_of_the_placed_point(pivot, velocity,
                                                                                  angular_velocity):
    """The surface velocity (numpy and numba, one rule) and acceleration at a placed point
    are the first and second differences of that body point's placed path."""
    motion = np.concatenate([pivot, velocity, angular_velocity])
    h = 1e-4
    for c, t in zip(rng.normal(0, 2, (10, 3)), rng.uniform(0.1, 3, 10), strict=True):
        path = [rm.placed(c[None], pivot, velocity, angular_velocity, t + s)[0] for s in (-h, 0.0, h)]
        x = path[1]
        numpy_form = rm.surface_velocity_at(x, pivot, velocity, angular_velocity, t)
        compiled = np.array(rm.surface_velocity(*x, motion, t))
        assert np.allclose(numpy_form, compiled, rtol=1e-14, atol=1e-14)
        assert np.allclose(compiled, (path[2] - path[0]) / (2 * h), rtol=1e-6, atol=1e-6)
        acceleration = np.array(rm.surface_acceleration(*x, motion, t))
        assert np.allclose(acceleration, (path[2] - 2 * path[1] + path[0]) / h**2, rtol=1e-4, atol=1e-4)


def test_a_scene_s_meshes_place_and_move_by_the_one_module():
    """state.Meshes (placed, transform, surface_velocity) give what rigid_motion gives for
    the paddle, bit for bit."""
    meshes = api.load_scene("paddle").walls.meshes
    corners, _ = meshes.placed(0.37)
    args = (meshes.pivot[0], meshes.velocity[0], meshes.angular_velocity[0], 0.37)
    assert np.array_equal(corners[meshes.mesh_of == 0], rm.placed(meshes.corners[meshes.mesh_of == 0], *args))
    turn, shift = meshes.transform(0, 0.37)
    want = rm.transform(*args)
    assert np.array_equal(turn, want[0]) and np.array_equal(shift, want[1])
    assert np.array_equal(meshes.surface_velocity(0, [0.3, 0.1, 0.2], 0.37),
                          rm.surface_velocity_at(np.array([0.3, 0.1, 0.2]), *args))
