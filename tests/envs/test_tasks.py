"""Tasks and the normalised-cost metric against the numbers of Li et al., RA-L 2021, Sec. IV-A."""

import math

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from hierloco.envs.frames import wrap_angle
from hierloco.envs.robots import START_YAW
from hierloco.envs.tasks import (
    TASKS,
    GoalReaching,
    TrajectoryTracking,
    VelocityTracking,
    make_task,
    s_path,
    task_options,
)

SCHEDULE = [(0.0, 0.2), (0.2, 0.0), (0.0, -0.2), (-0.2, 0.0)]  # m/s, world frame
START = torch.tensor([0.0, 0.0, START_YAW, 0.0, 0.0], dtype=torch.float64)


def standing(task, num_episodes=None):
    """``E x (T + 1) x 5`` states of robots that never leave the start."""
    num = task.num_episodes if num_episodes is None else num_episodes
    return START.expand(num, task.num_steps + 1, 5).clone()


def states_from_positions(positions):
    """``... x (T + 1) x 2`` positions -> states facing the start yaw, velocity = displacement over 1 s."""
    positions = torch.as_tensor(positions, dtype=torch.float64)
    states = torch.zeros(*positions.shape[:-1], 5, dtype=torch.float64)
    states[..., :2] = positions
    states[..., 2] = START_YAW
    states[..., 1:, 3:5] = positions[..., 1:, :] - positions[..., :-1, :]
    return states


def test_start_yaw_faces_plus_y():
    assert START_YAW == pytest.approx(math.pi / 2)
    for task in (VelocityTracking(), GoalReaching(), TrajectoryTracking()):
        assert torch.allclose(task.start_state().double(), START)


@pytest.mark.parametrize("angle", [math.pi, -math.pi, 3 * math.pi, -3 * math.pi, 0.0, 1.0, -1.0, 7.0, -7.0])
def test_wrap_angle_range(angle):
    wrapped = float(wrap_angle(torch.tensor(angle, dtype=torch.float64)))
    assert -math.pi < wrapped <= math.pi
    assert math.isclose(math.cos(wrapped), math.cos(angle), abs_tol=1e-9)
    assert math.isclose(math.sin(wrapped), math.sin(angle), abs_tol=1e-9)
    assert float(wrap_angle(np.float64(angle))) == pytest.approx(wrapped)


# --- velocity tracking ---------------------------------------------------------------------------------------------


def test_velocity_schedule():
    task = VelocityTracking()
    assert (task.num_episodes, task.num_steps) == (1, 40)
    targets = task.target(torch.zeros(40, dtype=torch.int64), torch.arange(40))
    expected = torch.tensor([SCHEDULE[(k // 5) % 4] for k in range(40)])
    assert torch.allclose(targets, expected)


def test_velocity_tracking_perfect_robot_costs_zero():
    task = VelocityTracking()
    velocities = torch.tensor([SCHEDULE[(k // 5) % 4] for k in range(40)], dtype=torch.float64)
    positions = torch.cat([torch.zeros(1, 2, dtype=torch.float64), velocities.cumsum(0)])  # 1 s per step
    result = task.evaluate(states_from_positions(positions)[None])
    assert result.costs.shape == (1, 40)
    assert np.abs(result.costs).max() < 1e-6  # targets are stored in float32
    assert result.normalized_cost[0] == pytest.approx(0.0, abs=1e-6)
    assert result.final_error[0] == pytest.approx(0.0, abs=1e-6)
    assert np.isnan(result.success[0])  # no success criterion
    assert not task.has_success


def test_velocity_tracking_standing_costs():
    task = VelocityTracking()
    assert torch.allclose(task.standing_costs(), torch.full((1, 40), 0.4))  # 2 * 0.2 m/s
    result = task.evaluate(standing(task))
    assert np.allclose(result.costs, 0.4)
    assert result.normalized_cost[0] == pytest.approx(1.0)
    assert result.final_error[0] == pytest.approx(0.2)


def test_velocity_is_the_displacement_over_the_step():
    task = VelocityTracking()
    state = START.clone()
    next_state = START.clone()
    next_state[:2] = torch.tensor([0.3, 0.2])  # moved (0.3, 0.2) m in 1 s
    next_state[3:5] = torch.tensor([5.0, -5.0])  # the instantaneous velocity is ignored
    # step 0 target (0, 0.2): error 0.3 m/s; step 5 target (0.2, 0): error ||(0.1, 0.2)||
    assert float(task.cost(state, next_state, 0, 0)) == pytest.approx(2 * 0.3)
    assert float(task.cost(state, next_state, 0, 5)) == pytest.approx(2 * math.hypot(0.1, 0.2))
    # the same displacement from elsewhere costs the same
    shifted = state.clone(), next_state.clone()
    shifted[0][:2] += 10.0
    shifted[1][:2] += 10.0
    assert float(task.cost(*shifted, 0, 0)) == pytest.approx(0.6)
    # velocity is m/s over the step duration
    task.step_duration = 2.0
    assert float(task.cost(state, next_state, 0, 0)) == pytest.approx(2 * math.hypot(0.15, 0.1))


# --- goal reaching -------------------------------------------------------------------------------------------------


def test_goals_on_a_circle():
    task = GoalReaching()
    assert (task.num_episodes, task.num_steps) == (8, 30)
    angles = np.deg2rad(np.arange(0, 360, 45))
    expected = 2.0 * np.stack([np.cos(angles), np.sin(angles)], -1)
    for e in range(8):
        for step in (0, 17, 29):
            assert np.allclose(task.target(torch.tensor(e), torch.tensor(step)).numpy(), expected[e], atol=1e-6)


def test_goal_reaching_standing_normalised_cost_is_one():
    task = GoalReaching()
    assert torch.allclose(task.standing_costs(), torch.full((8, 30), 4.0))  # 2 * 2 m
    result = task.evaluate(standing(task))
    assert np.allclose(result.normalized_cost, 1.0)
    assert np.allclose(result.final_error, 2.0)
    assert np.all(result.success == 0.0)


def test_goal_reaching_straight_at_02_mps():
    task = GoalReaching()
    k = np.arange(31)
    distance = np.minimum(0.2 * k, 2.0)  # along the line to the goal, reached after 10 steps
    angles = np.deg2rad(np.arange(0, 360, 45))
    positions = distance[None, :, None] * np.stack([np.cos(angles), np.sin(angles)], -1)[:, None, :]
    result = task.evaluate(states_from_positions(positions))
    # per-step cost 2 (2 - 0.2 k) for k = 1..10, then 0: sum 18 over 30 steps -> mean 0.6; standing 4
    assert np.allclose(result.costs[:, :10], 2 * (2 - 0.2 * k[1:11]), atol=1e-5)  # float32 goals
    assert np.allclose(result.costs[:, 10:], 0.0, atol=1e-5)
    assert np.allclose(result.normalized_cost, 0.15)
    assert np.all(result.success == 1.0)
    assert np.allclose(result.final_error, 0.0, atol=1e-6)


@pytest.mark.parametrize("short, success", [(0.19, 1.0), (0.21, 0.0)])
def test_goal_success_radius(short, success):
    task = GoalReaching()
    positions = np.zeros((31, 2))
    positions[1:] = [2.0 - short, 0.0]  # episode 0: goal (2, 0)
    result = task.evaluate(states_from_positions(positions)[None])
    assert result.success[0] == success
    assert result.final_error[0] == pytest.approx(short)


def test_goal_success_is_judged_at_the_end():
    task = GoalReaching()
    positions = np.zeros((31, 2))
    positions[1:30] = [2.0, 0.0]  # at the goal for 29 steps, then back at the start
    result = task.evaluate(states_from_positions(positions)[None])
    assert result.success[0] == 0.0
    assert result.final_error[0] == pytest.approx(2.0)


def test_evaluate_uses_the_given_episodes():
    task = GoalReaching()
    goal = task.goals[5].double()
    positions = torch.zeros(31, 2, dtype=torch.float64)
    positions[1:] = goal
    states = states_from_positions(positions)[None]
    assert task.evaluate(states, episodes=[5]).success[0] == 1.0
    assert task.evaluate(states).success[0] == 0.0  # row 0 is episode 0 by default: goal (2, 0)


# --- trajectory tracking -------------------------------------------------------------------------------------------


def test_s_path_geometry():
    path = s_path()
    assert np.allclose(path[0], [0.0, 0.0])
    assert np.allclose(path[-1], [4.0, 0.0])
    assert np.min(np.linalg.norm(path - [2.0, 0.0], axis=1)) < 1e-9  # passes (2, 0)
    heading = path[1] - path[0]
    assert heading[1] > 0 and abs(heading[0]) < 1e-2 * heading[1]  # leaves the origin along +y
    first, second = path[path[:, 0] <= 2.0], path[path[:, 0] >= 2.0]
    assert np.allclose((first[:, 0] - 1) ** 2 + (first[:, 1] / 1.5) ** 2, 1.0) and np.all(first[:, 1] >= -1e-12)
    assert np.allclose((second[:, 0] - 3) ** 2 + (second[:, 1] / 1.5) ** 2, 1.0) and np.all(second[:, 1] <= 1e-12)
    task = TrajectoryTracking()
    assert task.length == pytest.approx(7.93, abs=0.02)
    assert task.length == pytest.approx(np.linalg.norm(np.diff(path, axis=0), axis=1).sum(), rel=1e-6)


def test_trajectory_episode_length_and_reference_speed():
    task = TrajectoryTracking()
    assert task.speed == 0.1
    assert task.num_steps == math.ceil(task.length / 0.1) + 10 == 90
    refs = task.target(torch.zeros(task.num_steps, dtype=torch.int64), torch.arange(task.num_steps)).double()
    moving = math.floor(task.length / 0.1)  # steps whose reference is still before the end
    chords = (refs[1:moving] - refs[: moving - 1]).norm(dim=-1)
    assert torch.all(chords <= 0.1 + 1e-5) and torch.all(chords >= 0.0995)  # 0.1 m of arc per step (curved)
    assert refs[0].norm() == pytest.approx(0.1, abs=1e-3)  # 0.1 m from the start after the first step
    assert torch.allclose(refs[moving:], torch.tensor([4.0, 0.0], dtype=torch.float64), atol=1e-5)  # waits at end
    assert np.all(task.path_distance(refs) < 2e-3)  # every reference is on the path


def test_trajectory_robot_on_the_reference():
    task = TrajectoryTracking()
    refs = task.target(torch.tensor(0), torch.arange(task.num_steps)).double()
    positions = torch.cat([torch.zeros(1, 2, dtype=torch.float64), refs])
    result = task.evaluate(states_from_positions(positions)[None])
    assert result.costs.shape == (1, 90)
    assert np.abs(result.costs).max() < 1e-6
    assert result.normalized_cost[0] < 1e-6
    assert result.final_error[0] == pytest.approx(0.0, abs=1e-5)
    assert result.success[0] == 1.0


def test_trajectory_standing_and_offset_costs():
    task = TrajectoryTracking()
    result = task.evaluate(standing(task))
    assert result.normalized_cost[0] == pytest.approx(1.0)
    assert result.final_error[0] == pytest.approx(4.0)
    assert result.success[0] == 0.0
    step = 40
    ref = task.target(torch.tensor(0), torch.tensor(step)).double()
    next_state = START.clone()
    next_state[:2] = ref + torch.tensor([0.3, 0.4], dtype=torch.float64)
    assert float(task.cost(START, next_state, 0, step)) == pytest.approx(2 * 0.5, abs=1e-6)


def test_path_distance():
    task = TrajectoryTracking()
    on_path = s_path(777)  # other samples than the task's
    assert np.all(task.path_distance(on_path) < 2e-3)
    # 0.5 m outside the ellipses' vertices (curvature radius there > 0.5 m, so the vertex is the nearest point)
    off = np.array([[1.0, 2.0], [3.0, -2.0], [-0.5, 0.0], [4.5, 0.0]])
    assert np.allclose(task.path_distance(off), 0.5, atol=2e-3)
    assert task.path_distance(np.zeros((3, 4, 2))).shape == (3, 4)
    # a path with straight parts: an L
    corner = TrajectoryTracking(path=[[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]])
    assert corner.length == pytest.approx(4.0)
    assert corner.num_steps == 40 + 10
    points = np.array([[1.0, 0.5], [1.0, -0.5], [2.5, 1.0], [2.0, 1.3], [0.5, 0.0]])
    assert np.allclose(corner.path_distance(points), [0.5, 0.5, 0.5, 0.0, 0.0], atol=2e-3)


# --- shared behaviour ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(TASKS))
def test_yaw_error_is_wrapped(name):
    task = make_task(name)
    state = START.clone()
    base = float(task.cost(state, state, 0, 0))  # position/velocity part, yaw at the start yaw
    for turns in (-2, -1, 1, 3):
        for delta in (0.1, -0.1, 2.5):
            next_state = START.clone()
            next_state[2] = START_YAW + 2 * math.pi * turns + delta
            assert float(task.cost(state, next_state, 0, 0)) == pytest.approx(base + abs(delta), abs=1e-9)
    next_state = START.clone()
    next_state[2] = START_YAW + 2 * math.pi - 0.1
    assert float(task.cost(state, next_state, 0, 0)) == pytest.approx(base + 0.1, abs=1e-9)


@pytest.mark.parametrize("name", sorted(TASKS))
def test_cost_broadcasts_over_batches(name):
    task = make_task(name)
    gen = torch.Generator().manual_seed(0)
    b, s = 4, 8000
    state = torch.randn(b, 1, 5, generator=gen)
    next_state = torch.randn(b, s, 5, generator=gen) * 2
    episode = torch.randint(0, task.num_episodes, (b, 1), generator=gen)
    step = torch.randint(0, task.num_steps, (b, 1), generator=gen)
    cost = task.cost(state, next_state, episode, step)
    assert cost.shape == (b, s)
    flat = task.cost(state.expand(b, s, 5).reshape(-1, 5), next_state.reshape(-1, 5),
                     episode.expand(b, s).reshape(-1), step.expand(b, s).reshape(-1))
    assert torch.allclose(cost.reshape(-1), flat)
    for i, j in [(0, 0), (1, 4321), (2, 7999), (3, 17)]:
        single = task.cost(state[i, 0], next_state[i, j], int(episode[i, 0]), int(step[i, 0]))
        assert single.shape == ()
        assert float(single) == pytest.approx(float(cost[i, j]), rel=1e-5, abs=1e-6)
    # a scalar step broadcasts too
    assert task.cost(state, next_state, episode, 0).shape == (b, s)


@pytest.mark.parametrize("name", sorted(TASKS))
def test_numpy_inputs(name):
    task = make_task(name)
    rng = np.random.default_rng(1)
    state, next_state = rng.normal(size=(6, 5)), rng.normal(size=(6, 5))
    episode = rng.integers(0, task.num_episodes, 6)
    step = rng.integers(0, task.num_steps, 6)
    from_numpy = task.cost(state, next_state, episode, step)
    from_torch = task.cost(torch.as_tensor(state), torch.as_tensor(next_state), torch.as_tensor(episode),
                           torch.as_tensor(step))
    assert np.allclose(np.asarray(from_numpy), from_torch.numpy(), atol=1e-5)
    states = rng.normal(size=(2, task.num_steps + 1, 5))
    episodes = np.arange(2) % task.num_episodes
    a, b = task.evaluate(states, episodes), task.evaluate(torch.as_tensor(states), torch.as_tensor(episodes))
    assert np.allclose(a.normalized_cost, b.normalized_cost)
    assert np.allclose(a.final_error, b.final_error)
    assert np.allclose(a.costs, b.costs)


def test_reward_is_minus_cost_on_tensordicts():
    task = GoalReaching()
    state = START.float().expand(3, 5)
    next_state = state.clone()
    next_state[:, :2] = torch.tensor([[1.0, 0.0], [0.0, 1.0], [0.5, 0.5]])
    td = TensorDict({"com_state": state, "task_episode": torch.tensor([[0], [2], [1]]),
                     "task_step": torch.zeros(3, 1, dtype=torch.int64), "next": {"com_state": next_state}},
                    batch_size=[3])
    reward = task.reward(td)
    assert reward.shape == (3, 1)
    expected = -task.cost(state, next_state, torch.tensor([0, 2, 1]), 0)
    assert torch.allclose(reward.squeeze(-1), expected)
    assert reward[0, 0] == pytest.approx(-2.0) and reward[1, 0] == pytest.approx(-2.0)


@pytest.mark.parametrize("name", sorted(TASKS))
def test_evaluate_rejects_wrong_number_of_states(name):
    task = make_task(name)
    for steps in (task.num_steps, task.num_steps + 2):
        with pytest.raises(ValueError, match=str(task.num_steps + 1)):
            task.evaluate(np.zeros((1, steps, 5)))


def test_evaluate_rejects_bad_episodes_and_shapes():
    task = GoalReaching()
    states = np.zeros((2, 31, 5))
    for episodes in ([0], [0, 8], [-1, 0], [0, 1, 2]):
        with pytest.raises(ValueError, match="episodes"):
            task.evaluate(states, episodes)
    with pytest.raises(ValueError, match="episodes"):
        VelocityTracking().evaluate(np.zeros((2, 41, 5)))  # two rows of a one-episode task need episodes=[0, 0]
    assert VelocityTracking().evaluate(np.zeros((2, 41, 5)), [0, 0]).normalized_cost.shape == (2,)
    for shape in ((31, 5), (2, 31, 4)):
        with pytest.raises(ValueError, match="E x"):
            task.evaluate(np.zeros(shape))


@pytest.mark.parametrize("make", [
    pytest.param(lambda: VelocityTracking(velocities=[[0.1, 0.2, 0.3]]), id="velocity_3d"),
    pytest.param(lambda: VelocityTracking(velocities=[]), id="velocity_empty"),
    pytest.param(lambda: VelocityTracking(velocities=[[math.nan, 0.0]]), id="velocity_nan"),
    pytest.param(lambda: VelocityTracking(steps_per_target=0), id="steps_per_target_0"),
    pytest.param(lambda: VelocityTracking(rounds=0), id="rounds_0"),
    pytest.param(lambda: GoalReaching(radius=0.0), id="radius_0"),
    pytest.param(lambda: GoalReaching(radius=-1.0), id="radius_negative"),
    pytest.param(lambda: GoalReaching(radius=math.inf), id="radius_inf"),
    pytest.param(lambda: GoalReaching(num_goals=0), id="num_goals_0"),
    pytest.param(lambda: GoalReaching(num_steps=0), id="goal_steps_0"),
    pytest.param(lambda: GoalReaching(goals=[[1.0, 2.0, 3.0]]), id="goals_3d"),
    pytest.param(lambda: GoalReaching(goals=[[math.nan, 0.0]]), id="goals_nan"),
    pytest.param(lambda: TrajectoryTracking(speed=0.0), id="speed_0"),
    pytest.param(lambda: TrajectoryTracking(speed=-0.1), id="speed_negative"),
    pytest.param(lambda: TrajectoryTracking(speed=math.nan), id="speed_nan"),
    pytest.param(lambda: TrajectoryTracking(speed=math.inf), id="speed_inf"),
    pytest.param(lambda: TrajectoryTracking(extra_steps=-1), id="extra_steps_negative"),
    pytest.param(lambda: TrajectoryTracking(path=[[0.0, 0.0]]), id="path_one_point"),
    pytest.param(lambda: TrajectoryTracking(path=[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]), id="path_3d"),
    pytest.param(lambda: TrajectoryTracking(path=[[0.0, 0.0], [math.nan, 1.0]]), id="path_nan"),
    pytest.param(lambda: TrajectoryTracking(path=[[1.0, 1.0], [1.0, 1.0]]), id="path_zero_length"),
])
def test_bad_constructor_arguments(make):
    with pytest.raises(ValueError):
        make()


def test_make_task():
    assert set(TASKS) == {"velocity_tracking", "goal_reaching", "trajectory_tracking", "navigation"}
    task = make_task("goal_reaching", num_steps=5, radius=1.0)
    assert isinstance(task, GoalReaching) and task.num_steps == 5
    assert np.allclose(task.goals.norm(dim=-1).numpy(), 1.0)
    with pytest.raises(ValueError, match="walking") as info:
        make_task("walking")
    for name in TASKS:
        assert name in str(info.value)


# --- what a task carries: name, markers, extra metrics, training split, cost terms -------------------------------


@pytest.mark.parametrize("name", sorted(TASKS))
def test_name_defaults_to_the_registry_name_and_is_set_by_keyword(name):
    task = make_task(name)
    assert task.name == task.kind == name
    renamed = make_task(name, name=f"{name}_custom")
    assert renamed.name == f"{name}_custom" and renamed.kind == name
    result = renamed.evaluate(standing(renamed))
    assert result.task == f"{name}_custom"
    assert make_task(name).name == name  # the class is untouched


def test_markers():
    goals = GoalReaching()
    assert goals.markers().shape == (8, 2)
    assert np.allclose(goals.markers(), goals.goals.numpy())
    assert np.allclose(goals.markers(episode=3), goals.goals[3:4].numpy())
    path = TrajectoryTracking()
    assert path.markers().shape == (path.num_steps, 2)
    assert np.all(path.path_distance(path.markers()) < 2e-3)  # on the path
    assert path.markers().dtype == np.float64
    assert VelocityTracking().markers().shape == (0, 2)


def test_extra_metrics():
    task = TrajectoryTracking()
    rng = np.random.default_rng(0)
    paths = rng.normal(size=(3, 50, 5))
    metrics = task.extra_metrics(paths)
    assert set(metrics) == {"path_distance"} and metrics["path_distance"].shape == (3,)
    assert np.array_equal(metrics["path_distance"], task.path_distance(paths[..., :2]).mean(1))
    points = s_path(501)
    on_path = np.concatenate([points[None], np.zeros((1, len(points), 3))], -1)
    assert task.extra_metrics(on_path)["path_distance"][0] < 2e-3
    assert VelocityTracking().extra_metrics(paths) == {}


def test_steps_to_goal_counts_the_action_during_which_the_goal_was_first_reached():
    task = GoalReaching(goals=[[2.0, 0.0], [0.0, 2.0]], num_steps=10)
    n = 100  # samples per action
    line = np.linspace(0.0, 2.0, 10 * n)  # straight at the goal, arriving at the end of the 10th action
    towards_first = np.stack([line, np.zeros_like(line)], -1)
    # within 0.2 m from sample 900 (1.8 m): during the 10th action
    paths = np.stack([towards_first, np.zeros_like(towards_first)])  # the second robot stands still
    steps = task.extra_metrics(paths)["steps_to_goal"]
    assert steps[0] == 10 and np.isnan(steps[1])
    fast = np.stack([np.minimum(2 * line, 2.0), np.zeros_like(line)], -1)  # 1.8 m after 450 samples
    assert task.extra_metrics(fast[None])["steps_to_goal"][0] == 5
    # the episode decides the goal: robot 0 running episode 1 walks away from its goal
    assert np.isnan(task.extra_metrics(towards_first[None], episodes=[1])["steps_to_goal"][0])


def test_training_split_goals_every_other_on_both_axes():
    task = GoalReaching(name="goals")
    half = task.training_split()
    assert isinstance(half, GoalReaching) and half.name == "goals_train"
    assert torch.equal(half.goals, task.goals[[0, 2, 4, 6]])
    assert task.training_episodes == [0, 2, 4, 6] and GoalReaching(num_goals=5).training_episodes == [0, 2, 4]
    assert half.num_steps == task.num_steps
    on_x = (half.goals[:, 1].abs() < 1e-6) & (half.goals[:, 0].abs() > 1)
    on_y = (half.goals[:, 0].abs() < 1e-6) & (half.goals[:, 1].abs() > 1)
    assert on_x.sum() == 2 and on_y.sum() == 2


def test_training_split_velocities_first_half_on_both_axes():
    task = VelocityTracking()
    half = task.training_split()
    assert half.name == "velocity_tracking_train"
    assert task.training_episodes is None  # one episode mixes training and held-out velocities
    assert torch.equal(half.velocities, torch.tensor([[0.0, 0.2], [0.2, 0.0]]))  # one target on each axis
    assert half.steps_per_target == 5 and half.num_steps == task.num_steps == 40
    odd = VelocityTracking(velocities=[[0.1, 0.0], [0.0, 0.1], [-0.1, 0.0]], steps_per_target=2, rounds=1)
    odd_half = odd.training_split()
    assert len(odd_half.velocities) == 2 and odd_half.num_steps >= odd.num_steps


def test_training_split_path_first_half():
    task = TrajectoryTracking(speed=0.2, extra_steps=3)
    half = task.training_split()
    assert half.name == "trajectory_tracking_train"
    assert half.speed == 0.2 and half.extra_steps == 3
    assert len(half.path) == len(task.path) // 2 + 1 and torch.equal(half.path, task.path[: len(half.path)])
    assert half.length == pytest.approx(task.length / 2, rel=1e-3)  # the S path is symmetric


@pytest.mark.parametrize("name", sorted(TASKS))
def test_cost_is_the_sum_of_the_named_terms(name):
    task = make_task(name)
    gen = torch.Generator().manual_seed(3)
    state, next_state = torch.randn(64, 5, generator=gen), torch.randn(64, 5, generator=gen)
    episode = torch.randint(0, task.num_episodes, (64,), generator=gen)
    step = torch.randint(0, task.num_steps, (64,), generator=gen)
    terms = task.cost_terms(state, next_state, episode, step)
    assert list(terms) == list(task.cost_term_names) == ["tracking", "yaw"]
    assert torch.equal(task.cost(state, next_state, episode, step), terms["tracking"] + terms["yaw"])
    # the formula of the paper, term by term: w1 * tracking error + w2 * |wrapped yaw error|
    target = task.target(episode, step)
    yaw = wrap_angle(START_YAW - next_state[:, 2]).abs()
    assert torch.equal(terms["yaw"], 1.0 * yaw)
    assert torch.equal(terms["tracking"], 2.0 * task.tracking_error(state, next_state, target))


def test_task_result_carries_the_mean_cost_terms():
    task = GoalReaching()
    turned = standing(task)
    turned[:, 1:, 2] += 0.3  # yaw 0.3 rad off from the first step on
    result = task.evaluate(turned)
    assert set(result.cost_terms) == {"tracking", "yaw"}
    assert np.allclose(result.cost_terms["tracking"], 4.0)  # 2 * 2 m from every goal
    assert np.allclose(result.cost_terms["yaw"], 0.3)
    assert np.allclose(result.cost_terms["tracking"] + result.cost_terms["yaw"], result.costs.mean(1))


def test_make_task_refuses_unknown_options_naming_the_valid_ones():
    with pytest.raises(ValueError, match="unknown option 'radus'") as info:
        make_task("goal_reaching", radus=2)
    for option in ("radius", "num_goals", "num_steps", "angle_offset", "goals", "name"):
        assert option in str(info.value)
    with pytest.raises(ValueError, match="unknown options 'speeed', 'pth'"):
        make_task("trajectory_tracking", speeed=1, pth=None)
    assert task_options("velocity_tracking") == ["velocities", "steps_per_target", "rounds", "num_random",
                                                 "speed_range_mps", "targets_seed", "name"]


@pytest.mark.parametrize("name, options, message", [
    ("goal_reaching", dict(radius="2"), "radius must be a finite number"),
    ("goal_reaching", dict(radius=math.nan), "radius must be a finite number"),
    ("goal_reaching", dict(radius=True), "radius must be a finite number"),
    ("goal_reaching", dict(num_goals="8"), "num_goals must be a whole number"),
    ("goal_reaching", dict(num_steps=2.5), "num_steps must be a whole number"),
    ("goal_reaching", dict(num_steps=math.nan), "num_steps must be a whole number"),
    ("goal_reaching", dict(angle_offset=math.inf), "angle_offset must be a finite number"),
    ("goal_reaching", dict(goals=[["a", "b"]]), "goals must be a list of"),
    ("goal_reaching", dict(goals="far"), "goals must be a list of"),
    ("goal_reaching", dict(name=3), "name must be a non-empty string"),
    ("velocity_tracking", dict(velocities="fast"), "velocities must be a list of"),
    ("velocity_tracking", dict(velocities=[[0.1, math.nan]]), "velocities must be finite"),
    ("velocity_tracking", dict(rounds="2"), "rounds must be a whole number"),
    ("trajectory_tracking", dict(speed="0.1"), "speed must be a finite number"),
    ("trajectory_tracking", dict(speed=math.nan), "speed must be a finite number"),
    ("trajectory_tracking", dict(extra_steps=1.5), "extra_steps must be a whole number"),
    ("trajectory_tracking", dict(path=[[0.0, 0.0], ["x", 1.0]]), "path must be a list of"),
])
def test_make_task_refuses_bad_values_clearly(name, options, message):
    with pytest.raises(ValueError, match=message):
        make_task(name, **options)


def test_whole_floats_are_accepted():
    assert make_task("goal_reaching", num_goals=4.0, num_steps=5.0).num_steps == 5
