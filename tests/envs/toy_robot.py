"""A small user-written MJCF quadruped for the tests, described through :func:`robot_from_mjcf`.

The file is written like many published MJCF robots: torque ``motor`` actuators, no free joint, no floor. Only the
torso and the foot spheres collide. Its legs are two 0.15 m links; in the standing pose ``(0, 0.8, -1.6)`` the feet
are straight under the hips and the torso centre is ``2 * 0.15 * cos(0.8) + 0.02`` m above the floor.
"""

from __future__ import annotations

import math

from hierloco.envs import robot_from_mjcf

TOY_LINK = 0.15  # m, thigh and calf
TOY_FOOT_RADIUS = 0.02  # m
TOY_STANDING_LEG = (0.0, 0.8, -1.6)  # rad
TOY_STANDING_HEIGHT = 2 * TOY_LINK * math.cos(0.8) + TOY_FOOT_RADIUS  # m
TOY_HIPS = {"FR": (0.15, -0.07), "FL": (0.15, 0.07), "RR": (-0.15, -0.07), "RL": (-0.15, 0.07)}  # m

_LEG = """
      <body name="{leg}_hip" pos="{x} {y} 0">
        <joint name="{leg}_abduction" axis="1 0 0" range="-0.6 0.6"/>
        <geom type="cylinder" size="0.025 0.02" zaxis="0 1 0" mass="0.2"/>
        <body name="{leg}_thigh" pos="0 {side_offset} 0">
          <joint name="{leg}_hip_pitch" axis="0 1 0" range="-1.5 2.5"/>
          <geom type="capsule" fromto="0 0 0 0 0 -{link}" size="0.015" mass="0.3"/>
          <body name="{leg}_calf" pos="0 0 -{link}">
            <joint name="{leg}_knee" axis="0 1 0" range="-2.6 -0.5"/>
            <geom type="capsule" fromto="0 0 0 0 0 -{link}" size="0.012" mass="0.07"/>
            <geom name="{leg}_foot" class="foot" pos="0 0 -{link}" mass="0.03"/>
            <site name="{leg}_toe" pos="0 0 -{link}" size="0.025"/>
          </body>
        </body>
      </body>"""
_MOTORS = """
    <motor name="{leg}_abduction_motor" joint="{leg}_abduction" gear="1"/>
    <motor name="{leg}_hip_pitch_motor" joint="{leg}_hip_pitch" gear="1"/>
    <motor name="{leg}_knee_motor" joint="{leg}_knee" gear="1"/>"""

TOY_QUADRUPED_XML = f"""
<mujoco model="toy_quadruped">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="0.005"/>
  <default>
    <joint damping="0.5" armature="0.01"/>
    <geom contype="0" conaffinity="0" rgba="0.7 0.5 0.3 1"/>
    <motor ctrlrange="-15 15"/>
    <default class="foot">
      <geom type="sphere" size="{TOY_FOOT_RADIUS}" contype="1" friction="0.9" rgba="0.1 0.1 0.1 1"/>
    </default>
  </default>
  <worldbody>
    <body name="torso" pos="0 0 0.3">
      <geom name="torso" type="box" size="0.15 0.07 0.03" mass="3" contype="1"/>
      {"".join(_LEG.format(leg=leg, x=x, y=y, side_offset=math.copysign(0.03, y), link=TOY_LINK)
               for leg, (x, y) in TOY_HIPS.items())}
    </body>
  </worldbody>
  <actuator>{"".join(_MOTORS.format(leg=leg) for leg in TOY_HIPS)}
  </actuator>
</mujoco>
"""


def make_toy_robot(feet: str = "site"):
    """The toy quadruped as a :class:`RobotSpec`; ``feet`` names its feet by ``"site"`` or by (calf) ``"body"``."""
    return robot_from_mjcf(
        TOY_QUADRUPED_XML,
        name=f"toy_quadruped_{feet}",
        base_body="torso",
        legs={leg: [f"{leg}_abduction", f"{leg}_hip_pitch", f"{leg}_knee"] for leg in TOY_HIPS},
        feet={leg: f"{leg}_toe" if feet == "site" else f"{leg}_calf" for leg in TOY_HIPS},
        standing_pose=TOY_STANDING_LEG * len(TOY_HIPS),
        standing_height=TOY_STANDING_HEIGHT,
        gait_groups=[["FR", "RL"], ["FL", "RR"]],
        kp=[40.0] * 12,
    )

