"""LIB end to end: experts -> CoM dynamics over the expert index -> exhaustive MPC over the experts.

    python recipes/lib/train.py                       # paper scale, A1, seed 0
    python recipes/lib/train.py preset=small robot=daisy
    python recipes/lib/train.py -m seed=0,1,2         # a sweep (Hydra multirun)

Each stage is cached in the run directory with its config and reused when the config matches.
"""

from __future__ import annotations

import hierloco  # noqa: F401  (first: headless MuJoCo rendering is set before anything loads MuJoCo)
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from common.entry import model_based_main  # noqa: E402  (the pipeline shared by LAT, LIB and IK)

main = model_based_main(__file__)  # Hydra over this folder's config.yaml, with this folder's utils.py

if __name__ == "__main__":
    main()
