"""Docs are tests: every code block of ``README.md`` and ``docs/*.md`` runs as written, and every module's docstring
examples under ``hierloco/`` run as ``pytest --doctest-modules`` would run them (the standard library's doctest).

- ``python`` blocks run, each alone in a fresh namespace, from a folder that holds what the block names: a copy of
  the tiny LAT run (:func:`tests.conftest.tiny_lat_run`) at every run directory it names
  (``outputs/lat/paper/a1_seed0``) and the robot description of ``docs/robots.md`` at ``path/to/<name>.yaml``.
  A block whose comments state what it prints (``docs/statistics.md``) prints that.
- ``bash`` blocks: a command of paper-scale work (``hierloco train``, ``study``, ``evaluate``: this one against a copy
  of the tiny run at the ``run_dir`` it names) is checked by composing its config (``--cfg job``, one job per point
  of a ``-m`` sweep), so every override parses and names real keys; what is quick runs for real (``hierloco
  verdicts --check``, ``hierloco list``, ``hierloco demo``, the description check of ``hierloco robot-check``); a
  block of plain shell and ``python`` commands runs as a script in a sandbox (its own ``HOME``); ``ray start``'s
  options are parsed by Ray's own command line, ``./run.sh``'s commands read from the script, a ``bash script.sh``
  syntax-checked. A command nothing here checks fails the test.
- ``toml`` and ``yaml`` blocks parse; their entry-point groups are hierloco's, a YAML block that says it is a file
  of the repository is that file.
- ``text`` blocks are illustrations (a folder tree, a terminal's output): the only blocks not run, and few.

``docs/extending.md`` is run by ``tests/test_extending.py`` (its examples are user modules and a run directory
placeholder, ``RUN_DIR``); the test here checks that that file still runs every one of its blocks.
"""

from __future__ import annotations

import contextlib
import doctest
import importlib
import io
import itertools
import os
import re
import shlex
import shutil
import subprocess
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
LANGUAGES = ("python", "bash", "toml", "yaml", "text")
ELSEWHERE = {"docs/extending.md": "tests/test_extending.py"}  # blocks run by that test file, as it says
MOST_TEXT_BLOCKS = 5  # illustrations that cannot run: keep them few
FENCE = re.compile(r"^```([^\n`]*)\n(.*?)^```[ \t]*$", re.S | re.M)
RUN_DIR = re.compile(r"\boutputs/[\w/.-]+?_seed\d+")  # a trained run a block names (given a copy of the tiny run)
ROBOT_FILE = re.compile(r"\bpath/to/\w+\.yaml")  # a robot description a block names (given docs/robots.md's)
ROBOT_DOC, ROBOT_FIXTURE = "docs/robots.md", ROOT / "tests" / "fixtures" / "quadruped20"
STATED_OUTPUT = ("docs/statistics.md",)  # docs whose python blocks state what each print prints, as a comment
RENDERS = re.compile(r"mujoco\.Renderer|hierloco\.render\b")  # code that draws frames: it needs an OpenGL backend


@dataclass(frozen=True)
class Block:
    doc: str  # relative to the repository
    line: int  # of the opening fence
    language: str
    code: str

    @property
    def id(self) -> str:
        return f"{self.doc}:{self.line}"


def blocks_of(path: Path) -> list[Block]:
    """The fenced code blocks of a Markdown file, in order."""
    text = path.read_text()
    return [Block(path.relative_to(ROOT).as_posix(), text.count("\n", 0, m.start()) + 1, m.group(1).strip(),
                  m.group(2)) for m in FENCE.finditer(text)]


BLOCKS = [block for doc in DOCS for block in blocks_of(doc)]
HERE = [block for block in BLOCKS if block.doc not in ELSEWHERE]


def of(language: str) -> list[Block]:
    return [block for block in HERE if block.language == language]


def ids(blocks) -> list[str]:
    return [block.id for block in blocks]


def test_every_block_names_a_language_and_few_are_illustrations():
    unnamed = [b.id for b in BLOCKS if b.language not in LANGUAGES]
    assert not unnamed, f"blocks without a language this test runs ({', '.join(LANGUAGES)}): {unnamed}"
    assert len(BLOCKS) >= 30 and {b.doc for b in BLOCKS} >= {"README.md", "docs/cli.md", "docs/research.md"}
    text = [b.id for b in BLOCKS if b.language == "text"]
    assert len(text) <= MOST_TEXT_BLOCKS, f"more illustrations than runnable blocks should allow: {text}"


def test_the_blocks_left_to_another_test_file_are_all_run_there():
    for doc, test_file in ELSEWHERE.items():
        source = (ROOT / test_file).read_text()
        counted = {language: len([b for b in BLOCKS if b.doc == doc and b.language == language])
                   for language in ("python", "bash")}
        checked = re.search(r'len\((?:python|blocks\("python"\))\) == (\d+) and len\(blocks\("bash"\)\) == (\d+)',
                            source)
        assert checked and tuple(map(int, checked.groups())) == (counted["python"], counted["bash"]), \
            f"{test_file} no longer checks that it runs every block of {doc} ({counted})"
        assert {b.language for b in BLOCKS if b.doc == doc} <= {"python", "bash"}


# --- a folder holding what a block names -------------------------------------------------------------------------


def robot_yaml() -> str:
    """The robot description that ``docs/robots.md`` shows (the only YAML block there)."""
    (block,) = [b for b in BLOCKS if b.doc == ROBOT_DOC and b.language == "yaml"]
    return block.code


def sandbox(folder: Path, text: str, request) -> Path:
    """``folder``, holding a copy of the tiny LAT run at every run directory ``text`` names and the robot of
    ``docs/robots.md`` (with its MJCF file) at every ``path/to/<name>.yaml``; returns it."""
    for run_dir in sorted(set(RUN_DIR.findall(text))):
        shutil.copytree(request.getfixturevalue("tiny_lat_run"), folder / run_dir,
                        ignore=shutil.ignore_patterns(".lock"))
    for robot in sorted(set(ROBOT_FILE.findall(text))):
        (folder / robot).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(ROBOT_FIXTURE / "quadruped20.xml", (folder / robot).parent)
        (folder / robot).write_text(robot_yaml())
    return folder


# the registries a block or an example may add to (docs/claims.md declares a study): each test leaves them as it
# found them, so what one registers reaches no later test
REGISTRIES = ("hierloco.components.planners:PLANNERS", "hierloco.components.com_model:MODELS",
              "hierloco.envs.tasks:TASKS", "hierloco.envs.low_level:LOW_LEVELS", "hierloco.envs.terrain:TERRAINS",
              "hierloco.pipeline.methods:METHODS", "hierloco.pipeline.methods:STUDIES", "hierloco.claims:CLAIMS")


@pytest.fixture
def registries(monkeypatch):
    """Every registry of :data:`REGISTRIES`, its built-in entries loaded first, restored after the test."""
    for path in REGISTRIES:
        module, name = path.split(":")
        registry = getattr(importlib.import_module(module), name)
        getattr(registry, "_load_entry_points", getattr(registry, "discover", None))()
        entries = registry._entries
        monkeypatch.setattr(registry, "_entries", {key: dict(value) if isinstance(value, dict) else value
                                                   for key, value in entries.items()})


# --- python -------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("block", of("python"), ids=ids(of("python")))
def test_python_block_runs_as_written(block, tmp_path, request, monkeypatch, registries):
    """The block alone, in a fresh namespace, as pasted into an interpreter in a folder holding what it names."""
    monkeypatch.chdir(sandbox(tmp_path, block.code, request))
    namespace, printed = {"__name__": "__main__"}, io.StringIO()
    with contextlib.redirect_stdout(printed):
        exec(compile(block.code, f"{ROOT / block.doc}, block at line {block.line}", "exec"), namespace)
    if "load_run(" in block.code:
        assert type(namespace["run"]).__name__ == "TrainedRun"  # it loaded the run it names
    if block.doc in STATED_OUTPUT:
        lines = printed.getvalue().splitlines()
        assert lines, "the block prints what its comments state"
        for line in lines:
            assert f"# {line}" in block.code, f"printed {line!r}, which no comment of the block states"


def test_the_research_blocks_load_the_run_the_doc_names():
    research = [b for b in HERE if b.doc == "docs/research.md" and b.language == "python"]
    assert len(research) >= 3
    for block in research:
        assert re.findall(r"load_run\(\"([^\"]+)\"", block.code) == ["outputs/lat/paper/a1_seed0"], block.code


def test_the_recipe_of_the_pipeline_doc_is_lat_s_train_py_in_short():
    """The ``train.py`` that ``docs/pipeline.md`` shows (run above: it makes the entry point) is LAT's: each of its
    lines, comments aside, is one of ``hierloco/recipes/lat/train.py``'s."""
    (block,) = [b for b in HERE if b.doc == "docs/pipeline.md" and b.language == "python"]
    shipped = {line.split("#")[0].strip() for line in (ROOT / "hierloco/recipes/lat/train.py").read_text().splitlines()}
    missing = [line for line in (raw.split("#")[0].strip() for raw in block.code.splitlines())
               if line and line not in shipped]
    assert not missing, f"lines of docs/pipeline.md's train.py that hierloco/recipes/lat/train.py lacks: {missing}"


# --- bash ---------------------------------------------------------------------------------------------------------

SCRIPT_PROGRAMS = {"mkdir", "chmod", "export", "python", "cd", "cp", "echo"}  # a block of these runs as a script


@dataclass(frozen=True)
class Command:
    block: Block
    line: int
    words: list  # the program and its arguments, the variables set before it dropped

    @property
    def id(self) -> str:
        return f"{self.block.doc}:{self.line}"


def commands_of(block: Block) -> list[Command]:
    """The commands of a bash block (continued lines joined, comments dropped)."""
    found, lines = [], block.code.split("\n")
    number = 0
    while number < len(lines):
        start, line = number, lines[number]
        while line.endswith("\\") and number + 1 < len(lines):
            number += 1
            line = line[:-1] + " " + lines[number]
        number += 1
        words = shlex.split(line, comments=True)
        while len(words) > 1 and re.fullmatch(r"[A-Za-z_]\w*=.*", words[0]):  # VARIABLE=value program ...
            words.pop(0)
        if words:
            found.append(Command(block, block.line + 1 + start, words))
    return found


def is_script(block: Block) -> bool:
    return all(command.words[0] in SCRIPT_PROGRAMS for command in commands_of(block))


SCRIPTS = [block for block in of("bash") if is_script(block)]
COMMANDS = [command for block in of("bash") if not is_script(block) for command in commands_of(block)]


def hierloco(*arguments: str) -> tuple[int, str, str]:
    """``hierloco arguments`` in this process: exit status, stdout, stderr."""
    from hierloco.cli import main

    out, err, argv = io.StringIO(), io.StringIO(), list(sys.argv)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main(list(arguments))
            except SystemExit as done:
                code = done.code if isinstance(done.code, int) else (0 if done.code is None else 1)
    finally:
        sys.argv = argv
    return code, out.getvalue(), err.getvalue()


def sweep_jobs(arguments: list[str]) -> list[list[str]]:
    """The jobs a ``-m`` sweep over ``arguments`` runs (Hydra's grammar: ``a=1,2 b=x,y`` gives four), without the
    flag; ``[arguments]`` when there is no ``-m``."""
    if not {"-m", "--multirun"} & set(arguments):
        return [arguments]
    from hydra.core.override_parser.overrides_parser import OverridesParser

    flags = [a for a in arguments if a.startswith("-") and a not in ("-m", "--multirun")]
    overrides = [a for a in arguments if not a.startswith("-")]
    choices = []
    for text, parsed in zip(overrides, OverridesParser.create().parse_overrides(overrides)):
        if parsed.is_sweep_override():
            key = text.split("=", 1)[0]
            choices.append([f"{key}={value}" for value in parsed.sweep_string_iterator()])
        else:
            choices.append([text])
    return [[*job, *flags] for job in itertools.product(*choices)]


USER_RECIPES = {"./my_method": "lat", "my_package.recipes.my_method": "lat", "./my_study": "compare"}  # docs/cli.md


def own_recipes(folder: Path, words: list[str], monkeypatch) -> None:
    """The user's recipes of :data:`USER_RECIPES` that a command names, made in ``folder`` (copies of the shipped
    recipe, imports renamed; a module path's packages on ``sys.path``)."""
    for name in [name for name in sys.modules if name.split(".")[0] in ("my_package", "my_method", "my_study")]:
        del sys.modules[name]  # another test's copy
    for reference, source in USER_RECIPES.items():
        if reference not in words:
            continue
        target = Path(reference.replace(".", "/") if not reference.startswith("./") else reference)
        shutil.copytree(ROOT / "hierloco" / "recipes" / source, folder / target,
                        ignore=shutil.ignore_patterns("__pycache__"))
        for path in (folder / target).glob("*.py"):
            path.write_text(path.read_text().replace(f"hierloco.recipes.{source}", ".".join(target.parts)))
        if not reference.startswith("./"):  # a module path: its packages, importable from the folder
            for parent in list(target.parents)[:-1]:
                (folder / parent / "__init__.py").write_text("")
            monkeypatch.syspath_prepend(str(folder))


VERDICTS: dict = {}


def check(command: Command) -> None:
    """Checks ``command`` as the module docstring says (running it where that is quick), from the current folder."""
    words = command.words
    program, rest = words[0], words[1:]
    if program == "hierloco-robot-check":
        program, rest = "hierloco", ["robot-check", *rest]
    if program == "hierloco":
        verb, arguments = (rest[0], rest[1:]) if rest else ("", [])
        if verb in ("train", "study", "evaluate"):  # evaluate: a copy of the tiny run at the run_dir it names
            named, overrides = ([], arguments) if verb == "evaluate" else (arguments[:1], arguments[1:])
            assert named or verb == "evaluate", f"hierloco {verb} names no recipe"
            for job in sweep_jobs(overrides):
                code, out, err = hierloco(verb, *named, *job, "--cfg", "job")
                assert code == 0, f"hierloco {verb} {' '.join(named + job)} --cfg job: {err.strip()}"
                assert isinstance(yaml.safe_load(out), dict), out[-2000:]
        elif verb == "verdicts":  # 'hierloco verdicts' rewrites results/: its --check computes the same pages
            if "check" not in VERDICTS:  # in a process of its own: what this one registered is not the studies'
                VERDICTS["check"] = subprocess.run([sys.executable, "-m", "hierloco.cli", "verdicts", "--check"],
                                                   cwd=ROOT, capture_output=True, text=True, timeout=300)
            done = VERDICTS["check"]
            assert done.returncode == 0, done.stdout + done.stderr
        elif verb == "robot-check":  # the search takes minutes: the description check, in milliseconds
            code, out, err = hierloco(*rest, "--description-only")
            assert code == 0 and "description: ok" in out, out + err
        elif verb in ("list", "demo"):
            code, out, err = hierloco(*rest)
            assert code == 0 and out.strip(), err
        else:
            pytest.fail(f"no check for 'hierloco {verb}': add one to tests/test_docs.py")
    elif program == "./run.sh":
        script = (ROOT / "run.sh").read_text()
        verbs = re.findall(r"^\s+(\w+)\)", script.split('case "$cmd" in', 1)[1], re.M)
        assert rest and rest[0] in verbs, f"./run.sh has no command {rest[:1]} (it has {verbs})"
    elif program == "bash":
        assert (ROOT / rest[0]).is_file(), rest[0]
        subprocess.run(["bash", "-n", str(ROOT / rest[0])], check=True)
    elif program == "ray":
        from ray.scripts.scripts import cli

        ray_command = cli.commands[rest[0]]
        ray_command.make_context(rest[0], rest[1:])  # raises click's UsageError on an unknown option or bad value
    else:
        pytest.fail(f"no check for the command {' '.join(words)!r}: add one to tests/test_docs.py")


@pytest.mark.parametrize("command", COMMANDS, ids=[c.id for c in COMMANDS])
def test_bash_command_composes_or_runs(command, tmp_path, request, monkeypatch, registries):
    own_recipes(sandbox(tmp_path, " ".join(command.words), request), command.words, monkeypatch)
    monkeypatch.chdir(tmp_path)
    check(command)


@pytest.mark.parametrize("line, said", [
    ("hierloco train lat planner.num_candidate=10", "Could not override 'planner.num_candidate'"),
    ("hierloco study compare -m 'seeds=[0],[1]' robot=a1", "Could not override 'robot'"),
    ("hierloco train nope", "unknown method 'nope'"),
    ("./run.sh deploy", "./run.sh has no command"),
    ("make paper", "no check for the command"),
])
def test_a_command_the_docs_get_wrong_fails_its_check(line, said, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    block = Block("docs/example.md", 1, "bash", line + "\n")
    with pytest.raises((AssertionError, pytest.fail.Exception), match=re.escape(said)):
        check(commands_of(block)[0])


@pytest.mark.parametrize("block", SCRIPTS, ids=ids(SCRIPTS))
def test_bash_script_runs_as_written(block, tmp_path):
    """A block of plain shell and ``python`` commands runs as a bash script, from a folder holding copies of the
    repository's files it names (``results/...``), with a home of its own and the project's Python first."""
    for name in sorted(set(re.findall(r"\bresults/[\w/.-]+", block.code))):
        shutil.copytree(ROOT / name, tmp_path / name)
    (tmp_path / "home").mkdir()
    env = {**os.environ, "HOME": str(tmp_path / "home"), "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}"}
    done = subprocess.run(["bash", "-euo", "pipefail", "-c", block.code], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    if "hierloco.pipeline.records sign" in block.code:  # docs/pipeline.md: every record it names is signed
        signed = len(list(tmp_path.glob("results/**/record.json")))
        assert signed >= 10 and f"signed {signed} record(s)" in done.stdout, done.stdout


# --- toml, yaml ---------------------------------------------------------------------------------------------------


def entry_point_groups() -> set[str]:
    """The entry-point groups hierloco reads."""
    from hierloco.components.com_model import MODELS
    from hierloco.components.planners import PLANNERS
    from hierloco.envs.low_level import LOW_LEVELS
    from hierloco.envs.robots.registry import ENTRY_POINT_GROUP
    from hierloco.envs.tasks import TASKS
    from hierloco.envs.terrain import TERRAINS
    from hierloco.pipeline.methods import METHODS, STUDIES

    return {ENTRY_POINT_GROUP} | {r.group for r in (MODELS, PLANNERS, LOW_LEVELS, TASKS, TERRAINS, METHODS, STUDIES)}


@pytest.mark.parametrize("block", of("toml"), ids=ids(of("toml")))
def test_toml_block_parses_and_names_hierloco_s_entry_point_groups(block):
    groups = tomllib.loads(block.code).get("project", {}).get("entry-points", {})
    assert set(groups) <= entry_point_groups(), sorted(set(groups) - entry_point_groups())
    for group, entries in groups.items():
        assert entries and all(re.fullmatch(r"[\w.]+(:[\w.]+)?", value) for value in entries.values()), group


@pytest.mark.parametrize("block", of("yaml"), ids=ids(of("yaml")))
def test_yaml_block_parses_and_is_the_file_it_says_it_is(block):
    data = yaml.safe_load(block.code)
    assert isinstance(data, dict)
    before = (ROOT / block.doc).read_text().splitlines()[max(0, block.line - 4):block.line - 1]
    named = re.findall(r"`(tests/[\w/.-]+\.yaml)`", " ".join(before))
    for path in named:
        assert data == yaml.safe_load((ROOT / path).read_text()), f"{block.id} is not {path}"
    if block.doc == ROBOT_DOC:
        assert named, "docs/robots.md's YAML block names the fixture it is"


# --- docstring examples -------------------------------------------------------------------------------------------


def modules_with_examples() -> dict[str, Path]:
    """Every module under ``hierloco/`` (packages included) whose source holds a docstring example (``>>>``), by
    name, with its file: found from the files, nothing imported."""
    modules = {}
    for path in sorted((ROOT / "hierloco").rglob("*.py")):
        if "__pycache__" not in path.parts and ">>>" in path.read_text():
            parts = path.relative_to(ROOT).with_suffix("").parts
            modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return modules


MODULES = modules_with_examples()


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


def test_the_examples_of_every_part_of_the_package_are_found():
    assert {"hierloco.envs", "hierloco.envs.latent_env", "hierloco.components.planners.random_shooting",
            "hierloco.pipeline.methods", "hierloco.recipes.compare.run", "hierloco.results", "hierloco.stats",
            "hierloco.cli", "hierloco.trained"} <= set(MODULES)


@pytest.mark.parametrize("name", sorted(MODULES))
def test_docstring_examples_run(name, shared_expert_library, tmp_path, request, monkeypatch, registries):
    """The module's examples, each docstring in a copy of the module's globals, as ``--doctest-modules`` runs them,
    from a folder holding what they name (a trained run); a module that renders frames is skipped where no
    rendering backend is installed (``hierloco.render_backend``)."""
    import hierloco  # noqa: F401  (chooses MUJOCO_GL before anything renders)

    source = MODULES[name].read_text()
    if RENDERS.search(source) and os.environ.get("MUJOCO_GL") == "disable":
        pytest.skip(f"{name} renders frames and this machine has no rendering backend (MUJOCO_GL=disable)")
    monkeypatch.chdir(sandbox(tmp_path, source, request))
    module = importlib.import_module(name)
    runner, report = doctest.DocTestRunner(), io.StringIO()
    for test in doctest.DocTestFinder().find(module):
        runner.run(test, out=report.write)
    assert runner.tries > 0, f"{name}: no example found"
    assert runner.failures == 0, report.getvalue()
