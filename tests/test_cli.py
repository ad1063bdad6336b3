"""The ``hierloco`` command (``hierloco/cli.py``, ``docs/cli.md``): every recipe, study and tool by name, a user's
own method by folder or module path, Hydra's information flags without a run, and one line for a bad command."""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from hierloco.cli import main, parse

ROOT = Path(__file__).resolve().parents[1]


def hierloco(*args: str, cwd=ROOT) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "hierloco.cli", *args], capture_output=True, text=True, cwd=cwd,
                          timeout=300)


def test_parse_splits_the_command_the_recipe_and_the_overrides():
    assert parse(["train", "lat", "seed=1"]) == ("train", "lat", ["seed=1"])
    assert parse(["train", "seed=1"]) == ("train", None, ["seed=1"])
    assert parse(["study", "./my_study", "-m"]) == ("study", "./my_study", ["-m"])
    assert parse([]) == (None, None, [])


def test_help_lists_the_config_groups_and_the_composed_config():
    result = hierloco("train", "lat", "--help")
    assert result.returncode == 0, result.stderr
    out = result.stdout
    assert out.startswith("hierloco train lat: LAT")
    for group in ("preset: paper, small, tiny", "planner: ", "dynamics: ", "eval: "):
        assert f"\n  {group}" in out
    assert "\nplanner:\n  name: random_shooting" in out  # the composed config follows


def test_cfg_job_composes_the_overrides_without_running(tmp_path):
    result = hierloco("train", "lat", "preset=tiny", "robot=daisy", f"run_dir={tmp_path / 'run'}", "--cfg", "job")
    assert result.returncode == 0, result.stderr
    assert "robot: daisy" in result.stdout and "preset_name: tiny" in result.stdout
    assert not (tmp_path / "run").exists()
    study = hierloco("study", "compare", "robots=[a1]", "--cfg", "job")
    assert study.returncode == 0, study.stderr
    assert "robots:\n- a1" in study.stdout


@pytest.mark.parametrize("args, said", [
    (["bogus"], "error: unknown command 'bogus'"),
    (["train", "nope"], "error: unknown method 'nope'"),
    (["train"], "error: name the method"),
    (["study", "./no_such_folder"], "error: study './no_such_folder': no such folder"),
    (["train", "lat", "preset=huge", "--cfg", "job"], "error: "),
])
def test_a_bad_command_is_one_line_and_exit_2(args, said):
    result = hierloco(*args)
    assert result.returncode == 2, (result.stdout, result.stderr)
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith(said), lines


def test_a_method_of_the_users_own_is_found_by_folder_and_by_module_path(tmp_path):
    """A copy of LAT's recipe in the user's folder (imports renamed) is a method: found by its folder, composed
    from its own config.yaml; a module path finds the shipped recipe."""
    mine = tmp_path / "code" / "my_lat"
    shutil.copytree(ROOT / "hierloco" / "recipes" / "lat", mine, ignore=shutil.ignore_patterns("__pycache__"))
    for path in mine.glob("*.py"):
        path.write_text(path.read_text().replace("hierloco.recipes.lat", "my_lat"))
    config = mine / "config.yaml"
    config.write_text(config.read_text().replace("settings: [normal]", "settings: [legs_disabled]"))
    result = hierloco("train", str(mine), "--cfg", "job", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "settings:\n- legs_disabled" in result.stdout
    by_module = hierloco("train", "hierloco.recipes.lat", "--cfg", "job", cwd=tmp_path)
    assert by_module.returncode == 0 and "settings:\n- normal" in by_module.stdout
    not_a_recipe = hierloco("train", str(tmp_path / "code"), cwd=tmp_path)
    assert not_a_recipe.returncode == 2 and "has no train.py" in not_a_recipe.stderr


def test_list_names_the_methods_studies_and_parts(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert "methods: ik, lat, lib, sac, sac_sac" in out
    assert "compare" in out.split("studies: ")[1].splitlines()[0]
    assert "planners: cem, exhaustive, mppi, random_shooting" in out
    assert "terrains: " in out


def test_the_recipes_are_part_of_the_package():
    import hierloco.recipes
    import hierloco.recipes.conf

    assert Path(hierloco.recipes.__file__).parent == ROOT / "hierloco" / "recipes"
    assert (Path(next(iter(hierloco.recipes.conf.__path__))) / "preset" / "tiny.yaml").is_file()


def refuses_bad_seeds_and_cores(names, folder) -> None:
    hierloco = [sys.executable, "-m", "hierloco.cli", "study"]
    for name in names:
        for override, said in (("ray.cores_per_job=0", "ray.cores_per_job must be an integer >= 1, got 0"),
                               ("seeds=[-1]", "seed -1 is not an integer >= 0")):
            done = subprocess.run([*hierloco, name, override, "dry_run=true", f"out_dir={folder}"], cwd=folder,
                                  capture_output=True, text=True, timeout=120)
            if override.startswith("seeds") and "Could not override 'seeds'" in done.stderr:
                continue  # a study without seeds (the tuning of IK's law runs its own)
            lines = done.stderr.strip().splitlines()
            assert done.returncode == 2 and len(lines) == 1 and said in lines[0], (name, override, done.stderr[-500:])
    assert not list(Path(folder).iterdir())


def test_a_study_refuses_a_bad_seed_and_cores_per_job_in_one_line_before_any_work(tmp_path):
    """A negative seed and a ``ray.cores_per_job`` below 1 are one line, exit status 2, nothing written (the damage
    study ran seed -1's jobs before; most studies did not check the cores)."""
    refuses_bad_seeds_and_cores(["adverse", "ablations"], tmp_path)


@pytest.mark.slow
def test_every_study_refuses_a_bad_seed_and_cores_per_job_in_one_line_before_any_work(tmp_path):
    """As above, for every registered study (a study without ``seeds`` is checked for the cores alone)."""
    from hierloco.pipeline.methods import STUDIES

    refuses_bad_seeds_and_cores(STUDIES.names(), tmp_path)
