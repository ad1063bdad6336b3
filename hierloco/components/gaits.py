"""Expert libraries over several gaits, and telling a gait from its foot contacts (Li et al., Sec. V: "when the
low-level policy is learned with experts spanning multiple gaits, the high-level latent action space can be used to
transit between gaits").

A gait is named by its *gait groups*: the legs that are in stance together (:class:`hierloco.envs.robots.RobotSpec`'s
``gait_groups``). On A1 (legs ``FR, FL, RR, RL``)::

    trot:  [[FR, RL], [FL, RR]]      pace:  [[FR, RR], [FL, RL]]      bound: [[FR, FL], [RR, RL]]

:func:`build_gait_library` builds the experts of each gait with the same expert controller (the robot with those gait
groups) and stacks them into one library, each expert labelled with its gait (``metadata["expert_gaits"]``), so one
gait policy and one latent space are learned over all of them (``experts.gaits`` in the recipes).
:func:`gait_scores` tells which gait a stretch of foot contacts walks: legs of one group share their contact state,
legs of different groups do not; a gait's score is the mean agreement of the pairs of legs it puts in one group minus
that of the pairs it puts in different groups (1: exactly this gait; about 0: no relation).

Example (A1's experts in three gaits; each expert's contacts name its own gait):
    >>> from hierloco.envs.robots import get_robot
    >>> gaits = {"trot": [["FR", "RL"], ["FL", "RR"]], "pace": [["FR", "RR"], ["FL", "RL"]]}
    >>> lib = build_gait_library(get_robot("a1"), gaits, num_experts=4, seed=0, progress=False)
    >>> lib.metadata["expert_gaits"]
    ['pace', 'pace', 'trot', 'trot']
    >>> [classify_gait(c, gaits, lib.metadata["leg_names"]) for c in lib.foot_contacts]
    ['pace', 'pace', 'trot', 'trot']
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from hierloco.envs.robots import RobotSpec, admissible_gait_periods, get_robot

GaitGroups = Sequence[Sequence[str]]


def gait_robot(robot: RobotSpec, groups: GaitGroups) -> RobotSpec:
    """The robot walking with ``groups`` (every leg in exactly one group, at least two groups: else a
    :class:`ValueError` naming the problem); its gait period is kept when it suits that many groups, else derived."""
    groups = tuple(tuple(str(leg) for leg in group) for group in groups)
    if robot.gait_period is not None and robot.gait_period in admissible_gait_periods(len(groups)):
        return robot.replace(gait_groups=groups)
    return robot.replace(gait_groups=groups, gait_period=None)


def check_gaits(robot: str | RobotSpec, gaits: Mapping[str, GaitGroups]) -> list[str]:
    """A problem line per gait that the robot cannot walk (an unknown leg, a leg in no group or two), and one when
    fewer than two gaits are named; empty when every gait is a valid set of gait groups."""
    robot = get_robot(robot)
    problems = [] if len(gaits) >= 2 else [f"experts.gaits names {len(gaits)} gait(s): a library over gaits needs two "
                                            "or more (leave it null for the robot's own gait)"]
    for name, groups in gaits.items():
        try:
            gait_robot(robot, groups)
        except (TypeError, ValueError) as error:
            problems.append(f"gait {name!r}: {error}")
    return problems


def check_gait_boxes(robot: str | RobotSpec, gaits: Mapping[str, GaitGroups],
                     gait_boxes: Mapping[str, Mapping[str, Sequence[float]]] | None) -> list[str]:
    """A problem line per entry of ``gait_boxes`` (gait name -> ``{command_low: [vx, vy, yaw_rate], command_high:
    [...]}``, either bound optional) that names no gait of ``gaits``, has other keys, or is not a command box of the
    robot (:func:`hierloco.components.expert_library.command_box`), or one line when ``gait_boxes`` is not a
    mapping at all; empty when every box is valid (or ``gait_boxes`` is None)."""
    from hierloco.components.expert_library import command_box

    if gait_boxes is not None and not isinstance(gait_boxes, Mapping):
        return [f"gait_boxes must map gait names to {{command_low: [...], command_high: [...]}}, got {gait_boxes!r}"]
    robot = get_robot(robot)
    problems = []
    for name, box in (gait_boxes or {}).items():
        if name not in gaits:
            problems.append(f"gait_boxes names {name!r}, which is not one of the gaits ({', '.join(gaits)})")
            continue
        if not isinstance(box, Mapping) or set(box) - {"command_low", "command_high"}:
            problems.append(f"gait_boxes.{name} must be {{command_low: [vx, vy, yaw_rate], command_high: [...]}}, "
                            f"got {box!r}")
            continue
        try:
            command_box(robot, box.get("command_low"), box.get("command_high"))
        except ValueError as error:
            problems.append(f"gait_boxes.{name}: {error}")
    return problems


def build_gait_library(robot: str | RobotSpec, gaits: Mapping[str, GaitGroups], num_experts: int, *, seed: int = 0,
                       gait_boxes: Mapping[str, Mapping[str, Sequence[float]]] | None = None, **options):
    """An expert library over ``gaits`` (name -> gait groups): ``num_experts`` split as evenly as possible between
    them in the order of their names, each gait's experts built by :func:`hierloco.components.expert_library.
    build_expert_library` (``options``: its keyword arguments) with seed ``seed + index``. ``gait_boxes`` (gait name
    -> ``{command_low, command_high}``) gives a gait a command box of its own in place of ``options``' (e.g. a slow
    gait that only walks slowly, so that a fast target needs the other gait); the library's ``command_low`` /
    ``command_high`` are then the smallest box holding every gait's, and ``gait_boxes`` records each gait's. The
    library is the robot's own (its metadata names ``robot``, not the gait's copy) and adds ``gaits``,
    ``expert_gaits`` (one name per expert) and ``leg_names``."""
    from hierloco.components.expert_library import (
        ExpertLibrary, ExpertQualityError, build_expert_library, command_box, diagnose_expert_library, robot_metadata,
    )

    robot = get_robot(robot)
    problems = check_gaits(robot, gaits) + check_gait_boxes(robot, gaits, gait_boxes)
    if problems:
        raise ValueError("; ".join(problems))
    gait_boxes = dict(gait_boxes or {})
    gaits = dict(sorted(gaits.items()))  # by name: the library does not depend on the order a config lists them
    counts = [len(part) for part in np.array_split(np.arange(int(num_experts)), len(gaits))]
    if min(counts) < 1:
        raise ValueError(f"{num_experts} experts cannot be split between {len(gaits)} gaits")
    parts, boxes = [], {}
    for index, ((name, groups), count) in enumerate(zip(gaits.items(), counts)):
        own = gait_boxes.get(name, {})
        low, high = command_box(robot, own.get("command_low", options.get("command_low")),
                                own.get("command_high", options.get("command_high")))
        boxes[name] = {"command_low": low.tolist(), "command_high": high.tolist()}
        try:
            parts.append(build_expert_library(gait_robot(robot, groups), count, seed=seed + index,
                                              **{**options, **boxes[name]}))
        except ExpertQualityError as error:  # the same finding, saying which gait
            raise ExpertQualityError(f"gait {name!r} ({count} experts): {error}") from None
    arrays = {field: np.concatenate([getattr(part, field) for part in parts])
              for field in ("commands", "joint_targets", "com_states", "foot_contacts", "velocity_local", "yaw_rate",
                            "displacement_local", "tracking_error")}
    periods = {name: part.metadata["gait_period"] for name, part in zip(gaits, parts)}
    metadata = {**parts[0].metadata, **robot_metadata(robot), "seed": int(seed),
                "gait_period": next(iter(periods.values())) if len(set(periods.values())) == 1 else None,
                "gait_periods": periods,
                "rejected_commands": int(sum(part.metadata["rejected_commands"] for part in parts)),
                "gaits": {name: [list(group) for group in groups] for name, groups in gaits.items()},
                "expert_gaits": [name for name, count in zip(gaits, counts) for _ in range(count)],
                "leg_names": [leg.name for leg in robot.legs]}
    if gait_boxes:  # each gait's own box, and the library's: the smallest box holding them all
        metadata["gait_boxes"] = boxes
        metadata["command_low"] = np.min([box["command_low"] for box in boxes.values()], axis=0).tolist()
        metadata["command_high"] = np.max([box["command_high"] for box in boxes.values()], axis=0).tolist()
    library = ExpertLibrary(**arrays, metadata=metadata)
    library.metadata["tracking"] = diagnose_expert_library(library, robot=robot).summary()
    return library


def gait_scores(foot_contacts: np.ndarray, gaits: Mapping[str, GaitGroups], leg_names: Sequence[str]) -> dict:
    """``T x L`` foot contacts (legs in ``leg_names`` order) -> ``{gait: score}`` (module docstring): the mean
    agreement of the leg pairs the gait groups together minus that of the pairs it separates. A gait whose groups
    are all single legs (a wave gait) has no pair to agree and cannot be told this way (``ValueError``)."""
    contacts = np.asarray(foot_contacts, bool)
    if contacts.ndim != 2 or contacts.shape[1] != len(leg_names):
        raise ValueError(f"foot contacts must be T x {len(leg_names)}, got {contacts.shape}")
    agree = (contacts[:, :, None] == contacts[:, None, :]).mean(0)  # L x L: the fraction of steps two legs agree
    upper = np.triu_indices(len(leg_names), 1)
    scores = {}
    for name, groups in gaits.items():
        group_of = {leg: index for index, group in enumerate(groups) for leg in group}
        same = np.array([group_of[leg_names[i]] == group_of[leg_names[j]] for i, j in zip(*upper)])
        if not same.any() or same.all():
            raise ValueError(f"gait {name!r}: its groups {groups} put no two legs together (or all of them): its "
                             "contacts cannot tell it from another gait")
        pairs = agree[upper]
        scores[name] = float(pairs[same].mean() - pairs[~same].mean())
    return scores


def classify_gait(foot_contacts: np.ndarray, gaits: Mapping[str, GaitGroups], leg_names: Sequence[str]) -> str:
    """The gait of ``gaits`` whose score (:func:`gait_scores`) is highest for ``T x L`` foot contacts; of gaits that
    tie (all feet down the whole time scores every gait 0), the first by name, so that the label does not depend on
    the order of ``gaits``."""
    scores = gait_scores(foot_contacts, gaits, leg_names)
    return max(sorted(scores), key=scores.get)


def classify_actions(foot_contacts: np.ndarray, steps_per_action: int, gaits: Mapping[str, GaitGroups],
                     leg_names: Sequence[str]) -> list[str]:
    """The gait of each latent action in ``T x L`` foot contacts (``T`` a multiple of ``steps_per_action``: one
    name per action, in order), e.g. to see where a planner switches gaits."""
    contacts = np.asarray(foot_contacts, bool)
    if contacts.shape[0] % steps_per_action:
        raise ValueError(f"{contacts.shape[0]} steps are not whole actions of {steps_per_action}")
    return [classify_gait(chunk, gaits, leg_names)
            for chunk in contacts.reshape(-1, steps_per_action, contacts.shape[1])]
