"""Expert libraries over several gaits, and a gait told from its foot contacts (hierloco.components.gaits)."""

import numpy as np
import pytest

from hierloco.components.expert_library import diagnose_expert_library
from hierloco.components.gaits import (
    build_gait_library, check_gait_boxes, check_gaits, classify_actions, classify_gait, gait_scores,
)
from hierloco.envs.robots import get_robot, robot_fingerprint

A1_GAITS = {"trot": [["FR", "RL"], ["FL", "RR"]], "pace": [["FR", "RR"], ["FL", "RL"]],
            "bound": [["FR", "FL"], ["RR", "RL"]]}


@pytest.fixture(scope="module")
def library():
    return build_gait_library("a1", A1_GAITS, num_experts=9, seed=0, steps_per_action=100, progress=False)


def test_a_library_over_three_gaits_is_the_robot_s_own_with_a_gait_per_expert(library):
    a1 = get_robot("a1")
    assert library.num_experts == 9 and library.joint_targets.shape == (9, 100, 12)
    assert library.metadata["expert_gaits"] == ["bound"] * 3 + ["pace"] * 3 + ["trot"] * 3  # by name
    assert library.metadata["robot"] == "a1" and library.metadata["robot_fingerprint"] == robot_fingerprint(a1)
    assert library.metadata["gaits"] == {name: A1_GAITS[name] for name in sorted(A1_GAITS)}
    # the tracking diagnosed is the whole library's, not the last gait's part
    assert library.metadata["tracking"] == diagnose_expert_library(library, robot=a1).summary()


def test_each_expert_s_contacts_name_its_own_gait(library):
    legs = library.metadata["leg_names"]
    assert legs == [leg.name for leg in get_robot("a1").legs]
    found = [classify_gait(contacts, A1_GAITS, legs) for contacts in library.foot_contacts]
    assert found == library.metadata["expert_gaits"]
    # and clearly: its own gait scores well above the others
    for contacts, gait in zip(library.foot_contacts, library.metadata["expert_gaits"]):
        scores = gait_scores(contacts, A1_GAITS, legs)
        assert scores[gait] > 0.3 and all(scores[gait] > s + 0.3 for name, s in scores.items() if name != gait)


def test_a_switch_between_gaits_is_seen_per_action(library):
    legs = library.metadata["leg_names"]
    trot, bound = library.foot_contacts[6], library.foot_contacts[0]
    assert classify_actions(np.concatenate([trot, trot, bound]), 100, A1_GAITS, legs) == ["trot", "trot", "bound"]
    with pytest.raises(ValueError, match="not whole actions"):
        classify_actions(np.concatenate([trot, trot[:50]]), 100, A1_GAITS, legs)


def test_gaits_that_tie_give_the_same_label_whatever_their_order():
    """All feet down the whole action scores every gait 0: the label is the first gait by name, so a table built
    from a study's gaits (given by name) and one from a user's mapping in another order agree (a record's table
    and the same contacts classified again once disagreed)."""
    legs = ["FR", "FL", "RR", "RL"]
    standing = np.ones((100, 4), bool)
    assert set(gait_scores(standing, A1_GAITS, legs).values()) == {0.0}
    orders = [dict(order) for order in (A1_GAITS.items(), reversed(A1_GAITS.items()))]
    assert [classify_gait(standing, gaits, legs) for gaits in orders] == ["bound", "bound"]
    walking = np.tile(np.array([[1, 0, 0, 1], [0, 1, 1, 0]], bool).repeat(10, 0), (5, 1))  # FR+RL, FL+RR: trot
    assert [classify_gait(walking, gaits, legs) for gaits in orders] == ["trot", "trot"]


def test_gaits_a_robot_cannot_walk_are_named():
    problems = check_gaits("a1", {"trot": A1_GAITS["trot"], "bad": [["FR", "XX"], ["FL", "RR", "RL"]],
                                  "twice": [["FR", "FL"], ["FR", "RR", "RL"]]})
    assert len(problems) == 2 and problems[0].startswith("gait 'bad': ") and "XX" in problems[0]
    assert problems[1].startswith("gait 'twice': ")
    assert "needs two or more" in check_gaits("a1", {"trot": A1_GAITS["trot"]})[0]
    with pytest.raises(ValueError, match="gait 'bad'"):
        build_gait_library("a1", {"trot": A1_GAITS["trot"], "bad": [["FR"], ["FL"]]}, num_experts=2, progress=False)


def test_a_gait_of_single_legs_cannot_be_told_from_contacts():
    legs = ["L1", "L2", "L3", "R1", "R2", "R3"]
    wave = {"tripod": [["L1", "R2", "L3"], ["R1", "L2", "R3"]], "wave": [[leg] for leg in legs]}
    with pytest.raises(ValueError, match="'wave'.*cannot tell"):
        gait_scores(np.ones((10, 6), bool), wave, legs)


SLOW = {"command_low": [-0.1, -0.1, -0.2], "command_high": [0.1, 0.1, 0.2]}


def test_a_gait_with_a_box_of_its_own_walks_only_its_commands():
    gaits = {"trot": A1_GAITS["trot"], "pace": A1_GAITS["pace"]}
    library = build_gait_library("a1", gaits, num_experts=6, seed=0, gait_boxes={"pace": SLOW}, progress=False)
    a1 = get_robot("a1")
    pace = np.array(library.metadata["expert_gaits"]) == "pace"
    assert pace.sum() == 3
    assert (np.abs(library.commands[pace, :2]) <= 0.1).all() and (np.abs(library.commands[pace, 2]) <= 0.2).all()
    assert (np.abs(library.commands[~pace, :2]) > 0.1).any()  # trot keeps the robot's whole box
    assert library.metadata["gait_boxes"] == {"pace": {k: list(map(float, v)) for k, v in SLOW.items()},
                                              "trot": {"command_low": list(a1.command_low),
                                                       "command_high": list(a1.command_high)}}
    # the library's box holds every gait's, and its tracking is diagnosed against it
    assert library.metadata["command_low"] == list(a1.command_low)
    assert library.metadata["command_high"] == list(a1.command_high)
    assert library.metadata["tracking"] == diagnose_expert_library(library, robot=a1).summary()


def test_bad_gait_boxes_are_named():
    problems = check_gait_boxes("a1", A1_GAITS, {"gallop": SLOW, "pace": {"command_low": [0.0, 0.0]},
                                                 "trot": {"low": [0, 0, 0]},
                                                 "bound": {"command_low": [0.2, 0, 0], "command_high": [0.1, 0, 0]}})
    assert problems[0].startswith("gait_boxes names 'gallop', which is not one of the gaits")
    assert problems[1].startswith("gait_boxes.pace: command_low must be 3 finite numbers")
    assert problems[2].startswith("gait_boxes.trot must be {command_low")
    assert problems[3].startswith("gait_boxes.bound: command_low [0.2, 0.0, 0.0] must be at most command_high")
    assert check_gait_boxes("a1", A1_GAITS, None) == [] and check_gait_boxes("a1", A1_GAITS, {"pace": SLOW}) == []
    with pytest.raises(ValueError, match="gait_boxes names 'gallop'"):
        build_gait_library("a1", A1_GAITS, num_experts=3, gait_boxes={"gallop": SLOW}, progress=False)
