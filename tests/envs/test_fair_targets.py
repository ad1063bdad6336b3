"""Fair held-out targets (``docs/tasks.md``): every task's training half and held-out half drawn from one
distribution, fixed by seeds in ``targets=fair``, and a harder path; the paper's targets unchanged."""
import math

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from hierloco.envs.tasks import GoalReaching, TrajectoryTracking, VelocityTracking, make_task, random_path, s_path
from hierloco.pipeline.config import compose_recipe

METHODS = ("lat", "lib", "ik", "sac", "sac_sac")


def sectors(points: torch.Tensor, count: int) -> set[int]:
    angles = torch.atan2(points[:, 1], points[:, 0]).numpy() % (2 * math.pi)
    return set((angles // (2 * math.pi / count)).astype(int).tolist())


@pytest.mark.parametrize("seed", [0, 1, 4502])
def test_random_goals_take_one_sector_each_within_the_spread(seed):
    task = GoalReaching(radius=2.0, radius_spread=0.25, targets_seed=seed)
    distances = task.goals.norm(dim=-1)
    assert len(task.goals) == 8 and bool(((distances >= 1.5) & (distances <= 2.5)).all())
    assert sectors(task.goals, 8) == set(range(8))  # every 45-degree sector once, so no half-plane is empty
    train = task.goals[task.training_episodes]
    held_out = task.goals[[e for e in range(8) if e not in task.training_episodes]]
    assert sectors(train, 8).isdisjoint(sectors(held_out, 8))
    assert GoalReaching(radius=2.0, targets_seed=seed).goals.tolist() == task.goals.tolist()  # fixed by the seed
    assert GoalReaching(radius=2.0, targets_seed=seed + 1).goals.tolist() != task.goals.tolist()


def test_the_halves_of_random_goals_come_from_one_distribution():
    """Over many seeds the training goals' distances and directions are distributed as the held-out ones' (the
    paper's split puts the axes in one half and the diagonals in the other)."""
    train, held_out = [], []
    for seed in range(300):
        task = GoalReaching(radius=2.0, targets_seed=seed)
        chosen = task.training_episodes
        train += task.goals[chosen].tolist()
        held_out += task.goals[[e for e in range(8) if e not in chosen]].tolist()
    train, held_out = np.array(train), np.array(held_out)
    for values in (np.linalg.norm, lambda g, axis: np.abs(np.sin(2 * np.arctan2(g[:, 1], g[:, 0])))):
        a, b = values(train, axis=-1), values(held_out, axis=-1)
        assert abs(a.mean() - b.mean()) < 4 * math.hypot(a.std() / math.sqrt(len(a)), b.std() / math.sqrt(len(b)))
    paper = GoalReaching()
    diagonal = lambda goals: np.abs(np.sin(2 * np.arctan2(goals[:, 1], goals[:, 0])))  # noqa: E731  1 on a diagonal
    on_axes = paper.goals[paper.training_episodes].numpy()
    assert diagonal(on_axes).max() < 1e-6 and diagonal(paper.goals[1::2].numpy()).min() > 1 - 1e-6


def test_random_velocities_have_speeds_in_range_and_the_training_split_keeps_the_first_half():
    task = VelocityTracking(num_random=8, speed_range_mps=(0.1, 0.3), targets_seed=4501, rounds=1)
    speeds = task.velocities.norm(dim=-1)
    assert task.num_steps == 40 and bool(((speeds >= 0.1) & (speeds <= 0.3)).all())
    assert sectors(task.velocities, 8) == set(range(8))
    split = task.training_split()
    assert split.velocities.tolist() == task.velocities[:4].tolist() and split.num_steps >= task.num_steps


def test_a_random_path_starts_at_the_origin_along_plus_y_with_its_length_and_curvature():
    path = random_path(7, length_m=6.0, max_curvature_per_m=1.5)
    steps = np.diff(path, axis=0)
    assert np.allclose(path[0], 0.0) and np.linalg.norm(steps, axis=1).sum() == pytest.approx(6.0, rel=1e-9)
    assert steps[0, 1] > 0 and abs(steps[0, 0]) < 1e-3 * np.linalg.norm(steps[0])  # leaves along +y
    heading = np.unwrap(np.arctan2(steps[:, 1], steps[:, 0]))
    curvature = np.diff(heading) / np.linalg.norm(steps[1:], axis=1)
    assert np.abs(curvature).max() <= 1.5 + 1e-6 and np.abs(curvature).max() > 0.3


def test_a_random_path_s_halves_are_no_mirror_of_each_other_where_the_s_path_s_are():
    def second_half_mirrors_first(points: np.ndarray) -> bool:
        middle = len(points) // 2
        first = points[: middle + 1] - points[0]
        second = points[middle:] - points[middle]
        return np.allclose(second[:, 0], first[:, 0], atol=1e-6) and np.allclose(second[:, 1], -first[:, 1], atol=1e-6)

    assert second_half_mirrors_first(s_path())
    assert not any(second_half_mirrors_first(random_path(seed)) for seed in range(5))


def test_the_harder_path_lasts_its_length_over_its_speed():
    task = make_task("trajectory_tracking", path_seed=4504, path_length_m=6.0, max_curvature_per_m=2.0, speed=0.4,
                     name="trajectory_tracking_fast")
    assert task.num_steps == 15 + 10 and task.length == pytest.approx(6.0)
    assert task.training_split().path.tolist() == task.path[: len(task.path) // 2 + 1].tolist()


@pytest.mark.parametrize("options, message", [
    ({"task": GoalReaching, "targets_seed": 1, "radius_spread": 1.5}, "radius_spread must be in"),
    ({"task": GoalReaching, "targets_seed": -1}, "targets_seed must be a whole number"),
    ({"task": VelocityTracking, "num_random": 4, "speed_range_mps": [0.3, 0.1]}, "low <= high"),
    ({"task": VelocityTracking, "num_random": 4, "speed_range_mps": 0.2}, r"\[low, high\]"),
    ({"task": TrajectoryTracking, "path_seed": 1, "path_length_m": -2.0}, "length_m must be positive"),
    ({"task": TrajectoryTracking, "path_seed": 1, "path_length_m": 1e12}, "must be at most 10000"),  # no hang
    ({"task": VelocityTracking, "num_random": 10**9}, "num_random must be at most 10000"),
])
def test_bad_target_options_are_one_line(options, message):
    options = dict(options)
    task = options.pop("task")
    with pytest.raises(ValueError, match=message):
        task(**options)


@pytest.mark.parametrize("method", METHODS)
def test_targets_paper_leaves_every_recipe_s_config_as_it_was_and_fair_sets_the_four_tasks(method):
    plain = compose_recipe(method, ["preset=tiny"])
    assert "targets" not in plain
    assert compose_recipe(method, ["preset=tiny", "targets=paper"]) == plain
    fair = compose_recipe(method, ["preset=tiny", "targets=fair"])
    assert list(fair.eval.tasks) == ["velocity_tracking", "goal_reaching", "trajectory_tracking",
                                     "trajectory_tracking_fast"]
    assert fair.eval.tasks.goal_reaching.radius == plain.eval.tasks.goal_reaching.radius  # the preset's, spread
    assert fair.eval.tasks.goal_reaching.targets_seed == 4502
    fair, plain = OmegaConf.to_container(fair), OmegaConf.to_container(plain)
    fair["eval"]["tasks"] = {name: plain["eval"]["tasks"][name] for name in plain["eval"]["tasks"]}
    assert fair == plain  # nothing but the tasks differs


def test_the_comparison_s_fair_jobs_run_beside_the_paper_targets_runs():
    from hierloco.envs.robots import get_robot
    from hierloco.recipes.compare.run import comparison_job

    spec = get_robot("a1")
    paper = comparison_job("lat", spec, 0, preset="paper", settings=["normal"])
    fair = comparison_job("lat", spec, 0, preset="paper", settings=["normal"], targets="fair")
    assert paper.run_dir == "outputs/lat/paper/a1_seed0" and "targets=fair" not in paper.overrides
    assert fair.run_dir == "outputs/lat/paper_fair/a1_seed0" and "targets=fair" in fair.overrides


@pytest.mark.parametrize("method", ["sac", "sac_sac"])
def test_on_fair_targets_each_model_free_agent_is_evaluated_on_its_own_task_and_every_evaluation_once(method):
    """Two main tasks of one kind (the random path and the fast path) gave two evaluation stages of one name with
    different agents, one shadowing the other, and the SAC run stopped at its evaluations: now each agent evaluates
    its own task, the generalisation variants go to the first agent of their kind, and a plan refuses a name given to
    two different stages."""
    from hierloco.pipeline.config import prepare
    from hierloco.pipeline.methods import METHODS as RECIPES
    from hierloco.pipeline.plan import Plan, TaskPlan
    from hierloco.recipes.sac.utils import sac_evaluation_stage

    utils = RECIPES[method].utils()
    for targets in ("paper", "fair"):
        cfg = compose_recipe(method, ["preset=paper", f"targets={targets}"])
        planned = utils.plan(cfg, prepare(cfg, utils.checks))
        names = [stage.name for stage in planned.stages()]
        assert len(names) == len(set(names))
        evaluated = {t.agent.name: [e.name for e in t.evaluations] for t in planned.tasks}
        for agent, evaluations in evaluated.items():
            assert f"evaluation_normal_{agent.removeprefix('sac_')}" == evaluations[0]
        flat = [name for evaluations in evaluated.values() for name in evaluations]
        assert len(flat) == len(set(flat)) == len(cfg.eval.tasks) + len(cfg.eval.generalization or {})
    assert evaluated["sac_trajectory_tracking_fast"] == ["evaluation_normal_trajectory_tracking_fast"]
    first = planned.tasks[0]
    other = sac_evaluation_stage(cfg, "velocity_tracking", {"rounds": 2}, first.agent)  # another key, same name
    twice = Plan(tasks=[first, TaskPlan("again", first.agent, [other])])
    with pytest.raises(ValueError, match="names two different stages 'evaluation_normal_velocity_tracking'"):
        twice.stages()
