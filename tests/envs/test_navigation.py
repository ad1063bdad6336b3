"""Navigation: clearance geometry, a collision-free grid path, and the obstacles in the simulation."""

import math

import numpy as np
import pytest

from hierloco.envs.batched_sim import BatchedSimulator
from hierloco.envs.navigation import Arena, clearance, cluttered_arena, plan_path
from hierloco.envs.robots import Obstacle

BOX = Obstacle(1.0, 0.0, (0.5, 0.25, 0.25), yaw=math.pi / 2)  # after the turn: 0.5 m along y, 0.25 m along x


def test_clearance_of_a_rotated_box():
    arena = Arena((BOX,), (0.0, 0.0), (2.0, 0.0), (-1.0, 3.0, -2.0, 2.0))
    points = np.array([[1.0, 0.0], [1.0, 1.0], [0.0, 0.0], [1.25, 0.5], [1.0, 0.4]])
    np.testing.assert_allclose(clearance(arena, points), [-0.25, 0.5, 0.75, 0.0, -0.1], atol=1e-9)


@pytest.mark.parametrize("seed", range(5))
def test_planned_path_is_collision_free_and_connects(seed):
    arena = cluttered_arena(seed=seed)
    path = plan_path(arena, inflation=0.35, resolution=0.05)
    np.testing.assert_allclose(path[0], arena.start)
    np.testing.assert_allclose(path[-1], arena.goal)
    assert clearance(arena, path).min() >= 0.35 - 0.05  # the inflation, to the grid resolution
    assert np.linalg.norm(np.diff(path, axis=0), axis=1).max() <= 0.05 + 1e-9  # evenly resampled
    straight = np.linalg.norm(np.subtract(arena.goal, arena.start))
    assert np.linalg.norm(np.diff(path, axis=0), axis=1).sum() >= straight - 1e-6


def test_the_path_goes_around_a_wall():
    wall = Obstacle(0.0, 1.5, (1.0, 0.1, 0.25))
    arena = Arena((wall,), (0.0, 0.0), (0.0, 3.0), (-2.0, 2.0, -1.0, 4.0))
    path = plan_path(arena, inflation=0.3)
    crossing = path[np.argmin(np.abs(path[:, 1] - 1.5))]
    assert abs(crossing[0]) >= 1.0 + 0.3 - 0.05, "the path passes beside the wall, not through it"


def test_impossible_arenas_are_refused():
    blocked = Arena((Obstacle(0.0, 1.5, (5.0, 0.1, 0.25)),), (0.0, 0.0), (0.0, 3.0), (-2.0, 2.0, -1.0, 4.0))
    with pytest.raises(ValueError, match="no collision-free path"):
        plan_path(blocked, inflation=0.3)
    on_goal = Arena((Obstacle(0.0, 3.0, (0.3, 0.3, 0.25)),), (0.0, 0.0), (0.0, 3.0), (-2.0, 2.0, -1.0, 4.0))
    with pytest.raises(ValueError, match="goal is inside"):
        plan_path(on_goal, inflation=0.3)


def test_obstacles_are_solid_in_the_simulation():
    """A robot walking forward (+y) for 5 s goes well past y = 0.8 m in the open, and stops short of a wall there."""
    from hierloco.components.expert_library import build_expert_library

    library = build_expert_library("a1", 1, commands=np.array([[0.3, 0.0, 0.0]]), progress=False)
    wall = Obstacle(0.0, 0.8 + 0.1, (1.5, 0.1, 0.3))  # its near face at y = 0.8 m
    open_field, walled = BatchedSimulator("a1", 1), BatchedSimulator("a1", 1, obstacles=[wall])
    pattern = np.tile(library.joint_targets, (1, 5, 1))
    y_open = open_field.run(pattern).com_state[0, -1, 1]
    y_walled = walled.run(pattern).com_state[0, :, 1].max()
    assert y_open > 1.2
    assert y_walled < 0.8 - 0.1, "the trunk (0.125 m half-length) and feet stop at the wall"


def test_the_navigation_task_is_a_registered_task_with_its_arena():
    from hierloco.envs.navigation import Navigation
    from hierloco.envs.tasks import TASKS, make_task

    assert "navigation" in TASKS.names()
    task = make_task("navigation", arena_seed=3, num_obstacles=6, goal=[2.0, 3.0], inflation=0.3, name="arena3")
    assert isinstance(task, Navigation) and task.name == "arena3" and len(task.obstacles) == 6
    np.testing.assert_allclose(task.path[-1].numpy(), [2.0, 3.0], atol=1e-6)  # the path ends at the goal
    assert clearance(task.arena, task.path.numpy()).min() >= 0.3 - 0.05
    # a CoM path that stops 0.5 m short of the goal: its final error, its distance to the path, its clearance
    path = task.path.numpy()
    stop = int(np.argmin(np.abs(np.linalg.norm(path - path[-1], axis=1) - 0.5)))
    com = np.concatenate([path[: stop + 1], np.zeros((len(path[: stop + 1]), 3))], axis=1)[None]
    import torch

    assert abs(float(task.final_error(torch.as_tensor(com, dtype=torch.float32), torch.tensor([0]))[0]) - 0.5) < 0.03
    metrics = task.extra_metrics(com)
    assert metrics["path_distance"][0] < 1e-3
    np.testing.assert_allclose(metrics["clearance"], [clearance(task.arena, path[: stop + 1]).min()])
    assert task.training_split().obstacles == task.obstacles  # the split keeps the arena
    assert make_task("trajectory_tracking").obstacles == ()  # the other tasks are in the open


def test_a_navigation_task_without_a_path_or_with_bad_options_is_refused():
    from hierloco.envs.tasks import make_task

    with pytest.raises(ValueError, match="inside an \\(inflated\\) obstacle|no collision-free path"):
        make_task("navigation", inflation=3.0)
    with pytest.raises(ValueError, match="inflation must be >= 0"):
        make_task("navigation", inflation=-0.1)
    with pytest.raises(ValueError, match="unknown option 'arena'"):
        make_task("navigation", arena=1)
