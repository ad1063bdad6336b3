"""Extension points from user code: the five worked examples of ``docs/extending.md`` run as written (each under 40
lines), a planner, a task type and a dynamics model from user modules are used by the recipes' command line with
nothing else changed, and an option added at its default keeps the keys of a recorded job."""

import contextlib
import importlib
import io
import re
import sys
from pathlib import Path

import pytest
import torch

from hierloco.components.planners import PLANNERS, RandomShootingPlanner
from tests.runner import run_in_process, run_subprocess

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "extending.md"


def blocks(language: str) -> list[str]:
    """The ``language`` code blocks of docs/extending.md, in order."""
    return re.findall(rf"```{language}\n(.*?)```", DOC.read_text(), flags=re.S)


def run_example(code: str, run_dir: Path) -> str:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(code.replace("RUN_DIR", repr(str(run_dir))), str(DOC), "exec"), {"__name__": "example"})
    return out.getvalue()


@pytest.fixture(scope="module")
def user_modules(tmp_path_factory):
    """``my_tasks.py`` and ``my_planners.py`` of the doc, written to a folder on ``sys.path`` and imported."""
    folder = tmp_path_factory.mktemp("user")
    task_code, planner_code = blocks("python")[2:4]
    (folder / "my_tasks.py").write_text(task_code)
    (folder / "my_planners.py").write_text(planner_code)
    sys.path.insert(0, str(folder))
    modules = importlib.import_module("my_tasks"), importlib.import_module("my_planners")
    yield folder, modules
    sys.path.remove(str(folder))


def test_the_doc_has_five_examples_each_under_40_lines():
    python = blocks("python")
    assert len(python) == 6 and len(blocks("bash")) == 3
    assert all(len([line for line in code.splitlines() if line.strip()]) < 40 for code in python)


def test_example_1_an_ensemble_from_code_plans_the_robot_to_its_goals(copy_run):
    printed = run_example(blocks("python")[0], copy_run)
    cost, goals = re.search(r"cost ([\d.]+), goals (\d+)%", printed).groups()
    assert float(cost) < 0.9 and int(goals) >= 50, printed


def test_example_2_a_custom_cost_keeps_the_robot_out_of_the_disc(copy_run):
    code = blocks("python")[1]
    closest = lambda printed: float(re.search(r"centre: ([\d.]+) m", printed).group(1))  # noqa: E731
    assert closest(run_example(code, copy_run)) >= 0.2  # the disc's radius
    assert closest(run_example(code.replace("+ 50 * inside", "+ 0 * inside"), copy_run)) < 0.2  # it is in the way


def test_example_3_a_task_type_from_a_user_module_runs_from_the_command_line(copy_run, user_modules):
    folder, _ = user_modules
    command = blocks("bash")[0].replace("RUN_DIR", str(copy_run))
    arguments = [a.strip("'") for a in re.findall(r"'[^']*'|\S+", command.replace("\\\n", " "))]
    result = run_subprocess("evaluate.py", *arguments[3:], "eval.videos=[]", cwd=folder,
                            env={"PYTHONPATH": f"{ROOT}:{folder}"})
    assert result.returncode == 0, result.stderr[-3000:]
    table = (copy_run / "evaluations" / "patrol" / "results.md").read_text()
    assert "| lat | a1 | normal | patrol |" in table


def test_example_4_a_planner_from_a_user_module_runs_from_the_command_line(copy_run, user_modules):
    folder, _ = user_modules
    command = blocks("bash")[1].replace("RUN_DIR", str(copy_run))
    arguments = re.findall(r"\S+", command.replace("\\\n", " "))
    result = run_subprocess("evaluate.py", *arguments[3:], "eval.videos=[]", cwd=folder,
                            env={"PYTHONPATH": f"{ROOT}:{folder}"})
    assert result.returncode == 0, result.stderr[-3000:]
    assert (copy_run / "evaluations" / "grid" / "results.csv").is_file()


def test_example_5_a_dynamics_model_from_a_user_module_trains_and_reloads_with_its_option(copy_run, tmp_path,
                                                                                        monkeypatch):
    """``my_models.py`` of the doc trains in the bash block's run (a copy of the tiny run stands for
    ``runs/resmlp``: only its dynamics model and evaluations are new), which evaluates again trusting it; in a
    process that never imported it, the python block prints what its comment says: the option it was trained with."""
    from hierloco.components.com_model import MODELS

    folder = tmp_path / "user"
    folder.mkdir()
    (folder / "my_models.py").write_text(blocks("python")[4])
    monkeypatch.syspath_prepend(str(folder))  # PYTHONPATH=.
    for stale in ("dynamics_model_normal.pt", "dynamics_model_normal.pt.key.json"):
        (copy_run / stale).unlink()
    try:
        for line in blocks("bash")[2].replace("\\\n", " ").splitlines():
            _, _, command, *arguments = line.replace("runs/resmlp", str(copy_run)).split()  # PYTHONPATH=. hierloco
            script = arguments.pop(0) if command == "train" else "evaluate.py"
            result = run_in_process(script, *arguments, "eval.videos=[]", cwd=folder)
            assert result.returncode == 0, result.stderr[-3000:]
        MODELS.unregister("my_models:ResMLP")  # as in a fresh process: nothing imported
        sys.modules.pop("my_models")
        code = blocks("python")[5]
        printed = run_example(code.replace('"runs/resmlp"', repr(str(copy_run))), copy_run)
        assert printed.strip() == re.search(r"# (ResMLP .*)", code).group(1).strip()
    finally:
        MODELS.unregister("my_models:ResMLP")
        sys.modules.pop("my_models", None)


def test_a_user_planner_finds_the_known_optimum_and_checks_its_options(user_modules):
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
    action = make_planner(env, **section)(env.initial_state(episode=torch.tensor([0, 2])))["action"]
    assert torch.allclose(action, torch.tensor([[0.5, 0.0], [0.0, 0.5]]))  # goals at (2, 0) and (0, 2)
    assert check_planner_options("grid", {**section, "points_per_axis": "many"})  # a value unlike its default


def test_an_unknown_option_of_a_user_planner_is_named_with_the_valid_ones(copy_run, user_modules):
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


def test_a_dynamics_model_from_a_test_module_trains_in_a_recipe_and_loads_again(copy_run):
    """A model registered here (one class) is trained by the LAT recipe with ``dynamics.model=tanh_mlp`` and its
    option, recorded in the stage key, and loaded back by ``hierloco.load_run`` through the registry."""
    import json

    from torch import nn
    from torchrl.modules import MLP

    import hierloco
    from hierloco.components.com_model import MODELS, CoMDynamicsModel

    @MODELS.register("tanh_mlp")
    class TanhMLP(CoMDynamicsModel):
        """The CoM model with ``layers`` tanh layers of ``hidden`` units."""

        def __init__(self, action_dim: int, hidden: int = 64, *, layers: int = 3, **statistics):
            super().__init__(action_dim, hidden, **statistics)
            self.layers = int(layers)
            self.net = MLP(in_features=2 + action_dim, out_features=5, num_cells=[hidden] * self.layers,
                           activation_class=nn.Tanh)

        def config(self) -> dict:
            return {**super().config(), "layers": self.layers}

    try:
        for stale in [copy_run / "dynamics_model_normal.pt", copy_run / "dynamics_model_normal.pt.key.json"]:
            stale.unlink()
        result = run_in_process("lat", "preset=tiny", "progress=false", f"run_dir={copy_run}", "eval.videos=[]",
                                "dynamics.model=tanh_mlp", "+dynamics.layers=2")
        assert result.returncode == 0, result.stderr[-3000:]
        key = json.loads((copy_run / "dynamics_model_normal.pt.key.json").read_text())["params"]
        assert key["model"] == "tanh_mlp" and key["layers"] == 2
        model = hierloco.load_run(copy_run).com_model("normal").model
        assert isinstance(model, TanhMLP) and model.layers == 2
        refused = run_in_process("lat", "preset=tiny", f"run_dir={copy_run}", "dynamics.model=tanh_mlp",
                                 "+dynamics.layer=2")
        assert refused.returncode == 2 and "has no option 'layer' (its options: hidden, layers)" in refused.stderr
    finally:
        MODELS.unregister("tanh_mlp")
