"""The sample-efficiency claim (Li et al., RA-L 2021, Sec. I, III-C and IV-B), declared for ``hierloco verdicts``
(:mod:`hierloco.claims`, ``docs/claims.md``).

Decided by :func:`recipes.sample_efficiency.run.check_claims` on this study's records (the smaller budgets) and the
comparison's LAT and SAC runs of the paper's configuration (the full budgets) for the seeds it ran, as the study itself
takes them. It keeps no page of its own here (its ``paper_check.md`` is the study's).
"""

from __future__ import annotations

from hierloco.claims import CLAIMS, TASKS, Check, Claim, Evidence, Source, Study, job_minutes
from hierloco.recipes.compare.claims import DEFAULTS, paper_configuration


def sample_efficiency_checks(evidence: Evidence) -> list[Check]:
    """The study's claims on its records, its full budgets being the comparison's LAT and SAC runs of the paper's
    configuration for the seeds it ran."""
    from hierloco.recipes.sample_efficiency.run import check_claims, curves_of

    own = evidence.runs.get("sample_efficiency", [])
    seeds = {(r.robot, r.seed) for r in own}
    full = [r for r in evidence.runs.get("compare_full", []) if r.method in ("lat", "sac") and r.setting == "normal"
            and (r.robot, r.seed) in seeds and r.config and paper_configuration(r)]
    return check_claims(curves_of(own + full, TASKS), DEFAULTS["num_transitions"]) if own else []


def _folder(check: Check) -> str:
    """The full budgets are the comparison's runs."""
    full = any(name.endswith(f":{DEFAULTS['num_transitions']}") for part in check.parts for name in part.names)
    return "compare_full" if full else "sample_efficiency"


def budget_job(evidence: Evidence, robot: str, side: str) -> tuple[tuple, str, list[float]]:
    """The job a new seed of ``side`` (``"<method>:<samples>"``) runs: the method at that budget."""
    from hierloco.recipes.sample_efficiency.run import BUDGET

    method, _, samples = side.partition(":")
    runs = [r for r in evidence.runs.get("sample_efficiency", []) + evidence.runs.get("compare_full", [])
            if r.method == method and r.robot == robot and r.setting == "normal"
            and r.factor(BUDGET[method]) == int(samples)]
    return ("sample_efficiency", method, int(samples)), f"{method} with {samples} samples (per task)", \
        job_minutes(runs)


STUDY = Study("sample_efficiency", order=70, records=("sample_efficiency/records",),
              command="hierloco study sample_efficiency records=results/sample_efficiency/records "
                      "out_dir=results/sample_efficiency")

def configuration(name: str) -> str:
    """The full budget's sides are the comparison's runs of the paper's configuration (``"lat:10000"`` is
    ``"lat:normal"``): a comparison at that budget is the comparison's test of LAT against SAC, counted there."""
    method, _, samples = name.partition(":")
    return f"{method}:normal" if samples == str(DEFAULTS["num_transitions"]) else name


SOURCE = Source("sample_efficiency", order=60, checks=sample_efficiency_checks, folder=_folder, job=budget_job,
                alias=configuration)

SAMPLE_EFFICIENT = Claim(
    order=17, where="Sec. I; Sec. III-C; Sec. IV-B", source="sample_efficiency", key="sample_efficient",
    words="\"this model-based planner outperforms model-free approaches ... in sample-efficiency\"; SAC is "
          "\"re-trained for new tasks, hence using 3 times as much data\" (ours: LAT with N CoM transitions in all "
          "against SAC with N high-level steps per task, at N = 2000, 5000 and the comparison's 10,000)")

CLAIMS.add(STUDY, SOURCE, SAMPLE_EFFICIENT)
