"""The CoM dynamics model: the local-frame data transform, learning a known system, early stopping, checkpoints."""

import math

import numpy as np
import pytest
import torch

from hierloco.components.com_model import (CoMDynamicsModel, TrainedCoMModel, apply_delta, holdout_split,
                                           local_transition, prediction_errors, train_com_model)
from hierloco.envs.frames import local_to_world, wrap_angle
from hierloco.io import ArtifactError

NOISE = 0.01  # standard deviation of the noise on every local-frame output of the synthetic system (m, rad, m/s)


def _gait_response(action):
    """A smooth nonlinear map of a 3-D action to a steady-state local velocity (m/s)."""
    a0, a1, a2 = action[:, 0], action[:, 1], action[:, 2]
    return np.stack([0.5 * np.tanh(2 * a0) + 0.2 * a1 * a2, 0.4 * np.sin(np.pi * a1) - 0.1 * a0 ** 2], -1)


def _synthetic_transitions(num, seed, noise=NOISE):
    """World-frame transitions of a known system from random poses, and its noise-free local-frame deltas.

    The next local velocity relaxes towards the action's response, the displacement is the mean of the two
    velocities over 1 s, and the yaw change is 0.3 * a[2]; noise is added to the local-frame outputs.
    """
    rng = np.random.default_rng(seed)
    action = rng.uniform(-1, 1, (num, 3))
    velocity = rng.uniform(-0.5, 0.5, (num, 2))
    yaw = rng.uniform(-np.pi, np.pi, num)
    position = rng.uniform(-5, 5, (num, 2))
    next_velocity = 0.6 * velocity + 0.4 * _gait_response(action)
    clean = np.concatenate([0.5 * (velocity + next_velocity), 0.3 * action[:, 2:3], next_velocity], -1)
    noisy = clean + noise * rng.normal(size=clean.shape)
    state = np.concatenate([position, yaw[:, None], local_to_world(velocity, yaw)], -1)
    next_state = np.concatenate([position + local_to_world(noisy[:, :2], yaw), wrap_angle(yaw + noisy[:, 2])[:, None],
                                 local_to_world(noisy[:, 3:], yaw)], -1)
    return state, action, next_state, clean


def _random_states(num, rng):
    yaw = rng.uniform(-np.pi, np.pi, num)
    edge = np.array([np.pi, -np.pi, np.pi - 1e-4, -np.pi + 1e-4, 3.1, -3.1, 0.0, np.pi / 2])  # near and at the cut
    yaw[:len(edge)] = edge[:num]
    return np.concatenate([rng.uniform(-20, 20, (num, 2)), yaw[:, None], rng.uniform(-1, 1, (num, 2))], -1)


@pytest.fixture(scope="module")
def learned():
    state, action, next_state, _ = _synthetic_transitions(3000, seed=0)
    return train_com_model(state, action, next_state, hidden=128, seed=0, progress=False), (state, action, next_state)


@pytest.fixture(scope="module")
def small():
    state, action, next_state, _ = _synthetic_transitions(300, seed=1)
    return train_com_model(state, action, next_state, hidden=16, max_epochs=5, seed=0, progress=False)


def test_known_transition():
    """Facing +y and walking forward at 1 m/s, then 1 m further along +y: 1 m forward, v' seen from the start frame."""
    velocity, delta = local_transition(torch.tensor([1.0, 2.0, math.pi / 2, 0.0, 1.0], dtype=torch.float64),
                                       torch.tensor([1.0, 3.0, math.pi / 2 + 0.1, -0.5, 1.0], dtype=torch.float64))
    torch.testing.assert_close(velocity, torch.tensor([1.0, 0.0], dtype=torch.float64))
    torch.testing.assert_close(delta, torch.tensor([1.0, 0.0, 0.1, 1.0, 0.5], dtype=torch.float64))
    _, across = local_transition(np.array([0, 0, 3.1, 0, 0.0]), np.array([0, 0, -3.1, 0, 0.0]))
    assert across[2].item() == pytest.approx(2 * math.pi - 6.2)  # the short way across +-pi


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_round_trip(dtype):
    rng = np.random.default_rng(0)
    state, next_state = _random_states(1000, rng).astype(dtype), _random_states(1000, rng).astype(dtype)
    velocity, delta = local_transition(state, next_state)
    assert isinstance(delta, torch.Tensor) and velocity.shape == (1000, 2) and delta.shape == (1000, 5)
    assert delta[:, 2].abs().max() <= math.pi
    rebuilt = apply_delta(torch.as_tensor(state), delta)
    assert rebuilt.dtype == delta.dtype == torch.as_tensor(state).dtype
    pi = np.asarray(np.pi, dtype)  # the wrap is to (-pi, pi] as represented in the working precision
    assert np.all((rebuilt[:, 2].numpy() > -pi) & (rebuilt[:, 2].numpy() <= pi))
    rebuilt = rebuilt.double().numpy()
    expected = next_state.astype(np.float64)
    np.testing.assert_allclose(rebuilt[:, [0, 1, 3, 4]], expected[:, [0, 1, 3, 4]], atol=1e-5)
    yaw_error = wrap_angle(rebuilt[:, 2] - expected[:, 2])
    np.testing.assert_allclose(yaw_error, 0.0, atol=1e-5)


def test_transform_is_invariant_to_moving_the_world():
    """Rotating and translating both states (positions, headings, velocities) changes no training pair."""
    rng = np.random.default_rng(1)
    state, next_state = _random_states(500, rng), _random_states(500, rng)
    velocity, delta = local_transition(state, next_state)
    for angle, shift in [(0.7, (3.0, -2.0)), (-2.9, (-10.0, 4.0)), (math.pi, (0.0, 0.0))]:
        def move(s):
            return np.concatenate([local_to_world(s[:, :2], angle) + shift, wrap_angle(s[:, 2:3] + angle),
                                   local_to_world(s[:, 3:], angle)], -1)
        moved_velocity, moved_delta = local_transition(move(state), move(next_state))
        torch.testing.assert_close(moved_velocity, velocity, atol=1e-9, rtol=0)
        dyaw_error = wrap_angle(moved_delta[:, 2] - delta[:, 2])
        torch.testing.assert_close(dyaw_error, torch.zeros_like(dyaw_error), atol=1e-9, rtol=0)
        torch.testing.assert_close(moved_delta[:, [0, 1, 3, 4]], delta[:, [0, 1, 3, 4]], atol=1e-9, rtol=0)


def test_learns_a_known_system(learned):
    """The noise puts a floor of NOISE under every held-out RMSE; a fit that has learned the system sits near it.

    Allowing 2 x NOISE leaves room for the approximation error of a small network on 2700 samples but fails any
    model that has not captured the nonlinear response (the constant-velocity predictor is 8-19 x NOISE here).
    """
    trained, _ = learned
    rmse = np.array(trained.metadata["heldout_rmse"])
    baseline = np.array(trained.metadata["constant_velocity_rmse"])
    assert trained.metadata["num_train"] == 2700 and trained.metadata["num_heldout"] == 300
    assert np.all(rmse >= 0.7 * NOISE), f"held-out RMSE {rmse} below the noise floor: leaking held-out data?"
    assert np.all(rmse < 2 * NOISE), f"held-out RMSE {rmse}"
    assert np.all(rmse < 0.5 * baseline), f"held-out RMSE {rmse} vs constant velocity {baseline}"


def test_predicts_fresh_samples(learned):
    """On new transitions from the same system the world-frame prediction matches the noise-free next state."""
    trained, _ = learned
    state, action, _, clean = _synthetic_transitions(2000, seed=123, noise=0.0)
    with torch.no_grad():
        predicted = trained.model.predict(state, action).double()
    expected = apply_delta(state, clean)
    position_error = (predicted[:, :2] - expected[:, :2]).norm(dim=-1)
    yaw_error = wrap_angle(predicted[:, 2] - expected[:, 2]).abs()
    velocity_error = (predicted[:, 3:] - expected[:, 3:]).norm(dim=-1)
    assert position_error.pow(2).mean().sqrt() < 1.5 * NOISE
    assert yaw_error.pow(2).mean().sqrt() < 1.5 * NOISE
    assert velocity_error.pow(2).mean().sqrt() < 1.5 * NOISE


def _heldout_loss(model, state, action, next_state, heldout):
    """The standardised held-out MSE, recomputed from the returned model."""
    velocity, delta = local_transition(state[heldout], next_state[heldout])
    with torch.no_grad():
        prediction = model.normalized(velocity, action[heldout])
    target = (delta.float() - model.output_mean) / model.output_std
    return float(((prediction - target) ** 2).mean())


def test_early_stopping_keeps_the_best_weights():
    """On 60 pure-noise transitions the held-out loss stops improving at once: training stops patience epochs
    after its best epoch, long before max_epochs, and the model returned is the one of that best epoch."""
    rng = np.random.default_rng(2)
    state, action = _random_states(60, rng), rng.uniform(-1, 1, (60, 2))
    next_state = state + rng.normal(size=(60, 5))
    trained = train_com_model(state, action, next_state, hidden=64, lr=1e-2, batch_size=16, patience=5,
                              max_epochs=500, seed=0, progress=False)
    meta = trained.metadata
    history = meta["heldout_loss_history"]
    assert meta["epochs"] < 100 and meta["epochs"] == len(history) == meta["best_epoch"] + 5
    assert meta["best_epoch"] == int(np.argmin(history)) + 1 and meta["heldout_loss"] == min(history)
    assert meta["epochs"] > meta["best_epoch"] and history[-1] > min(history)
    _, heldout = holdout_split(60, 0.1, seed=0)
    assert _heldout_loss(trained.model, state, action, next_state, heldout) == pytest.approx(min(history), rel=1e-5)
    velocity, delta = local_transition(state[heldout], next_state[heldout])
    with torch.no_grad():
        rmse = (trained.model(velocity, action[heldout]).double() - delta).pow(2).mean(0).sqrt()
    np.testing.assert_allclose(rmse.numpy(), meta["heldout_rmse"], rtol=1e-5)


def test_same_seed_same_model(small):
    state, action, next_state, _ = _synthetic_transitions(300, seed=1)
    again = train_com_model(state, action, next_state, hidden=16, max_epochs=5, seed=0, progress=False)
    for name, value in small.model.state_dict().items():
        assert torch.equal(value, again.model.state_dict()[name]), name
    for key, value in small.metadata.items():
        if key != "train_seconds":
            assert again.metadata[key] == value, key
    other = train_com_model(state, action, next_state, hidden=16, max_epochs=5, seed=1, progress=False)
    assert not torch.equal(other.model.net[0].weight, small.model.net[0].weight)
    assert other.metadata["heldout_rmse"] != small.metadata["heldout_rmse"]
    assert not torch.equal(holdout_split(300, 0.1, 0)[1], holdout_split(300, 0.1, 1)[1])


def test_training_leaves_the_global_rng_alone():
    state, action, next_state, _ = _synthetic_transitions(50, seed=3)
    before = torch.random.get_rng_state()
    train_com_model(state, action, next_state, hidden=8, max_epochs=2, progress=False)
    assert torch.equal(torch.random.get_rng_state(), before)


def test_batched_shapes_agree_with_flattening():
    torch.manual_seed(0)
    model = CoMDynamicsModel(3, hidden=32, input_mean=torch.randn(5), input_std=torch.rand(5) + 0.5,
                             output_mean=torch.randn(5), output_std=torch.rand(5) + 0.5).eval()
    velocity, action = torch.randn(4, 8000, 2), torch.rand(4, 8000, 3)
    with torch.no_grad():
        delta = model(velocity, action)
        flat = model(velocity.reshape(-1, 2), action.reshape(-1, 3)).reshape(4, 8000, 5)
    assert delta.shape == (4, 8000, 5)
    torch.testing.assert_close(delta, flat)

    state = torch.as_tensor(_random_states(4, np.random.default_rng(4)), dtype=torch.float32)
    with torch.no_grad():
        broadcast = model.predict(state[:, None], action)  # one state per robot, 8000 sampled actions
        expanded = model.predict(state[:, None].expand(4, 8000, 5), action)
        single = model.predict(state[2], action[2, 17])
    assert broadcast.shape == (4, 8000, 5)
    torch.testing.assert_close(broadcast, expanded)
    torch.testing.assert_close(single, broadcast[2, 17])
    velocity_local, _ = local_transition(state, state)
    torch.testing.assert_close(broadcast, apply_delta(state[:, None], model(velocity_local[:, None], action)))
    with pytest.raises(ValueError, match="action"):
        model(velocity, torch.rand(4, 8000, 2))


def test_save_load_round_trip(small, tmp_path):
    path = tmp_path / "com_model.pt"
    small.save(path)
    loaded = TrainedCoMModel.load(path)
    assert loaded.metadata == small.metadata and loaded.model.config() == small.model.config()
    state = torch.as_tensor(_random_states(100, np.random.default_rng(5)))
    action = torch.rand(100, 3)
    with torch.no_grad():
        assert torch.equal(loaded.model.predict(state, action), small.model.predict(state, action))
    assert [p.name for p in tmp_path.iterdir()] == ["com_model.pt"], "temporary files left behind"


def test_bad_checkpoints_are_refused(small, tmp_path):
    with pytest.raises(ArtifactError, match="missing.pt"):
        TrainedCoMModel.load(tmp_path / "missing.pt")
    path = tmp_path / "com_model.pt"
    small.save(path)
    truncated = tmp_path / "truncated.pt"
    truncated.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.raises(ArtifactError, match="truncated.pt"):
        TrainedCoMModel.load(truncated)
    other = tmp_path / "gait_policy.pt"
    torch.save({"format": 1, "kind": "gait_policy", "config": {}, "state_dict": {}, "metadata": {}}, other)
    with pytest.raises(ArtifactError, match="gait_policy.pt"):
        TrainedCoMModel.load(other)
    payload = torch.load(path, weights_only=True)
    payload["config"]["action_dim"] = 7  # weights of another config
    mismatched = tmp_path / "mismatched.pt"
    torch.save(payload, mismatched)
    with pytest.raises(ArtifactError, match="mismatched.pt"):
        TrainedCoMModel.load(mismatched)


def _bad_inputs():
    state, action, next_state, _ = _synthetic_transitions(40, seed=6)
    nan_action, inf_state = action.copy(), next_state.copy()
    nan_action[7, 1] = np.nan
    inf_state[3, 0] = np.inf
    return [
        ((state, action[:-1], next_state), {}, "same length"),
        ((state[:, :4], action, next_state), {}, "com_state must be M x 5"),
        ((state, action, next_state[:, :, None]), {}, "next_com_state must be M x 5"),
        ((state, action[:, 0], next_state), {}, "action must be M x A"),
        ((state, nan_action, next_state), {}, "action has NaN or inf"),
        ((state, action, inf_state), {}, "next_com_state has NaN or inf"),
        ((state[:5], action[:5], next_state[:5]), {}, "at least 10 transitions"),
        ((state, action, next_state), {"holdout": 0.0}, "holdout"),
        ((state, action, next_state), {"holdout": 1.0}, "holdout"),
        ((state, action, next_state), {"batch_size": 0}, "batch_size"),
    ]


@pytest.mark.parametrize("args, kwargs, message", _bad_inputs())
def test_bad_inputs_are_refused(args, kwargs, message):
    with pytest.raises(ValueError, match=message):
        train_com_model(*args, **kwargs, hidden=8, max_epochs=1, progress=False)


def test_net_is_a_torchrl_mlp_with_the_hand_built_layout_and_weights():
    """Same layer creation order as the hand-built ``nn.Sequential`` it replaced: same initial weights under the
    same seed, same state_dict keys (the checkpoint format is unchanged)."""
    from torch import nn
    from torchrl.modules import MLP

    torch.manual_seed(3)
    model = CoMDynamicsModel(action_dim=3)
    torch.manual_seed(3)
    hand_built = nn.Sequential(nn.Linear(5, 512), nn.ReLU(), nn.Linear(512, 512), nn.ReLU(), nn.Linear(512, 5))
    assert isinstance(model.net, MLP)
    assert list(model.net.state_dict()) == list(hand_built.state_dict())
    for key, value in hand_built.state_dict().items():
        torch.testing.assert_close(model.net.state_dict()[key], value, rtol=0, atol=0)
    old_state = {f"net.{key}": value for key, value in hand_built.state_dict().items()}
    fresh = CoMDynamicsModel(action_dim=3)
    fresh.load_state_dict({**dict(fresh.state_dict()), **old_state})
    torch.testing.assert_close(fresh(torch.ones(4, 2), torch.ones(4, 3)), model(torch.ones(4, 2), torch.ones(4, 3)))


class _FixedDelta(torch.nn.Module):
    """A stand-in CoM model that always predicts the same local-frame delta."""

    def __init__(self, delta):
        super().__init__()
        self.delta = torch.as_tensor(delta, dtype=torch.float64)

    def forward(self, velocity_local, action):
        return self.delta.expand(*torch.broadcast_shapes(velocity_local.shape[:-1], action.shape[:-1]), 5)


def test_prediction_errors_on_taken_actions():
    # a robot turning 0.4 rad per action across the +-pi seam, moving 0.2 m forward: the exact model errs by 0
    delta = torch.tensor([0.2, 0.0, 0.4, 0.2, 0.0], dtype=torch.float64)
    states = [torch.tensor([1.0, -2.0, 2.5, 0.0, 0.0], dtype=torch.float64)]
    for _ in range(4):
        states.append(apply_delta(states[-1], delta))
    states = torch.stack(states)[None].repeat(2, 1, 1)  # E=2 x (T+1)=5 x 5
    actions = torch.zeros(2, 4, 3)
    exact = prediction_errors(_FixedDelta(delta), states, actions)
    assert exact.shape == (2, 4, 5)
    assert exact.abs().max() < 1e-9
    # one that over-predicts the turn by 0.3 rad (wrapped) and the forward step by 0.05 m errs by exactly that
    off = prediction_errors(_FixedDelta(delta + torch.tensor([0.05, 0.0, 0.3 + 2 * math.pi, 0.0, 0.0])), states,
                            actions)
    np.testing.assert_allclose(off[..., 0], 0.05, atol=1e-9)
    np.testing.assert_allclose(off[..., 2], 0.3, atol=1e-6)  # wrap_angle works to float32 precision
    np.testing.assert_allclose(off[..., [1, 3, 4]], 0.0, atol=1e-9)
    with pytest.raises(ValueError, match="E x \\(T \\+ 1\\) x 5 and actions E x T x A"):
        prediction_errors(_FixedDelta(delta), states, torch.zeros(2, 5, 3))
