"""``hierloco``: one command for every recipe, study and tool (``docs/cli.md``).

.. code-block:: text

    hierloco train lat robot=daisy preset=small        # a method's recipe, with its Hydra overrides
    hierloco train ./my_method seed=1                  # a method of your own: a folder (train.py, utils.py, config.yaml)
    hierloco evaluate run_dir=outputs/lat/paper/a1_seed0 planner=cem
    hierloco study compare 'robots=[a1]' 'seeds=[0,1,2]'
    hierloco verdicts --check                          # every claim of the paper, decided from the records
    hierloco robot-check path/to/robot.yaml            # a robot description and its expert parameters
    hierloco list                                      # the methods, studies and every registry's parts
    hierloco demo                                      # the robots and their gaits

A method or a study is found by name (the recipes shipped in :mod:`hierloco.recipes`, then the installed entry points
``hierloco.methods`` / ``hierloco.studies``), by a module path (``my_pkg.recipes.my_method``), or by a folder path.
``--help``, ``--cfg job`` and the other Hydra information flags compose the recipe's config without importing the
recipe, so they answer in about a second.

Example:
    >>> parse(["train", "lat", "preset=tiny"])
    ('train', 'lat', ['preset=tiny'])
    >>> parse(["verdicts", "--check"])
    ('verdicts', None, ['--check'])
"""

from __future__ import annotations

import sys

USAGE = """usage: hierloco COMMAND [ARGS...]

commands:
  train METHOD [overrides]     run a method's recipe (lat, lib, ik, sac, sac_sac, ...; a module path; a folder)
  evaluate run_dir=... [overrides]   evaluate a trained run on more tasks or planners, training nothing
  study STUDY [overrides]      run a study's jobs on Ray (compare, adverse, ablations, ...; a module path; a folder)
  verdicts [--check]           decide the paper's claims from the committed records
  robot-check ROBOT.yaml       check a robot description and search its expert parameters
  list                         the methods, studies, robots and registered parts
  demo                         the robots and their gaits

'hierloco train lat --help' lists a recipe's config groups and options; every command takes Hydra's overrides.
"""
COMMANDS = ("train", "evaluate", "study", "verdicts", "robot-check", "list", "demo")
NAMED = ("train", "study")  # the commands whose first argument names a recipe


def parse(argv: list[str]) -> tuple[str | None, str | None, list[str]]:
    """``(command, recipe, rest)`` of the command line (``recipe`` only for ``train`` and ``study``)."""
    if not argv or argv[0] in ("-h", "--help", "help"):
        return None, None, []
    command, rest = argv[0], list(argv[1:])
    if command in NAMED and rest and not rest[0].startswith("-") and "=" not in rest[0]:
        return command, rest[0], rest[1:]
    return command, None, rest


def _fail(message: str) -> int:
    print(f"error: {message}", file=sys.stderr)
    return 2


def _run_hydra_entry(entry, program: str, arguments: list[str]) -> int:
    """Runs a Hydra entry point as if ``program arguments`` were the command line; returns the exit status."""
    sys.argv = [program, *arguments]
    try:
        result = entry()
    except SystemExit as done:
        return done.code if isinstance(done.code, int) else (0 if done.code is None else 1)
    return 0 if result is None or not isinstance(result, int) else result


def _information_only(arguments: list[str]) -> bool:
    from hierloco.pipeline.entry import information_only

    return information_only(arguments)


def describe(recipe, command: str, arguments: list[str]) -> int:
    """Hydra's ``--help`` / ``--cfg`` / ``--info`` for ``recipe`` (a method or a study), composing its config only."""
    from hierloco.pipeline.entry import describe_config

    return describe_config(recipe.folder, f"hierloco {command} {recipe.name}", arguments)


def train(name: str | None, arguments: list[str]) -> int:
    from hierloco.pipeline.methods import METHODS, RecipeNotFound

    if name is None:
        return _fail(f"name the method: hierloco train METHOD [overrides] (methods: {', '.join(METHODS.names())})")
    try:
        method = METHODS.find(name)
    except RecipeNotFound as error:
        return _fail(str(error))
    if _information_only(arguments):
        return describe(method, "train", arguments)
    return _run_hydra_entry(method.main(), f"hierloco train {method.name}", arguments)


def study(name: str | None, arguments: list[str]) -> int:
    from hierloco.pipeline.methods import STUDIES, RecipeNotFound

    if name is None:
        return _fail(f"name the study: hierloco study STUDY [overrides] (studies: {', '.join(STUDIES.names())})")
    try:
        found = STUDIES.find(name)
    except RecipeNotFound as error:
        return _fail(str(error))
    if _information_only(arguments):
        return describe(found, "study", arguments)
    return _run_hydra_entry(found.main(), f"hierloco study {found.name}", arguments)


def evaluate(arguments: list[str]) -> int:
    from hierloco.pipeline.evaluate import evaluate_main

    return _run_hydra_entry(evaluate_main, "hierloco evaluate", arguments)


def verdicts(arguments: list[str]) -> int:
    from hierloco.recipes.verdicts import main

    return main(arguments)


def robot_check(arguments: list[str]) -> int:
    from hierloco.envs.robots.check.__main__ import main

    return main(arguments)


def demo(arguments: list[str]) -> int:
    from hierloco.demo import main

    sys.argv = ["hierloco demo", *arguments]
    main(arguments)
    return 0


def listing(arguments: list[str]) -> int:
    """Prints the methods, studies, robots and every registry's parts."""
    if arguments:
        return _fail(f"hierloco list takes no arguments (got {' '.join(arguments)})")
    from hierloco.components.com_model import MODELS
    from hierloco.components.planners import PLANNERS
    from hierloco.envs.low_level import LOW_LEVELS
    from hierloco.envs.robots import available_robots
    from hierloco.envs.tasks import TASKS
    from hierloco.envs.terrain import TERRAINS
    from hierloco.pipeline.methods import METHODS, STUDIES

    lines = [f"methods: {', '.join(METHODS.names())}", f"studies: {', '.join(STUDIES.names())}",
             f"robots: {', '.join(available_robots())}"]
    for registry in (PLANNERS, MODELS, TASKS, LOW_LEVELS, TERRAINS):
        lines.append(f"{registry.kind}s: {', '.join(registry.names())}")
    print("\n".join(lines))
    return 0


def main(argv: list[str] | None = None) -> int:
    """The ``hierloco`` console command; returns the exit status (2: a bad command line, one line)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    command, name, rest = parse(argv)
    if command is None:
        print(USAGE, end="")
        return 0
    if command not in COMMANDS:
        return _fail(f"unknown command {command!r} (choose from {', '.join(COMMANDS)}; hierloco --help)")
    if command == "train":
        return train(name, rest)
    if command == "study":
        return study(name, rest)
    import hierloco  # noqa: F401  (the rendering backend is chosen before anything loads MuJoCo)

    return {"evaluate": evaluate, "verdicts": verdicts, "robot-check": robot_check, "demo": demo,
            "list": listing}[command](rest)


def console() -> None:
    """The console-script entry point."""
    sys.exit(main())


__all__ = ["COMMANDS", "main", "parse"]


if __name__ == "__main__":
    console()
