"""A probabilistic ensemble CoM dynamics model, as in PETS (Chua, Calandra, McAllister, Levine, "Deep Reinforcement
Learning in a Handful of Trials using Probabilistic Dynamics Models", NeurIPS 2018), over the local-frame delta of
Li et al. (RA-L 2021, Sec. III-C; see :mod:`hierloco.components.com_model`).

``M`` members, each an MLP (2 hidden ReLU layers) on the standardised ``(vx, vy, a)``. With ``head="gaussian"``
each member predicts a mean and a log-variance of the standardised delta ``(dx, dy, dyaw, vx', vy')``, trained by the
Gaussian negative log-likelihood, the log-variance softly bounded between two learned limits (PETS, Appendix A.1);
with ``head="deterministic"`` it predicts the mean alone, trained by MSE. Each member sees its own data: a bootstrap
resample of the training transitions (``member_data="bootstrap"``) or all of them in its own order
(``member_data="shuffle"``).

Over a planning horizon the model carries ``P = M`` particles (:meth:`CoMEnsembleModel.predict_particles`):

- ``propagation="ts"``: trajectory sampling (PETS's TS-infinity): particle ``m`` is always moved by member ``m``,
  drawing from its Gaussian head (its mean with a deterministic head);
- ``propagation="mm"``: moment matching: each particle is moved as in ``ts``, then the particle set is replaced by
  ``P`` draws from the Gaussian with the particles' mean and standard deviation (per dimension; yaw about its
  circular mean);
- ``propagation="expectation"``: every member moves the particles' mean state by its head's mean; the members'
  disagreement is seen by the cost of that step, and the next state is their mean.

:meth:`CoMEnsembleModel.predict` is the deterministic mean prediction (the members' mean delta), so the ensemble
drops in wherever the MLP goes (world model, exporter, :func:`~hierloco.components.com_model.prediction_errors`).

Example:
    >>> import torch
    >>> model = CoMEnsembleModel(action_dim=3, hidden=32, members=4)
    >>> com_state = torch.zeros(2, 1, 5)                                # B x 1 x 5
    >>> model.predict(com_state, torch.rand(2, 100, 3)).shape           # B x S mean next states
    torch.Size([2, 100, 5])
    >>> model.predict_members(com_state, torch.rand(2, 100, 3)).shape   # B x S x M, one per member
    torch.Size([2, 100, 4, 5])
    >>> particles = torch.zeros(2, 100, 4, 5)                           # B x S x P particles, P = M
    >>> model.predict_particles(particles, torch.rand(2, 100, 1, 3)).shape
    torch.Size([2, 100, 4, 5])
"""

from __future__ import annotations

import math

import torch
from torch import nn

from hierloco.components.com_model import MODELS, CoMModel, _check_last_dim, apply_delta, _as_float_tensor
from hierloco.envs.frames import wrap_angle, world_to_local
from hierloco.envs.world_model import particle_moments

HEADS = ("gaussian", "deterministic")
PROPAGATIONS = ("ts", "mm", "expectation")
MEMBER_DATA = ("bootstrap", "shuffle")
LOG_VARIANCE_BOUNDS = (-10.0, 0.5)  # initial soft limits of the standardised log-variance (PETS)
BOUND_PENALTY = 0.01  # weight of the term that keeps the learned limits tight (PETS)


class EnsembleLinear(nn.Module):
    """``M`` independent linear layers applied at once: ``M x N x in`` -> ``M x N x out``.

    Each member is initialised as :class:`torch.nn.Linear` (weights and biases uniform in ``+-1/sqrt(in)``).
    """

    def __init__(self, members: int, in_features: int, out_features: int):
        super().__init__()
        bound = 1.0 / math.sqrt(in_features)
        self.weight = nn.Parameter(torch.empty(members, in_features, out_features, device="cpu").uniform_(-bound,
                                                                                                        bound))
        self.bias = nn.Parameter(torch.empty(members, 1, out_features, device="cpu").uniform_(-bound, bound))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.baddbmm(self.bias, x, self.weight)


@MODELS.register("ensemble")
class CoMEnsembleModel(CoMModel):
    """``M`` probabilistic members ``f_m(v_local, a)`` -> a Gaussian (or a point) over the local-frame delta.

    Args:
        action_dim: A, the size of the action vector.
        hidden: width of each member's 2 hidden ReLU layers.
        members: M.
        head: ``"gaussian"`` (mean and bounded log-variance, NLL) or ``"deterministic"`` (mean, MSE).
        propagation: ``"ts"``, ``"mm"`` or ``"expectation"`` (see the module doc).
        member_data: ``"bootstrap"`` or ``"shuffle"``: what each member trains on.
        input_mean, input_std: ``2 + A`` statistics of ``(vx, vy, a)``. output_mean, output_std: ``5`` statistics of
            the delta (the standardised units of the heads); kept as buffers by :class:`CoMModel`.

    Shapes: ``forward`` and :meth:`predict` take ``... x 2`` / ``... x 5`` and ``... x A`` (broadcast) and return the
    mean over members, ``... x 5``; :meth:`members` and :meth:`predict_members` return ``... x M x 5``.
    """

    def __init__(self, action_dim: int, hidden: int = 512, members: int = 5, head: str = "gaussian",
                 propagation: str = "ts", member_data: str = "bootstrap", *, input_mean: torch.Tensor | None = None,
                 input_std: torch.Tensor | None = None, output_mean: torch.Tensor | None = None,
                 output_std: torch.Tensor | None = None):
        super().__init__(action_dim, hidden, input_mean=input_mean, input_std=input_std, output_mean=output_mean,
                         output_std=output_std)
        if isinstance(members, bool) or int(members) != members or int(members) < 1:
            raise ValueError(f"members must be a whole number >= 1, got {members!r}")
        for name, value, valid in [("head", head, HEADS), ("propagation", propagation, PROPAGATIONS),
                                   ("member_data", member_data, MEMBER_DATA)]:
            if value not in valid:
                raise ValueError(f"{name} must be one of {', '.join(valid)}, got {value!r}")
        self.num_members = int(members)
        self.head, self.propagation, self.member_data = head, propagation, member_data
        outputs = 10 if head == "gaussian" else 5
        self.layers = nn.ModuleList([EnsembleLinear(self.num_members, self.num_inputs, self.hidden),
                                     EnsembleLinear(self.num_members, self.hidden, self.hidden),
                                     EnsembleLinear(self.num_members, self.hidden, outputs)])
        if head == "gaussian":
            low, high = LOG_VARIANCE_BOUNDS
            self.min_log_variance = nn.Parameter(torch.full((5,), low, device="cpu"))
            self.max_log_variance = nn.Parameter(torch.full((5,), high, device="cpu"))

    @property
    def num_particles(self) -> int:
        """P, the particles a world model carries over the horizon: one per member."""
        return self.num_members

    # ------------------------------------------------------------------------------------------ the members
    def standardised_heads(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None]:
        """``M x N x (2 + A)`` standardised inputs (member ``m`` reads row ``m``) -> mean and log-variance
        ``M x N x 5`` of the standardised delta (log-variance ``None`` with a deterministic head)."""
        h = torch.relu(self.layers[0](x))
        h = torch.relu(self.layers[1](h))
        out = self.layers[2](h)
        if self.head != "gaussian":
            return out, None
        mean, raw = out[..., :5], out[..., 5:]
        log_variance = self.max_log_variance - nn.functional.softplus(self.max_log_variance - raw)
        log_variance = self.min_log_variance + nn.functional.softplus(log_variance - self.min_log_variance)
        return mean, log_variance

    def standardised_delta(self, x: torch.Tensor) -> torch.Tensor:
        """``... x (2 + A)`` standardised inputs -> the members' mean standardised delta ``... x 5``."""
        flat = x.reshape(1, -1, x.shape[-1]).expand(self.num_members, -1, -1)
        return self.standardised_heads(flat)[0].mean(0).reshape(*x.shape[:-1], 5)

    def _per_member(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None]:
        """``... x M x in`` (member ``m`` reads ``[..., m, :]``) -> physical mean and variance ``... x M x 5``."""
        batch = x.shape[:-2]
        flat = x.reshape(-1, self.num_members, x.shape[-1]).transpose(0, 1)  # M x N x in
        mean, log_variance = self.standardised_heads(flat)
        mean = (mean * self.output_std + self.output_mean).transpose(0, 1).reshape(*batch, self.num_members, 5)
        if log_variance is None:
            return mean, None
        variance = (log_variance.exp() * self.output_std ** 2).transpose(0, 1).reshape(*batch, self.num_members, 5)
        return mean, variance

    def members(self, velocity_local, action) -> tuple[torch.Tensor, torch.Tensor | None]:
        """Every member's prediction from the same inputs: the mean ``... x M x 5`` of the delta in physical units
        and its (aleatoric) variance ``... x M x 5`` (``None`` with a deterministic head)."""
        x = self.standardised_inputs(velocity_local, action)
        return self._per_member(x.unsqueeze(-2).expand(*x.shape[:-1], self.num_members, x.shape[-1]))

    def forward(self, velocity_local, action) -> torch.Tensor:
        """``... x 2`` local velocity (m/s), ``... x A`` action -> ``... x 5`` the members' mean delta."""
        return self.members(velocity_local, action)[0].mean(-2)

    def predict_members(self, com_state, action) -> torch.Tensor:
        """``... x 5`` world state, ``... x A`` action -> ``... x M x 5``: each member's mean next world state."""
        state = _as_float_tensor(com_state)
        _check_last_dim("com_state", state, 5)
        velocity_local = world_to_local(state[..., 3:5], state[..., 2])
        delta, _ = self.members(velocity_local, action)
        return apply_delta(state.to(self.input_mean.device).unsqueeze(-2), delta)

    # ------------------------------------------------------------------------------------------ propagation
    def predict_particles(self, particles: torch.Tensor, action: torch.Tensor,
                          generator: torch.Generator | None = None) -> torch.Tensor:
        """Moves ``... x P x 5`` world-frame particles (``P = M``) through one action ``... x 1 x A`` (or
        ``... x P x A``) by the model's ``propagation`` (see the module doc); returns ``... x P x 5``.

        Draws (``ts``, ``mm`` with a Gaussian head; ``mm`` always) come from ``generator``.
        """
        _check_last_dim("particles", particles, 5)
        if particles.shape[-2] != self.num_members:
            raise ValueError(f"need {self.num_members} particles (one per member), got {particles.shape[-2]}")
        if self.propagation == "expectation":
            if action.shape[-2] != 1:
                raise ValueError("propagation 'expectation' moves the particles' mean: give one action (... x 1 x A)")
            mean, _ = particle_moments(particles)
            return self.predict_members(mean, action.squeeze(-2))
        velocity_local = world_to_local(particles[..., 3:5], particles[..., 2])
        x = self.standardised_inputs(velocity_local, action)
        mean, variance = self._per_member(x)
        if variance is not None:
            noise = torch.randn(mean.shape, generator=generator, device=mean.device, dtype=mean.dtype)
            mean = mean + variance.sqrt() * noise
        moved = apply_delta(particles, mean)
        if self.propagation == "ts":
            return moved
        centre, spread = particle_moments(moved)
        noise = torch.randn(moved.shape, generator=generator, device=moved.device, dtype=moved.dtype)
        drawn = centre.unsqueeze(-2) + spread.unsqueeze(-2) * noise
        return torch.cat([drawn[..., :2], wrap_angle(drawn[..., 2:3]), drawn[..., 3:]], -1)

    # ------------------------------------------------------------------------------------------ training
    def training_rows(self, num_train: int, generator: torch.Generator) -> torch.Tensor:
        """``M x num_train`` indices of the training transitions each member learns from (drawn once)."""
        if self.member_data == "bootstrap":
            return torch.randint(num_train, (self.num_members, num_train), generator=generator, device="cpu")
        return torch.arange(num_train, device="cpu").expand(self.num_members, num_train)

    def epoch_order(self, rows: torch.Tensor, num_train: int, generator: torch.Generator) -> torch.Tensor:
        """``M x num_train``: each member's rows in a new random order for one epoch."""
        permutation = torch.rand(rows.shape, generator=generator, device="cpu").argsort(-1)
        return rows.gather(-1, permutation)

    def training_loss(self, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        """The loss on ``M x b x (2 + A)`` standardised inputs and ``M x b x 5`` standardised targets: the Gaussian
        NLL (up to a constant) plus the bound penalty, or the MSE with a deterministic head."""
        mean, log_variance = self.standardised_heads(x)
        if log_variance is None:
            return ((mean - y) ** 2).mean()
        nll = (((mean - y) ** 2) * torch.exp(-log_variance) + log_variance).mean()
        return nll + BOUND_PENALTY * (self.max_log_variance.sum() - self.min_log_variance.sum())

    @torch.no_grad()
    def standardised_prediction(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The predictive mean and variance ``N x 5`` of the standardised delta for ``N x (2 + A)`` standardised
        inputs: the members' mixture summarised by its first two moments (the mixture's mean; the mean of the
        members' variances plus the variance of their means)."""
        mean, log_variance = self.standardised_heads(x.unsqueeze(0).expand(self.num_members, *x.shape))
        aleatoric = torch.zeros_like(mean) if log_variance is None else log_variance.exp()
        centre = mean.mean(0)
        return centre, aleatoric.mean(0) + mean.var(0, correction=0)

    def heldout_loss(self, x: torch.Tensor, y: torch.Tensor) -> float:
        """The standardised MSE of the ensemble's mean on ``N`` held-out rows (what early stopping watches)."""
        centre, _ = self.standardised_prediction(x)
        return float(((centre - y) ** 2).mean())

    def heldout_report(self, x: torch.Tensor, y: torch.Tensor) -> dict:
        """Held-out calibration in standardised units: ``heldout_nll`` (the Gaussian NLL per dimension of the
        moment-matched prediction, including ``log(2 pi) / 2``), ``heldout_coverage_2std`` (the fraction of targets
        within two predicted standard deviations; 0.95 for a calibrated Gaussian), and the members' mean disagreement
        ``heldout_member_std`` (the standard deviation of their means, averaged)."""
        centre, variance = self.standardised_prediction(x)
        variance = variance.clamp_min(1e-8)
        nll = 0.5 * (((centre - y) ** 2) / variance + variance.log() + math.log(2 * math.pi)).mean()
        with torch.no_grad():
            means, _ = self.standardised_heads(x.unsqueeze(0).expand(self.num_members, *x.shape))
        return {"heldout_nll": float(nll),
                "heldout_coverage_2std": float(((centre - y).abs() <= 2 * variance.sqrt()).float().mean()),
                "heldout_member_std": float(means.std(0, correction=0).mean())}


CALIBRATION_OUTPUTS = ("dx", "dy", "dyaw", "vx", "vy")  # the local-frame delta: m, m, rad, m/s, m/s


@torch.no_grad()
def transition_calibration(model: CoMEnsembleModel, com_state, action, next_com_state) -> dict[str, list[float]]:
    """Whether the members' disagreement tells where the model is wrong, on ``N`` transitions: ``N x 5`` world CoM
    states before and after one action, ``N x A`` action features (e.g. transitions collected on a damaged or
    perturbed robot the model never saw).

    Per output of the local-frame delta (:data:`CALIBRATION_OUTPUTS`): ``error``, the RMS error of the members'
    mean; ``spread``, the RMS over transitions of the members' standard deviation about their mean (the epistemic
    part, what ``planner.risk`` weighs); ``noise``, the RMS of the Gaussian heads' standard deviation (the aleatoric
    part, 0 with a deterministic head); ``coverage``, the fraction of transitions whose error lies within two
    predictive standard deviations (spread and noise together; 0.95 for a calibrated Gaussian).

        >>> model = CoMEnsembleModel(action_dim=3, hidden=16, members=3)
        >>> state = torch.zeros(4, 5)
        >>> report = transition_calibration(model, state, torch.rand(4, 3), state)
        >>> sorted(report), len(report["error"])
        (['coverage', 'error', 'noise', 'spread'], 5)
    """
    from hierloco.components.com_model import local_transition

    state, next_state = _as_float_tensor(com_state), _as_float_tensor(next_com_state)
    velocity_local, delta = local_transition(state, next_state)
    means, variances = model.members(velocity_local.float(), _as_float_tensor(action))  # N x M x 5
    delta = delta.to(means)
    centre = means.mean(-2)
    error = centre - delta
    error = torch.cat([error[..., :2], wrap_angle(error[..., 2:3]), error[..., 3:]], -1)
    spread = means.std(-2, correction=0)
    noise = torch.zeros_like(spread) if variances is None else variances.mean(-2).sqrt()
    total = (spread ** 2 + noise ** 2).sqrt()

    def rms(x: torch.Tensor) -> list[float]:
        return [float(v) for v in x.pow(2).mean(0).sqrt()]

    return {"error": rms(error), "spread": rms(spread), "noise": rms(noise),
            "coverage": [float(v) for v in (error.abs() <= 2 * total).float().mean(0)]}


__all__ = ["CALIBRATION_OUTPUTS", "HEADS", "MEMBER_DATA", "PROPAGATIONS", "CoMEnsembleModel", "EnsembleLinear",
           "transition_calibration"]
