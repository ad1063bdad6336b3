"""SAC baseline: the LAT low level (experts -> latent gait policy), then per task a goal-conditioned SAC high level
over z, trained on half of the task's targets and tested on all of them (and on the generalisation tasks).

    python recipes/sac/train.py                       # paper scale, A1, seed 0
    python recipes/sac/train.py preset=small robot=daisy
"""

from __future__ import annotations

import hierloco  # noqa: F401  (first: headless MuJoCo rendering is set before anything loads MuJoCo)
import sys
import time
from pathlib import Path

import hydra
from omegaconf import DictConfig

sys.path[:0] = [str(Path(__file__).resolve().parent), str(Path(__file__).resolve().parents[1])]
import utils  # noqa: E402  (this recipe's factories)
from common import latent, pipeline  # noqa: E402
from hierloco.components.sac import SACAgent  # noqa: E402


@hydra.main(config_path=".", config_name="config", version_base=None)
def main(cfg: DictConfig) -> None:
    utils.validate(cfg)
    start = time.perf_counter()
    run, logger = pipeline.open_run(cfg, utils.METHOD)
    reports: dict = {}
    low_level = latent.prepare(cfg, run, logger, reports).make(1)  # z -> pi(., z): stateless, shared
    tasks = pipeline.make_tasks(cfg)
    episodes = []
    for name in cfg.eval.tasks:
        task = tasks[name]
        config = {"low_level": latent.policy_config(cfg), "task": name, "train_task": pipeline.section(cfg, "eval")
                  ["tasks"][name], **pipeline.section(cfg, "sac")}
        trained = run.stage(f"sac_{name}", config,
                            lambda: utils.train_sac(cfg, low_level, utils.training_task(task), logger, name),
                            lambda result, path: result[0].save(path, result[1]), SACAgent.load, f"sac_{name}.pt")
        agent, reports[f"sac_{name}"] = trained
        # every task of the same kind (the main one and its generalisation variants) with this policy
        same_kind = [n for n, t in tasks.items() if type(t) is type(task)]
        eval_config = {"agent": config, "eval": pipeline.eval_section(cfg), "tasks": same_kind}
        episodes += run.stage(f"evaluation_{name}", eval_config,
                              lambda: [row for n in same_kind
                                       for row in utils.evaluate_sac(cfg, run, agent, low_level, n, tasks[n], logger)],
                              pipeline.save_json, pipeline.load_json, f"evaluation_{name}.json")
    pipeline.finish_run(cfg, utils.METHOD, run, logger, episodes, reports, start)


if __name__ == "__main__":
    main()
