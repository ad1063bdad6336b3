"""Docs are tests: every ``python`` block of ``docs/research.md`` runs as written, from a folder that holds a tiny
trained run where the blocks load theirs, and the docstring examples of every module of :mod:`hierloco.envs` and
:mod:`hierloco.components` run as ``pytest --doctest-modules`` would run them (the standard library's doctest)."""

import doctest
import importlib
import io
import os
import re
import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
RESEARCH = ROOT / "docs" / "research.md"
RUN_PATH = Path("outputs/lat/paper/a1_seed0")  # the run the blocks of docs/research.md load, relative to their folder
PACKAGES = ("hierloco/envs", "hierloco/components")


def python_blocks(path: Path) -> list[str]:
    """The code of every fenced ``python`` block of a Markdown file, in order."""
    return re.findall(r"^```python\n(.*?)^```", path.read_text(), re.S | re.M)


def modules_with_examples() -> dict[str, Path]:
    """The modules under :data:`PACKAGES` (packages included) whose source holds a docstring example (``>>>``), by
    name, with their file: found from the files, nothing imported."""
    modules = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            if ">>>" in path.read_text():
                parts = path.relative_to(ROOT).with_suffix("").parts
                modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return modules


BLOCKS = python_blocks(RESEARCH)
MODULES = modules_with_examples()
RENDERS = re.compile(r"mujoco\.Renderer|hierloco\.render\b")  # code that draws frames: it needs an OpenGL backend


@pytest.fixture(scope="module")
def docs_folder(tiny_lat_run, tmp_path_factory):
    """A folder holding the tiny LAT run (A1) at :data:`RUN_PATH`, as a user's folder holds their trained run."""
    folder = tmp_path_factory.mktemp("docs")
    shutil.copytree(tiny_lat_run, folder / RUN_PATH, ignore=shutil.ignore_patterns(".lock"))
    return folder


def test_research_md_has_its_blocks_and_each_loads_the_run_it_names():
    assert len(BLOCKS) >= 3
    for block in BLOCKS:
        for path in re.findall(r"load_run\(\"([^\"]+)\"", block):
            assert Path(path) == RUN_PATH, block


@pytest.mark.parametrize("index", range(len(BLOCKS)), ids=[f"block{i + 1}" for i in range(len(BLOCKS))])
def test_research_md_block_runs_as_written(index, docs_folder, monkeypatch):
    """The block alone, in a fresh namespace, as pasted into an interpreter in the run's folder."""
    monkeypatch.chdir(docs_folder)
    namespace = {"__name__": "__main__"}
    exec(compile(BLOCKS[index], f"{RESEARCH}, block {index + 1}", "exec"), namespace)
    assert type(namespace["run"]).__name__ == "TrainedRun"  # each block loads the run it uses


@pytest.fixture(scope="module")
def shared_expert_library():
    """Several modules' examples build the same small expert library (``build_expert_library("daisy", 3, ...)``,
    about 3 s each): the real function, each distinct call made once while these tests run."""
    import hierloco.components.expert_library as expert_library

    original, made = expert_library.build_expert_library, {}

    def build_once(*args, **kwargs):
        key = (args, tuple(sorted(kwargs.items())))
        try:
            hash(key)
        except TypeError:
            return original(*args, **kwargs)
        if key not in made:
            made[key] = original(*args, **kwargs)
        return made[key]

    expert_library.build_expert_library = build_once
    yield
    expert_library.build_expert_library = original


def test_the_examples_of_both_packages_are_found():
    assert {"hierloco.envs", "hierloco.envs.latent_env", "hierloco.components.planners.random_shooting"} <= set(MODULES)


@pytest.mark.parametrize("name", sorted(MODULES))
def test_docstring_examples_run(name, shared_expert_library):
    """The module's examples, each docstring in a copy of the module's globals, as ``--doctest-modules`` runs them;
    a module that renders frames is skipped where no rendering backend is installed (``hierloco.render_backend``)."""
    import hierloco  # noqa: F401  (chooses MUJOCO_GL before anything renders)

    if RENDERS.search(MODULES[name].read_text()) and os.environ.get("MUJOCO_GL") == "disable":
        pytest.skip(f"{name} renders frames and this machine has no rendering backend (MUJOCO_GL=disable)")
    module = importlib.import_module(name)
    runner, report = doctest.DocTestRunner(), io.StringIO()
    for test in doctest.DocTestFinder().find(module):
        runner.run(test, out=report.write)
    assert runner.tries > 0, f"{name}: no example found"
    assert runner.failures == 0, report.getvalue()
