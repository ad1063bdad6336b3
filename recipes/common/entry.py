"""The entry point of the model-based recipes (LAT, LIB, IK): a Hydra ``main`` over the recipe's own
``config.yaml`` and ``utils.py`` (``validate``, ``METHOD``, ``prepare``), running the shared pipeline."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import hydra
from omegaconf import DictConfig

from common import pipeline


def load_recipe_utils(recipe_file: str):
    """The ``utils.py`` beside ``recipe_file``, as a module of its own name (recipes do not share one ``utils``)."""
    folder = Path(recipe_file).resolve().parent
    spec = importlib.util.spec_from_file_location(f"{folder.name}_utils", folder / "utils.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def model_based_main(recipe_file: str):
    """``main()`` for the recipe whose ``train.py`` is ``recipe_file``."""
    folder = Path(recipe_file).resolve().parent
    utils = load_recipe_utils(recipe_file)

    @hydra.main(config_path=str(folder), config_name="config", version_base=None)
    def main(cfg: DictConfig) -> None:
        utils.validate(cfg)
        pipeline.run_pipeline(cfg, utils.METHOD, utils.prepare)

    return main
