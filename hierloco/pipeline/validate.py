"""Artifacts checked against the stage that made them before anything uses them.

An artifact can load and still be wrong: arrays of another shape than the config asks for, non-finite weights,
non-finite or forged costs. :func:`validate` checks each kind of artifact against its stage's ``params`` and the
robot (shapes, finiteness, rows against their own summary), and raises :class:`hierloco.io.ArtifactError` naming
the file and what is wrong; the run then stops with that one line and rewrites nothing (``docs/pipeline.md``).

Example:
    >>> import numpy as np
    >>> from hierloco.results import TaskEvaluation
    >>> rows = [{"normalized_cost": 0.2}, {"normalized_cost": 0.4}]
    >>> evaluation = TaskEvaluation(rows, {"normalized_cost": 0.3})
    >>> check_evaluation(evaluation, "e.npz")
    >>> evaluation.rows[0]["normalized_cost"] = 0.0123
    >>> try:
    ...     check_evaluation(evaluation, "e.npz")
    ... except ArtifactError as error:
    ...     print(error)
    e.npz: its rows' mean normalised cost 0.206 differs from the summary it was saved with (0.300)
"""

from __future__ import annotations

import math

import numpy as np

from hierloco.io import ArtifactError, brief


def _finite_array(name: str, value, where) -> None:
    array = np.asarray(value)
    if array.dtype.kind in "fc" and not np.all(np.isfinite(array)):
        raise ArtifactError(f"{where}: {name} holds NaN or inf")


def _finite_module(module, where) -> None:
    import torch

    for name, tensor in list(module.state_dict().items()):
        if torch.is_tensor(tensor) and tensor.is_floating_point() and not bool(torch.isfinite(tensor).all()):
            raise ArtifactError(f"{where}: weight {name} holds NaN or inf")


def _shape(name: str, array, expected: tuple, where) -> None:
    shape = tuple(np.shape(array))
    if len(shape) != len(expected) or any(e is not None and s != e for s, e in zip(shape, expected)):
        wanted = " x ".join("?" if e is None else str(e) for e in expected)
        raise ArtifactError(f"{where}: {name} has shape {shape}, expected {wanted}")


def check_expert_library(library, params: dict, robot, where) -> None:
    num = params.get("num_experts")
    steps = params.get("steps_per_action")
    joints = robot.num_joints
    _shape("joint_targets", library.joint_targets, (num, steps, joints), where)
    _shape("commands", library.commands, (num, 3), where)
    _shape("com_states", library.com_states, (num, None if steps is None else steps + 1, 5), where)
    _shape("velocity_local", library.velocity_local, (num, 2), where)
    for name in ("joint_targets", "commands", "com_states", "velocity_local", "yaw_rate", "displacement_local"):
        _finite_array(name, getattr(library, name), where)


def check_gait_policy(trained, where) -> None:
    _finite_module(trained.policy, where)
    for name in ("latents", "latent_low", "latent_high"):
        _finite_array(name, getattr(trained, name).detach().cpu().numpy(), where)


def check_transitions(data, params: dict, where, low_level: dict | None = None) -> None:
    """Transitions of the stage's size whose actions are those of the low level they were collected on: one column
    per dimension of the action box their metadata records (``low_level``: the low level's description), of the
    kind the stage's key names (``low_level``: the key's ``low_level`` entry, e.g. ``{"kind": "latent", ...}``).
    A dynamics model fitted to actions of another width would only fail later, at the first plan."""
    count = len(data.com_state)
    _shape("com_state", data.com_state, (count, 5), where)
    _shape("next_com_state", data.next_com_state, (count, 5), where)
    if np.ndim(data.action) != 2 or len(data.action) != count:
        raise ArtifactError(f"{where}: action has shape {np.shape(data.action)}, expected {count} x A")
    described = data.metadata.get("low_level")
    box = [described.get(end) for end in ("action_low", "action_high")] if isinstance(described, dict) else None
    if box is None or not all(isinstance(end, list) and end for end in box) or len(box[0]) != len(box[1]):
        raise ArtifactError(f"{where}: its metadata does not describe the low level it was collected on (low_level "
                            "with its action box action_low, action_high)")
    kind = described.get("kind")
    wanted = low_level.get("kind") if isinstance(low_level, dict) else None
    if wanted is not None and kind != wanted:
        raise ArtifactError(f"{where}: collected on a {brief(kind)} low level, the stage asks for a {wanted!r} one")
    if np.shape(data.action)[1] != len(box[0]):
        raise ArtifactError(f"{where}: action has {np.shape(data.action)[1]} column(s), but the {brief(kind)} low "
                            f"level it was collected on has {len(box[0])} action dimension(s) (its action box)")
    wanted = params.get("num_transitions")
    if wanted is not None and count != wanted:
        raise ArtifactError(f"{where}: {count} transitions, the stage asks for {wanted}")
    for name in ("com_state", "action", "next_com_state"):
        _finite_array(name, getattr(data, name), where)


def check_com_model(trained, where) -> None:
    _finite_module(trained.model, where)


def check_evaluation(evaluation, where) -> None:
    """Finite per-episode costs, a finite summary, and rows that agree with the summary saved beside them."""
    costs = [row.get("normalized_cost") for row in evaluation.rows]
    if not costs or any(not isinstance(c, (int, float)) or not math.isfinite(c) or c < 0 for c in costs):
        raise ArtifactError(f"{where}: its per-episode normalised costs are not all finite numbers >= 0")
    summary = evaluation.metrics.get("normalized_cost")
    if not isinstance(summary, (int, float)) or not math.isfinite(summary):
        raise ArtifactError(f"{where}: its summary normalised cost is {summary!r}")
    if abs(float(np.mean(costs)) - summary) > 1e-9 * max(1.0, abs(summary)):
        raise ArtifactError(f"{where}: its rows' mean normalised cost {np.mean(costs):.3f} differs from the summary "
                            f"it was saved with ({summary:.3f})")


def check_sac_agent(agent, where) -> None:
    for name in ("actor", "qvalue", "loss_module"):
        module = getattr(agent, name, None)
        if module is not None and hasattr(module, "state_dict"):
            _finite_module(module, where)
            return


def validate(stage, artifact, robot, where) -> None:
    """Checks ``artifact`` (loaded or just built for ``stage``) against the stage's params and the robot."""
    from hierloco.components.com_model import TrainedCoMModel
    from hierloco.components.dynamics_data import TransitionData
    from hierloco.components.expert_library import ExpertLibrary
    from hierloco.components.gait_policy import TrainedGaitPolicy
    from hierloco.results import TaskEvaluation

    if isinstance(artifact, ExpertLibrary):
        check_expert_library(artifact, stage.params, robot, where)
    elif isinstance(artifact, TrainedGaitPolicy):
        check_gait_policy(artifact, where)
    elif isinstance(artifact, TransitionData):
        check_transitions(artifact, stage.params, where, (stage.after or {}).get("low_level"))
    elif isinstance(artifact, TrainedCoMModel):
        check_com_model(artifact, where)
    elif isinstance(artifact, TaskEvaluation):
        from hierloco.pipeline.report import checked_rows

        check_evaluation(artifact, where)
        checked_rows(artifact, stage.params, where)  # rows against their recording and their stage's labels
    elif type(artifact).__name__ == "SACAgent":
        check_sac_agent(artifact, where)


__all__ = ["ArtifactError", "check_evaluation", "validate"]
