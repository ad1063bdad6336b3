"""The paper's ablation claims checked on hand-made trials: each verdict follows the numbers."""

import numpy as np
import pytest

from recipes.ablations.paper_check import check_claims, load_causes, paper_check_markdown, significant


def trials(costs: dict, task="goal_reaching"):
    """``costs``: "<ablation>=<value>" -> each trial's cost (one target per trial)."""
    return [{"method": m, "robot": "daisy", "setting": "normal", "task": task, "seed": s, "normalized_cost": c}
            for m, per_trial in costs.items() for s, c in enumerate(per_trial)]


def verdicts(rows, task="goal_reaching"):
    return {c.key: c.verdict for c in check_claims(rows) if c.task == task}


def test_significant_needs_both_the_tie_margin_and_two_standard_errors():
    tight = np.array([0.10, 0.11, 0.10, 0.11])
    assert significant(tight, tight + 0.05)
    assert not significant(tight, tight + 0.015)  # within the tie margin, however tight
    spread = np.array([0.0, 0.3, 0.0, 0.3])
    assert not significant(spread, spread + 0.05)  # 0.05 apart, two standard errors of 0.17


def test_each_claim_follows_the_numbers():
    rows = trials({"latent_dim=2": [0.30, 0.32, 0.31], "latent_dim=3": [0.10, 0.11, 0.10],
                   "latent_dim=4": [0.10, 0.10, 0.11],
                   "num_experts=10": [0.20, 0.21, 0.20], "num_experts=30": [0.10, 0.11, 0.10],
                   "num_experts=50": [0.10, 0.10, 0.11],
                   "dynamics_samples=1000": [0.10, 0.11, 0.10], "dynamics_samples=2000": [0.10, 0.10, 0.11]})
    got = verdicts(rows)
    assert got["latent_dim_no_effect"] == "does not hold (2 vs 3, 2 vs 4)"
    assert got["experts_10_30_better"] == "holds" and got["experts_30_50_minor"] == "holds"
    assert got["samples_1000_2000_better"] == "does not hold (no significant difference)"
    assert got["samples_2000_5000_minor"] == "not measured"  # no 5000-sample trials
    opposite = trials({"num_experts=10": [0.1, 0.1, 0.1], "num_experts=30": [0.3, 0.3, 0.3]})
    assert verdicts(opposite)["experts_10_30_better"] == "does not hold (the opposite)"
    assert set(verdicts(rows, task="velocity_tracking").values()) == {"not measured"}


def test_markdown_quotes_the_paper_and_gives_the_causes(tmp_path):
    causes = tmp_path / "causes.yaml"
    causes.write_text("- {claims: [latent_dim_no_effect], cause: Two latent dimensions hold three commands badly.}")
    rows = trials({"latent_dim=2": [0.3, 0.3], "latent_dim=3": [0.1, 0.1]})
    text = paper_check_markdown(check_claims(rows), title="test", causes=load_causes(causes))
    assert "\"no significant effect on the performance\"" in text and "2: 0.30 +- 0.00, 3: 0.10 +- 0.00" in text
    assert "| does not hold (2 vs 3) | [1](#cause-1) |" in text and "hold three commands badly" in text
    causes.write_text("- {claims: [learned_best], cause: a comparison's claim, not an ablation's}")
    with pytest.raises(ValueError, match="unknown claim 'learned_best'"):
        load_causes(causes)
