"""Reusable parts of the hierarchy (Li et al., RA-L 2021, Sec. III; ``docs/index.md`` maps them to the paper).

- ``kinematics``: generic leg FK/IK from the MuJoCo model. ``experts``: the Raibert footstep controller.
- ``expert_library``: recorded expert gaits. ``gait_policy``: the latent gait policy ``pi(t, z)``.
- ``low_level``: latent, expert-replay and command low levels. ``dynamics_data``: random-action transitions.
- ``com_model``: the local-frame CoM dynamics model and the registry of models (``MODELS``: ``mlp``, ``ensemble``).
  ``com_ensemble``: the probabilistic ensemble (PETS). ``planners``: random shooting, CEM, MPPI, exhaustive MPC.
- ``policies``: the task-policy protocol of closed-loop evaluation. ``evaluation``: closed-loop task episodes and
  gait-policy checks. ``sac``: the SAC agent and its batched training loop. ``sac_low_level``: SAC-SAC's 100 Hz
  velocity-tracking low level and its tracking evaluation.
"""

from hierloco.components.com_ensemble import CoMEnsembleModel
from hierloco.components.com_model import (
    MODELS,
    CoMDynamicsModel,
    TrainedCoMModel,
    apply_delta,
    com_model_module,
    holdout_split,
    local_transition,
    train_com_model,
)
from hierloco.components.dynamics_data import TransitionData, UniformActionPolicy, collect_transitions
from hierloco.components.evaluation import TaskRollout, check_gait_policy, latent_grid_paths, run_task
from hierloco.components.expert_library import ExpertLibrary, action_motion, build_expert_library
from hierloco.components.experts import RaibertController, run_closed_loop
from hierloco.components.gait_policy import LatentGaitPolicy, TrainedGaitPolicy, train_gait_policy
from hierloco.components.kinematics import LegKinematics
from hierloco.components.low_level import CommandLowLevel, ExpertReplayLowLevel, LatentLowLevel, LowLevel
from hierloco.components.planners import (
    PLANNERS,
    BoxCEMPlanner,
    BoxMPPIPlanner,
    BoxPlannerBase,
    ExhaustivePlanner,
    RandomShootingPlanner,
)
from hierloco.components.policies import ActorPolicy, TaskPolicy
from hierloco.components.sac import SACAgent, train_sac
from hierloco.components.sac_low_level import SACLowLevel, TrainedSACLowLevel, train_sac_low_level

__all__ = [
    "MODELS", "PLANNERS", "ActorPolicy", "BoxCEMPlanner", "BoxMPPIPlanner", "BoxPlannerBase", "CoMDynamicsModel",
    "CoMEnsembleModel", "com_model_module",
    "CommandLowLevel", "ExhaustivePlanner", "ExpertLibrary", "ExpertReplayLowLevel", "LatentGaitPolicy",
    "LatentLowLevel", "LegKinematics", "LowLevel", "RaibertController", "RandomShootingPlanner", "SACAgent",
    "SACLowLevel", "TaskPolicy", "TaskRollout", "TrainedCoMModel", "TrainedGaitPolicy", "TrainedSACLowLevel", "TransitionData", "UniformActionPolicy",
    "action_motion", "apply_delta", "build_expert_library", "check_gait_policy", "collect_transitions",
    "holdout_split", "latent_grid_paths", "local_transition", "run_closed_loop", "run_task", "train_com_model",
    "train_gait_policy", "train_sac", "train_sac_low_level",
]
