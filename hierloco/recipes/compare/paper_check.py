"""The paper's claims about its baselines (Li et al., Sec. IV-B and IV-C) decided by tests over seeds.

Each claim is tested per robot and task on the seeds' mean normalised costs (each seed's mean over its episodes
first; a seed run more than once, say on two machines, counts once with the mean of its runs), with the tests of
:mod:`hierloco.stats` (``docs/statistics.md``): "better" is a significantly lower cost (one-sided Welch t at
:data:`hierloco.stats.ALPHA`) by at least the minimum effect; "close" is an equivalence test (TOST) within a margin
relative to the reference's cost; a claim where every method compared is no better than standing still is not
testable. Each claim gets "holds", "does not hold", "inconclusive", "not testable here" or, without the numbers,
"not measured", and is written as a Markdown table beside the numbers the paper states (A1's). Each claim that is
not found to hold is listed with the cause we checked for it, from a YAML file of causes (:func:`load_causes`), or
with "not checked"; a cause whose claim now holds is listed apart, so it does not go stale unseen.

    >>> rows = [{"method": m, "robot": "a1", "setting": "normal", "task": "velocity_tracking", "seed": s,
    ...          "normalized_cost": c + 0.01 * s} for m, c in (("lat", 0.1), ("lib", 0.5), ("ik", 0.105))
    ...         for s in range(3)]
    >>> [(c.key, c.verdict) for c in check_claims(rows)]
    [('learned_best', 'holds'), ('close:ik', 'holds'), ('lib_worse', 'holds')]
"""

from __future__ import annotations

from hierloco import claims as claims_lib
from hierloco import stats
from hierloco.claims import NOT_MEASURED, TASKS, Check, decided, describe, part, seed_means

LEARNED = ("lib", "sac", "sac_sac")   # the learned baselines LAT is claimed to beat on every task
MODEL_FREE = ("sac", "sac_sac")       # trained on half of the targets, claimed not to generalise to the others
IK_METHODS = ("ik", "ik_plain")       # IK with our footstep law, and with the plain footstep law
# the paper's stated numbers, all A1 in simulation: (robot, setting, task, method) -> "mean +- std"; where each is
# stated: Sec. IV-B with Fig. 7b (A1's baseline comparison), Sec. IV-C with Fig. 7d (A1, LAT and IK)
PAPER = {("a1", "normal", "goal_reaching", "lat"): "0.34 +- 0.02",
         ("a1", "normal", "goal_reaching", "sac"): "0.57 +- 0.06",
         ("a1", "normal", "goal_reaching", "sac_sac"): "0.92 +- 0.04",
         ("a1", "normal", "velocity_tracking", "lat"): "0.16 +- 0.10",
         ("a1", "normal", "velocity_tracking", "lib"): "0.58 +- 0.01",
         ("a1", "legs_disabled", "velocity_tracking", "lat"): "0.62 +- 0.06",
         ("a1", "legs_disabled", "velocity_tracking", "ik"): "0.91 +- 0.06"}
# the paper's figure of each claim, per robot (figures numbered in the order of the paper's source): Fig. 7a/7b the
# learned baselines (Daisy/A1), Fig. 7c/7d LAT and IK (Daisy/A1)
FIGURES = {"learned_best": {"daisy": "Fig. 7a, Sec. IV-B", "a1": "Fig. 7b, Sec. IV-B"},
           "lib_worse": {"daisy": "Fig. 7a, Sec. IV-B", "a1": "Fig. 7b, Sec. IV-B"},
           "lib_goals_close": {"daisy": "Fig. 7a, Sec. IV-B", "a1": "Fig. 7b, Sec. IV-B"},
           "sac_sac_worse": {"daisy": "Fig. 7a, Sec. IV-B", "a1": "Fig. 7b, Sec. IV-B"},
           "heldout_worse": {"daisy": "Sec. IV-B", "a1": "Sec. IV-B"},
           "close": {"daisy": "Fig. 7c, Sec. IV-C", "a1": "Fig. 7d, Sec. IV-C"},
           "damaged": {"daisy": "Fig. 7c, Sec. IV-C", "a1": "Fig. 7d, Sec. IV-C"},
           "ik_deteriorates": {"daisy": "Fig. 7c, Sec. IV-C", "a1": "Fig. 7d, Sec. IV-C"}}

# the claims by key (what a file of causes names): a word for the claim, ":<method>" for the baseline it is about
CLAIMS = ("learned_best", "close:ik", "close:ik_plain", "damaged:ik", "damaged:ik_plain", "lib_worse",
          "lib_goals_close", "sac_sac_worse", "ik_deteriorates:ik", "ik_deteriorates:ik_plain", "heldout_worse:sac",
          "heldout_worse:sac_sac")


def check_claims(rows, tuned_ik: dict | None = None, tasks: tuple[str, ...] = TASKS) -> list[Check]:
    """Every claim on every robot and task the rows cover (see the module doc). ``tuned_ik`` (robot -> ``ik`` or
    ``ik_plain``) marks the IK claims of the variant tuned on the training targets (``recipes/tune``), the fair IK.
    ``tasks``: the tasks the per-task claims are tested on (the fair targets add ``trajectory_tracking_fast``)."""
    rows = list(rows)
    tuned_ik = dict(tuned_ik or {})
    checks = []
    for robot in sorted({r["robot"] for r in rows}):
        def means(method, setting, task):
            return seed_means(rows, method=method, robot=robot, setting=setting, task=task)

        def paper(setting, task, methods):
            known = [f"{m} {PAPER[(robot, setting, task, m)]}" for m in methods if (robot, setting, task, m) in PAPER]
            return ", ".join(known) or "-"

        def figure(key):
            return FIGURES[key.split(":")[0]].get(robot, "")

        for task in tasks:
            lat = means("lat", "normal", task)
            others = {m: s for m in LEARNED if (s := means(m, "normal", task)).size}
            if lat.size and others:
                ours = ", ".join([describe("lat", lat)] + [describe(m, s) for m, s in others.items()])
                checks.append(decided("learned_best", "LAT is best among the learned methods", robot, "normal",
                                       task, ours, paper("normal", task, ("lat", *LEARNED)),
                                       [part(f"vs {m}", lat, s, "better", parts=len(others),
                                              names=("lat:normal", f"{m}:normal")) for m, s in others.items()],
                                       figure("learned_best")))
            sac, sac_sac = means("sac", "normal", task), means("sac_sac", "normal", task)
            if sac.size and sac_sac.size:
                checks.append(decided("sac_sac_worse", "SAC-SAC's user-defined action space does worse than SAC's "
                                       "learned one", robot, "normal", task,
                                       f"{describe('sac', sac)}, {describe('sac_sac', sac_sac)}",
                                       paper("normal", task, ("sac", "sac_sac")),
                                       [part("sac vs sac_sac", sac, sac_sac, "better",
                                              names=("sac:normal", "sac_sac:normal"))], figure("sac_sac_worse")))
            for ik in IK_METHODS:
                tuned = " (the IK tuned on the training targets)" if tuned_ik.get(robot) == ik else ""
                base = means(ik, "normal", task)
                if lat.size and base.size:
                    checks.append(decided(f"close:{ik}", f"LAT is close to {ik.upper()}{tuned} (within "
                                           f"{stats.EQUIV_MARGIN_REL:.0%})", robot, "normal", task,
                                           f"{describe('lat', lat)}, {describe(ik, base)}", "-",
                                           [part(f"lat vs {ik}", lat, base, "close",
                                                  names=("lat:normal", f"{ik}:normal"))], figure("close")))
                damaged, damaged_ik = means("lat", "legs_disabled", task), means(ik, "legs_disabled", task)
                if damaged.size and damaged_ik.size:
                    checks.append(decided(f"damaged:{ik}", f"LAT beats {ik.upper()}{tuned} with legs disabled",
                                           robot, "legs_disabled", task,
                                           f"{describe('lat', damaged)}, {describe(ik, damaged_ik)}",
                                           paper("legs_disabled", task, ("lat", ik)),
                                           [part(f"lat vs {ik}", damaged, damaged_ik, "better",
                                                  names=("lat:legs_disabled", f"{ik}:legs_disabled"))],
                                           figure("damaged")))
                if base.size and damaged_ik.size:
                    checks.append(decided(f"ik_deteriorates:{ik}", f"{ik.upper()}{tuned} deteriorates with legs "
                                           "disabled", robot, "legs_disabled", task,
                                           f"normal {describe(ik, base)}, legs disabled {describe(ik, damaged_ik)}",
                                           paper("legs_disabled", task, (ik,)),
                                           [part(f"{ik} normal vs legs disabled", base, damaged_ik, "better",
                                                  names=(f"{ik}:normal", f"{ik}:legs_disabled"))],
                                           figure("ik_deteriorates")))
        lat, lib = means("lat", "normal", "velocity_tracking"), means("lib", "normal", "velocity_tracking")
        claim = "LIB is worse than LAT at velocity tracking"
        known = paper("normal", "velocity_tracking", ("lat", "lib"))
        if lat.size and lib.size:
            checks.append(decided("lib_worse", claim, robot, "normal", "velocity_tracking",
                                   f"{describe('lat', lat)}, {describe('lib', lib)}", known,
                                   [part("lat vs lib", lat, lib, "better", names=("lat:normal", "lib:normal"))],
                                   figure("lib_worse")))
        else:
            checks.append(Check("lib_worse", claim, robot, "normal", "velocity_tracking", "-", known, NOT_MEASURED,
                                "LAT and LIB are not both in the rows", figure("lib_worse")))
        lat, lib = means("lat", "normal", "goal_reaching"), means("lib", "normal", "goal_reaching")
        if lat.size and lib.size:
            checks.append(decided("lib_goals_close", "LIB generalises well to goal reaching (close to LAT, "
                                   f"within {stats.EQUIV_MARGIN_REL:.0%})", robot, "normal", "goal_reaching",
                                   f"{describe('lib', lib)}, {describe('lat', lat)}", "-",
                                   [part("lib vs lat", lib, lat, "close", names=("lib:normal", "lat:normal"))],
                                   figure("lib_goals_close")))
        checks += _generalisation(rows, robot)
    return checks


def _generalisation(rows, robot: str) -> list[Check]:
    """"SAC and SAC-SAC fail to generalise to new targets" (Sec. IV-B) on goal reaching, the task whose held-out
    targets are whole episodes: a model-free method's cost on its held-out goals against its training goals, seed
    by seed (the same policy on both halves: a paired test)."""
    checks = []
    for method in MODEL_FREE:
        episodes = {int(r["episode"]) for r in rows if (r["method"], r["robot"], r["setting"], r["task"])
                    == (method, robot, "normal", "goal_reaching")}
        if len(episodes) < 2:
            continue
        from hierloco.envs.tasks import GoalReaching  # torch: only where a table is judged

        training = set(GoalReaching(num_goals=max(episodes) + 1).training_episodes)
        split = {name: seed_means(rows, method=method, robot=robot, setting="normal", task="goal_reaching",
                                  episodes=chosen)
                 for name, chosen in (("training goals", training), ("held-out goals", episodes - training))}
        checks.append(decided(f"heldout_worse:{method}", f"{method.upper()} does worse on its held-out goals than "
                               "on its training goals", robot, "normal", "goal_reaching",
                               ", ".join(describe(name, means) for name, means in split.items()), "-",
                               [part("training vs held-out goals", split["training goals"], split["held-out goals"],
                                      "better", paired=True, names=(f"{method}:training", f"{method}:held-out"))],
                               FIGURES["heldout_worse"].get(robot, "")))
    return checks


def load_causes(path, claims: tuple[str, ...] = CLAIMS) -> list[claims_lib.Cause]:
    """The causes in the YAML file ``path`` for these claims (:func:`hierloco.claims.load_causes`; ``claims``: the
    keys of the checks the causes are for, default :data:`CLAIMS`). Raises ValueError naming every malformed entry.

        >>> import tempfile
        >>> f = tempfile.NamedTemporaryFile("w", suffix=".yaml", delete=False)
        >>> _ = f.write("- {claims: [lib_worse], robots: [a1], cause: LIB's experts cover two speeds.}")
        >>> f.close()
        >>> load_causes(f.name)[0].claims
        ('lib_worse',)
    """
    return claims_lib.load_causes(path, claims)


CRITERIA = (f"Tests over seeds (`docs/statistics.md`, `hierloco.stats`), alpha = {stats.ALPHA}: \"better\", "
            f"\"beats\", \"worse\" and \"best\" hold when the cost is significantly lower (one-sided Welch t) by at "
            f"least {stats.MIN_EFFECT_REL:.0%} of the other's mean (and {stats.MIN_EFFECT_ABS}), and do not hold when "
            f"the gain is significantly below that; \"best\" needs every comparison to hold. \"Close\" is an "
            f"equivalence test (TOST) with a margin of {stats.EQUIV_MARGIN_REL:.0%} of the reference's mean (at least "
            f"{stats.EQUIV_MARGIN_ABS}). A comparison of methods that are all at {stats.NOT_TESTABLE_COST} of "
            f"standing still's cost or worse is not testable here; otherwise a claim neither established nor refuted "
            f"is inconclusive at this many seeds. d: the difference of the means with its {1 - 2 * stats.ALPHA:.0%} "
            "interval.")
PAPER_COLUMN = "paper (A1's numbers: Fig. 7b, Sec. IV-B; legs disabled Fig. 7d, Sec. IV-C)"


def paper_check_markdown(checks: list[Check], *, title: str, causes: list[claims_lib.Cause] = (),
                         criteria: str = CRITERIA, paper_column: str = PAPER_COLUMN,
                         with_causes: bool = True) -> str:
    """The checks as ``paper_check.md`` (:func:`hierloco.claims.checks_markdown`), each claim not found to hold with
    its numbered cause from ``causes`` or "not checked"; ``criteria`` says what the verdicts mean (default the
    comparison's tests), ``paper_column`` heads the column of what the paper says (A1's numbers)."""
    return claims_lib.checks_markdown(checks, title=title, causes=causes, criteria=criteria,
                                      paper_column=paper_column, with_causes=with_causes)
