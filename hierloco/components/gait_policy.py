"""The latent gait policy ``q_des = pi(t, z)`` and its joint training with one latent per expert (Li et al., RA-L
2021, Sec. III-A.1 and III-B).

``t = n / N`` in (0, 1] is the phase within one latent action of N control steps. The policy sees only phase
features and the latent z, never the robot state: for a fixed z it is a periodic open-loop joint-target pattern.
Phase features are ``sin/cos(2 pi k m t)`` for harmonics ``k = 1..K`` of the gait frequency (``m`` gait periods
per action). The network is a :class:`torchrl.modules.MLP` with 2 hidden layers of 512 ReLU units whose output is
de-normalised with the experts' per-joint mean and standard deviation.

Training fits the policy and one learnable latent per expert together by MSE to the experts' joint targets; the
latents have their own Adam optimiser with weight decay, which keeps the latent space compact.

Example:
    >>> import torch
    >>> policy = LatentGaitPolicy(num_joints=12, latent_dim=3, steps_per_action=100, periods_per_action=5)
    >>> policy.pattern(torch.zeros(4, 3)).shape  # B x N x J joint targets for B latents
    torch.Size([4, 100, 12])
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass

import numpy as np
import torch
from tensordict.nn import TensorDictModule
from torch import nn
from torchrl.modules import MLP
from tqdm.auto import tqdm

from hierloco.io import ArtifactError, load_checkpoint, save_checkpoint

CHECKPOINT_FORMAT = 1
CHECKPOINT_KIND = "gait_policy"


class LatentGaitPolicy(nn.Module):
    """``pi(t, z)``: phase ``... x 1`` and latent ``... x Z`` -> joint targets ``... x J`` in rad.

    Args:
        num_joints: J. latent_dim: Z (2 to 4). steps_per_action: N.
        periods_per_action: gait periods in one action (m), sets the base frequency of the phase features.
        num_harmonics: K harmonics of the gait frequency in the phase features (capped at Nyquist).
        hidden: width of the 2 hidden layers.
        joint_mean, joint_std: ``J`` expert statistics used to de-normalise the output (rad).
    """

    def __init__(self, num_joints: int, latent_dim: int = 3, *, steps_per_action: int = 100,
                 periods_per_action: int = 1, num_harmonics: int = 8, hidden: int = 512,
                 joint_mean: torch.Tensor | None = None, joint_std: torch.Tensor | None = None):
        super().__init__()
        if not 1 <= latent_dim <= 8:
            raise ValueError(f"latent_dim must be between 1 and 8 (2 to 4 in the paper), got {latent_dim}")
        self.num_joints, self.latent_dim = int(num_joints), int(latent_dim)
        self.steps_per_action, self.periods_per_action = int(steps_per_action), int(periods_per_action)
        nyquist = max(1, (self.steps_per_action // self.periods_per_action) // 2)
        self.num_harmonics = int(min(num_harmonics, nyquist))
        self.hidden = int(hidden)
        self.net = MLP(in_features=2 * self.num_harmonics + self.latent_dim, out_features=self.num_joints,
                       num_cells=[self.hidden, self.hidden], activation_class=nn.ReLU)
        self.register_buffer("joint_mean", torch.zeros(num_joints, device="cpu") if joint_mean is None
                             else joint_mean.float())
        self.register_buffer("joint_std", torch.ones(num_joints, device="cpu") if joint_std is None
                             else joint_std.float())
        frequencies = 2 * math.pi * self.periods_per_action * torch.arange(1, self.num_harmonics + 1, device="cpu")
        self.register_buffer("frequencies", frequencies.float())
        self.register_buffer("phases", torch.arange(1, self.steps_per_action + 1, device="cpu").float()
                             / self.steps_per_action)

    def phase_features(self, phase: torch.Tensor) -> torch.Tensor:
        """``... x 1`` phase in (0, 1] -> ``... x 2K`` features."""
        angle = phase * self.frequencies
        return torch.cat([torch.sin(angle), torch.cos(angle)], -1)

    def normalized(self, phase: torch.Tensor, latent: torch.Tensor) -> torch.Tensor:
        """The network output before de-normalisation (what the MSE is computed on)."""
        features = self.phase_features(phase)
        latent = latent.expand(*features.shape[:-1], self.latent_dim)
        return self.net(torch.cat([features, latent], -1))

    def forward(self, phase: torch.Tensor, latent: torch.Tensor) -> torch.Tensor:
        return self.normalized(phase, latent) * self.joint_std + self.joint_mean

    def pattern(self, latent: torch.Tensor) -> torch.Tensor:
        """All N joint targets of one action for each latent: ``B x Z`` -> ``B x N x J``, in one forward pass."""
        phases = self.phases[:, None].expand(*latent.shape[:-1], self.steps_per_action, 1)
        return self(phases, latent.unsqueeze(-2))

    def config(self) -> dict:
        return {"num_joints": self.num_joints, "latent_dim": self.latent_dim, "hidden": self.hidden,
                "steps_per_action": self.steps_per_action, "periods_per_action": self.periods_per_action,
                "num_harmonics": self.num_harmonics}

    def as_module(self, phase_key="phase", latent_key="latent", out_key="joint_targets") -> TensorDictModule:
        """This policy as a TensorDict module reading ``phase`` (``B x 1``, t = n / N in (0, 1]) and ``latent``
        (``B x Z``), writing ``joint_targets`` (``B x J``, rad): one control step."""
        return TensorDictModule(self, in_keys=[phase_key, latent_key], out_keys=[out_key])

    def pattern_module(self, latent_key="latent", out_key="joint_pattern") -> TensorDictModule:
        """This policy as a TensorDict module reading ``latent`` (``B x Z``) and writing the whole action's
        ``joint_pattern`` (``B x N x J``, rad; step n at phase n / N), as :meth:`pattern`.

        Example:
            >>> import torch
            >>> from tensordict import TensorDict
            >>> policy = LatentGaitPolicy(num_joints=12, latent_dim=3, hidden=32, steps_per_action=100)
            >>> td = policy.pattern_module()(TensorDict({"latent": torch.zeros(2, 3)}, [2]))
            >>> td["joint_pattern"].shape
            torch.Size([2, 100, 12])
        """
        return TensorDictModule(GaitPattern(self), in_keys=[latent_key], out_keys=[out_key])


class GaitPattern(nn.Module):
    """``latent`` ``B x Z`` -> ``joint_targets`` ``B x N x J`` (rad): :meth:`LatentGaitPolicy.pattern` as a module."""

    def __init__(self, policy: LatentGaitPolicy):
        super().__init__()
        self.policy = policy

    def forward(self, latent: torch.Tensor) -> torch.Tensor:
        return self.policy.pattern(latent)


@dataclass
class TrainedGaitPolicy:
    """A trained policy with its expert latents (``G x Z``), latent box and training report."""

    policy: LatentGaitPolicy
    latents: torch.Tensor
    latent_low: torch.Tensor
    latent_high: torch.Tensor
    metadata: dict

    def save(self, path: str | os.PathLike) -> None:
        """Writes a checkpoint (weights, config, latents, box, metadata) to ``path`` atomically."""
        save_checkpoint(path, CHECKPOINT_KIND, CHECKPOINT_FORMAT, {
            "config": self.policy.config(), "state_dict": self.policy.state_dict(), "latents": self.latents,
            "latent_low": self.latent_low, "latent_high": self.latent_high, "metadata": self.metadata})

    @classmethod
    def load(cls, path: str | os.PathLike, map_location="cpu") -> "TrainedGaitPolicy":
        payload = load_checkpoint(path, CHECKPOINT_KIND, CHECKPOINT_FORMAT, map_location)
        try:
            policy = LatentGaitPolicy(**payload["config"])
            policy.load_state_dict(payload["state_dict"])
            trained = cls(policy, payload["latents"], payload["latent_low"], payload["latent_high"],
                          payload["metadata"])
        except (KeyError, TypeError, ValueError, RuntimeError) as error:  # weights of another shape, ...
            raise ArtifactError(f"corrupted gait policy checkpoint {path}: {' '.join(str(error).split())}") from None
        policy.eval()
        return trained


def train_gait_policy(
    joint_targets: np.ndarray,
    *,
    latent_dim: int = 3,
    periods_per_action: int = 1,
    num_harmonics: int = 8,
    hidden: int = 512,
    epochs: int = 400,
    batch_size: int = 1000,
    lr: float = 1e-3,
    latent_lr: float = 1e-2,
    latent_weight_decay: float = 1e-4,
    seed: int = 0,
    device: str = "cpu",
    progress: bool = False,
) -> TrainedGaitPolicy:
    """Fits ``pi`` and one latent per expert to ``G x N x J`` expert joint targets (rad).

    Returns the trained policy, the ``G x Z`` latents, the latent box they span, and a report in ``metadata``:
    ``rmse_per_joint`` (rad), ``rmse``, the training time and ``loss_history`` (the mean standardised MSE per epoch).
    """
    targets = torch.as_tensor(np.asarray(joint_targets), dtype=torch.float32, device="cpu")
    if targets.ndim != 3:
        raise ValueError(f"joint_targets must be G x N x J, got shape {tuple(targets.shape)}")
    num_experts, steps, joints = targets.shape
    generator = torch.Generator().manual_seed(seed)
    torch.manual_seed(seed)
    mean = targets.reshape(-1, joints).mean(0)
    std = targets.reshape(-1, joints).std(0).clamp_min(1e-3)
    policy = LatentGaitPolicy(joints, latent_dim, steps_per_action=steps, periods_per_action=periods_per_action,
                              num_harmonics=num_harmonics, hidden=hidden, joint_mean=mean, joint_std=std).to(device)
    latents = nn.Parameter(0.1 * torch.randn(num_experts, latent_dim, generator=generator, device="cpu").to(device))
    policy_optim = torch.optim.Adam(policy.parameters(), lr=lr)
    latent_optim = torch.optim.Adam([latents], lr=latent_lr, weight_decay=latent_weight_decay)

    normalized = ((targets - mean) / std).to(device).reshape(-1, joints)  # (G * N) x J
    expert_index = torch.arange(num_experts, device=device).repeat_interleave(steps)
    phase = policy.phases.repeat(num_experts)[:, None]
    total = normalized.shape[0]
    start = time.perf_counter()
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(policy_optim, T_max=epochs)
    loss_history = []  # per epoch, the mean standardised MSE over its minibatches
    for _ in tqdm(range(epochs), desc="gait policy", disable=not progress):
        order = torch.randperm(total, generator=generator, device="cpu").to(device)
        epoch_loss = torch.zeros((), device=device)
        for begin in range(0, total, batch_size):
            idx = order[begin:begin + batch_size]
            prediction = policy.normalized(phase[idx], latents[expert_index[idx]])
            loss = ((prediction - normalized[idx]) ** 2).mean()
            policy_optim.zero_grad(set_to_none=True)
            latent_optim.zero_grad(set_to_none=True)
            loss.backward()
            policy_optim.step()
            latent_optim.step()
            epoch_loss += loss.detach() * len(idx)
        loss_history.append(float(epoch_loss) / total)
        schedule.step()
    policy.eval()
    with torch.no_grad():
        reconstruction = policy.pattern(latents.detach()).cpu()
    rmse_per_joint = ((reconstruction - targets) ** 2).mean((0, 1)).sqrt()
    z = latents.detach().cpu()
    metadata = {"rmse_per_joint": rmse_per_joint.tolist(), "rmse": float(((reconstruction - targets) ** 2).mean().sqrt()),
                "train_seconds": time.perf_counter() - start, "num_experts": num_experts, "epochs": epochs,
                "seed": seed, "loss_history": loss_history}
    return TrainedGaitPolicy(policy.cpu(), z, z.min(0).values, z.max(0).values, metadata)


# ---------------------------------------------------------------------------------------------------- adaptive fit
ADAPTIVE_STEPS = ("as configured", "longer", "wider", "lower learning rate")
