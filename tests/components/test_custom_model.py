"""A user's CoM dynamics model (one :class:`CoMModel` subclass) keeps what it was trained with: its options are
recorded as it is built, saved with its checkpoint and given back by ``TrainedCoMModel.load``, ``load_run``,
``hierloco evaluate`` and the exporter, with no method of the user's; option names cannot shadow the training
settings; and in a recipe, a model named by import path or by registered name trains, reloads with bit-identical
predictions and re-evaluates to the same evaluation."""

import importlib
import inspect
import json
import shutil
import sys

import numpy as np
import pytest
import torch
from torch import nn

import hierloco
from hierloco.components.com_ensemble import CoMEnsembleModel
from hierloco.components.com_model import (CHECKPOINT_FORMAT, CHECKPOINT_KIND, MODELS, RESERVED_OPTIONS,
                                           CoMDynamicsModel, CoMModel, TrainedCoMModel, train_com_model)
from hierloco.io import ArtifactError, load_checkpoint
from hierloco.results import TaskEvaluation
from tests.runner import run_in_process

# The user's model, as a file of their own package (under 40 lines): a residual network whose option scales the skip.
USER_MODEL = '''\
import torch
from torch import nn

from hierloco.components.com_model import CoMModel


class ResMLP(CoMModel):
    """A 2-layer tanh network plus ``skip_scale`` times a linear skip, on the standardised inputs."""

    def __init__(self, action_dim: int, hidden: int = 64, *, skip_scale: float = 1.0, **statistics):
        super().__init__(action_dim, hidden, **statistics)
        self.skip_scale = float(skip_scale)
        self.body = nn.Sequential(nn.Linear(self.num_inputs, hidden), nn.Tanh(), nn.Linear(hidden, 5))
        self.skip = nn.Linear(self.num_inputs, 5)

    def standardised_delta(self, x: torch.Tensor) -> torch.Tensor:
        return self.body(x) + self.skip_scale * self.skip(x)
'''
PATH = "my_models.residual:ResMLP"


@pytest.fixture
def user_package(tmp_path, monkeypatch):
    """``my_models/residual.py`` (:data:`USER_MODEL`) in a folder on ``sys.path``, forgotten afterwards by Python
    and by the registry."""
    package = tmp_path / "user" / "my_models"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "residual.py").write_text(USER_MODEL)
    monkeypatch.syspath_prepend(str(package.parent))
    yield package.parent
    MODELS.unregister(PATH)
    for module in ("my_models.residual", "my_models"):
        sys.modules.pop(module, None)


def _transitions(num=300, seed=0):
    rng = np.random.default_rng(seed)
    state, action = rng.normal(size=(num, 5)), rng.uniform(-1, 1, size=(num, 2))
    return state, action, state + 0.1 * np.tanh(rng.normal(size=(num, 5)) + action.sum(1, keepdims=True))


def _predictions(model, seed=0):
    generator = torch.Generator().manual_seed(seed)
    state = torch.randn(64, 5, generator=generator)
    action = torch.rand(64, model.action_dim, generator=generator) * 2 - 1
    with torch.no_grad():
        return model.predict(state, action)


# ---------------------------------------------------------------------------------------------------- the contract
def test_the_built_in_models_are_com_models_recording_what_they_were_built_with():
    assert issubclass(CoMDynamicsModel, CoMModel) and issubclass(CoMEnsembleModel, CoMModel)
    assert CoMDynamicsModel(action_dim=3, hidden=8).config() == {"action_dim": 3, "hidden": 8}
    ensemble = CoMEnsembleModel(3, 8, members=2, head="deterministic")
    assert ensemble.options == {"hidden": 8, "members": 2, "head": "deterministic", "propagation": "ts",
                                "member_data": "bootstrap"}


def test_a_user_model_trains_saves_and_loads_with_its_option_and_no_method_of_its_own(user_package, tmp_path):
    """The module's class, named by import path: trained with ``skip_scale=0.5``, its checkpoint gives back a model
    with that option and bit-identical predictions; the same weights with the default option predict otherwise."""
    cls = MODELS.import_path(PATH, base=CoMModel)
    assert len(inspect.getsource(cls).splitlines()) < 40 and "def config" not in USER_MODEL
    state, action, next_state = _transitions()
    trained = train_com_model(state, action, next_state, model=PATH, hidden=16, max_epochs=3, skip_scale=0.5)
    assert trained.model.options == {"hidden": 16, "skip_scale": 0.5}
    assert trained.metadata["model_options"] == {"hidden": 16, "skip_scale": 0.5}
    trained.save(tmp_path / "model.pt")
    loaded = TrainedCoMModel.load(tmp_path / "model.pt")
    assert type(loaded.model) is cls and loaded.model.skip_scale == 0.5 and loaded.name == PATH
    assert torch.equal(_predictions(loaded.model), _predictions(trained.model))
    default = cls(2, 16)
    default.load_state_dict(trained.model.state_dict())
    assert not torch.allclose(_predictions(default), _predictions(trained.model))  # the option matters


def test_a_checkpoint_naming_an_import_path_loads_only_when_trusted(user_package, tmp_path):
    MODELS.import_path(PATH, base=CoMModel)
    state, action, next_state = _transitions()
    train_com_model(state, action, next_state, model=PATH, hidden=8, max_epochs=1,
                    skip_scale=0.25).save(tmp_path / "model.pt")
    MODELS.unregister(PATH)
    sys.modules.pop("my_models.residual")
    with pytest.raises(ArtifactError, match=r"import path read from the file.*trust_imports=\['my_models"):
        TrainedCoMModel.load(tmp_path / "model.pt")
    assert "my_models.residual" not in sys.modules
    loaded = TrainedCoMModel.load(tmp_path / "model.pt", trust_imports=[PATH])
    assert loaded.model.options == {"hidden": 8, "skip_scale": 0.25}


def test_options_passed_on_by_keyword_and_inherited_constructors_are_recorded():
    class Wider(CoMDynamicsModel):  # no constructor of its own: the MLP's options
        pass

    class Scaled(CoMDynamicsModel):  # its option, and the base's passed on through **options
        def __init__(self, action_dim, *, gain: float = 1.0, **options):
            super().__init__(action_dim, **options)
            self.gain = gain

        def standardised_delta(self, x):
            return self.gain * super().standardised_delta(x)

    assert Wider(2, hidden=12).options == {"hidden": 12}
    scaled = Scaled(2, hidden=6, gain=0.5, input_mean=torch.zeros(4))
    assert scaled.options == {"gain": 0.5, "hidden": 6}
    again = Scaled(**scaled.config())
    again.load_state_dict(scaled.state_dict())
    assert torch.equal(_predictions(again), _predictions(scaled))


def test_an_option_named_like_a_training_setting_is_refused_when_the_class_is_defined():
    with pytest.raises(TypeError, match="option lr named like train_com_model's own settings"):
        class Clashing(CoMModel):  # noqa: F841
            def __init__(self, action_dim, hidden=8, *, lr: float = 0.1, **statistics):
                super().__init__(action_dim, hidden, **statistics)


def test_the_reserved_names_are_the_training_settings_of_the_function_and_the_pipeline():
    """:data:`RESERVED_OPTIONS` is every name that train_com_model and the dynamics config section use themselves
    (``hidden``, the width every model takes, is both): nothing else, nothing left out."""
    from hierloco.pipeline.config import DYNAMICS_KEYS
    from hierloco.pipeline.stages import DATA_KEYS, MODEL_KEYS

    own = {name for name, parameter in inspect.signature(train_com_model).parameters.items()
           if parameter.kind is not parameter.VAR_KEYWORD}
    assert set(RESERVED_OPTIONS) == (own | set(DATA_KEYS) | set(MODEL_KEYS) | set(DYNAMICS_KEYS)) - {"hidden"}


def test_a_model_without_a_network_or_with_an_option_a_checkpoint_cannot_hold_says_so(tmp_path):
    class Empty(CoMModel):
        pass

    with pytest.raises(NotImplementedError, match="Empty must write standardised_delta"):
        Empty(2).predict(torch.zeros(5), torch.zeros(2))

    @MODELS.register("test_with_object_option")
    class WithObject(CoMDynamicsModel):
        def __init__(self, action_dim, hidden=8, *, scale=None, **statistics):
            super().__init__(action_dim, hidden, **statistics)

    try:
        state, action, next_state = _transitions()
        trained = train_com_model(state, action, next_state, model="test_with_object_option", hidden=8,
                                  max_epochs=1, scale=object())
        with pytest.raises(ValueError, match="its options must be numbers"):
            trained.save(tmp_path / "model.pt")
        assert not (tmp_path / "model.pt").exists()
    finally:
        MODELS.unregister("test_with_object_option")


# ---------------------------------------------------------------------------------------------------- in a recipe
@pytest.mark.parametrize("how", [pytest.param("import path", marks=pytest.mark.slow), "registered name"])
def test_a_custom_model_in_a_recipe_reloads_and_re_evaluates_as_it_was_evaluated(copy_run, user_package, tmp_path,
                                                                                 how):
    """The tiny LAT run's dynamics stages rebuilt with the user's model and ``+dynamics.skip_scale=0.5``: the stage
    key holds the option; ``load_run`` gives the model the recipe built (the key's options, the checkpoint's
    weights: bit-identical predictions); ``hierloco evaluate`` with the evaluations removed computes them again,
    equal to the recipe's (with the option lost they differ); the export manifest records the option (exported once:
    the manifest reads the options as the loader does, whatever the model's name)."""
    from hierloco.exporting import export_run

    if how == "registered name":
        module = importlib.import_module("my_models.residual")
        name = "test_resmlp"
        MODELS.register(name)(module.ResMLP)
    else:
        name = PATH
    trust = [PATH] if how == "import path" else []
    try:
        for stale in ("dynamics_model_normal.pt", "dynamics_model_normal.pt.key.json"):
            (copy_run / stale).unlink()
        before = set((copy_run / "evaluation").rglob("*.npz"))
        result = run_in_process("lat", "preset=tiny", "progress=false", f"run_dir={copy_run}", "eval.videos=[]",
                                "eval.figures=false", f"dynamics.model={name}", "+dynamics.skip_scale=0.5",
                                "dynamics.max_epochs=5")
        assert result.returncode == 0, result.stderr[-3000:]
        key = json.loads((copy_run / "dynamics_model_normal.pt.key.json").read_text())["params"]
        assert key["model"] == name and key["skip_scale"] == 0.5

        if how == "import path":  # a fresh process: nothing imported; the run's files alone never import it
            MODELS.unregister(PATH)
            sys.modules.pop("my_models.residual")
            with pytest.raises(ArtifactError, match="trust_imports"):
                hierloco.load_run(copy_run).com_model("normal")
        model = hierloco.load_run(copy_run, trust_imports=trust).com_model("normal").model
        cls = MODELS[name]
        assert type(model) is cls and model.options == {"hidden": key["hidden"], "skip_scale": 0.5}
        built = cls(model.action_dim, key["hidden"], skip_scale=key["skip_scale"])  # what the recipe evaluated
        checkpoint = load_checkpoint(copy_run / "dynamics_model_normal.pt", CHECKPOINT_KIND, CHECKPOINT_FORMAT)
        built.load_state_dict(checkpoint["state_dict"])
        assert torch.equal(_predictions(model), _predictions(built.eval()))

        evaluated = sorted(set((copy_run / "evaluation").rglob("*.npz")) - before)
        assert evaluated
        first = {path: TaskEvaluation.load(path) for path in evaluated}
        for path in evaluated:
            path.unlink()
        again = run_in_process("evaluate.py", f"run_dir={copy_run}", "name=again", "eval.videos=[]",
                               "eval.figures=false", *([f"trust_imports={PATH}"] if trust else []))
        assert again.returncode == 0, again.stderr[-3000:]
        for path, evaluation in first.items():
            second = TaskEvaluation.load(path)
            assert evaluation.recording.keys() == second.recording.keys() and evaluation.recording
            for array in evaluation.recording:
                assert np.array_equal(evaluation.recording[array], second.recording[array]), (path.name, array)
            numbers = ("normalized_cost", "success", "final_error")
            assert [[row[k] for k in numbers] for row in evaluation.rows] == \
                [[row[k] for k in numbers] for row in second.rows]

        if how == "import path":  # the model alone (the gait policy's export is another test's): the manifest
            alone = tmp_path / "model_alone"
            alone.mkdir()
            for artifact in ("dynamics_model_normal.pt", "dynamics_data_normal.npz", "config.yaml"):
                shutil.copy(copy_run / artifact, alone / artifact)
            manifest = export_run(alone, tmp_path / "exported", trust_imports=trust)
            assert manifest["dynamics_model"]["model"] == name
            assert manifest["dynamics_model"]["options"] == {"hidden": key["hidden"], "skip_scale": 0.5}
    finally:
        MODELS.unregister("test_resmlp")
