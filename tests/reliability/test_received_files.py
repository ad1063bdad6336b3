"""Received run directories are data (issue 42, cases 1-3 and 5, and the import paths of its one-line list): a run
directory from someone else never makes hierloco delete or write a file outside it, never gets its own artifacts
deleted by its ``outputs.json``, never has its lock written through a link, never names code that is imported, and
is never taken over by another method once its ``run.json`` is lost. Every attack is made with real files."""

import json
import os
import sys
import time
from pathlib import Path

import pytest
from omegaconf import OmegaConf

import hierloco
from hierloco.io import ArtifactError, UnsafePathError, inside
from hierloco.pipeline.outputs import Outputs
from hierloco.pipeline.rundir import RunDirectory, RunDirectoryError
from tests.runner import run_in_process, snapshot


def contents(folder) -> dict:
    """Every file under ``folder`` with its bytes (links not followed)."""
    return {path.relative_to(folder).as_posix(): path.read_bytes() for path in sorted(folder.rglob("*"))
            if path.is_file() and not path.is_symlink()}


@pytest.fixture
def elsewhere(tmp_path):
    """A folder outside the run directory holding a thesis and a file named like a figure: both must survive."""
    folder = tmp_path / "elsewhere"
    folder.mkdir()
    (folder / "thesis.tex").write_text("\\chapter{Results}\n")
    (folder / "normal_goal_reaching_paths.png").write_bytes(b"not hierloco's figure")
    return folder


def shipped_module(folder, name: str, marker, body: str = "") -> None:
    """A module ``name`` in ``folder`` that writes ``marker`` when it is imported."""
    code = f"from pathlib import Path\nPath({str(marker)!r}).write_text('imported')\n{body}"
    (folder / f"{name}.py").write_text(code)


@pytest.fixture
def importable(copy_run, monkeypatch):
    """The run directory on ``sys.path``, as when Python runs from inside it: a module shipped there could be
    imported. Modules named ``shipped_*`` are forgotten afterwards."""
    monkeypatch.syspath_prepend(str(copy_run))
    yield copy_run
    for name in [name for name in sys.modules if name.startswith("shipped_")]:
        del sys.modules[name]


# ---------------------------------------------------------------------------------------------------- paths
def test_inside_refuses_absolute_paths_parent_steps_and_links(tmp_path, elsewhere):
    root = tmp_path / "run"
    (root / "figures").mkdir(parents=True)
    os.symlink(elsewhere, root / "linked")
    os.symlink(elsewhere / "thesis.tex", root / "figures" / "a.png")
    assert inside(root, "figures/new.png") == root / "figures" / "new.png"
    assert inside(root, "not/yet/made.npz") == root / "not" / "yet" / "made.npz"
    for bad in ("../elsewhere/thesis.tex", str(elsewhere / "thesis.tex"), "figures/../../x", "", ".", None, 3,
                "linked/thesis.tex", "linked", "figures/a.png"):
        with pytest.raises(UnsafePathError):
            inside(root, bad, source="outputs.json")


def draw_nothing(out):
    """A finish that draws no figure: every earlier figure its ``outputs.json`` lists is stale."""
    cfg = OmegaConf.create({"steps_per_action": 1, "eval": {"tasks": {}, "generalization": None, "videos": [],
                                                            "figures": True}})
    outputs = Outputs(out, cfg, None, "lat", None)
    outputs.draw({})
    return outputs


def test_outputs_json_never_deletes_through_a_link_nor_outside_nor_the_runs_artifacts(tmp_path, elsewhere):
    """Case 1: a ``figures/`` link plus the entry ``figures/thesis.tex``, entries naming the run's own artifacts, a
    ``..`` and an absolute path: nothing outside changes, the run's artifacts stay, a warning says so."""
    out = tmp_path / "run"
    out.mkdir()
    (out / "experts.npz").write_bytes(b"the run's experts")
    (out / "run.json").write_text('{"method": "lat"}')
    os.symlink(elsewhere, out / "figures")
    listed = ["figures/thesis.tex", "figures/normal_goal_reaching_paths.png", "experts.npz", "run.json",
              "../elsewhere/thesis.tex", str(elsewhere / "thesis.tex")]
    (out / "outputs.json").write_text(json.dumps({"files": {path: "0123456789ab" for path in listed}}))
    before, own = contents(elsewhere), contents(out)
    outputs = draw_nothing(out)
    assert contents(elsewhere) == before
    assert {name: own[name] for name in ("experts.npz", "run.json")} == \
        {name: (out / name).read_bytes() for name in ("experts.npz", "run.json")}
    assert any("outputs.json lists files this run does not write" in line for line in outputs.warnings)
    assert any("no figures written" in line and "symbolic link" in line for line in outputs.warnings)
    assert json.loads((out / "outputs.json").read_text()) == {"files": {}}


def test_stale_figures_hierloco_listed_are_still_removed_and_nothing_else(tmp_path):
    """What ``outputs.json`` may name (a figure or video it wrote, a plain file) still goes when no longer drawn;
    a file it did not list, or a link in its place, stays."""
    out = tmp_path / "run"
    (out / "figures").mkdir(parents=True)
    (out / "videos").mkdir()
    for name in ("figures/old.png", "figures/mine.png", "videos/old.mp4"):
        (out / name).write_bytes(b"png")
    (tmp_path / "target.png").write_bytes(b"someone's")
    os.symlink(tmp_path / "target.png", out / "figures" / "linked.png")
    files = {"figures/old.png": "run", "videos/old.mp4": "run", "figures/linked.png": "run"}
    (out / "outputs.json").write_text(json.dumps({"files": files}))
    draw_nothing(out)
    assert sorted(p.relative_to(out).as_posix() for p in out.rglob("*.*") if p.name != "outputs.json") == \
        ["figures/linked.png", "figures/mine.png"]
    assert (tmp_path / "target.png").read_bytes() == b"someone's"


def test_a_rerun_into_a_run_directory_whose_figures_lead_elsewhere_is_refused(copy_run, elsewhere):
    """Case 1 from the command line: the re-run stops in one line before any work; the other folder and the run
    directory are as they were."""
    import shutil

    shutil.rmtree(copy_run / "figures")
    os.symlink(elsewhere, copy_run / "figures")
    files = json.loads((copy_run / "outputs.json").read_text())
    files["files"]["figures/thesis.tex"] = "0123456789ab"
    (copy_run / "outputs.json").write_text(json.dumps(files))
    before, run_before = contents(elsewhere), snapshot(copy_run)
    result = run_in_process("lat", "preset=tiny", "progress=false", f"run_dir={copy_run}")
    assert result.returncode == 2 and len(result.lines) == 1, result.stderr
    assert "symbolic links that lead out of it (figures)" in result.lines[0]
    assert contents(elsewhere) == before and snapshot(copy_run) == run_before


def test_outputs_json_naming_the_runs_own_artifacts_leaves_them(copy_run, tmp_path):
    """Case 1: ``experts.npz``, ``gait_policy.pt``, ``run.json`` and a file beside the run directory listed in
    ``outputs.json``; a re-run finishes (exit 0), each is still there, and the warning is kept in report.json."""
    (tmp_path / "outside.txt").write_text("mine")
    files = json.loads((copy_run / "outputs.json").read_text())
    for name in ("experts.npz", "gait_policy.pt", "run.json", "../outside.txt", "evaluation"):
        files["files"][name] = "0123456789ab"
    (copy_run / "outputs.json").write_text(json.dumps(files))
    artifacts = {name: (copy_run / name).read_bytes() for name in ("experts.npz", "gait_policy.pt")}
    result = run_in_process("lat", "preset=tiny", "progress=false", f"run_dir={copy_run}", "eval.videos=[]")
    assert result.returncode == 0, result.stderr[-2000:]
    assert {name: (copy_run / name).read_bytes() for name in artifacts} == artifacts
    assert json.loads((copy_run / "run.json").read_text())["method"] == "lat"
    assert (tmp_path / "outside.txt").read_text() == "mine" and (copy_run / "evaluation").is_dir()
    warnings = json.loads((copy_run / "report.json").read_text())["warnings"]
    assert any("outputs.json lists files this run does not write" in line for line in warnings)
    assert "experts.npz" not in json.loads((copy_run / "outputs.json").read_text())["files"]


# ---------------------------------------------------------------------------------------------------- the lock
@pytest.mark.parametrize("link", ["symbolic", "hard"])
def test_a_lock_that_is_a_link_is_refused_and_its_target_kept(copy_run, tmp_path, link):
    """Case 2: ``evaluate.py`` on a run whose ``.lock`` is a link to another file: one line, exit 2, the file
    byte-identical (before, it was emptied and the lock's JSON written into it)."""
    target = tmp_path / "precious.txt"
    target.write_bytes(b"ten years of notes\n")
    (os.symlink if link == "symbolic" else os.link)(target, copy_run / ".lock")
    result = run_in_process("evaluate.py", f"run_dir={copy_run}", "planner.name=cem")
    assert result.returncode == 2 and len(result.lines) == 1, result.stderr
    assert "not the lock file hierloco makes" in result.lines[0]
    assert target.read_bytes() == b"ten years of notes\n"
    assert not (copy_run / "evaluations").exists()


# ---------------------------------------------------------------------------------------------------- imports
def test_load_run_never_imports_what_run_json_names(importable, tmp_path):
    """Case 3: ``run.json`` naming a module shipped in the run directory as its low level, or as its planner: one
    :class:`ArtifactError` each, the module never imported; ``trust_imports`` names it, and then it is."""
    from hierloco.envs.low_level import LOW_LEVELS
    from hierloco.envs.tasks import GoalReaching

    marker = tmp_path / "IMPORTED"
    shipped_module(importable, "shipped_low_level", marker,
                   "from hierloco.components.low_level import LatentLowLevel\n\n\nclass Shipped(LatentLowLevel):\n"
                   "    pass\n")
    manifest = json.loads((importable / "run.json").read_text())
    (importable / "run.json").write_text(json.dumps({**manifest, "low_level": {"kind": "shipped_low_level:Shipped"}}))
    with pytest.raises(ArtifactError, match="low_level.kind 'shipped_low_level:Shipped' is an import path .* "
                                            "trust_imports"):
        hierloco.load_run(importable).low_level()
    (importable / "run.json").write_text(json.dumps({**manifest, "planner": {**manifest["planner"],
                                                                             "name": "shipped_low_level:Shipped"}}))
    with pytest.raises(ArtifactError, match="planner.name 'shipped_low_level:Shipped' is an import path"):
        hierloco.load_run(importable).planner(GoalReaching())
    assert not marker.exists() and "shipped_low_level" not in sys.modules
    (importable / "run.json").write_text(json.dumps({**manifest, "low_level": {"kind": "shipped_low_level:Shipped"}}))
    try:
        low_level = hierloco.load_run(importable, trust_imports=["shipped_low_level:Shipped"]).low_level()
        assert marker.exists() and type(low_level).__name__ == "Shipped"
    finally:
        LOW_LEVELS.unregister("shipped_low_level:Shipped")


RECEIVED = {  # where a received run directory names a module: the file, the key, the value
    "planner": ("config.yaml", "planner.name", "shipped_code:Planner"),
    "task": ("config.yaml", "eval.tasks.goal_reaching.task", "shipped_code:Task"),
    "dynamics": ("config.yaml", "dynamics.model", "shipped_code:Model"),
    "method": ("run.json", "method", "shipped_code:main"),
}


@pytest.mark.parametrize("where", list(RECEIVED))
def test_evaluate_never_imports_what_a_received_run_directory_names(importable, tmp_path, where):
    """Case 3: ``config.yaml`` naming ``planner.name: shipped_code:Planner`` (a task's ``task:``, the dynamics
    model) or ``run.json`` naming a method by import path: one line, exit 2, the module never imported, nothing
    written."""
    file, key, value = RECEIVED[where]
    marker = tmp_path / "IMPORTED"
    shipped_module(importable, "shipped_code", marker, "Planner = Task = Model = main = object\n")
    if file == "config.yaml":
        cfg = OmegaConf.load(importable / file)
        OmegaConf.update(cfg, key, value, merge=False)
        OmegaConf.save(cfg, importable / file)
    else:
        manifest = json.loads((importable / file).read_text())
        (importable / file).write_text(json.dumps({**manifest, key: value}))
    before = snapshot(tmp_path)
    result = run_in_process("evaluate.py", f"run_dir={importable}", "planner.num_candidates=64")
    assert result.returncode == 2 and len(result.lines) == 1, result.stderr
    assert value in result.lines[0] and ("never imported" in result.lines[0] or "never an import path" in
                                         result.lines[0])
    assert not marker.exists() and "shipped_code" not in sys.modules
    assert snapshot(tmp_path) == before


@pytest.mark.parametrize("given", ["trust_imports=shipped_code:Planner", "planner.name=shipped_code:Planner"])
def test_an_import_path_given_again_is_imported_and_checked_for_its_kind(importable, tmp_path, given):
    """The user names the received import path again (``trust_imports=`` or the override itself): it is
    imported, and refused in one line because it names no planner; nothing is written."""
    marker = tmp_path / "IMPORTED"
    shipped_module(importable, "shipped_code", marker, "Planner = object\n")
    cfg = OmegaConf.load(importable / "config.yaml")
    OmegaConf.update(cfg, "planner.name", "shipped_code:Planner", merge=False)
    OmegaConf.save(cfg, importable / "config.yaml")
    before = snapshot(importable)
    result = run_in_process("evaluate.py", f"run_dir={importable}", given)
    assert result.returncode == 2 and len(result.lines) == 1, result.stderr
    assert "planner.name: planner 'shipped_code:Planner' is the class builtins.object, not a BoxPlannerBase " \
           "subclass" in result.lines[0]
    assert marker.exists() and snapshot(importable) == before


def test_a_trusted_import_path_in_a_received_config_evaluates(copy_run):
    """A real planner named by its import path in the run's ``config.yaml`` evaluates once the command line trusts
    it."""
    cfg = OmegaConf.load(copy_run / "config.yaml")
    OmegaConf.update(cfg, "planner.name", "hierloco.components.planners.cem:BoxCEMPlanner", merge=False)
    OmegaConf.save(cfg, copy_run / "config.yaml")
    result = run_in_process("evaluate.py", f"run_dir={copy_run}", "name=cem", "eval.videos=[]", "eval.figures=false",
                            "trust_imports=hierloco.components.planners.cem:BoxCEMPlanner")
    assert result.returncode == 0, result.stderr[-2000:]
    assert (copy_run / "evaluations" / "cem" / "results.csv").is_file()


@pytest.mark.parametrize("override, message", [
    ("planner.name=os:getcwd", "planner.name: planner 'os:getcwd' is a function (posix.getcwd), not a "
                               "BoxPlannerBase subclass"),
    ("planner.name=json:JSONDecoder", "planner 'json:JSONDecoder' is the class json.decoder.JSONDecoder, not a "
                                      "BoxPlannerBase subclass"),
    ("dynamics.model=os:getcwd", "dynamics.model: dynamics_model 'os:getcwd' is a function (posix.getcwd), not a "
                                 "CoMModel subclass"),
    ("+eval.tasks.goal_reaching.task=json:JSONDecoder", "eval.tasks.goal_reaching.task: task 'json:JSONDecoder' is "
                                                        "the class json.decoder.JSONDecoder, not a Task subclass"),
    ("planner.name=no_such_module:Planner", "cannot import it (ModuleNotFoundError"),
])
def test_an_import_path_of_the_wrong_kind_is_one_line_before_any_stage(tmp_path, override, message):
    """The one-line list: ``planner.name=os:getcwd`` and ``json:JSONDecoder``, ``dynamics.model=os:getcwd`` (a
    traceback after 24 s with stages built, before): refused by the config check, in seconds, nothing made."""
    start = time.perf_counter()
    result = run_in_process("lat", "preset=tiny", "progress=false", f"run_dir={tmp_path / 'run'}", override)
    assert result.returncode == 2 and len(result.lines) == 1 and message in result.lines[0], result.stderr
    assert not (tmp_path / "run").exists() and time.perf_counter() - start < 60


# ---------------------------------------------------------------------------------------------------- owners
def test_a_run_directory_that_lost_its_run_json_is_refused_to_another_method(copy_run):
    """Case 5: ``sac/train.py`` into a finished LAT run directory without its ``run.json`` overwrote LAT's
    results, config and figures (exit 0); now one line, exit 2, nothing changed."""
    (copy_run / "run.json").unlink()
    before = snapshot(copy_run)
    result = run_in_process("sac", "preset=tiny", "progress=false", f"run_dir={copy_run}")
    assert result.returncode == 2 and len(result.lines) == 1, result.stderr
    assert "has no run.json" in result.lines[0] and "dynamics_data_normal.npz" in result.lines[0]
    assert snapshot(copy_run) == before


def test_a_run_directory_whose_owner_cannot_be_established_is_refused(copy_run):
    """Without ``run.json`` and without a single stage key, whose results these are cannot be told: even the
    method that made them is refused, in one line, nothing changed."""
    (copy_run / "run.json").unlink()
    for key in copy_run.glob("*.key.json"):
        key.unlink()
    before = snapshot(copy_run)
    result = run_in_process("lat", "preset=tiny", "progress=false", f"run_dir={copy_run}")
    assert result.returncode == 2 and len(result.lines) == 1, result.stderr
    assert "has no run.json" in result.lines[0] and "builds.json" in result.lines[0]
    assert snapshot(copy_run) == before


def test_foreign_artifacts_are_what_the_plan_does_not_make(tmp_path):
    """A directory's stage artifacts a plan does not make; a new directory, or one of the plan's own stages (a
    run killed before its ``run.json``), has none."""
    run = RunDirectory(tmp_path / "run")
    assert run.foreign_artifacts(["experts.npz"]) == []
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / ".lock").write_text("")
    assert run.foreign_artifacts(["experts.npz"]) == []
    for name in ("experts.npz", "experts.npz.key.json", "builds.json"):
        (tmp_path / "run" / name).write_text("{}")
    assert run.foreign_artifacts(["experts.npz", "gait_policy.pt"]) == []
    (tmp_path / "run" / "dynamics_model_normal.pt.key.json").write_text("{}")
    assert run.foreign_artifacts(["experts.npz"]) == ["dynamics_model_normal.pt"]
    os.symlink(tmp_path, tmp_path / "run" / "up")
    with pytest.raises(RunDirectoryError, match=r"symbolic links that lead out of it \(up\)"):
        run.verify([])


TINY_EVALUATION = ("eval.videos=[]", "eval.figures=false", "eval.generalization=null",
                   "++eval.tasks={goal_reaching: {radius: 0.6, num_steps: 2, num_goals: 1}}")


def received_terrain_file(copy_run, tmp_path) -> Path:
    """The run's ``config.yaml`` made to name a heightmap elsewhere on this machine (as a received one may)."""
    import numpy as np
    from matplotlib import pyplot

    ground = tmp_path / "elsewhere" / "ground.png"
    ground.parent.mkdir()
    pyplot.imsave(ground, np.zeros((8, 8)), cmap="gray")
    cfg = OmegaConf.load(copy_run / "config.yaml")
    OmegaConf.update(cfg, "eval.terrain", {"name": "heightmap", "path": str(ground), "height_m": 0.01}, merge=False)
    OmegaConf.save(cfg, copy_run / "config.yaml")
    return ground


def test_evaluate_reads_no_terrain_file_a_received_config_names_outside_its_run_directory(copy_run, tmp_path):
    """A received ``config.yaml`` whose evaluations name a terrain file elsewhere on this machine is refused in one
    line before anything is read or written."""
    ground = received_terrain_file(copy_run, tmp_path)
    before = snapshot(copy_run)
    result = run_in_process("evaluate.py", f"run_dir={copy_run}", "name=ground", *TINY_EVALUATION)
    assert result.returncode == 2 and len(result.lines) == 1, result.stderr
    assert f"eval.terrain.path={ground}" in result.lines[0] and "outside the run directory" in result.lines[0]
    assert snapshot(copy_run) == before


@pytest.mark.slow
def test_a_received_terrain_file_named_again_or_shipped_inside_is_read(copy_run, tmp_path):
    """Named again on the command line, or shipped inside the run directory, the file is read and the evaluation
    runs."""
    ground = received_terrain_file(copy_run, tmp_path)
    tiny = TINY_EVALUATION
    cfg = OmegaConf.load(copy_run / "config.yaml")
    again = run_in_process("evaluate.py", f"run_dir={copy_run}", "name=ground", *tiny, f"eval.terrain.path={ground}")
    assert again.returncode == 0, again.stderr[-2000:]
    shipped = copy_run / "ground.png"
    shipped.write_bytes(ground.read_bytes())
    OmegaConf.update(cfg, "eval.terrain.path", str(shipped), merge=False)
    OmegaConf.save(cfg, copy_run / "config.yaml")
    inside = run_in_process("evaluate.py", f"run_dir={copy_run}", "name=shipped", *tiny)
    assert inside.returncode == 0, inside.stderr[-2000:]


def test_the_file_links_wandb_makes_in_its_run_folder_do_not_refuse_the_run_directory(tmp_path):
    """Weights & Biases (offline, the paper preset's logger) links ``debug-core.log`` in its run folder to its
    service's log in the user's cache: the run directory hierloco made is used again (``hierloco evaluate`` refused
    it). A link to a folder there, or a file link anywhere else, is still refused."""
    from hierloco.pipeline.rundir import RunDirectory, RunDirectoryError

    outside = tmp_path / "cache" / "core-debug.log"
    outside.parent.mkdir()
    outside.write_text("")
    run = RunDirectory(tmp_path / "run")
    wandb_logs = tmp_path / "run" / "logs" / "lat_a1_0" / "wandb" / "offline-run-1" / "logs"
    wandb_logs.mkdir(parents=True)
    os.symlink(outside, wandb_logs / "debug-core.log")
    assert run.verify([]) == {}
    os.symlink(outside.parent, wandb_logs / "cache")
    with pytest.raises(RunDirectoryError, match=r"lead out of it \(logs/lat_a1_0/wandb/offline-run-1/logs/cache\)"):
        run.verify([])
    (wandb_logs / "cache").unlink()
    os.symlink(outside, tmp_path / "run" / "logs" / "lat_a1_0" / "metrics.csv")
    with pytest.raises(RunDirectoryError, match=r"lead out of it \(logs/lat_a1_0/metrics.csv\)"):
        run.verify([])
