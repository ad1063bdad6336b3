"""The LIB, IK and SAC recipes end to end with the tiny preset: they run every stage and write the shared results."""

import csv
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
COLUMNS = ["method", "robot", "setting", "task", "seed", "normalized_cost", "success_rate", "final_error"]


def run(method, *overrides):
    env = {**os.environ, "WANDB_MODE": "offline"}
    return subprocess.run([sys.executable, str(ROOT / "recipes" / method / "train.py"), "preset=tiny",
                           "progress=false", *overrides], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=600)


@pytest.mark.parametrize("method, settings", [
    ("lib", "[normal]"), ("ik", "[normal,legs_disabled]"), ("sac", "[normal]"),
    pytest.param("sac_sac", "[normal]", marks=pytest.mark.slow)])  # ~50 s: two SAC trainings
def test_baseline_recipe_runs(method, settings, tmp_path):
    result = run(method, f"run_dir={tmp_path}", f"settings={settings}")
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    with open(tmp_path / "results.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == COLUMNS
    expected = {(s, t) for s in settings.strip("[]").split(",")
                for t in ("velocity_tracking", "goal_reaching", "trajectory_tracking")}
    assert expected <= {(r["setting"], r["task"]) for r in rows}  # (SAC's tiny preset adds generalisation tasks)
    assert all(r["method"] == method for r in rows)
    assert (tmp_path / "figures" / "normal_goal_reaching_paths.png").exists()
    if method == "sac_sac":  # the SAC low level, reported on its own
        import json

        tracking = json.loads((tmp_path / "sac_low_level_tracking.json").read_text())
        assert len(tracking["rows"]) == 27 and "fall_rate" in tracking["summary"]
        assert (tmp_path / "videos" / "sac_low_level_walking.mp4").stat().st_size > 1000
        assert (tmp_path / "sac_low_level.pt").exists() and not (tmp_path / "sac_low_level.training.pt").exists()
        report = (tmp_path / "sac_low_level_report.md").read_text()  # its curve, the budget, tracking per command
        assert "## Learning curve" in report and "frames" in report.split("\n")[2]
        assert sum(line.startswith("| (") for line in report.splitlines()) == 27
        # the table says how the low level acted: the recipe's default, samples of its policy
        assert "the tracking table acts with samples of the policy" in report
        assert "## Tracking per command (stochastic actor)" in report and "deterministic" not in report
        again = subprocess.run([sys.executable, str(ROOT / "recipes" / "sac_sac" / "report.py"), str(tmp_path),
                                str(tmp_path / "report")], capture_output=True, text=True, timeout=120)
        assert again.returncode == 0, again.stderr[-2000:]
        assert (tmp_path / "report" / "report.md").read_text() == report
        assert (tmp_path / "report" / "learning_curve.png").read_bytes()[:4] == b"\x89PNG"
    if method in ("sac", "sac_sac"):  # one SAC agent per task, trained on half the targets
        assert {p.name for p in tmp_path.glob("sac_*.pt") if "low_level" not in p.name} == {f"sac_{t}.pt" for t in
                                                              ("velocity_tracking", "goal_reaching",
                                                               "trajectory_tracking")}
        assert not list(tmp_path.glob("*.training.pt"))  # the training checkpoints go once their stage is built
    else:
        data = (tmp_path / "dynamics_data_normal.npz.key.json").read_text()
        assert ('"kind": "expert_replay"' in data) if method == "lib" else ('"kind": "command"' in data)


def test_lib_refuses_a_continuous_planner(tmp_path):
    result = run("lib", f"run_dir={tmp_path / 'x'}", "planner.name=random_shooting")
    assert result.returncode == 2 and "unknown planner" in result.stderr


def test_sac_trains_on_half_the_targets_on_both_axes():
    from hierloco.envs.tasks import GoalReaching, TrajectoryTracking, VelocityTracking

    goals = GoalReaching().training_split()
    assert np.allclose(goals.goals, GoalReaching().goals[::2], atol=1e-6) and goals.num_steps == 30
    velocity = VelocityTracking().training_split()
    assert np.allclose(velocity.velocities.numpy(), [[0.0, 0.2], [0.2, 0.0]]) and velocity.num_steps == 40
    path = TrajectoryTracking().training_split()
    assert abs(path.length - TrajectoryTracking().length / 2) < 0.05 and np.allclose(path.path[-1], [2.0, 0.0])


class _KilledAt:
    """A logger that records the frames it is told of and stops the training (as a kill would) at ``frames``."""

    def __init__(self, frames=None):
        self.frames, self.steps = frames, []

    def log_metrics(self, metrics, step):
        self.steps.append(step)
        if self.frames is not None and step >= self.frames:
            raise KeyboardInterrupt


def test_a_killed_sac_high_level_resumes_from_its_checkpoint(tmp_path):
    """SAC's high level (SAC's and SAC-SAC's) writes its training state as it trains: stopped half-way, it goes on
    from its last checkpoint (nothing collected twice) to the full budget and removes the checkpoint; a checkpoint
    of other parameters is refused."""
    from types import SimpleNamespace

    from hierloco.components.low_level import CommandLowLevel
    from hierloco.components.sac import SACAgent
    from hierloco.pipeline.config import compose_recipe
    from hierloco.pipeline.rundir import RunDirectory
    from hierloco.recipes.sac.utils import train_high_level

    params = {"seed": 0, "device": "cpu", "task_name": "velocity_tracking", "task": {}, "total_frames": 64,
              "init_random_frames": 16, "num_robots": 8, "updates_per_frame": 0.25, "batch_size": 16,
              "buffer_size": 256, "hidden": 16, "lr": 1e-3, "gamma": 0.95, "tau": 0.005}
    checkpoint = tmp_path / "sac_velocity_tracking.training.pt"

    directory = RunDirectory(tmp_path)
    cfg = compose_recipe("sac", ["preset=tiny"])  # flat ground, nominal dynamics: the world the stage runs in

    def train(logger, **changed):
        run = SimpleNamespace(path=tmp_path, dir=directory, nthread=1, progress=False, logger=logger, cfg=cfg)
        return train_high_level(run, {**params, **changed}, lambda n: CommandLowLevel("a1", n, steps_per_action=10))

    with pytest.raises(KeyboardInterrupt):
        train(_KilledAt(frames=32))
    assert checkpoint.exists()  # written every tenth of the budget (here every step of 8 robots)
    with pytest.raises(ValueError, match="other settings"):
        train(_KilledAt(), lr=3e-4)
    resumed = _KilledAt()
    agent = directory.stage("sac_velocity_tracking", params, lambda: train(resumed), lambda a, p: a.save(p),
                            SACAgent.load, "sac_velocity_tracking.pt")
    build = directory.builds()["sac_velocity_tracking"]  # the killed run's training time is counted
    assert 0 < build["interrupted_seconds"] < build["seconds"]
    curve = agent.metadata["learning_curve"]
    assert agent.metadata["frames"] == 64 and [p["frames"] for p in curve] == list(range(8, 65, 8))
    # stopped while logging frame 32, before that step's checkpoint: it goes on from the checkpoint of frame 24
    assert resumed.steps == list(range(32, 65, 8))
    assert agent.updates == 7 * 2  # 2 updates per step of 8 robots on the 7 steps from frame 16: none lost or redone
    assert not checkpoint.exists()
