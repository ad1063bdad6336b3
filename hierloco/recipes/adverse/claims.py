"""The damage study's claims (Li et al., RA-L 2021, Sec. IV-C and IV-D), declared for ``hierloco verdicts``
(:mod:`hierloco.claims`, ``docs/claims.md``).

Per robot, actuator profile and fault, "LAT beats IK" (both footstep laws) and, in the normal setting, "LAT is close
to IK"; and the dynamics re-learned after damage from few samples against 10,000. Its own-profile normal and
legs-disabled jobs are the comparison's configurations (pooled there); the paper's sample-efficiency claim reads
its 2000-sample re-learning; the rest are the study's own questions.
"""

from __future__ import annotations

from hierloco import stats
from hierloco.claims import CLAIMS, TASKS, Check, Claim, Evidence, Source, Study, decided, describe, job_minutes, part
from hierloco.claims import seed_costs
from hierloco.evidence import Run
from hierloco.recipes.compare.claims import comparison_job
from hierloco.recipes.compare.paper_check import IK_METHODS

PROFILES = ("own", "stiff", "stiff_servos")
FAULTS = ("legs_disabled", "one_leg_locked", "rear_limp")
SAMPLES = (200, 500, 1000, 2000)


def adverse_checks(runs: list[Run], findings: list[dict]) -> list[Check]:
    """The damage study: per robot, profile and fault, "LAT beats IK" (our integral law, and the plain footstep law)
    on each task, and in the normal setting "LAT is close to IK"; faults in which a method's jobs ended in a finding
    (every random action fell) are not testable; and the dynamics re-learned after damage from few samples against
    10,000 (rear legs locked, own profile)."""
    checks = []
    own = lambda r: r.profile == "own" and r.factor("num_transitions", 10000) == 10000  # noqa: E731
    for robot in sorted({r.robot for r in runs}):
        for profile in PROFILES:
            chosen = [r for r in runs if r.robot == robot and (own(r) if profile == "own" else r.profile == profile)]
            for setting in ("normal", *FAULTS):
                failed = [f for f in findings if f["robot"] == robot and f["profile"] == profile
                          and setting in f["settings"]]
                where = f"{setting} ({profile})"
                for task in TASKS:
                    lat = seed_costs(chosen, method="lat", setting=setting, task=task)
                    for ik in IK_METHODS:
                        base = seed_costs(chosen, method=ik, setting=setting, task=task)
                        claim = (f"LAT is close to {ik.upper()} (within {stats.EQUIV_MARGIN_REL:.0%})"
                                 if setting == "normal" else f"LAT beats {ik.upper()} after damage")
                        key = f"close:{ik}" if setting == "normal" else f"damaged:{ik}"
                        if failed and not (lat.size and base.size):
                            methods = sorted({f["method"] for f in failed})
                            checks.append(Check(key, claim, robot, where, task, "-", "-", stats.NOT_TESTABLE,
                                                f"not evaluable ({', '.join(methods)}): {failed[0]['error']}",
                                                "Sec. IV-C"))
                        elif lat.size and base.size:
                            kind = "close" if setting == "normal" else "better"
                            checks.append(decided(
                                key, claim, robot, where, task, f"{describe('lat', lat)}, {describe(ik, base)}", "-",
                                [part(f"lat vs {ik}", lat, base, kind,
                                      names=(f"lat:{setting}:{profile}", f"{ik}:{setting}:{profile}"))],
                                "Sec. IV-C"))
        for method in ("lat", "ik"):
            chosen = [r for r in runs if r.robot == robot and r.profile == "own" and r.method == method]
            for task in TASKS:
                full = seed_costs(chosen, setting="legs_disabled", task=task, num_transitions=10000)
                for count in SAMPLES:
                    few = seed_costs(chosen, setting="legs_disabled", task=task, num_transitions=count)
                    if few.size and full.size:
                        checks.append(decided(
                            "samples", f"{method.upper()} re-learned from {count} samples is close to 10,000 (within "
                            f"{stats.EQUIV_MARGIN_REL:.0%})", robot, "legs_disabled (own)", task,
                            f"{describe(str(count), few)}, {describe('10000', full)}", "-",
                            [part(f"{count} vs 10000", few, full, "close",
                                  names=(f"{method}:samples={count}", f"{method}:samples=10000"))],
                            "Sec. IV-D (2000 samples)"))
    return checks


def damage_job(evidence: Evidence, robot: str, side: str) -> tuple[tuple, str, list[float]]:
    """The job a new seed of ``side`` runs: a few-sample re-learning job (``"<method>:samples=<n>"``), a fault job
    (``"<method>:<fault>:<profile>"``), else a comparison job (:func:`recipes.compare.claims.comparison_job`)."""
    method, _, rest = side.partition(":")
    setting, _, profile = rest.partition(":")
    profile = profile or "own"
    adverse = evidence.runs.get("adverse", [])
    if setting.startswith("samples="):
        count = int(setting.split("=")[1])
        runs = [r for r in adverse if r.method == method and r.robot == robot and "/samples/" in r.record
                and r.factor("num_transitions") == count]
        return ("samples", method, count), f"{method} re-learned from {count} samples (rear legs locked)", \
            job_minutes(runs)
    if setting in FAULTS[1:]:
        runs = [r for r in adverse if r.method == method and r.robot == robot and r.profile == profile
                and r.setting == setting]
        return ("fault", method, profile, setting), f"{method} {setting} ({profile})", job_minutes(runs)
    return comparison_job(evidence, robot, side)


def _checks(evidence: Evidence) -> list[Check] | None:
    return adverse_checks(evidence.runs["adverse"], evidence.findings.get("adverse", []))


STUDY = Study(
    "adverse", order=20, records=("adverse/records",),
    command="hierloco study adverse records=results/adverse/records out_dir=results/adverse",
    pooled=True, checks=_checks,
    questions="the damage study's other faults, actuator profiles and few-sample re-learning")

SOURCE = Source(
    "adverse", order=50,
    checks=lambda evidence: _checks(evidence) if "adverse" in evidence.runs else [],
    job=damage_job,
    # the paper's normal and legs-disabled settings on the robot's own profile are decided on the pooled runs
    questions=lambda check: not (check.setting in ("normal (own)", "legs_disabled (own)") and check.key != "samples"))

SAMPLE_EFFICIENT = Claim(
    order=16, where="Abstract; Sec. IV-D; Sec. VI", source="adverse", key="samples",
    words="sample-efficient: tasks solved \"with only 2000 hardware samples\" (ours: after damage, the dynamics "
          "re-learned from 2000 samples against 10,000)",
    select=lambda check: check.claim.startswith("LAT") and "from 2000 samples" in check.claim)

CLAIMS.add(STUDY, SOURCE, SAMPLE_EFFICIENT)
