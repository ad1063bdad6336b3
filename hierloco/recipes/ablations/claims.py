"""The ablation claims (Li et al., RA-L 2021, Sec. IV-E, Fig. 10b-d), declared for ``hierloco verdicts``
(:mod:`hierloco.claims`, ``docs/claims.md``).

The claims themselves are :mod:`recipes.ablations.paper_check`'s, decided on rows labelled ``"<ablation>=<value>"``
(:func:`ablation_rows`). For the paper's claims the trials at the preset's sizes are pooled with the same
configuration's LAT runs on Daisy made elsewhere (:func:`recipes.compare.claims.pooled_runs`). ``ablations/no_turn``
(experts that do not turn, latent dimension 2 and 3) is this study's own question.
"""

from __future__ import annotations

from hierloco.claims import CLAIMS, NOT_MEASURED, Check, Claim, Evidence, Source, Study, job_minutes
from hierloco.evidence import Run, rows_of
from hierloco.recipes.ablations import paper_check
from hierloco.recipes.compare.claims import DEFAULTS, pooled_runs


def ablation_rows(runs: list[Run]) -> list[dict]:
    """Rows labelled ``"<ablation>=<value>"`` from the stage keys' sizes: a run that differs from the preset in one
    size is that ablation's; a run at the preset's sizes is both ``latent_dim=3`` and ``num_experts=50``."""
    rows = []
    for run in runs:
        f = {name: run.factor(name) for name in DEFAULTS}
        other = {name for name, value in f.items() if value != DEFAULTS[name]}
        labels = [f"{name}={f[name]}" for name in ("latent_dim", "num_experts") if other <= {name}]
        labels += [f"dynamics_samples={f['num_transitions']}"] if other == {"num_transitions"} else []
        for label in labels:
            rows += rows_of([run], method=lambda _, label=label: label)
    return rows


def ablation_checks(runs: list[Run]) -> list[Check]:
    """The ablation claims (:func:`recipes.ablations.paper_check.check_claims`) on these runs."""
    return paper_check.check_claims(ablation_rows(runs))


def paper_ablation_checks(evidence: Evidence) -> list[Check]:
    """The ablation claims on the study's trials, the preset's LAT runs on Daisy made elsewhere pooled in."""
    if "ablations" not in evidence.runs:
        return []
    extra = [r for r in pooled_runs(evidence) if (r.method, r.robot, r.setting) == ("lat", "daisy", "normal")
             and r.folder != "ablations"]
    return ablation_checks(evidence.runs["ablations"] + extra)


def trial_job(study: str):
    """The job a new trial of ``side`` (``"<ablation>=<value>"``) runs in ``study``: one LAT trial at that value."""
    def job(evidence: Evidence, robot: str, side: str) -> tuple[tuple, str, list[float]]:
        factor, _, value = side.partition("=")
        factor = {"dynamics_samples": "num_transitions"}.get(factor, factor)
        runs = [r for r in evidence.runs.get(study, []) if str(r.factor(factor)) == value
                and all(r.factor(f) == v for f, v in DEFAULTS.items() if f != factor)]
        return ("ablation", study, side), f"LAT trial {side} ({study})", job_minutes(runs)

    return job


def _no_turn_note(checks: dict) -> str:
    """Beside the latent-dimension claim: where the same claim with experts that do not turn is decided (the
    study's own question, not counted in the ledger)."""
    if not checks.get("ablations/no_turn"):
        return ""
    return ("\nExperts that do not turn (latent dimension 2 and 3 only) are the ablation study's own question: "
            "`ablations/no_turn/verdicts.md`, not counted here.")


STUDIES = (
    Study("ablations", order=50, records=("ablations/records",),
          command="hierloco study ablations records=results/ablations/records out_dir=results/ablations",
          pooled=True, checks=lambda evidence: ablation_checks(evidence.runs["ablations"]),
          causes=paper_check.load_causes, paper_column=paper_check.PAPER_COLUMN),
    Study("ablations/no_turn", order=60, records=("ablations/no_turn/records",),
          command="hierloco study ablations trials=3 run=[latent_dim] 'ablations.latent_dim.values=[2,3]' "
                  "(experts that do not turn)",
          checks=lambda evidence: [c for c in ablation_checks(evidence.runs["ablations/no_turn"])
                                   if c.verdict != NOT_MEASURED],   # it varies the latent dimension only
          questions="experts that do not turn"),
)

SOURCES = (
    Source("ablations", order=20, checks=paper_ablation_checks, job=trial_job("ablations")),
    Source("ablations/no_turn", order=30,
           checks=lambda evidence: ablation_checks(evidence.runs.get("ablations/no_turn", [])),
           job=trial_job("ablations/no_turn"), questions=lambda check: True),
)

PAPER_CLAIMS = (
    Claim(order=11, words="latent dimension 2, 3, 4: \"no significant effect on the performance\"",
          where="Sec. IV-E; Fig. 10b (Daisy)", robots=("daisy",), source="ablations", key="latent_dim_no_effect",
          note=_no_turn_note),
    Claim(order=12, words="\"as the number of experts increases the performance on each task improves\" (10 to 30)",
          where="Sec. IV-E; Fig. 10c (Daisy)", robots=("daisy",), source="ablations", key="experts_10_30_better"),
    Claim(order=13, words="\"the difference from 30 to 50 [experts] is minor\"", where="Sec. IV-E; Fig. 10c (Daisy)",
          robots=("daisy",), source="ablations", key="experts_30_50_minor"),
    Claim(order=14, words="\"a significant improvement in performance when the dynamics is learned from 2000 data "
                          "points versus 1000\"",
          where="Sec. IV-E; Fig. 10d (Daisy)", robots=("daisy",), source="ablations",
          key="samples_1000_2000_better"),
    Claim(order=15, words="\"no significant difference in performance between 2000 and 5000 data points\"",
          where="Sec. IV-E; Fig. 10d (Daisy)", robots=("daisy",), source="ablations", key="samples_2000_5000_minor"),
)

CLAIMS.add(*STUDIES, *SOURCES, *PAPER_CLAIMS)
