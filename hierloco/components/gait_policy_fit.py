"""A gait policy fitted until it reproduces its experts in simulation (Li et al., RA-L 2021, Sec. III-B: pi(., z_g)
must walk like expert g): :func:`fit_gait_policy` adapts the training (longer, wider, a lower learning rate) before
a run gives up (``policy.adaptive=true``; ``docs/robots.md``)."""

from __future__ import annotations

import time
from dataclasses import dataclass

from hierloco.components.evaluation import check_gait_policy, replayed_fraction
from hierloco.components.gait_policy import TrainedGaitPolicy, train_gait_policy
from hierloco.components.low_level import LatentLowLevel
from hierloco.envs.locomotion import periods_per_action as gait_periods
from hierloco.envs.robots import get_robot


@dataclass
class GaitPolicyFit:
    """A gait policy fitted until it reproduces its experts in simulation (:func:`fit_gait_policy`).

    Attributes:
        trained: the fit kept (the first that reaches the bar, else the one that reproduces most).
        check: its :func:`hierloco.components.evaluation.check_gait_policy` result.
        attempts: every fit tried, in order: ``name``, ``epochs``, ``hidden``, ``num_harmonics``, ``lr``,
            ``overrides`` (those that differ from the configured ones: the recipe's ``policy.*`` overrides that
            train it), ``reproduced_fraction``, ``rmse`` and ``seconds``.
        min_reproduced_fraction: the bar.
    """

    trained: TrainedGaitPolicy
    check: dict
    attempts: list[dict]
    min_reproduced_fraction: float
    experts_replayed_fraction: float | None = None

    @property
    def limited_by_experts(self) -> bool:
        """The experts' own targets, replayed open loop, reproduce fewer than the bar: no fit can reach it."""
        return self.experts_replayed_fraction is not None and \
            self.experts_replayed_fraction < self.min_reproduced_fraction

    @property
    def reproduced_fraction(self) -> float:
        return float(self.check["reproduced_fraction"])

    @property
    def ok(self) -> bool:
        return self.reproduced_fraction >= self.min_reproduced_fraction


def fit_gait_policy(
    library,
    *,
    robot=None,
    min_reproduced_fraction: float = 0.8,
    adaptive: bool = True,
    budget_epochs: int | None = None,
    budget_seconds: float | None = None,
    min_attempts: int = 1,
    check_pairs: int = 50,
    check_actions: int = 4,
    periods_per_action: int | None = None,
    progress: bool = False,
    **train_kwargs,
) -> GaitPolicyFit:
    """Trains the gait policy on ``library``'s experts, checks it in simulation, and when it reproduces fewer
    than ``min_reproduced_fraction`` of them, adapts the training before giving up (Li et al., Sec. III-B: pi(., z_g)
    must walk like expert g).

    The ladder, stopping at the first fit that reaches the bar; every fit is :func:`train_gait_policy` from scratch,
    so each is what a recipe trains with the ``policy`` overrides its attempt records (``overrides``):

    1. ``"as configured"``: ``train_kwargs`` as given (what the pipeline trains without this function; with
       ``adaptive=False`` that is all);
    2. ``"longer"``: twice the epochs;
    3. ``"wider"``: twice the epochs, twice the hidden units and twice the phase harmonics (up to the Nyquist limit:
       short swing phases in long periods need them);
    4. ``"lower learning rate"``: the wider network for four times the epochs at a third of the learning rate.

    Steps after the first ``min_attempts`` run only while their epochs fit in ``budget_epochs`` (all fits together;
    deterministic: the choice for a cached pipeline stage) and their estimated time in ``budget_seconds`` (from the
    first fit's speed). Before adapting, the experts' own targets are replayed open loop
    (:func:`hierloco.components.evaluation.replayed_fraction`): when they reproduce fewer than the bar, no fit can
    reach it and the ladder stops there (``limited_by_experts``: the experts need other parameters,
    ``hierloco-robot-check``).

    Args:
        library: a :class:`hierloco.components.expert_library.ExpertLibrary`.
        robot: its robot (default: the library's).
        periods_per_action: gait periods per action (default: from the robot's gait period).
        min_attempts: fits tried whatever the budgets (while the experts' own replay reaches the bar).
        check_pairs, check_actions: :func:`hierloco.components.evaluation.check_gait_policy`'s ``num_pairs`` and
            ``num_actions``.
        **train_kwargs: :func:`train_gait_policy`'s keyword arguments (``epochs``, ``hidden``, ``lr``, ``seed``...).

    Example:
        >>> from hierloco.components.expert_library import build_expert_library
        >>> library = build_expert_library("daisy", 4, settle_time=1.0, progress=False)  # doctest: +SKIP
        >>> fit = fit_gait_policy(library, epochs=50, hidden=64, budget_epochs=300)  # doctest: +SKIP
        >>> [a["name"] for a in fit.attempts], fit.ok  # doctest: +SKIP
        (['as configured'], True)
    """
    robot = get_robot(robot if robot is not None else library.robot)
    if periods_per_action is None:
        periods_per_action = gait_periods(robot, library.steps_per_action)
    epochs = int(train_kwargs.pop("epochs", 400))
    hidden = int(train_kwargs.pop("hidden", 512))
    harmonics = int(train_kwargs.pop("num_harmonics", 8))
    lr = float(train_kwargs.pop("lr", 1e-3))
    seed = int(train_kwargs.get("seed", 0))
    nyquist = max(1, (library.steps_per_action // periods_per_action) // 2)
    configured = dict(epochs=epochs, hidden=hidden, num_harmonics=harmonics, lr=lr)
    plan = [("as configured", configured)]
    if adaptive:
        wide = dict(hidden=2 * hidden, num_harmonics=min(2 * harmonics, nyquist))
        plan += [("longer", {**configured, "epochs": 2 * epochs}),
                 ("wider", {**configured, "epochs": 2 * epochs, **wide}),
                 ("lower learning rate", {**configured, "epochs": 4 * epochs, "lr": lr / 3, **wide})]
    start = time.perf_counter()
    attempts, fits, spent_epochs, seconds_per_epoch, ceiling = [], [], 0, None, None
    for name, options in plan:
        if attempts:
            if ceiling is None:
                ceiling = replayed_fraction(library, robot=robot, num_actions=check_actions, seed=seed)
            if ceiling < min_reproduced_fraction:
                break
            cost = options["epochs"] * (options["hidden"] / hidden) ** 2  # in epochs of the configured width
            within = len(attempts) < min_attempts or (
                (budget_epochs is None or spent_epochs + options["epochs"] <= budget_epochs)
                and (budget_seconds is None or time.perf_counter() - start + cost * seconds_per_epoch
                     <= budget_seconds))
            if not within:
                break
        tic = time.perf_counter()
        trained = train_gait_policy(library.joint_targets, periods_per_action=periods_per_action, progress=progress,
                                    **options, **train_kwargs)
        check = check_gait_policy(LatentLowLevel(trained, robot), library, trained.latents.numpy(),
                                  num_pairs=check_pairs, num_actions=check_actions, seed=seed)
        seconds = time.perf_counter() - tic
        if seconds_per_epoch is None:
            seconds_per_epoch = seconds / max(epochs, 1)
        spent_epochs += options["epochs"]
        overrides = {key: value for key, value in options.items() if value != configured[key]}
        attempts.append({"name": name, "epochs": options["epochs"], "hidden": trained.policy.hidden,
                         "num_harmonics": trained.policy.num_harmonics, "lr": options["lr"], "overrides": overrides,
                         "reproduced_fraction": float(check["reproduced_fraction"]),
                         "rmse": float(trained.metadata["rmse"]), "seconds": seconds})
        fits.append((trained, check))
        if check["reproduced_fraction"] >= min_reproduced_fraction:
            break
    best = next((i for i, (_, c) in enumerate(fits) if c["reproduced_fraction"] >= min_reproduced_fraction),
                max(range(len(fits)), key=lambda i: fits[i][1]["reproduced_fraction"]))
    trained, check = fits[best]
    trained.metadata["adaptive_fit"] = {"attempts": attempts, "kept": attempts[best]["name"],
                                        "min_reproduced_fraction": float(min_reproduced_fraction),
                                        "experts_replayed_fraction": ceiling}
    return GaitPolicyFit(trained=trained, check=check, attempts=attempts,
                         min_reproduced_fraction=float(min_reproduced_fraction), experts_replayed_fraction=ceiling)


__all__ = ["GaitPolicyFit", "fit_gait_policy"]
