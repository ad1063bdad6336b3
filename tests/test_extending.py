"""Extension points from user code (``docs/extending.md``): a planner and a task type registered in this test module
are used by the recipes' command line with nothing else changed; an option added at its default keeps the keys of a
recorded job."""

from pathlib import Path

import pytest
import torch

from hierloco.components.planners import PLANNERS, BoxPlannerBase, RandomShootingPlanner
from hierloco.envs.tasks import TASKS, Task

ROOT = Path(__file__).resolve().parents[1]


# ---------------------------------------------------------------------------------------------- a new planner
@PLANNERS.register("grid")
class GridPlanner(BoxPlannerBase):
    """Scores a regular grid of first actions, ``points_per_axis`` per axis of the action box (horizon 1)."""

    def __init__(self, env, planning_horizon: int = 1, seed: int = 0, *, points_per_axis: int = 11):
        super().__init__(env, planning_horizon, num_candidates=1, seed=seed)
        axes = [torch.linspace(lo, hi, points_per_axis) for lo, hi in zip(self.low.tolist(), self.high.tolist())]
        self.grid = torch.cartesian_prod(*axes).reshape(-1, self.action_dim)

    @torch.no_grad()
    def planning(self, tensordict):
        td = self._flat(tensordict)
        candidates = self.grid[None, :, None].expand(td.batch_size[0], -1, self.planning_horizon, -1)
        best = self.score(td, candidates).argmax(1)
        return self._output(tensordict, self.grid[best])


# ---------------------------------------------------------------------------------------------- a new task type
@TASKS.register("patrol")
class Patrol(Task):
    """Visit ``waypoints`` (world frame, m) in turn, ``steps_per_waypoint`` task steps each."""

    kind = "patrol"

    def __init__(self, waypoints=((0.4, 0.0), (0.4, 0.4), (0.0, 0.4)), steps_per_waypoint: int = 2, name=None):
        super().__init__(name)
        self.waypoints = torch.as_tensor(waypoints, dtype=torch.float32)
        self.steps_per_waypoint = int(steps_per_waypoint)
        self.num_steps = len(self.waypoints) * self.steps_per_waypoint

    def target(self, episode, step):
        return self.waypoints[(step // self.steps_per_waypoint).clamp(max=len(self.waypoints) - 1)]

    def tracking_error(self, state, next_state, target):
        return (next_state[..., :2] - target).norm(dim=-1)

    def markers(self, episode=None):
        return self.waypoints.numpy()


def test_a_registered_planner_is_built_from_a_config_section_and_finds_the_optimum():
    from hierloco.components.planners import check_planner_options, make_planner
    from hierloco.envs.tasks import GoalReaching
    from hierloco.envs.world_model import CoMWorldModelEnv

    class Drift(torch.nn.Module):  # moves by the action in the world frame: the optimum is known
        def predict(self, com_state, action):
            return torch.cat([com_state[..., :2] + action, com_state[..., 2:]], -1)

    env = CoMWorldModelEnv(Drift(), action_low=[-0.5, -0.5], action_high=[0.5, 0.5], task=GoalReaching())
    section = {"name": "grid", "horizon": 1, "num_candidates": 8000, "points_per_axis": 11}  # one section, all
    assert check_planner_options("grid", section) == []
    assert PLANNERS.options("grid") == {"points_per_axis": 11}
    planner = make_planner(env, **section)
    action = planner(env.initial_state(episode=torch.tensor([0, 2])))["action"]  # goals at (2, 0) and (0, 2)
    assert torch.allclose(action, torch.tensor([[0.5, 0.0], [0.0, 0.5]]))
    assert check_planner_options("grid", {**section, "points_per_axis": "many"})  # a value unlike its default


def test_a_registered_planner_and_task_type_run_from_the_command_line(copy_run):
    """``planner.name=grid`` and a task of type ``patrol``, on a trained run, from ``evaluate.py``: the test module
    is the only file that knows them."""
    from tests.runner import run_in_process

    result = run_in_process("evaluate.py", f"run_dir={copy_run}", "name=grid", "planner.name=grid",
                            "+planner.points_per_axis=7", "+eval.tasks.patrol={task: patrol, steps_per_waypoint: 2}",
                            "eval.videos=[]")
    assert result.returncode == 0, result.stderr[-3000:]
    table = (copy_run / "evaluations" / "grid" / "results.md").read_text()
    assert "| lat | a1 | normal | patrol |" in table
    by_reference = run_in_process("evaluate.py", f"run_dir={copy_run}", "name=ref",
                                  "+eval.tasks.patrol={task: 'tests.test_extending:Patrol'}", "eval.videos=[]")
    assert by_reference.returncode == 0, by_reference.stderr[-3000:]


def test_an_unknown_planner_option_is_named_with_the_valid_ones(copy_run):
    from tests.runner import run_in_process

    result = run_in_process("evaluate.py", f"run_dir={copy_run}", "planner.name=grid", "+planner.point_per_axis=7")
    assert result.returncode == 2 and len(result.lines) == 1
    assert "planner has no option 'point_per_axis'" in result.lines[0] and "points_per_axis" in result.lines[0]


def test_an_option_added_at_its_default_keeps_the_keys_of_a_recorded_job(monkeypatch):
    """A new option of the paper's planner, at a default that reproduces it, leaves a committed record of the
    comparison current; the same option at another value changes only the evaluation keys."""
    from hierloco.pipeline import records, studies

    class WithDummy(RandomShootingPlanner):
        def __init__(self, env, planning_horizon: int = 1, num_candidates: int = 8000, seed: int = 0, *,
                     dummy: float = 0.0):
            super().__init__(env, planning_horizon, num_candidates, seed)

    monkeypatch.setitem(PLANNERS._entries, "random_shooting", WithDummy)
    where = ROOT / "results" / "compare_full" / "records" / "lat" / "paper" / "a1_seed0"
    record = records.read(where)
    job = studies.Job("lat", "outputs/lat/paper/a1_seed0", record["signature"]["overrides"])
    assert records.matches(record, job.signature(), studies.planned_stages(job))
    changed = studies.Job("lat", job.run_dir, [*job.overrides, "+planner.dummy=1.0"])
    keys = {spec.filename: spec.key for spec in studies.planned_stages(changed)}
    differ = [name for name, entry in record["stages"].items() if keys.get(name) != entry["key"]]
    assert differ and all(name.startswith("evaluation/") for name in differ)
