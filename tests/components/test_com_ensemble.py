"""The dynamics-model registry and the probabilistic ensemble (PETS, Chua et al., NeurIPS 2018) over the CoM delta
of Li et al. (RA-L 2021, Sec. III-C): the MLP trains bit for bit as before the registry, the ensemble learns a known
system with calibrated variances, its members disagree away from the data, checkpoints rebuild either model."""

import hashlib
import math

import numpy as np
import pytest
import torch

from hierloco.components.com_ensemble import CoMEnsembleModel
from hierloco.components.com_model import (MODELS, CoMDynamicsModel, TrainedCoMModel, _nonzero_std, holdout_split,
                                           local_transition, train_com_model)
from hierloco.envs.frames import wrap_angle
from hierloco.io import save_checkpoint
from tests.components.test_com_model import NOISE, _synthetic_transitions


def _reference_mlp_training(state, action, next_state, *, hidden, lr, batch_size, holdout, max_epochs, patience,
                            seed):
    """The MLP's training loop as it was before the registry (commit 048da98), frozen here: weights and held-out
    history of the best epoch."""
    state, act, next_state = (torch.as_tensor(np.asarray(x, float)).double() for x in (state, action, next_state))
    velocity_local, delta = local_transition(state, next_state)
    inputs = torch.cat([velocity_local, act], -1)
    train_idx, heldout_idx = holdout_split(len(inputs), holdout, seed)
    input_mean, input_std = inputs[train_idx].mean(0), _nonzero_std(inputs[train_idx].std(0, correction=0))
    output_mean, output_std = delta[train_idx].mean(0), _nonzero_std(delta[train_idx].std(0, correction=0))
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        model = CoMDynamicsModel(act.shape[1], hidden, input_mean=input_mean, input_std=input_std,
                                 output_mean=output_mean, output_std=output_std)
    generator = torch.Generator().manual_seed(seed)

    def standardised(index):
        x = (inputs[index].float() - model.input_mean) / model.input_std
        y = (delta[index].float() - model.output_mean) / model.output_std
        return x, y

    train_x, train_y = standardised(train_idx)
    heldout_x, heldout_y = standardised(heldout_idx)
    optimizer = torch.optim.Adam(model.parameters(), lr=lr)
    history, best_loss, best_epoch = [], math.inf, 0
    best_state = {k: v.detach().clone() for k, v in model.state_dict().items()}
    model.train()
    for epoch in range(1, max_epochs + 1):
        order = torch.randperm(len(train_x), generator=generator)
        for begin in range(0, len(order), batch_size):
            idx = order[begin:begin + batch_size]
            loss = ((model.net(train_x[idx]) - train_y[idx]) ** 2).mean()
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
        model.eval()
        with torch.no_grad():
            history.append(float(((model.net(heldout_x) - heldout_y) ** 2).mean()))
        model.train()
        if history[-1] < best_loss:
            best_loss, best_epoch = history[-1], epoch
            best_state = {k: v.detach().clone() for k, v in model.state_dict().items()}
        if epoch - best_epoch >= patience:
            break
    return best_state, history


def _digest(state_dict) -> str:
    digest = hashlib.sha256()
    for key, value in sorted(state_dict.items()):
        digest.update(key.encode())
        digest.update(value.detach().cpu().numpy().tobytes())
    return digest.hexdigest()


@pytest.fixture(scope="module")
def ensemble():
    state, action, next_state, _ = _synthetic_transitions(2000, seed=0)
    return train_com_model(state, action, next_state, model="ensemble", members=4, hidden=64, seed=0,
                           progress=False)


def test_registry_names_and_options():
    assert {"mlp", "ensemble"} <= set(MODELS.names())
    assert MODELS["mlp"] is CoMDynamicsModel and MODELS["ensemble"] is CoMEnsembleModel
    assert MODELS.options("mlp") == {"hidden": 512}
    assert MODELS.options("ensemble") == {"hidden": 512, "members": 5, "head": "gaussian", "propagation": "ts",
                                          "member_data": "bootstrap"}


def test_default_mlp_trains_bit_for_bit_as_before_the_registry():
    """``model="mlp"`` (the default) gives the very weights and held-out history of the frozen pre-registry loop:
    same seed, same split, same minibatches, same floats."""
    rng = np.random.default_rng(0)
    state, action = rng.normal(size=(400, 5)), rng.uniform(-1, 1, size=(400, 3))
    next_state = state + 0.1 * rng.normal(size=(400, 5))
    settings = dict(hidden=32, lr=1e-3, batch_size=64, holdout=0.1, max_epochs=15, patience=5, seed=3)
    expected_state, expected_history = _reference_mlp_training(state, action, next_state, **settings)
    for trained in (train_com_model(state, action, next_state, progress=False, **settings),
                    train_com_model(state, action, next_state, model="mlp", progress=False, **settings)):
        assert trained.metadata["heldout_loss_history"] == expected_history
        assert _digest(trained.model.state_dict()) == _digest(expected_state)
        assert trained.metadata["model"] == "mlp" and trained.metadata["model_options"] == {"hidden": 32}


def test_ensemble_learns_a_known_system_with_calibrated_variances(ensemble):
    """The same bars as the MLP's (held-out RMSE under 2 x NOISE, at least 0.7 x NOISE); its Gaussian heads are
    calibrated: 2 predicted standard deviations cover 90-99 % of held-out targets (95 % for a true Gaussian)."""
    meta = ensemble.metadata
    rmse = np.array(meta["heldout_rmse"])
    assert meta["model"] == "ensemble" and meta["model_options"]["members"] == 4
    assert np.all(rmse >= 0.7 * NOISE) and np.all(rmse < 2 * NOISE), rmse
    assert 0.90 <= meta["heldout_coverage_2std"] <= 0.99, meta["heldout_coverage_2std"]
    # standardised NLL of a Gaussian with the noise's scale: 0.5 log(2 pi e sigma^2), sigma = NOISE / output_std
    assert math.isfinite(meta["heldout_nll"]) and meta["heldout_nll"] < 0.0


def test_members_disagree_away_from_the_data(ensemble):
    """Epistemic uncertainty: the spread of the members' means is several times larger for actions far outside the
    training box than inside it."""
    model = ensemble.model
    generator = torch.Generator().manual_seed(0)
    velocity = 0.5 * torch.rand(500, 2, generator=generator) - 0.25
    inside = 2 * torch.rand(500, 3, generator=generator) - 1
    with torch.no_grad():
        spread_in = model.members(velocity, inside)[0].std(-2).mean()
        spread_out = model.members(velocity, 4 * inside.sign() + inside)[0].std(-2).mean()
    assert spread_out > 3 * spread_in, (spread_in, spread_out)


def test_log_variance_stays_within_its_soft_bounds(ensemble):
    model = ensemble.model
    generator = torch.Generator().manual_seed(0)
    with torch.no_grad():
        x = 100 * torch.randn(model.num_members, 50, 2 + model.action_dim, generator=generator)
        _, log_variance = model.standardised_heads(x)
        # the upper soft clamp is followed by the lower one, min + softplus(max - min) = max + log(1 + e^-(max - min)):
        # the exact ceiling of the two together, reached where the raw head saturates high
        span = model.max_log_variance - model.min_log_variance
        ceiling = model.max_log_variance + torch.log1p(torch.exp(-span))
    assert torch.isfinite(log_variance).all()
    assert bool((log_variance <= ceiling + 1e-6).all()), (log_variance.amax((0, 1)), ceiling)
    assert bool((log_variance >= model.min_log_variance - 1e-6).all())


def test_member_data_bootstrap_and_shuffle():
    generator = torch.Generator().manual_seed(0)
    boot = CoMEnsembleModel(2, hidden=8, members=3).training_rows(1000, generator)
    assert boot.shape == (3, 1000)
    unique = [len(row.unique()) for row in boot]
    assert all(550 < u < 700 for u in unique), unique  # about 1 - 1/e = 63 % of the rows in each resample
    assert not torch.equal(boot[0], boot[1])
    shuffle = CoMEnsembleModel(2, hidden=8, members=3, member_data="shuffle")
    rows = shuffle.training_rows(1000, generator)
    order = shuffle.epoch_order(rows, 1000, generator)
    assert all(torch.equal(row.sort().values, torch.arange(1000)) for row in order)
    assert not torch.equal(order[0], order[1])


def test_checkpoints_record_the_model_and_rebuild_it(ensemble, tmp_path):
    path = tmp_path / "ensemble.pt"
    ensemble.save(path)
    payload = torch.load(path, weights_only=True)
    assert payload["model"] == "ensemble" and payload["config"]["members"] == 4
    loaded = TrainedCoMModel.load(path)
    assert isinstance(loaded.model, CoMEnsembleModel) and loaded.name == "ensemble"
    state, action = torch.randn(20, 5), torch.rand(20, 3)
    with torch.no_grad():
        torch.testing.assert_close(loaded.model.predict(state, action), ensemble.model.predict(state, action))
    # a checkpoint written before the registry (no model name) is an MLP
    mlp = CoMDynamicsModel(action_dim=3, hidden=8)
    save_checkpoint(tmp_path / "old.pt", "com_model", 1, {"config": mlp.config(), "state_dict": mlp.state_dict(),
                                                          "metadata": {}})
    assert isinstance(TrainedCoMModel.load(tmp_path / "old.pt").model, CoMDynamicsModel)


def test_unknown_model_or_option_is_refused_before_training():
    state, action, next_state, _ = _synthetic_transitions(50, seed=0)
    with pytest.raises(ValueError, match="unknown dynamics model 'gp'"):
        train_com_model(state, action, next_state, model="gp", progress=False)
    with pytest.raises(ValueError, match="has no option 'members'"):
        train_com_model(state, action, next_state, members=3, progress=False)
    with pytest.raises(ValueError, match="propagation must be one of"):
        train_com_model(state, action, next_state, model="ensemble", propagation="sampled", progress=False)


def test_propagation_modes():
    """``ts`` with a deterministic head moves particle m by member m; ``expectation`` moves the particles' mean by
    every member; ``mm`` draws particles with the moved particles' mean and spread."""
    torch.manual_seed(0)
    model = CoMEnsembleModel(action_dim=2, hidden=16, members=3, head="deterministic")
    particles = torch.randn(4, 3, 5)
    action = torch.rand(4, 1, 2)
    with torch.no_grad():
        moved = model.predict_particles(particles, action)
        for m in range(3):
            torch.testing.assert_close(moved[:, m], model.predict_members(particles[:, m], action[:, 0])[:, m])
        model.propagation = "expectation"
        from hierloco.envs.world_model import particle_moments

        mean, _ = particle_moments(particles)
        torch.testing.assert_close(model.predict_particles(particles, action),
                                   model.predict_members(mean, action[:, 0]))
        model.propagation = "mm"
        many = particles[:1].expand(20000, 3, 5)
        drawn = model.predict_particles(many, action[:1].expand(20000, 1, 2), torch.Generator().manual_seed(0))
        centre, spread = particle_moments(moved[:1])
        sample = drawn.reshape(-1, 5)
        torch.testing.assert_close(sample[:, [0, 1, 3, 4]].mean(0), centre[0, [0, 1, 3, 4]], atol=0.01, rtol=0)
        torch.testing.assert_close(sample[:, [0, 1, 3, 4]].std(0), spread[0, [0, 1, 3, 4]], atol=0.01, rtol=0.02)
        assert bool((wrap_angle(sample[:, 2]) == sample[:, 2]).all())


def test_transition_calibration_tells_a_known_system_from_a_shifted_one(ensemble):
    """On fresh transitions of the system it learned, the mean's error is about the noise and 2 predictive standard
    deviations cover about 95 %; on the same inputs with every dx shifted by 0.2 m (a robot the model never saw), the
    error of dx grows by the shift while the members' spread stays as it was: the disagreement cannot see a shift
    the data never showed."""
    from hierloco.components.com_ensemble import transition_calibration
    from hierloco.components.com_model import apply_delta

    state, action, next_state, _ = _synthetic_transitions(1000, seed=1)
    known = transition_calibration(ensemble.model, state, action, next_state)
    assert all(0.7 * NOISE <= e < 2 * NOISE for e in known["error"]), known
    assert all(0.88 <= c <= 0.99 for c in known["coverage"]), known
    assert all(s < n for s, n in zip(known["spread"], known["noise"])), known  # inside the data: mostly noise
    _, delta = local_transition(torch.as_tensor(state), torch.as_tensor(next_state))
    shifted = apply_delta(torch.as_tensor(state), delta + torch.tensor([0.2, 0.0, 0.0, 0.0, 0.0], dtype=delta.dtype))
    moved = transition_calibration(ensemble.model, state, action, shifted)
    assert moved["error"][0] > 0.19 and moved["coverage"][0] < 0.1, moved
    assert moved["spread"] == known["spread"] and moved["error"][1:] == pytest.approx(known["error"][1:], rel=1e-4)
