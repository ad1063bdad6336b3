"""The paper's ablation claims checked on hand-made trials: each verdict follows the numbers."""

import numpy as np
import pytest

from hierloco.recipes.ablations.paper_check import check_claims, load_causes, paper_check_markdown, significant


def trials(costs: dict, task="goal_reaching"):
    """``costs``: "<ablation>=<value>" -> each trial's cost (one target per trial)."""
    return [{"method": m, "robot": "daisy", "setting": "normal", "task": task, "seed": s, "normalized_cost": c}
            for m, per_trial in costs.items() for s, c in enumerate(per_trial)]


def verdicts(rows, task="goal_reaching"):
    return {c.key: c.verdict for c in check_claims(rows) if c.task == task}


def test_significant_needs_both_the_test_and_the_minimum_effect():
    tight = np.array([0.10, 0.11, 0.10, 0.11])
    assert significant(tight, tight + 0.05)
    assert not significant(tight, tight + 0.008)  # below the minimum effect (0.01), however tight
    spread = np.array([0.0, 0.3, 0.0, 0.3])
    assert not significant(spread, spread + 0.05)  # 0.05 apart, within the spread of the trials


def test_each_claim_follows_the_numbers():
    rows = trials({"latent_dim=2": [0.30, 0.32, 0.31], "latent_dim=3": [0.10, 0.11, 0.10],
                   "latent_dim=4": [0.10, 0.10, 0.11],
                   "num_experts=10": [0.20, 0.21, 0.20], "num_experts=30": [0.10, 0.11, 0.10],
                   "num_experts=50": [0.10, 0.10, 0.11],
                   "dynamics_samples=1000": [0.10, 0.13, 0.11], "dynamics_samples=2000": [0.10, 0.12, 0.09]})
    checks = {c.key: c for c in check_claims(rows) if c.task == "goal_reaching"}
    got = {key: c.verdict for key, c in checks.items()}
    assert got["latent_dim_no_effect"] == "does not hold"
    assert checks["latent_dim_no_effect"].detail.startswith("differ: 2 vs 3, 2 vs 4;")
    assert got["experts_10_30_better"] == "holds" and got["experts_30_50_minor"] == "holds"
    # three trials 0.01 apart in a spread of 0.015 neither show nor exclude a 10 % gain
    assert got["samples_1000_2000_better"] == "inconclusive"
    assert got["samples_2000_5000_minor"] == "not measured"  # no 5000-sample trials
    opposite = trials({"num_experts=10": [0.10, 0.11, 0.10], "num_experts=30": [0.30, 0.31, 0.30]})
    decided = next(c for c in check_claims(opposite) if c.key == "experts_10_30_better" and c.task == "goal_reaching")
    assert decided.verdict == "does not hold" and "significantly higher cost" in decided.detail
    flat = trials({"dynamics_samples=1000": [0.100, 0.101, 0.100, 0.101], "dynamics_samples=2000": [0.101, 0.100,
                                                                                                     0.101, 0.100]})
    assert verdicts(flat)["samples_1000_2000_better"] == "does not hold"   # a gain significantly below 0.01
    assert set(verdicts(rows, task="velocity_tracking").values()) == {"not measured"}


def test_markdown_quotes_the_paper_and_gives_the_causes(tmp_path):
    causes = tmp_path / "causes.yaml"
    causes.write_text("- {claims: [latent_dim_no_effect], cause: Two latent dimensions hold three commands badly.}")
    rows = trials({"latent_dim=2": [0.3, 0.3], "latent_dim=3": [0.1, 0.1]})
    text = paper_check_markdown(check_claims(rows), title="test", causes=load_causes(causes))
    assert "\"no significant effect on the performance\"" in text and "2: 0.30 +- 0.00, 3: 0.10 +- 0.00" in text
    assert "| does not hold | differ: 2 vs 3; " in text and "| [1](#cause-1) |" in text
    assert "hold three commands badly" in text
    causes.write_text("- {claims: [learned_best], cause: a comparison's claim, not an ablation's}")
    with pytest.raises(ValueError, match="unknown claim 'learned_best'"):
        load_causes(causes)
