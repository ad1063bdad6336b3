"""The paper's claims checked on hand-made rows: each verdict follows the numbers and the tests over seeds."""

import pytest

from hierloco.claims import seed_means
from hierloco.recipes.compare.paper_check import check_claims, load_causes, paper_check_markdown


def rows(costs: dict, setting="normal", task="velocity_tracking", robot="a1"):
    """``costs``: method -> per-seed lists of episode costs."""
    return [{"method": m, "robot": robot, "setting": setting, "task": task, "seed": seed, "episode": e,
             "normalized_cost": c} for m, seeds in costs.items() for seed, episodes in enumerate(seeds)
            for e, c in enumerate(episodes)]


def seeds(*means):
    """One episode per seed."""
    return [[m] for m in means]


def verdicts(checks):
    return {(c.claim, c.setting, c.task): c.verdict for c in checks}


def test_seed_means_average_each_seed_and_count_a_fall_as_one():
    data = rows({"lat": [[0.2, 0.4], [float("nan"), 0.0]]})
    assert seed_means(data, method="lat", robot="a1", setting="normal", task="velocity_tracking").tolist() == [
        0.30000000000000004, 0.5]


def test_seed_means_pool_a_seeds_replicates():
    # seed 1 run on two machines: each run's mean, then the seed's mean over its runs
    data = [{"method": "ik", "robot": "daisy", "setting": "legs_disabled", "task": "velocity_tracking", "seed": s,
             "episode": 0, "normalized_cost": c, "run": r} for s, c, r in ((0, 0.51, "a"), (1, 1.01, "a"),
                                                                            (1, 0.59, "b"), (2, 0.54, "a"))]
    means = seed_means(data, method="ik", robot="daisy", setting="legs_disabled", task="velocity_tracking")
    assert means.round(2).tolist() == [0.51, 0.8, 0.54]


def test_each_claim_follows_the_numbers():
    data = (rows({"lat": seeds(0.20, 0.21, 0.19), "lib": seeds(0.60, 0.50, 0.55), "sac": seeds(0.10, 0.11, 0.09),
                  "ik": seeds(0.05, 0.06, 0.05)})
            + rows({"lat": seeds(0.60, 0.62, 0.61), "ik": seeds(0.90, 0.88, 0.89),
                    "ik_plain": seeds(0.50, 0.52, 0.49)}, setting="legs_disabled"))
    got = verdicts(check_claims(data))
    assert got[("LAT is best among the learned methods", "normal", "velocity_tracking")] == "does not hold"  # SAC
    assert got[("LAT is close to IK (within 20%)", "normal", "velocity_tracking")] == "does not hold"
    assert got[("LAT beats IK with legs disabled", "legs_disabled", "velocity_tracking")] == "holds"
    assert got[("LAT beats IK_PLAIN with legs disabled", "legs_disabled", "velocity_tracking")] == "does not hold"
    assert got[("LIB is worse than LAT at velocity tracking", "normal", "velocity_tracking")] == "holds"
    assert got[("IK deteriorates with legs disabled", "legs_disabled", "velocity_tracking")] == "holds"


def test_a_single_seed_decides_nothing():
    # the old fixed margins gave these verdicts from one seed; a test over seeds cannot
    data = rows({"lat": [[0.6]], "ik": [[0.9]]}, setting="legs_disabled")
    check = next(c for c in check_claims(data) if c.key == "damaged:ik")
    assert check.verdict == "inconclusive" and "fewer than 2 seeds" in check.detail


def test_close_is_relative_and_two_sided():
    # Daisy's velocity tracking: LAT 0.16 against the tuned IK's 0.10 is 60 % above (within 0.1 it was "close")
    data = rows({"lat": seeds(0.157, 0.162, 0.166), "ik_plain": seeds(0.109, 0.092, 0.089)}, robot="daisy")
    [check] = [c for c in check_claims(data, tuned_ik={"daisy": "ik_plain"}) if c.key == "close:ik_plain"]
    assert check.verdict == "does not hold" and "significantly higher" in check.detail
    near = rows({"lat": seeds(0.090, 0.088, 0.092), "ik": seeds(0.091, 0.089, 0.090)})
    assert next(c for c in check_claims(near) if c.key == "close:ik").verdict == "holds"
    spread = rows({"lat": seeds(0.10, 0.16, 0.12), "ik": seeds(0.10, 0.11, 0.09)})
    assert next(c for c in check_claims(spread) if c.key == "close:ik").verdict == "inconclusive"


def test_both_no_better_than_standing_still_is_not_testable():
    # A1 with its rear legs locked: LAT 0.93 against IK 1.01 is no evidence that LAT copes with the damage
    data = rows({"lat": seeds(0.934, 0.907, 0.937), "ik": seeds(1.014, 1.039, 0.969)}, setting="legs_disabled")
    check = next(c for c in check_claims(data) if c.key == "damaged:ik")
    assert check.verdict == "not testable here" and "0.93, 1.01" in check.detail


def test_a_difference_within_the_spread_of_the_seeds_is_inconclusive():
    # Daisy with its rear legs locked: LAT 0.62 / 0.87 / 0.54 against IK 0.51 / 1.01 / 0.54
    data = rows({"lat": seeds(0.62, 0.87, 0.54), "ik": seeds(0.51, 1.01, 0.54)}, setting="legs_disabled")
    assert next(c for c in check_claims(data) if c.key == "damaged:ik").verdict == "inconclusive"


def test_a_gain_below_the_minimum_effect_is_no_win():
    data = rows({"lat": seeds(0.600, 0.601, 0.599), "ik": seeds(0.610, 0.611, 0.609)}, setting="legs_disabled")
    check = next(c for c in check_claims(data) if c.key == "damaged:ik")
    assert check.verdict == "does not hold" and "significantly below" in check.detail


def test_markdown_counts_and_quotes_the_paper():
    data = rows({"lat": seeds(0.20, 0.21, 0.20), "lib": seeds(0.10, 0.11, 0.10)})
    text = paper_check_markdown(check_claims(data), title="test")
    assert "lib 0.58 +- 0.01" in text and "| does not hold | d = " in text and text.rstrip().endswith(
        "0 hold, 2 do not hold, 0 inconclusive, 0 not testable here (0 of the 2 not found to hold "
        "with the cause we checked, 2 not checked).")
    only_lib = paper_check_markdown(check_claims(rows({"lib": seeds(0.5, 0.6, 0.5)})), title="test")
    assert "| LIB is worse than LAT at velocity tracking | a1 | normal | velocity_tracking | - | " \
           "lat 0.16 +- 0.10, lib 0.58 +- 0.01 | not measured |" in only_lib


def test_the_tuned_ik_is_named_in_its_claims():
    data = [{"method": m, "robot": "daisy", "setting": s, "task": "velocity_tracking", "seed": seed,
             "normalized_cost": c + 0.01 * seed}
            for m, s, c in (("lat", "normal", 0.16), ("ik", "normal", 0.37), ("ik_plain", "normal", 0.10),
                            ("lat", "legs_disabled", 0.68), ("ik", "legs_disabled", 0.57),
                            ("ik_plain", "legs_disabled", 0.93)) for seed in range(3)]
    checks = {c.claim: c.verdict for c in check_claims(data, tuned_ik={"daisy": "ik_plain"})}
    assert checks["LAT beats IK_PLAIN (the IK tuned on the training targets) with legs disabled"] == "holds"
    assert checks["LAT beats IK with legs disabled"] == "does not hold"
    assert "LAT is close to IK_PLAIN (the IK tuned on the training targets) (within 20%)" in checks


def test_sac_against_sac_sac_and_lib_at_goals():
    data = rows({"lat": seeds(0.090, 0.091, 0.090), "lib": seeds(0.15, 0.16, 0.15),
                 "sac": seeds(0.091, 0.090, 0.091), "sac_sac": seeds(0.40, 1.20, 0.85)}, task="goal_reaching")
    got = {c.key: c.verdict for c in check_claims(data)}
    assert got["sac_sac_worse"] == "holds"           # 0.09 against 0.82, spread and all
    assert got["lib_goals_close"] == "does not hold"  # 0.15 is 60 % above LAT's 0.09
    assert got["learned_best"] == "does not hold"     # SAC ties LAT: the gain is significantly below 10 %


def goal_rows(method: str, train: list, held: list, robot="a1"):
    """Goal reaching over 8 goals: per seed, the even goals (the training split) cost ``train[seed]``, the odd
    ``held[seed]``."""
    return [{"method": method, "robot": robot, "setting": "normal", "task": "goal_reaching", "seed": seed,
             "episode": e, "normalized_cost": train[seed] if e % 2 == 0 else held[seed]}
            for seed in range(len(train)) for e in range(8)]


def test_generalisation_compares_held_out_goals_with_training_goals_seed_by_seed():
    checks = check_claims(goal_rows("sac", train=[0.10, 0.20, 0.30], held=[0.40, 0.50, 0.62])
                          + goal_rows("sac_sac", train=[0.10, 0.20, 0.30], held=[0.11, 0.21, 0.30]))
    got = {c.key: c for c in checks}
    assert got["heldout_worse:sac"].verdict == "holds"  # paired: the seeds' spread does not hide a constant gap
    assert got["heldout_worse:sac"].ours == "training goals 0.20 +- 0.08, held-out goals 0.51 +- 0.09"
    assert got["heldout_worse:sac_sac"].verdict == "does not hold"


def write(tmp_path, text):
    path = tmp_path / "causes.yaml"
    path.write_text(text)
    return path


def test_each_claim_not_found_to_hold_gets_its_cause_and_stale_causes_are_listed(tmp_path):
    data = rows({"lat": seeds(0.20, 0.21, 0.20), "lib": seeds(0.10, 0.11, 0.10), "ik": seeds(0.05, 0.05, 0.06)})
    causes = load_causes(write(tmp_path, """
- claims: [lib_worse]
  robots: [a1]
  cause: >
    LIB's experts
    cover the commanded speeds.
- {claims: [learned_best], tasks: [goal_reaching], cause: Every method reaches every goal.}
- {claims: [close:ik], robots: [daisy], cause: Daisy only.}
"""))
    text = paper_check_markdown(check_claims(data), title="test", causes=causes)
    lib_row = next(line for line in text.splitlines() if line.startswith("| LIB is worse"))
    assert "| does not hold |" in lib_row and lib_row.endswith("| [1](#cause-1) |")
    best_row = next(line for line in text.splitlines() if line.startswith("| LAT is best"))
    assert best_row.endswith("| not checked |")          # the cause is for goal reaching only
    assert "1. LIB's experts cover the commanded speeds." in text
    assert "(1 of the 3 not found to hold with the cause we checked, 2 not checked)" in text
    stale = text.split("## Causes given for claims that hold or were not measured here")[1]
    assert "Every method reaches every goal." in stale and "Daisy only." in stale
    # an inconclusive claim gets its cause too
    spread = rows({"lat": seeds(0.62, 0.87, 0.54), "ik": seeds(0.51, 1.01, 0.54)}, setting="legs_disabled",
                  robot="daisy")
    causes = load_causes(write(tmp_path, "- {claims: ['damaged:ik'], robots: [daisy], cause: One seed lost.}"))
    text = paper_check_markdown(check_claims(spread), title="test", causes=causes)
    assert "| inconclusive |" in text and "| [1](#cause-1) |" in text and "1. One seed lost." in text


@pytest.mark.parametrize("text, message", [
    ("- {claims: [lat_best], cause: x}", "unknown claim 'lat_best'"),
    ("- {claims: [lib_worse], tasks: [walking], cause: x}", "unknown task 'walking'"),
    ("- {claims: [lib_worse]}", "cause must be a non-empty text"),
    ("- {claims: lib_worse, cause: x}", "claims must be a list of names"),
    ("- {claims: [lib_worse], cause: x, why: y}", "unknown fields ['why']"),
    ("claims: [lib_worse]", "must hold a list of entries"),
])
def test_a_malformed_causes_file_is_refused_with_the_problem_named(tmp_path, text, message):
    with pytest.raises(ValueError, match=message.replace("[", r"\[").replace("]", r"\]")):
        load_causes(write(tmp_path, text))
    with pytest.raises(ValueError, match="no file"):
        load_causes(tmp_path / "missing.yaml")


def test_the_docstring_examples_run():
    import doctest

    import hierloco.recipes.ablations.paper_check
    import hierloco.recipes.compare.paper_check

    for module in (hierloco.recipes.compare.paper_check, hierloco.recipes.ablations.paper_check):
        assert doctest.testmod(module).failed == 0
