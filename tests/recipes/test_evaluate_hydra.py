"""``hierloco evaluate`` as a Hydra app, and planner and model types as config groups (issue 43, item 3): ``--help``
lists the groups an evaluation may choose, ``--cfg job`` composes the run's own config with the overrides, ``-m``
sweeps through Hydra's sweeper into one evaluation folder per job named by Hydra's override dirname (without the
settings that change no result), ``hydra/launcher=joblib`` runs the jobs; ``planner=cem`` and
``dynamics/model=ensemble`` compose what ``planner.name=cem`` and ``dynamics.model=ensemble`` do."""

import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from hierloco.cli import main
from hierloco.pipeline.evaluate import EVALUATION_KEYS
from hierloco.pipeline.run import NOT_IN_RUN_DIR_NAME
from tests.runner import run_in_process, run_subprocess, snapshot

ROOT = Path(__file__).resolve().parents[2]
TASKS = {"velocity_tracking", "goal_reaching", "trajectory_tracking"}  # the tiny preset's, without generalisation
QUIET = ("progress=false", "eval.videos=[]", "eval.generalization=null")


def cfg_job(capsys, *arguments: str) -> dict:
    """The config ``hierloco ARGUMENTS --cfg job`` prints, as a dict."""
    assert main([*arguments, "--cfg", "job"]) == 0
    return yaml.safe_load(capsys.readouterr().out)


def test_evaluate_help_lists_what_an_evaluation_may_choose_without_importing_torch():
    code = ("import sys; from hierloco.cli import main; code = main(['evaluate', '--help']); "
            "sys.exit(3 if 'torch' in sys.modules else code)")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert result.returncode == 0, result.stderr
    out = result.stdout
    assert out.startswith("hierloco evaluate: Evaluate a trained run")
    assert "\n  planner: cem, exhaustive, mppi, random_shooting\n" in out
    assert "\n  planner_scale: paper, small, tiny\n" in out
    assert "\n  dynamics" not in out and "\n  experts" not in out  # training's groups are not an evaluation's
    assert out.endswith("run_dir: ???\nname: null\ntrust_imports: null\n")  # the composed config, without a run


def test_train_help_lists_the_planner_and_model_types_and_the_planner_presets(capsys):
    assert main(["train", "lat", "--help"]) == 0
    out = capsys.readouterr().out
    for line in ("planner: cem, exhaustive, mppi, random_shooting", "planner_scale: paper, small, tiny",
                 "dynamics/model: ensemble, mlp"):
        assert f"\n  {line}\n" in out


@pytest.mark.parametrize("method", ["lat", "ik"])
@pytest.mark.parametrize("preset", ["paper", "tiny"])
def test_planner_and_model_types_are_groups_composing_what_their_keys_compose(capsys, method, preset):
    base = ("train", method, f"preset={preset}")
    default = cfg_job(capsys, *base)
    assert default["planner"]["name"] == "random_shooting" and default["dynamics"]["model"] == "mlp"
    assert default["planner"]["num_candidates"] == {"paper": 8000, "tiny": 500}[preset]  # the preset sizes it
    cem = cfg_job(capsys, *base, "planner=cem")
    assert cem == cfg_job(capsys, *base, "planner.name=cem") and cem["planner"] == {**default["planner"], "name": "cem"}
    ensemble = cfg_job(capsys, *base, "dynamics/model=ensemble")
    assert ensemble == cfg_job(capsys, *base, "dynamics.model=ensemble") and ensemble["dynamics"]["model"] == "ensemble"
    assert cfg_job(capsys, *base, "planner_scale=small")["planner"]["num_candidates"] == 4000


def test_evaluate_cfg_job_is_the_runs_config_with_the_overrides(copy_run, capsys):
    trained = yaml.safe_load((copy_run / "config.yaml").read_text())
    composed = cfg_job(capsys, "evaluate", f"run_dir={copy_run}", "planner=cem", "planner_scale=paper")
    assert composed["planner"] == {**trained["planner"], "name": "cem", "num_candidates": 8000}
    assert composed == {**trained, "planner": composed["planner"], "run_dir": str(copy_run), "name": None,
                        "trust_imports": None}
    assert cfg_job(capsys, "evaluate", f"run_dir={copy_run}", "planner.name=cem")["planner"] == {
        **trained["planner"], "name": "cem"}
    assert not (copy_run / "evaluations").exists()


def test_a_sweep_evaluates_each_planner_into_the_folder_hydra_names_it(copy_run):
    """``-m planner=random_shooting,cem``: Hydra's sweeper runs two jobs on the trained run, each into
    ``evaluations/<its override dirname>``, which leaves out ``progress`` and ``eval.videos`` (no result changes);
    the run's own planner reuses every evaluation, CEM evaluates anew; no training stage is built."""
    result = run_in_process("evaluate.py", "-m", f"run_dir={copy_run}", "planner=random_shooting,cem", *QUIET)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    evaluations = copy_run / "evaluations"
    folders = {path.name for path in evaluations.iterdir() if path.is_dir()}
    assert folders == {"eval.generalization=null,planner=random_shooting", "eval.generalization=null,planner=cem"}
    for folder in folders:
        cfg = yaml.safe_load((evaluations / folder / "config.yaml").read_text())
        assert cfg["planner"]["name"] == folder.rsplit("=", 1)[1] and cfg["progress"] is False
        assert "name" not in cfg and "trust_imports" not in cfg and cfg["run_dir"] == str(copy_run)
        assert {row["task"] for row in csv.DictReader(open(evaluations / folder / "results.csv"))} == TASKS
        reused = json.loads((evaluations / folder / "report.json").read_text())["reused_stages"]
        assert all(done for name, done in reused.items() if not name.startswith("evaluation_"))
        evaluated = {done for name, done in reused.items() if name.startswith("evaluation_")}
        assert evaluated == ({True} if folder.endswith("random_shooting") else {False})


def test_the_launchers_compose_with_evaluate_and_its_folder_names_leave_out_what_run_dirs_leave_out(copy_run,
                                                                                                     capsys):
    assert main(["evaluate", f"run_dir={copy_run}", "hydra/launcher=joblib", "--cfg", "hydra"]) == 0
    hydra = yaml.safe_load(capsys.readouterr().out)["hydra"]
    assert hydra["launcher"]["_target_"] == "hydra_plugins.hydra_joblib_launcher.joblib_launcher.JoblibLauncher"
    excluded = set(hydra["job"]["config"]["override_dirname"]["exclude_keys"])
    assert {"run_dir", "name", "trust_imports"} <= excluded
    for key in NOT_IN_RUN_DIR_NAME:  # a training sweep's run directories leave them out: so do its evaluations
        if key.split(".")[0] in EVALUATION_KEYS:
            assert any(item == key or item.startswith(f"{key}.") for item in excluded), key


@pytest.mark.parametrize("arguments, said", [
    (["dynamics/model=ensemble"], "evaluate.py changes only eval, planner, settings"),
    (["policy.epochs=3", "planner=cem"], "got policy.epochs=3 (a training change needs hierloco train"),
    (["-m", "name=mine", "planner=cem,mppi"], "name= names one evaluation; a sweep (planner=cem,mppi)"),
    (["planner=nope"], "Could not find 'planner/nope'"),
])
def test_a_mistake_is_one_line_before_any_work(copy_run, arguments, said):
    before = snapshot(copy_run)
    result = run_in_process("evaluate.py", f"run_dir={copy_run}", *arguments)
    assert result.returncode == 2 and len(result.lines) == 1 and said in result.lines[0], result.stderr
    assert snapshot(copy_run) == before


@pytest.mark.parametrize("section", ["hydra", "trust_imports"])
def test_a_received_config_that_configures_hydra_or_trusts_itself_is_refused(copy_run, tmp_path, section):
    """The run's ``config.yaml`` is Hydra's base config: a ``hydra:`` section in it would run its callbacks (here
    ``Path.touch`` on a marker), a ``trust_imports`` would trust what it names itself. Refused in one line."""
    marker = tmp_path / "RAN"
    added = {"hydra": f"hydra:\n  callbacks:\n    x:\n      _target_: pathlib.Path.touch\n      self: {marker}\n",
             "trust_imports": "trust_imports: [os:getcwd]\n"}[section]
    (copy_run / "config.yaml").write_text((copy_run / "config.yaml").read_text() + added)
    result = run_in_process("evaluate.py", f"run_dir={copy_run}", *QUIET)
    assert result.returncode == 2 and len(result.lines) == 1, result.stderr
    assert f"config.yaml sets {section}: a run's config configures neither Hydra nor" in result.lines[0]
    assert not marker.exists() and not (copy_run / "evaluations").exists()


@pytest.mark.slow
def test_a_sweep_runs_on_the_joblib_launcher(copy_run):
    result = run_subprocess("evaluate.py", "-m", f"run_dir={copy_run}", "planner.num_candidates=64,128", *QUIET,
                            "hydra/launcher=joblib", "hydra.launcher.n_jobs=2")
    assert result.returncode == 0, result.stderr[-3000:]
    for candidates in (64, 128):
        folder = copy_run / "evaluations" / f"eval.generalization=null,planner.num_candidates={candidates}"
        assert yaml.safe_load((folder / "config.yaml").read_text())["planner"]["num_candidates"] == candidates
        assert {row["task"] for row in csv.DictReader(open(folder / "results.csv"))} == TASKS
