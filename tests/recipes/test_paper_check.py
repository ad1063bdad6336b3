"""The paper's claims checked on hand-made rows: each verdict follows the numbers."""

from recipes.compare.paper_check import check_claims, paper_check_markdown, seed_means


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
    assert "lib 0.58 +- 0.01" in text and "| does not hold |" in text and "0 hold, 2 do not hold." in text


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
