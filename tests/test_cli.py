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
