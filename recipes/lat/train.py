"""LAT end to end: experts -> latent gait policy -> CoM dynamics data -> dynamics model -> MPC on every task.

    python recipes/lat/train.py                       # paper scale, A1, seed 0
    python recipes/lat/train.py preset=small robot=daisy settings=[normal,legs_disabled]
    python recipes/lat/train.py -m seed=0,1,2         # a sweep (Hydra multirun)

Each stage is cached in the run directory with its config and reused when the config matches.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import hydra
import torch
from omegaconf import DictConfig, OmegaConf

sys.path.insert(0, str(Path(__file__).resolve().parent))
import utils  # noqa: E402  (the recipe's factories, beside this file)

from hierloco.io import write_text  # noqa: E402
from hierloco.results import write_results  # noqa: E402
from hierloco.runs import RunDirectory  # noqa: E402


@hydra.main(config_path=".", config_name="config", version_base=None)
def main(cfg: DictConfig) -> None:
    utils.validate(cfg)
    torch.manual_seed(cfg.seed)
    start = time.perf_counter()
    run = RunDirectory(cfg.run_dir)
    logger = utils.make_logger(cfg, run)

    library = utils.stage_experts(cfg, run)
    trained = utils.stage_gait_policy(cfg, run, library)
    low_level = utils.make_low_level(cfg, trained)
    check = utils.stage_gait_policy_check(cfg, run, low_level, library, trained)
    reports = {"experts": library.metadata, "gait_policy": trained.metadata, "gait_policy_check": check}
    logger.log_metrics({"train/gait_policy/rmse": trained.metadata["rmse"],
                        "eval/gait_policy/reproduced_fraction": check["reproduced_fraction"],
                        "eval/gait_policy/interpolation_walks": check["interpolation_walks"],
                        "eval/gait_policy/interpolation_between": check["interpolation_between"]})

    episodes = []
    for setting in cfg.settings:
        data = utils.stage_dynamics_data(cfg, run, low_level, setting)
        model = utils.stage_dynamics_model(cfg, run, data, setting)
        reports[f"dynamics_model_{setting}"] = model.metadata
        reports[f"dynamics_data_{setting}"] = data.metadata
        for name, rmse in zip(("dx", "dy", "dyaw", "vx", "vy"), model.metadata["heldout_rmse"]):
            logger.log_scalar(f"train/dynamics_{setting}/heldout_rmse_{name}", rmse)
        eval_config = {"dynamics": utils.dynamics_config(cfg, setting), "planner": utils._section(cfg, "planner"),
                       "eval": utils._section(cfg, "eval")}
        episodes += run.stage(f"evaluation_{setting}", eval_config,
                              lambda: utils.evaluate(cfg, run, low_level, model, setting, logger),
                              utils._save_json, utils._load_json, f"evaluation_{setting}.json")
    utils.latent_map(cfg, run, low_level)

    reports["stage_seconds"] = run.timings
    reports["reused_stages"] = run.reused
    reports["total_seconds"] = time.perf_counter() - start
    utils.stage_report(run, reports)
    for stage, seconds in run.timings.items():
        logger.log_scalar(f"time/{stage}", seconds)
    table = write_results(run.path, episodes)
    write_text(run.path / "config.yaml", OmegaConf.to_yaml(cfg, resolve=True))
    logger.close()
    print(f"\nLAT on {cfg.robot} (seed {cfg.seed}), run directory {run.path}\n")
    print(table)
    print("stage wall-clock (s): " + ", ".join(f"{k} {v:.1f}" + (" (cached)" if run.reused[k] else "")
                                              for k, v in run.timings.items()))
    print(f"figures in {run.path / 'figures'}/, results in {run.path / 'results.csv'}")


if __name__ == "__main__":
    main()
