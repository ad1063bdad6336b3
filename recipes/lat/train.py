"""LAT end to end: experts -> latent gait policy -> CoM dynamics data -> dynamics model -> MPC on every task.

    python recipes/lat/train.py                       # paper scale, A1, seed 0
    python recipes/lat/train.py preset=small robot=daisy settings=[normal,legs_disabled]
    python recipes/lat/train.py -m seed=0,1,2         # a sweep (Hydra multirun)

Each stage is cached in the run directory with its config and reused when the config matches.
"""

from __future__ import annotations

import hierloco  # noqa: F401  (first: headless MuJoCo rendering is set before anything loads MuJoCo)
import sys
from pathlib import Path

import hydra
from omegaconf import DictConfig

sys.path[:0] = [str(Path(__file__).resolve().parent), str(Path(__file__).resolve().parents[1])]
import utils  # noqa: E402  (this recipe's factories)
from common import pipeline  # noqa: E402  (the model-based pipeline shared by LAT, LIB and IK)


@hydra.main(config_path=".", config_name="config", version_base=None)
def main(cfg: DictConfig) -> None:
    utils.validate(cfg)
    pipeline.run_pipeline(cfg, utils.METHOD, utils.prepare)


if __name__ == "__main__":
    main()
