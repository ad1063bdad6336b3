"""The paper's claims checked on hand-made rows: each verdict follows the numbers."""

import pytest

from recipes.compare.paper_check import check_claims, load_causes, paper_check_markdown, seed_means


def rows(costs: dict, setting="normal", task="velocity_tracking", robot="a1"):
    """``costs``: method -> per-seed lists of episode costs."""
    return [{"method": m, "robot": robot, "setting": setting, "task": task, "seed": seed, "normalized_cost": c}
            for m, seeds in costs.items() for seed, episodes in enumerate(seeds) for c in episodes]


def verdicts(checks):
    return {(c.claim, c.setting, c.task): c.verdict for c in checks}


def test_seed_means_average_each_seed_and_count_a_fall_as_one():
    data = rows({"lat": [[0.2, 0.4], [float("nan"), 0.0]]})
    assert seed_means(data, method="lat", robot="a1", setting="normal", task="velocity_tracking").tolist() == [
        0.30000000000000004, 0.5]


def test_each_claim_follows_the_numbers():
    data = (rows({"lat": [[0.2], [0.2]], "lib": [[0.6], [0.5]], "sac": [[0.1], [0.1]], "ik": [[0.05], [0.05]]})
            + rows({"lat": [[0.6]], "ik": [[0.9]], "ik_plain": [[0.5]]}, setting="legs_disabled"))
    got = verdicts(check_claims(data))
    assert got[("LAT is best among the learned methods", "normal", "velocity_tracking")] == "does not hold"  # SAC
    assert got[("LAT is close to IK (at most 0.1 above)", "normal", "velocity_tracking")] == "does not hold"
    assert got[("LAT beats IK with legs disabled", "legs_disabled", "velocity_tracking")] == "holds"
    assert got[("LAT beats IK_PLAIN with legs disabled", "legs_disabled", "velocity_tracking")] == "does not hold"
    assert got[("LIB is worse than LAT at velocity tracking", "normal", "velocity_tracking")] == "holds"


def test_markdown_counts_and_quotes_the_paper():
    data = rows({"lat": [[0.2]], "lib": [[0.1]]})
    text = paper_check_markdown(check_claims(data), title="test")
    assert "lib 0.58 +- 0.01" in text and "| does not hold | not checked |" in text
    assert "0 hold, 2 do not hold (0 with the cause we checked, 2 not checked)." in text


def test_a_difference_within_the_tie_margin_is_no_win():
    data = rows({"lat": [[0.60]], "ik": [[0.61]]}, setting="legs_disabled")
    got = verdicts(check_claims(data))
    assert got[("LAT beats IK with legs disabled", "legs_disabled", "velocity_tracking")].startswith(
        "does not hold (a tie")


def test_the_tuned_ik_is_named_in_its_claims():
    rows = [{"method": m, "robot": "daisy", "setting": s, "task": "velocity_tracking", "seed": 0, "normalized_cost": c}
            for m, s, c in (("lat", "normal", 0.16), ("ik", "normal", 0.37), ("ik_plain", "normal", 0.10),
                            ("lat", "legs_disabled", 0.68), ("ik", "legs_disabled", 0.57),
                            ("ik_plain", "legs_disabled", 0.93))]
    checks = {c.claim: c.verdict for c in check_claims(rows, tuned_ik={"daisy": "ik_plain"})}
    assert checks["LAT beats IK_PLAIN (the IK tuned on the training targets) with legs disabled"] == "holds"
    assert checks["LAT beats IK with legs disabled"] == "does not hold"
    assert "LAT is close to IK_PLAIN (the IK tuned on the training targets) (at most 0.1 above)" in checks


def goal_rows(method: str, train: float, held: float, robot="a1"):
    """Goal reaching over 8 goals and 2 seeds: the even goals (the training split) cost ``train``, the odd ``held``."""
    return [{"method": method, "robot": robot, "setting": "normal", "task": "goal_reaching", "seed": seed,
             "episode": e, "normalized_cost": train if e % 2 == 0 else held} for seed in (0, 1) for e in range(8)]


def test_generalisation_compares_held_out_goals_with_training_goals():
    checks = check_claims(goal_rows("sac", train=0.10, held=0.40) + goal_rows("sac_sac", train=0.10, held=0.11))
    got = {c.key: c for c in checks}
    assert got["heldout_worse:sac"].verdict == "holds"
    assert got["heldout_worse:sac"].ours == "training goals 0.10 +- 0.00, held-out goals 0.40 +- 0.00"
    assert got["heldout_worse:sac_sac"].verdict.startswith("does not hold (a tie")


def write(tmp_path, text):
    path = tmp_path / "causes.yaml"
    path.write_text(text)
    return path


def test_each_claim_that_does_not_hold_gets_its_cause_and_stale_causes_are_listed(tmp_path):
    data = rows({"lat": [[0.2]], "lib": [[0.1]], "ik": [[0.05]]})
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
    assert lib_row.endswith("| does not hold | [1](#cause-1) |")
    best_row = next(line for line in text.splitlines() if line.startswith("| LAT is best"))
    assert best_row.endswith("| does not hold | not checked |")          # the cause is for goal reaching only
    assert "1. LIB's experts cover the commanded speeds." in text
    assert "(2 with the cause we checked" not in text and "(1 with the cause we checked, 2 not checked)" in text
    stale = text.split("## Causes given for claims that hold or were not measured here")[1]
    assert "Every method reaches every goal." in stale and "Daisy only." in stale


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
