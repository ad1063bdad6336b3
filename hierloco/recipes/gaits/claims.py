"""The gait-transition claim (Li et al., RA-L 2021, Sec. V, Fig. 9), declared for ``hierloco verdicts``
(:mod:`hierloco.claims`, ``docs/claims.md``): the planner picks the gait a target needs, on a speed profile whose
fast targets only some gaits reach (``docs/gaits.md``).

Decided from the study's profile table (one row per action: its gait and the gaits its target needs), not from job
records: a record holds one row per episode, not the gait of each action, so rebuilding this verdict from records
needs the evaluation to record each action's gait.
"""

from __future__ import annotations

import math

import numpy as np

from hierloco.claims import CLAIMS, Check, Claim, Source, Study, decided, part


def gait_checks(rows: list[dict]) -> list[Check]:
    """The gait-transition claim on a speed profile (Sec. V, Fig. 9), from a gait study's profile rows with the
    gaits each target needs (``recipes/gaits``, ``gait_boxes``): per seed, the share of actions in the needed gaits
    where only they reach the target against their share where any gait will do, higher by at least
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
            "gait_needed", "The planner picks the gait a target needs: where only some gaits reach the target, its "
            f"actions walk them at least {NEEDED_GAIT_EFFECT:.0%} more often than where any gait will do", robot,
            "normal", "speed profile", ours, "-",
            [part("where needed vs where any will do", 1.0 - fast, 1.0 - slow, "better", paired=True,
                  names=("other gaits' share where needed", "other gaits' share where any will do"),
                  options={"min_effect_rel": 0.0, "min_effect_abs": NEEDED_GAIT_EFFECT,
                           "not_testable": math.inf})], "Sec. V, Fig. 9"))
    return checks


STUDIES = (
    Study("gaits/daisy_speeds", order=100, rows="gaits/daisy_speeds/profile.csv", robot="daisy",
          rows_note=" (the gait study's table of every action, made from its runs' evaluations: no records)",
          command="hierloco study gaits robot=daisy own=tripod '~gaits' '+gaits={tripod: [[FL, MR, RL], "
                  "[FR, ML, RR]], ripple: [[FL, MR], [ML, RR], [RL, FR]]}' 'gait_boxes={ripple: {command_low: "
                  "[-0.1, -0.1, -0.2], command_high: [0.1, 0.1, 0.2]}}' tag=speeds records=results/gaits/records "
                  "out_dir=results/gaits/daisy_speeds",
          checks=lambda evidence: gait_checks(evidence.rows["gaits/daisy_speeds"])),
)

SOURCE = Source(
    "gaits", order=90,
    checks=lambda evidence: [c for study in STUDIES if study.name in evidence.rows
                             for c in gait_checks(evidence.rows[study.name])],
    folder=lambda check: next(study.name for study in STUDIES if study.robot == check.robot))

GAIT_NEEDED = Claim(
    order=20, where="Sec. V; Fig. 9", source="gaits", key="gait_needed", robots=("daisy",),
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
