"""The latent gait policy: fits the experts, reproduces their gaits in simulation, saves and loads safely."""

from dataclasses import replace

import numpy as np
import pytest
import torch

from hierloco.components.evaluation import check_gait_policy
from hierloco.components.expert_library import build_expert_library
from hierloco.components.gait_policy_fit import fit_gait_policy
from hierloco.components.gait_policy import (
    LatentGaitPolicy,
    TrainedGaitPolicy,
    train_gait_policy,
)
from hierloco.components.low_level import LatentLowLevel
from hierloco.io import ArtifactError


def _periodic_experts(num_experts=5, steps=100, joints=4, periods=2, seed=0):
    """Synthetic experts: per joint, a phase-shifted sine of expert-specific amplitude, periodic in the action."""
    rng = np.random.default_rng(seed)
    t = np.arange(1, steps + 1) / steps
    amplitude = rng.uniform(0.1, 0.5, (num_experts, 1, joints))
    phase = rng.uniform(0, 2 * np.pi, (num_experts, 1, joints))
    return amplitude * np.sin(2 * np.pi * periods * t[None, :, None] + phase) + 0.3


def test_fits_synthetic_experts_and_separates_their_latents():
    experts = _periodic_experts()
    trained = train_gait_policy(experts, latent_dim=2, periods_per_action=2, hidden=128, epochs=300,
                                batch_size=500, progress=False)
    assert trained.metadata["rmse"] < 0.02, trained.metadata["rmse"]  # rad, against amplitudes of 0.1-0.5
    z = trained.latents
    distances = torch.cdist(z, z) + torch.eye(len(z)) * 1e9
    assert distances.min() > 1e-3, "every expert gets its own latent"
    assert torch.all(trained.latent_low <= z.min(0).values) and torch.all(trained.latent_high >= z.max(0).values)


def test_pattern_is_periodic_and_one_forward_pass():
    policy = LatentGaitPolicy(num_joints=6, latent_dim=3, steps_per_action=100, periods_per_action=1)
    z = torch.randn(5, 3)
    pattern = policy.pattern(z)
    assert pattern.shape == (5, 100, 6)
    # phase t = 1 (the last step) and t = 0 give the same output: the pattern repeats seamlessly
    at_zero = policy(torch.zeros(5, 1), z)
    torch.testing.assert_close(pattern[:, -1], at_zero, atol=1e-5, rtol=0)
    # the TensorDict module agrees with the plain call
    from tensordict import TensorDict

    td = policy.as_module()(TensorDict({"phase": torch.full((5, 1), 0.3), "latent": z}, batch_size=[5]))
    torch.testing.assert_close(td["joint_targets"], policy(torch.full((5, 1), 0.3), z))


@pytest.fixture(scope="module")
def daisy_policy():
    library = build_expert_library("daisy", 6, seed=0, progress=False)
    trained = train_gait_policy(library.joint_targets, latent_dim=3, periods_per_action=1, hidden=256,
                                epochs=250, batch_size=600, progress=False)
    return library, trained


def test_policy_reproduces_the_experts_in_simulation(daisy_policy):
    """pi(., z_g) run open loop walks like expert g: within 0.05 m/s for at least 90 % of experts."""
    library, trained = daisy_policy
    check = check_gait_policy(LatentLowLevel(trained, "daisy"), library, trained.latents.numpy(), num_pairs=6)
    assert check["reproduced_fraction"] >= 0.9, check["reproduction_error"]
    assert check["interpolation_walks"] == 1.0


def test_save_load_round_trip(daisy_policy, tmp_path):
    _, trained = daisy_policy
    path = tmp_path / "policy.pt"
    trained.save(path)
    loaded = TrainedGaitPolicy.load(path)
    torch.testing.assert_close(loaded.policy.pattern(loaded.latents), trained.policy.pattern(trained.latents))
    torch.testing.assert_close(loaded.latent_low, trained.latent_low)
    assert loaded.metadata == trained.metadata
    path.write_bytes(path.read_bytes()[:1000])
    with pytest.raises(ArtifactError, match="corrupted"):
        TrainedGaitPolicy.load(path)
    torch.save({"kind": "something else"}, tmp_path / "other.pt")
    with pytest.raises(ArtifactError, match="not a gait policy"):
        TrainedGaitPolicy.load(tmp_path / "other.pt")


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="latent_dim"):
        LatentGaitPolicy(num_joints=4, latent_dim=0)
    with pytest.raises(ValueError, match="G x N x J"):
        train_gait_policy(np.zeros((10, 4)), progress=False)


def test_net_is_a_torchrl_mlp_with_the_hand_built_layout_and_weights():
    """The 2 x 512 ReLU net is torchrl's MLP: the same layer creation order as the hand-built ``nn.Sequential`` it
    replaced, so the same seed gives the same initial weights and old checkpoints load unchanged."""
    from torch import nn
    from torchrl.modules import MLP

    torch.manual_seed(0)
    policy = LatentGaitPolicy(num_joints=12, latent_dim=3, periods_per_action=5)
    torch.manual_seed(0)
    inputs = 2 * policy.num_harmonics + 3
    hand_built = nn.Sequential(nn.Linear(inputs, 512), nn.ReLU(), nn.Linear(512, 512), nn.ReLU(),
                               nn.Linear(512, 12))
    assert isinstance(policy.net, MLP)
    assert list(policy.net.state_dict()) == list(hand_built.state_dict()) == [
        "0.weight", "0.bias", "2.weight", "2.bias", "4.weight", "4.bias"]
    for key, value in hand_built.state_dict().items():
        torch.testing.assert_close(policy.net.state_dict()[key], value, rtol=0, atol=0)
    x = torch.randn(5, inputs)
    torch.testing.assert_close(policy.net(x), hand_built(x), rtol=0, atol=0)


# ---------------------------------------------------------------------------------------------------- adaptive fit
@pytest.fixture(scope="module")
def small_daisy_library():
    return build_expert_library("daisy", 6, settle_time=1.0, seed=0, progress=False)


SHORT_FIT = dict(epochs=30, hidden=64, batch_size=100, latent_dim=3)  # too short a fit for Daisy's 6 experts


def test_fit_without_adapting_is_the_plain_training(small_daisy_library):
    """What the pipeline trains today is unchanged: ``adaptive=False`` is :func:`train_gait_policy`, bit for bit."""
    fit = fit_gait_policy(small_daisy_library, adaptive=False, check_pairs=4, **SHORT_FIT)
    plain = train_gait_policy(small_daisy_library.joint_targets, periods_per_action=1, progress=False, **SHORT_FIT)
    assert [a["name"] for a in fit.attempts] == ["as configured"]
    for key, value in plain.policy.state_dict().items():
        torch.testing.assert_close(fit.trained.policy.state_dict()[key], value, rtol=0, atol=0)
    torch.testing.assert_close(fit.trained.latents, plain.latents, rtol=0, atol=0)


def test_fit_adapts_until_the_gait_policy_reproduces_its_experts(small_daisy_library):
    """30 epochs of 64 units reproduce none of the 6 experts, nor do 60; twice the units and harmonics for 60 epochs
    do (the bar here is half of them). Each fit is what the recipe trains with the overrides it records."""
    fit = fit_gait_policy(small_daisy_library, min_reproduced_fraction=0.5, check_pairs=4, **SHORT_FIT)
    names = [a["name"] for a in fit.attempts]
    assert names == ["as configured", "longer", "wider"], fit.attempts
    first, longer, wider = fit.attempts
    assert first["reproduced_fraction"] < 0.5 and longer["reproduced_fraction"] < 0.5
    assert first["overrides"] == {} and longer["overrides"] == {"epochs": 60}
    assert wider["overrides"] == {"epochs": 60, "hidden": 128, "num_harmonics": 16}
    assert fit.ok and fit.reproduced_fraction == wider["reproduced_fraction"] >= 0.5
    assert fit.trained.policy.hidden == 128 and fit.experts_replayed_fraction == 1.0
    assert fit.trained.metadata["adaptive_fit"]["kept"] == "wider"
    # a budget of epochs stops the ladder before the wider fit
    budget = fit_gait_policy(small_daisy_library, min_reproduced_fraction=0.5, check_pairs=4, budget_epochs=90,
                             **SHORT_FIT)
    assert [a["name"] for a in budget.attempts] == ["as configured", "longer"] and not budget.ok


def test_fit_stops_when_the_experts_themselves_do_not_replay(small_daisy_library):
    """Experts whose recorded velocities their own targets do not walk (here: recorded 0.3 m/s too fast) cannot be
    reproduced by any fit: one fit, then the diagnosis."""
    library = small_daisy_library
    tampered = replace(library, velocity_local=library.velocity_local + 0.3)
    fit = fit_gait_policy(tampered, check_pairs=4, **SHORT_FIT)
    assert len(fit.attempts) == 1 and fit.experts_replayed_fraction == 0.0
    assert fit.limited_by_experts and not fit.ok
