"""Evaluate a trained run on any tasks: ``python recipes/<method>/evaluate.py run_dir=... [overrides]``.

The run's own config (``<run_dir>/config.yaml``, written when training finished) is the base; the overrides may
change only what evaluation depends on (the ``eval`` and ``planner`` sections, ``settings``, threads, device,
progress, logging) and use Hydra's override grammar (``+eval.tasks.goal_reaching_5m={task: goal_reaching,
radius: 5}``, ``planner.name=cem``). The recipe then runs with every training stage loaded (a missing one is an
error: nothing is ever trained here) and each evaluation cached per task and planner; tables, figures and videos go
to ``<run_dir>/evaluations/<name>/`` (``name=...``, default a digest of the evaluation config).

Example:
    python recipes/lat/train.py preset=small run_dir=runs/a1
    python recipes/lat/evaluate.py run_dir=runs/a1 '+eval.tasks.goal_reaching_5m={task: goal_reaching, radius: 5}'
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Callable

from recipes.common.entry import EXIT_INTERRUPTED, EXIT_USER_ERROR, one_line, user_errors

EVALUATION_KEYS = ("eval", "planner", "settings", "nthread", "device", "progress", "logger")
USAGE = "usage: python recipes/<method>/evaluate.py run_dir=<trained run> [name=<label>] [eval/planner overrides]"


def _split(arguments: list[str]) -> tuple[str | None, str | None, list[str]]:
    run_dir = name = None
    overrides = []
    for argument in arguments:
        if argument.startswith("run_dir="):
            run_dir = argument.split("=", 1)[1]
        elif argument.startswith("name="):
            name = argument.split("=", 1)[1]
        else:
            overrides.append(argument)
    return run_dir, name, overrides


def _key_of(override: str) -> str:
    return override.split("=", 1)[0].lstrip("+~").split(".")[0]


def evaluation_config(run_dir: str, overrides: list[str]):
    """The trained run's config with the evaluation ``overrides`` applied (refusing any other key)."""
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra

    from recipes.common.config import ConfigError

    config = Path(run_dir) / "config.yaml"
    if not config.exists():
        raise ConfigError(f"{run_dir} has no config.yaml: it is not a finished training run (run train.py first)")
    bad = [o for o in overrides if _key_of(o) not in EVALUATION_KEYS]
    if bad:
        raise ConfigError(f"evaluate.py changes only {', '.join(EVALUATION_KEYS)}; got {', '.join(bad)} (a "
                          "training change needs train.py and another run_dir)")
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(config.parent.resolve()), version_base=None):
        return compose(config_name="config", overrides=overrides)


def evaluate_main(body: Callable) -> None:
    """Runs ``body(cfg)`` (a recipe's ``main``) in evaluation mode; exits 2 on a user error, printing one line."""
    from hydra.errors import HydraException
    from omegaconf import OmegaConf, open_dict

    from hierloco.runs import digest
    from recipes.common import run as run_module
    from recipes.common.config import ConfigError

    run_dir, name, overrides = _split(sys.argv[1:])
    try:
        if run_dir is None:
            raise ConfigError(f"give the trained run: run_dir=... ({USAGE})")
        cfg = evaluation_config(run_dir, overrides)
        with open_dict(cfg):
            cfg.run_dir = run_dir
        label = name or digest(OmegaConf.to_container(cfg, resolve=True))[:8]
        run_module.EVALUATE["out"] = str(Path(run_dir) / "evaluations" / label)
        os.environ.setdefault("HYDRA_FULL_ERROR", "1")
        body(cfg)
    except KeyboardInterrupt:
        print("interrupted: finished evaluations are kept; run the same command again to resume", file=sys.stderr)
        sys.exit(EXIT_INTERRUPTED)
    except (HydraException, *user_errors()) as error:
        print(f"error: {one_line(error)}", file=sys.stderr)
        sys.exit(EXIT_USER_ERROR)
