"""The gait-transition claim (Li et al., RA-L 2021, Sec. V, Fig. 9), declared for ``hierloco verdicts``
(:mod:`hierloco.claims`, ``docs/claims.md``): the planner picks the gait a target needs, on a speed profile whose
fast targets only some gaits reach (``docs/gaits.md``).

Decided from job records, as every other claim: the gait study's profile jobs keep a per-action table in their
records (each action's gait, classified from its foot contacts, its target speed and the gaits that reach it:
:func:`hierloco.recipes.gaits.run.action_table`), and the study's profile table is made again from those records
(:func:`hierloco.recipes.gaits.run.profile_from_records`, the rows ``profile.csv`` holds) and decided with the study's
own test (:func:`hierloco.recipes.gaits.run.needed_gait_shares`, ``decide_needed_gait``'s options). While any of
the study's profile records lacks that table (made before the study kept it), the claim is "not measured yet" and
says what it needs: the study's command run again, which runs those jobs again.
"""

from __future__ import annotations

import math

import numpy as np

from hierloco.claims import CLAIMS, NOT_MEASURED, Check, Claim, Source, Study, decided, part

RECORDS = "gaits/records"  # the gait study's records, under results/
TAG = "speeds"             # the run directories of the library with a slow ripple (daisy_seed<seed>_speeds...)
COMMAND = ("hierloco study gaits robot=daisy own=tripod '~gaits' '+gaits={tripod: [[FL, MR, RL], [FR, ML, RR]], "
           "ripple: [[FL, MR], [ML, RR], [RL, FR]]}' 'gait_boxes={ripple: {command_low: [-0.1, -0.1, -0.2], "
           f"command_high: [0.1, 0.1, 0.2]}}}}' tag={TAG} records=results/{RECORDS} out_dir=results/gaits/daisy_speeds")
NEEDS = (f"the per-action table of the gait study's profile jobs in their records (`results/{RECORDS}`: each "
         "action's gait from its foot contacts, its target speed and the gaits that reach it); records made before "
         f"the study kept it hold one row per episode only: run the study again, `{COMMAND}` (it runs the jobs whose "
         "records lack the table)")


def claim_text() -> str:
    from hierloco.recipes.gaits.run import NEEDED_GAIT_EFFECT

    return ("The planner picks the gait a target needs: where only some gaits reach the target, its actions walk them "
            f"at least {NEEDED_GAIT_EFFECT:.0%} more often than where any gait will do")


def gait_checks(rows: list[dict]) -> list[Check]:
    """The gait-transition claim on a speed profile (Sec. V, Fig. 9), from a gait study's profile rows with the
    gaits each target needs (``recipes/gaits``, ``gait_boxes``; ``profile.csv``, or the same rows made from the
    study's records, :func:`hierloco.recipes.gaits.run.profile_from_records`): per seed, the share of actions in the
    needed gaits where only they reach the target against their share where any gait will do, higher by at least
    ``NEEDED_GAIT_EFFECT`` (paired by seed; :func:`recipes.gaits.run.decide_needed_gait`)."""
    from hierloco.recipes.gaits.run import NEEDED_GAIT_EFFECT, needed_gait_shares, targets_needing

    checks = []
    for robot in sorted({r["robot"] for r in rows}):
        mine = [r for r in rows if r["robot"] == robot]
        several = next((r["method"] for r in mine if r["gait"]), None)
        shares = needed_gait_shares(mine, several) if several else {}
        if not shares:
            continue
        fast = np.array([shares[seed][0] for seed in sorted(shares)])
        slow = np.array([shares[seed][1] for seed in sorted(shares)])
        targets = ", ".join(f"{float(speed):.2f} m/s: {gaits.replace('|', ', ')}"
                            for speed, gaits in targets_needing(mine, several))
        ours = (f"the needed gaits' share {100 * fast.mean():.0f} +- {100 * fast.std():.0f} % where only they reach "
                f"the target ({targets}), {100 * slow.mean():.0f} +- {100 * slow.std():.0f} % where any gait will "
                f"do (n={len(shares)}; {several})")
        checks.append(decided(
            "gait_needed", claim_text(), robot, "normal", "speed profile", ours, "-",
            [part("where needed vs where any will do", 1.0 - fast, 1.0 - slow, "better", paired=True,
                  names=("other gaits' share where needed", "other gaits' share where any will do"),
                  options={"min_effect_rel": 0.0, "min_effect_abs": NEEDED_GAIT_EFFECT,
                           "not_testable": math.inf})], "Sec. V, Fig. 9"))
    return checks


def measured(evidence, study: Study) -> list[Check]:
    """The claim's checks on ``study``'s profile table made from its records; none (not measured yet) where it has
    no records, or where any of its profile jobs' records lacks its per-action table (a verdict on the seeds that
    have it would be another test than the study's)."""
    if study.name not in evidence.rows or evidence.incomplete.get(study.name):
        return []
    return gait_checks(evidence.rows[study.name])


def study_checks(evidence, study: Study) -> list[Check]:
    """The checks of the study's own page (``<study>/verdicts.md``): :func:`measured`, else one check "not measured",
    naming the records that lack the per-action table and what it needs."""
    found = measured(evidence, study)
    if found:
        return found
    lacking = evidence.incomplete.get(study.name, [])
    which = (f"{len(lacking)} profile record(s) without a per-action table ({', '.join(lacking[:2])}"
             f"{', ...' if len(lacking) > 2 else ''}); " if lacking
             else "no profile rows with the gaits a target needs; ")
    return [Check("gait_needed", claim_text(), study.robot, "normal", "speed profile", "-", "-", NOT_MEASURED,
                  f"not measured yet: {which}it needs {NEEDS}", "Sec. V, Fig. 9")]


def profile_rows(folder):
    from hierloco.recipes.gaits.run import profile_from_records

    return profile_from_records(folder, robot="daisy", tag=TAG)


STUDIES = (
    Study("gaits/daisy_speeds", order=100, records=(RECORDS,), rows_from=profile_rows, robot="daisy",
          rows_note=" (the gait study's profile jobs: the table of every action, made from their records)",
          command=COMMAND, checks=lambda evidence: study_checks(evidence, STUDIES[0])),
)

SOURCE = Source(
    "gaits", order=90,
    checks=lambda evidence: [c for study in STUDIES for c in measured(evidence, study)],
    folder=lambda check: next(study.name for study in STUDIES if study.robot == check.robot))

GAIT_NEEDED = Claim(
    order=20, where="Sec. V; Fig. 9", source="gaits", key="gait_needed", robots=("daisy",), needs=NEEDS,
    words="\"Our learned latent space can induce gait transitions in the low-level if needed by the task\" (Fig. 9); "
          "\"the high-level latent action space can be used to transit between gaits, if needed by the task\" (ours: "
          "Daisy's experts in tripod over its whole command box and in a ripple that walks only slowly, one latent "
          "space over both; a speed profile whose fast targets only the tripod reaches)")

A1_TRANSITIONS = Claim(
    order=20.1, words="gait transitions \"if needed by the task\" on A1 (trot, pace, bound in one latent space)",
    where="Sec. V (\"on both robot simulations\"), Fig. 9", status="not testable here", robots=("a1",),
    needs="an A1 speed profile whose fast targets only some gaits reach (the design of the Daisy gait claim above, run "
          "on Daisy only); "
          "measured outside a test: A1's latent space over several gaits costs 0.643 (seeds 0, 2) against its own "
          "gait's 0.190 (3 seeds), \"several gaits cost as little as the own gait\" does not hold "
          "(`gaits/README.md`), so a gait transition on A1 would come at a cost the test here has not weighed")

CLAIMS.add(*STUDIES, SOURCE, GAIT_NEEDED, A1_TRANSITIONS)
