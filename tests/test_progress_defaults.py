"""Progress bars: off by default in the library functions (a user's own code and logs stay free of bars), on in the
recipes (``progress: true`` in their runtime config, passed to every stage as ``run.progress``)."""

import importlib
import inspect

import numpy as np
import pytest

LIBRARY_FUNCTIONS = [
    ("hierloco.components.expert_library", "build_expert_library"),
    ("hierloco.components.gait_policy", "train_gait_policy"),
    ("hierloco.components.gait_policy_fit", "fit_gait_policy"),
    ("hierloco.components.dynamics_data", "collect_transitions"),
    ("hierloco.components.com_model", "train_com_model"),
    ("hierloco.components.sac", "train_sac"),
    ("hierloco.components.sac_low_level", "train_sac_low_level"),
    ("hierloco.components.evaluation", "run_task"),
]


@pytest.mark.parametrize("module, name", LIBRARY_FUNCTIONS)
def test_library_functions_show_no_bar_unless_asked(module, name):
    function = getattr(importlib.import_module(module), name)
    assert inspect.signature(function).parameters["progress"].default is False


def test_a_library_call_prints_no_bar_by_default_and_one_when_asked(capfd):
    from hierloco.components.gait_policy import train_gait_policy

    targets = np.zeros((2, 100, 12))
    train_gait_policy(targets, hidden=8, epochs=2)
    assert capfd.readouterr().err == ""
    train_gait_policy(targets, hidden=8, epochs=2, progress=True)
    assert "gait policy" in capfd.readouterr().err


def test_recipes_show_bars_by_default():
    from hierloco.pipeline.config import compose_recipe

    assert compose_recipe("lat", ["preset=tiny"]).progress is True
    assert compose_recipe("lat", ["preset=tiny", "progress=false"]).progress is False
