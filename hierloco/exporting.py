"""Export of a trained run for deployment: ONNX and TorchScript files and a ``manifest.json``.

The hierarchy of Li et al., "Planning in Learned Latent Action Spaces for Generalizable Legged Locomotion"
(RA-L 2021) needs three functions on a robot: the latent gait policy ``pi(t, z)`` (joint targets at 100 Hz), the CoM
dynamics model over one action, and the planner's scoring of candidate actions with that model (MPC over z at about
1 Hz). :func:`export_run` writes each of them, from the artifacts a run directory holds, as an ONNX file (checked
with onnxruntime) and a TorchScript file (checked with ``torch.jit.load``), both against PyTorch on random inputs:

=========================  ===========================================================  ============================
file stem                  inputs -> outputs (float32)                                  from
=========================  ===========================================================  ============================
``gait_policy_pattern``    ``latent`` B x Z -> ``joint_targets`` B x N x J (rad)        ``gait_policy.pt``
``gait_policy_step``       ``phase`` B x 1, ``latent`` B x Z -> ``joint_targets`` B x J  ``gait_policy.pt``
``com_model_predict``      ``com_state`` B x 5, ``action`` B x A -> ``next_com_state``   ``dynamics_model_<setting>``
``planner_model_step``     ``com_state`` B x 5, ``candidates`` B x S x A -> B x S x 5    ``dynamics_model_<setting>``
``score_goal_reaching``    ``com_state`` B x 5, ``candidates`` B x S x H x A,            ``dynamics_model_<setting>``
                           ``target`` B x H x 2 (goal, m) -> ``cost`` B x S
``score_velocity_tracking`` same, ``target`` B x H x 2 (velocity, m/s) -> ``cost`` B x S  ``dynamics_model_<setting>``
``com_model_members``      ``com_state`` B x 5, ``action`` B x A -> B x M x 5            an ensemble's
=========================  ===========================================================  ============================

The dynamics model is any model of the registry :data:`hierloco.components.com_model.MODELS` (its checkpoint names
it, with the options it was trained with, which the manifest's ``dynamics_model`` records; a model named by import
path is imported only when ``trust_imports`` lists it): the paper's MLP, a user's
:class:`~hierloco.components.com_model.CoMModel`, or the probabilistic ensemble, whose exported prediction is its
members' mean (the planner's scoring with that mean) and which also exports every member's prediction
(``com_model_members``, M members), for a risk-aware planner on the robot.

CoM states are world-frame ``(x, y, yaw, vx, vy)`` in m, rad, m/s. The scoring rolls the model ``H`` actions ahead
and sums the task cost ``w1 |target - .| + w2 |yaw_target - yaw|`` of every step (``[w1, w2] = [2, 1]``, the yaw
target the start heading); the planner keeps the candidate of lowest cost. ``score_goal_reaching`` also scores
trajectory tracking (target: the reference point of each step). For LIB runs the action is the model's one-hot
expert vector (``A = G``), for IK the velocity command; runs without a gait policy (LIB, IK) export only the model.
``manifest.json`` (written last) describes every file: inputs and outputs with shapes and units, the latent box,
the expert latents, the robot's joint order, and the measured agreement with PyTorch. From a shell:
``python -m hierloco.exporting RUN_DIR OUT_DIR [--setting legs_disabled] [--trust-import pkg.module:Class]``.

Example:
    >>> import tempfile, numpy as np, onnxruntime
    >>> from hierloco.components.com_model import train_com_model
    >>> rng = np.random.default_rng(0)
    >>> state, action = rng.normal(size=(200, 5)), rng.uniform(-1, 1, size=(200, 3))
    >>> run_dir, out_dir = tempfile.mkdtemp(), tempfile.mkdtemp()
    >>> train_com_model(state, action, state + 0.1, hidden=16, max_epochs=2, progress=False).save(
    ...     f"{run_dir}/dynamics_model_normal.pt")
    >>> manifest = export_run(run_dir, out_dir)  # doctest: +ELLIPSIS
    >>> sorted(manifest["models"])
    ['com_model_predict', 'planner_model_step', 'score_goal_reaching', 'score_velocity_tracking']
    >>> session = onnxruntime.InferenceSession(f"{out_dir}/planner_model_step.onnx")
    >>> session.run(None, {"com_state": np.zeros((2, 5), np.float32),
    ...                    "candidates": np.zeros((2, 100, 3), np.float32)})[0].shape
    (2, 100, 5)
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
import math
import os
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from hierloco.components.com_model import CoMDynamicsModel, CoMModel, TrainedCoMModel, model_name
from hierloco.components.gait_policy import LatentGaitPolicy, TrainedGaitPolicy
from hierloco.envs.robots import CONTROL_TIMESTEP, get_robot
from hierloco.envs.tasks import GoalReaching, Task, VelocityTracking, W_POSITION, W_YAW
from hierloco.io import ArtifactError, atomic_path, load_arrays, load_yaml, write_text
from hierloco.registry import is_import_path

MANIFEST_FORMAT = 1
DEFAULT_OPSET = 18
TOLERANCE = 1e-5  # largest absolute difference allowed between an exported function and PyTorch
COM_STATE_UNITS = "world frame (x m, y m, yaw rad, vx m/s, vy m/s)"


# ---------------------------------------------------------------------------------------------------- functions
class GaitPolicyPattern(nn.Module):
    """``latent`` ``B x Z`` -> ``joint_targets`` ``B x N x J`` (rad): the whole action of ``pi(., z)``."""

    def __init__(self, policy: LatentGaitPolicy):
        super().__init__()
        self.policy = policy

    def forward(self, latent: torch.Tensor) -> torch.Tensor:
        return self.policy.pattern(latent)


class GaitPolicyStep(nn.Module):
    """``phase`` ``B x 1`` (``t = n / N``) and ``latent`` ``B x Z`` -> ``joint_targets`` ``B x J`` (rad)."""

    def __init__(self, policy: LatentGaitPolicy):
        super().__init__()
        self.policy = policy

    def forward(self, phase: torch.Tensor, latent: torch.Tensor) -> torch.Tensor:
        return self.policy(phase, latent)


class CoMPredict(nn.Module):
    """``com_state`` ``B x 5`` and ``action`` ``B x A`` -> the world-frame ``next_com_state`` ``B x 5``."""

    def __init__(self, model: CoMModel):
        super().__init__()
        self.model = model

    def forward(self, com_state: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return self.model.predict(com_state, action)


class CoMMembers(nn.Module):
    """``com_state`` ``B x 5`` and ``action`` ``B x A`` -> each member's world-frame next state ``B x M x 5`` (a model
    with members: the ensemble)."""

    def __init__(self, model: nn.Module):
        super().__init__()
        self.model = model

    def forward(self, com_state: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return self.model.predict_members(com_state, action)


class CoMPlannerStep(nn.Module):
    """``com_state`` ``B x 5`` and ``candidates`` ``B x S x A`` -> next states ``B x S x 5``: the model step with
    which the planner imagines S candidate actions from each of B states."""

    def __init__(self, model: CoMModel):
        super().__init__()
        self.model = model

    def forward(self, com_state: torch.Tensor, candidates: torch.Tensor) -> torch.Tensor:
        return self.model.predict(com_state.unsqueeze(-2), candidates)


class TaskScoring(nn.Module):
    """The planner's score as a function of the target: total cost ``B x S`` of ``B x S x H x A`` candidate action
    sequences from ``B x 5`` states against ``B x H x 2`` targets (one per step of the horizon), the model rolled
    out ``H`` actions (the horizon is fixed by the candidates' shape at export).

    Example:
        >>> import torch
        >>> from hierloco.envs.tasks import GoalReaching
        >>> scoring = TaskScoring(CoMDynamicsModel(action_dim=2, hidden=8), GoalReaching())
        >>> scoring(torch.zeros(3, 5), torch.rand(3, 50, 2, 2), torch.ones(3, 2, 2)).shape
        torch.Size([3, 50])
    """

    def __init__(self, model: CoMModel, task: Task):
        super().__init__()
        self.model = model
        self.task = task

    def forward(self, com_state: torch.Tensor, candidates: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        state = com_state.unsqueeze(-2)  # B x 1 x 5, broadcast against the S candidates
        total = torch.zeros_like(candidates[:, :, 0, 0])  # B x S (traced from a tensor, so S stays free)
        for step in range(candidates.shape[2]):
            next_state = self.model.predict(state, candidates[:, :, step])
            total = total + self.task.cost_to_target(state, next_state, target[:, step].unsqueeze(-2))
            state = next_state
        return total


# ---------------------------------------------------------------------------------------------------- run dir
def _read_low_level(run_dir: Path, setting: str) -> dict | None:
    """The low level the dynamics data of ``setting`` was collected on (kind, robot, action box), if recorded."""
    path = run_dir / f"dynamics_data_{setting}.npz"
    if not path.exists():
        return None
    _, metadata = load_arrays(path)
    return metadata.get("low_level")


def _read_run_config(run_dir: Path) -> dict:
    path = run_dir / "config.yaml"
    if not path.exists():
        return {}
    try:
        config = load_yaml(path)  # a received file: read safely (no YAML bomb), errors in one bounded line
    except ArtifactError as error:
        raise ArtifactError(f"corrupted run config: {error}") from None
    return config if isinstance(config, dict) else {}


def _joint_names(robot_name: str | None, num_joints: int) -> list[str] | None:
    if not robot_name:
        return None
    try:
        names = list(get_robot(robot_name).joint_names)
    except ValueError:  # a robot this process has not registered
        return None
    return names if len(names) == num_joints else None


def _action_description(low_level: dict | None, action_dim: int) -> tuple[dict, str]:
    """The manifest's ``action`` entry and the units text of an action vector."""
    kind = (low_level or {}).get("kind")
    entry = {"kind": kind, "dim": action_dim}
    if low_level:
        entry.update(action_low=low_level.get("action_low"), action_high=low_level.get("action_high"),
                     num_choices=low_level.get("num_choices"))
    if kind == "expert_replay":
        entry["features"] = "one_hot"
        return entry, f"one-hot expert index (G = {action_dim}): action g is the vector with a 1 at index g"
    if kind == "command":
        return entry, "desired CoM velocity command (vx m/s, vy m/s, yaw_rate rad/s) in the robot's local frame"
    if kind == "latent":
        return entry, "latent action z (unitless), inside latent_box"
    return entry, "the action vector the dynamics model was trained on"


# ---------------------------------------------------------------------------------------------------- export
def _quiet():
    """Silences torch's exporter chatter (progress lines, tracer and deprecation warnings) within the block."""
    stack = contextlib.ExitStack()
    stack.enter_context(contextlib.redirect_stdout(io.StringIO()))
    stack.enter_context(warnings.catch_warnings())
    warnings.simplefilter("ignore")
    for name in ("torch.onnx", "torch.export", "torch._export", "torch.fx", "onnxscript"):
        logger = logging.getLogger(name)
        previous = logger.level
        logger.setLevel(logging.ERROR)
        stack.callback(logger.setLevel, previous)
    return stack


def _export_onnx(module: nn.Module, example: tuple, names: list[str], outputs: list[str],
                 dynamic: list[dict[int, str]], path: Path, opset: int) -> None:
    dims: dict[str, Any] = {}
    shapes = tuple({axis: dims.setdefault(label, torch.export.Dim(label)) for axis, label in spec.items()}
                   for spec in dynamic)
    with atomic_path(path) as tmp, _quiet():
        torch.onnx.export(module, example, tmp, input_names=names, output_names=outputs, dynamic_shapes=shapes,
                          opset_version=opset, dynamo=True, external_data=False, verbose=False)


def _export_torchscript(module: nn.Module, example: tuple, path: Path) -> None:
    with _quiet():
        traced = torch.jit.trace(module, example, check_trace=False)
    with atomic_path(path) as tmp:
        torch.jit.save(traced, tmp)


def _max_error(reference: torch.Tensor, value) -> float:
    value = torch.as_tensor(np.asarray(value), device="cpu") if not isinstance(value, torch.Tensor) else value
    if tuple(value.shape) != tuple(reference.shape):
        return math.inf
    return float((value.double() - reference.double()).abs().max())


def _verify(module: nn.Module, onnx_path: Path, script_path: Path, names: list[str],
            checks: list[tuple]) -> dict[str, float]:
    """Largest absolute difference to PyTorch of the ONNX (onnxruntime) and TorchScript files over ``checks``."""
    import onnxruntime

    options = onnxruntime.SessionOptions()
    options.intra_op_num_threads = 1
    session = onnxruntime.InferenceSession(str(onnx_path), options, providers=["CPUExecutionProvider"])
    with _quiet():
        script = torch.jit.load(str(script_path))
    errors = {"onnx": 0.0, "torchscript": 0.0}
    with torch.no_grad():
        for inputs in checks:
            reference = module(*inputs)
            onnx_out = session.run(None, {n: x.numpy() for n, x in zip(names, inputs)})[0]
            errors["onnx"] = max(errors["onnx"], _max_error(reference, onnx_out))
            errors["torchscript"] = max(errors["torchscript"], _max_error(reference, script(*inputs)))
    return errors


def _uniform(generator, shape, low, high) -> torch.Tensor:
    low = torch.as_tensor(low, dtype=torch.float32, device="cpu")
    high = torch.as_tensor(high, dtype=torch.float32, device="cpu")
    return low + (high - low) * torch.rand(shape, generator=generator, device="cpu")


def _random_states(generator, batch: int) -> torch.Tensor:
    """``batch x 5`` world CoM states: positions within 5 m, any heading, speeds up to 0.5 m/s."""
    return _uniform(generator, (batch, 5), [-5, -5, -math.pi, -0.5, -0.5], [5, 5, math.pi, 0.5, 0.5])


def export_run(run_dir: str | os.PathLike, out_dir: str | os.PathLike, *, setting: str = "normal",
               horizon: int | None = None, opset: int = DEFAULT_OPSET, seed: int = 0, trust_imports=()) -> dict:
    """Exports what a run directory holds for deployment; returns the manifest (also ``out_dir/manifest.json``).

    Args:
        run_dir: a recipe's run directory: ``gait_policy.pt`` (LAT, SAC) and/or ``dynamics_model_<setting>.pt``
            (LAT, LIB, IK); ``dynamics_data_<setting>.npz`` and ``config.yaml``, when present, describe the action
            and the robot.
        out_dir: where the files go (created; files of the same names are replaced atomically).
        setting: which dynamics model, ``"normal"`` or ``"legs_disabled"`` (the adverse setting).
        horizon: H of the exported scoring; default the run's ``planner.horizon`` (``config.yaml``), else 1.
        opset: the ONNX opset. seed: seeds the random inputs of the checks.
        trust_imports: import paths (``pkg.module:Class``) the model's checkpoint may name (imported then); a run
            directory's files are data, so any other import path in them is refused.

    Raises:
        ValueError: no such run directory, no artifact to export, a bad horizon or opset, artifacts that do not
            fit together (:class:`hierloco.io.ArtifactError` for a corrupted file), before anything is written.
        RuntimeError: an exported file disagrees with PyTorch by more than ``TOLERANCE`` (1e-5).
    """
    run_dir, out_dir = Path(run_dir), Path(out_dir)
    if not run_dir.is_dir():
        raise ValueError(f"no such run directory: {run_dir}")
    if not isinstance(setting, str) or not setting:
        raise ValueError(f"setting must be a name such as 'normal' or 'legs_disabled', got {setting!r}")
    if isinstance(opset, bool) or not isinstance(opset, int) or not 13 <= opset <= 23:
        raise ValueError(f"opset must be an ONNX opset between 13 and 23, got {opset!r}")
    if isinstance(trust_imports, str) or not all(is_import_path(item) for item in trust_imports):
        raise ValueError(f"trust_imports must list import paths ('pkg.module:Class'), got {trust_imports!r}")
    policy_path, model_path = run_dir / "gait_policy.pt", run_dir / f"dynamics_model_{setting}.pt"
    if not policy_path.exists() and not model_path.exists():
        others = sorted(p.name for p in run_dir.glob("dynamics_model_*.pt"))
        hint = f" (it has {', '.join(others)}: pass that setting)" if others else ""
        raise ValueError(f"{run_dir} holds nothing to export: neither gait_policy.pt nor {model_path.name}{hint}")
    trained_policy = TrainedGaitPolicy.load(policy_path) if policy_path.exists() else None
    trained_model = TrainedCoMModel.load(model_path, trust_imports=trust_imports) if model_path.exists() else None
    low_level = _read_low_level(run_dir, setting) if trained_model is not None else None
    config = _read_run_config(run_dir)
    if horizon is None:
        planner = config.get("planner")
        horizon = planner.get("horizon", 1) if isinstance(planner, dict) else 1
    if isinstance(horizon, bool) or not isinstance(horizon, int) or horizon < 1:
        raise ValueError(f"horizon must be a positive integer, got {horizon!r}")
    if trained_model is not None and low_level is None and trained_policy is not None:
        low_level = {"kind": "latent", "action_low": trained_policy.latent_low.tolist(),
                     "action_high": trained_policy.latent_high.tolist(), "num_choices": None}
    if trained_model is not None and trained_model.metadata.get("context"):
        raise ArtifactError(f"{model_path.name} also reads {', '.join(trained_model.metadata['context'])} beside the "
                            "action (dynamics.body_state): the export does not carry such a model yet")
    if (trained_model is not None and trained_policy is not None and (low_level or {}).get("kind") == "latent"
            and trained_model.model.action_dim != trained_policy.policy.latent_dim):
        raise ArtifactError(f"{model_path.name} takes {trained_model.model.action_dim}-D actions but "
                            f"{policy_path.name} has {trained_policy.policy.latent_dim}-D latents: not one run")
    robot_name = (low_level or {}).get("robot") or config.get("robot")
    robot_name = robot_name if isinstance(robot_name, str) else None

    generator = torch.Generator().manual_seed(seed)
    manifest: dict[str, Any] = {
        "format": MANIFEST_FORMAT,
        "method": "Li et al., Planning in Learned Latent Action Spaces for Generalizable Legged Locomotion, "
                  "RA-L 2021",
        "source": {"run_dir": str(run_dir.resolve()), "setting": setting,
                   "artifacts": [p.name for p in (policy_path, model_path) if p.exists()]},
        "robot": robot_name, "control_timestep_s": CONTROL_TIMESTEP,
        "opset": opset, "tolerance": TOLERANCE,
        "versions": {"torch": torch.__version__, **_versions("onnx", "onnxruntime", "onnxscript")},
        "models": {},
    }
    out_dir.mkdir(parents=True, exist_ok=True)

    def write(stem, module, description, inputs, outputs, example, checks):
        module = module.eval()
        names = [spec["name"] for spec in inputs]
        dynamic = [{axis: label for axis, label in enumerate(spec["shape"]) if isinstance(label, str)}
                   for spec in inputs]
        _export_onnx(module, example, names, [spec["name"] for spec in outputs], dynamic, out_dir / f"{stem}.onnx",
                     opset)
        _export_torchscript(module, example, out_dir / f"{stem}.pt")
        errors = _verify(module, out_dir / f"{stem}.onnx", out_dir / f"{stem}.pt", names, checks)
        if max(errors.values()) > TOLERANCE:
            raise RuntimeError(f"exported {stem} disagrees with PyTorch: largest differences {errors} (over "
                               f"{TOLERANCE})")
        manifest["models"][stem] = {"description": description, "onnx": f"{stem}.onnx", "torchscript": f"{stem}.pt",
                                    "inputs": inputs, "outputs": outputs, "max_abs_error": errors}

    if trained_policy is not None:
        policy = trained_policy.policy.cpu().eval()
        z_dim, steps, joints = policy.latent_dim, policy.steps_per_action, policy.num_joints
        low, high = trained_policy.latent_low, trained_policy.latent_high
        joint_names = _joint_names(robot_name, joints)
        manifest.update(latent_box={"low": low.tolist(), "high": high.tolist()},
                        expert_latents=trained_policy.latents.tolist(), steps_per_action=steps,
                        action_duration_s=steps * CONTROL_TIMESTEP, joint_names=joint_names)
        joint_units = "rad, position targets in " + ("joint_names order" if joint_names else "the robot's joint order")
        latent = {"name": "latent", "shape": ["B", z_dim], "dtype": "float32",
                  "units": "latent action z (unitless), inside latent_box"}

        def z(batch):
            return _uniform(generator, (batch, z_dim), low, high)

        def phase(batch):
            return torch.randint(1, steps + 1, (batch, 1), generator=generator, device="cpu").float() / steps

        write("gait_policy_pattern", GaitPolicyPattern(policy),
              "pi(., z): all N joint targets of one latent action (step n at phase n / N), 100 Hz",
              [latent], [{"name": "joint_targets", "shape": ["B", steps, joints], "dtype": "float32",
                          "units": joint_units}],
              (z(3),), [(z(1),), (z(5),)])
        write("gait_policy_step", GaitPolicyStep(policy),
              "pi(t, z): the joint targets at phase t = n / N of the latent action z",
              [{"name": "phase", "shape": ["B", 1], "dtype": "float32",
                "units": "t = n / N in (0, 1], n the control step within the action (1..N)"}, latent],
              [{"name": "joint_targets", "shape": ["B", joints], "dtype": "float32", "units": joint_units}],
              (phase(3), z(3)), [(phase(1), z(1)), (phase(6), z(6))])

    if trained_model is not None:
        model = trained_model.model.cpu().eval()
        a_dim = model.action_dim
        action_entry, action_units = _action_description(low_level, a_dim)
        manifest["action"] = action_entry
        manifest["com_state"] = {"names": ["x", "y", "yaw", "vx", "vy"], "units": ["m", "m", "rad", "m/s", "m/s"],
                                 "frame": "world"}
        manifest["dynamics_model"] = {"model": model_name(model),
                                      "options": model.options,
                                      **{k: trained_model.metadata.get(k) for k in
                                         ("heldout_rmse", "output_names", "num_train", "duration")}}
        box_low, box_high = _action_box(low_level, a_dim)

        def actions(*shape):
            if action_entry.get("features") == "one_hot":
                index = torch.randint(0, a_dim, shape, generator=generator, device="cpu")
                return torch.nn.functional.one_hot(index, a_dim).float()
            return _uniform(generator, (*shape, a_dim), box_low, box_high)

        state = {"name": "com_state", "shape": ["B", 5], "dtype": "float32", "units": COM_STATE_UNITS}
        write("com_model_predict", CoMPredict(model),
              "the learned CoM dynamics over one action: world-frame state after the action",
              [state, {"name": "action", "shape": ["B", a_dim], "dtype": "float32", "units": action_units}],
              [{"name": "next_com_state", "shape": ["B", 5], "dtype": "float32", "units": COM_STATE_UNITS}],
              (_random_states(generator, 3), actions(3)),
              [(_random_states(generator, 1), actions(1)), (_random_states(generator, 7), actions(7))])
        write("planner_model_step", CoMPlannerStep(model),
              "the model step of the planner: S candidate actions imagined from each of B states",
              [state, {"name": "candidates", "shape": ["B", "S", a_dim], "dtype": "float32",
                       "units": action_units}],
              [{"name": "next_com_state", "shape": ["B", "S", 5], "dtype": "float32", "units": COM_STATE_UNITS}],
              (_random_states(generator, 2), actions(2, 7)),
              [(_random_states(generator, 1), actions(1, 1)), (_random_states(generator, 3), actions(3, 500))])
        if hasattr(model, "predict_members"):
            members = model.num_members
            write("com_model_members", CoMMembers(model),
                  f"each of the {members} ensemble members' prediction over one action: world-frame states after it",
                  [state, {"name": "action", "shape": ["B", a_dim], "dtype": "float32", "units": action_units}],
                  [{"name": "next_com_state_members", "shape": ["B", members, 5], "dtype": "float32",
                    "units": COM_STATE_UNITS}],
                  (_random_states(generator, 3), actions(3)),
                  [(_random_states(generator, 1), actions(1)), (_random_states(generator, 7), actions(7))])
        goal, velocity = GoalReaching(), VelocityTracking()
        manifest["cost"] = {"w_position": W_POSITION, "w_yaw": W_YAW, "yaw_target_rad": goal.start_yaw,
                            "step_duration_s": velocity.step_duration, "horizon": horizon}
        for stem, task, target_units, scale in [
                ("score_goal_reaching", goal, "goal position (x, y) in m, world frame, for each step of the "
                                              "horizon (trajectory tracking: the reference point of each step)", 3.0),
                ("score_velocity_tracking", velocity, "target CoM velocity (vx, vy) in m/s, world frame, for each "
                                                      "step of the horizon", 0.3)]:
            def target(batch, scale=scale):
                return _uniform(generator, (batch, horizon, 2), [-scale] * 2, [scale] * 2)

            write(stem, TaskScoring(model, task),
                  f"the planner's {task.name} cost of candidate action sequences (summed over the horizon, lower is "
                  f"better): cost = {W_POSITION:g} |target - .| + {W_YAW:g} |yaw_target - yaw| per step",
                  [state, {"name": "candidates", "shape": ["B", "S", horizon, a_dim], "dtype": "float32",
                           "units": action_units},
                   {"name": "target", "shape": ["B", horizon, 2], "dtype": "float32", "units": target_units}],
                  [{"name": "cost", "shape": ["B", "S"], "dtype": "float32", "units": "task cost (unitless)"}],
                  (_random_states(generator, 2), actions(2, 7, horizon), target(2)),
                  [(_random_states(generator, 1), actions(1, 1, horizon), target(1)),
                   (_random_states(generator, 3), actions(3, 400, horizon), target(3))])

    write_text(out_dir / "manifest.json", json.dumps(manifest, indent=2))
    return manifest


def _action_box(low_level: dict | None, action_dim: int) -> tuple[list[float], list[float]]:
    """The box random check actions are drawn from: the recorded one when it fits, else ``[-1, 1]``."""
    low, high = (low_level or {}).get("action_low"), (low_level or {}).get("action_high")
    if low is not None and high is not None and len(low) == len(high) == action_dim:
        return list(low), list(high)
    return [-1.0] * action_dim, [1.0] * action_dim


def _versions(*packages: str) -> dict[str, str | None]:
    from importlib import metadata

    versions = {}
    for package in packages:
        try:
            versions[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            versions[package] = None
    return versions


__all__ = ["CoMMembers", "CoMPlannerStep", "CoMPredict", "GaitPolicyPattern", "GaitPolicyStep", "TaskScoring", "export_run"]


def main(argv=None) -> int:
    """``python -m hierloco.exporting RUN_DIR OUT_DIR [--setting legs_disabled] [--horizon H] [--trust-import P]``;
    exit 1 on bad input."""
    import argparse
    import sys

    parser = argparse.ArgumentParser(prog="python -m hierloco.exporting", description="Exports a trained run for "
                                     "deployment: ONNX and TorchScript files and a manifest.json.")
    parser.add_argument("run_dir")
    parser.add_argument("out_dir")
    parser.add_argument("--setting", default="normal", help="normal or legs_disabled: which dynamics model")
    parser.add_argument("--horizon", type=int, default=None, help="H of the exported scoring (default: the run's)")
    parser.add_argument("--trust-import", action="append", default=[], metavar="PKG.MODULE:CLASS",
                        help="an import path the run's model checkpoint may name (repeatable)")
    args = parser.parse_args(argv)
    try:
        manifest = export_run(args.run_dir, args.out_dir, setting=args.setting, horizon=args.horizon,
                              trust_imports=args.trust_import)
    except ValueError as error:
        print(f"hierloco.exporting: {error}", file=sys.stderr)
        return 1
    for stem, entry in manifest["models"].items():
        print(f"{stem:26s} {entry['onnx']}, {entry['torchscript']}  (largest difference to PyTorch "
              f"{max(entry['max_abs_error'].values()):.1e})")
    print(f"manifest: {Path(args.out_dir) / 'manifest.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
