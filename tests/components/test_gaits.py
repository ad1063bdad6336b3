"""Expert libraries over several gaits, and a gait told from its foot contacts (hierloco.components.gaits)."""

import numpy as np
import pytest

from hierloco.components.expert_library import diagnose_expert_library
from hierloco.components.gaits import build_gait_library, check_gaits, classify_actions, classify_gait, gait_scores
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
