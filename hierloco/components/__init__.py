"""Reusable parts of the hierarchy.

- ``kinematics``: generic leg FK/IK from the MuJoCo model. ``experts``: the Raibert footstep controller.
- ``expert_library``: recorded expert gaits. ``gait_policy``: the latent gait policy ``pi(t, z)``.
- ``low_level``: latent, expert-replay and command low levels. ``dynamics_data``: random-action transitions.
- ``com_model``: the local-frame CoM dynamics model. ``planners``: random shooting, CEM, MPPI, exhaustive MPC.
- ``evaluation``: closed-loop task episodes and gait-policy checks. ``sac``: the SAC agent and its batched
  training loop. ``sac_low_level``: SAC-SAC's 100 Hz velocity-tracking low level and its tracking evaluation.
"""
