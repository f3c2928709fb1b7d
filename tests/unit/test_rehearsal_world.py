"""The rehearsal world's operator, ticked directly on simulated time (no processes, no real time)."""

from __future__ import annotations

import ctypes

import numpy as np

from hoh_cosim.rehearsal.world import _COMMAND, _STATE, TASK_LEAD_S, WORLD_DT, WorldSetup, _World


def _world(setup: WorldSetup) -> _World:
    state = (ctypes.c_double * (1 + _STATE))()
    command = (ctypes.c_double * (1 + _COMMAND))()
    return _World(setup, state, command)


def test_a_held_push_release_pushes_after_the_rebias_however_late_it_ends():
    # the runner's rebias can end well after the 3 s a push_release lets go at on its own clock;
    # the hand pushes once told to come (start_task), for the task's 3 s, then lets go
    world = _world(WorldSetup(task="push_release", task_start_s=None))
    try:
        forces = []
        for k in range(9000):
            t = k * WORLD_DT
            if k == 4000:  # the rebias is done at 4 s of the world's clock
                world.command.write(np.array([1.0]), slice(10, 11))
            world._tick(t)
            forces.append(float(np.linalg.norm(world.hand["F_hand_B"])))
    finally:
        world.close()
    forces_N = np.array(forces)
    start = round((4.0 + TASK_LEAD_S) / WORLD_DT)  # the hand comes TASK_LEAD_S after start_task
    assert np.all(forces_N[: start - 1] == 0.0)
    assert np.all(forces_N[start + 100 : start + 2900] > 1.0)  # pushing for its 3 s
    assert np.all(forces_N[start + 3100 :] == 0.0)  # and let go
