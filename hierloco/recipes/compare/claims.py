"""The comparison's claims (Li et al., RA-L 2021, Sec. IV-B and IV-C), declared for ``hierloco verdicts``
(:mod:`hierloco.claims`, ``docs/claims.md``).

The comparison (``compare_full``) is decided on its own runs (its ``verdicts.md``) and, for the paper's claims, on
every run of the paper's configurations wherever it was made (:func:`pooled_runs`: the studies that declare
``pooled``, and the archived tables of this study), each seed counted once. Its method variants and the names of
methods in the claims are this study's config's (``config.yaml``: ``variants``, ``names``), declared there once.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

from hierloco.claims import (CLAIMS, SANITY_PAGE, TASKS, Check, Claim, Counted, Evidence, Source, Study,
                             entry_check, folders_of, job_minutes, verdict_text)
from hierloco.evidence import Run, distinct, rows_of
from hierloco.recipes.compare import paper_check

CONFIG = Path(__file__).with_name("config.yaml")
# the paper preset's sizes (docs/index.md): a run with other values is another configuration; the ablations vary
# LAT's, the sample-efficiency study also SAC's high-level steps per task
DEFAULTS = {"latent_dim": 3, "num_experts": 50, "num_transitions": 10000}
PAPER_SIZES = {**DEFAULTS, "high_level_frames": 10000}
FALLBACK_TUNED_IK = {"a1": "ik", "daisy": "ik_plain"}
# the sets of the project's runs of the paper's configurations whose verdicts are compared (fragile_claims.md): this
# study's records, the same jobs run again by the damage study, and an archived table of this study
REPLICATING = ("compare_full", "adverse")
ARCHIVED_SET = "compare_model_based"


def _config(key: str):
    from hierloco.io import load_yaml

    return (load_yaml(CONFIG) or {}).get(key) if CONFIG.is_file() else None


def tuned_ik() -> dict:
    """The IK law tuned on the training targets per robot: ``tuned_ik`` of the comparison's config."""
    found = _config("tuned_ik")
    return found if isinstance(found, dict) else dict(FALLBACK_TUNED_IK)


def method_names() -> dict:
    """Each method's name in the tables and claims where it is not its own: ``names`` of the comparison's config
    (say SAC-SAC at the paper's 2 x 512 named ``sac_sac``, the 2 x 256 runs ``sac_sac_2x256``)."""
    found = _config("names")
    return dict(found) if isinstance(found, dict) else {}


def variants() -> dict:
    """The comparison's method variants (``variants`` of its config: ``ik_plain``, ``sac_sac_2x512``)."""
    found = _config("variants")
    return dict(found) if isinstance(found, dict) else {}


def paper_configuration(run: Run) -> bool:
    """Whether a run is of the paper preset's configuration: the robot's own profile and the preset's sizes (a
    factor a method does not have is no difference)."""
    factors = dict(run.factors)
    return (run.profile == "own" and "command_low" not in factors
            and all(factors.get(name, value) == value for name, value in PAPER_SIZES.items()))


def pooled_runs(evidence: Evidence) -> list[Run]:
    """The runs of the paper's configurations (robot's own profile, the paper preset's sizes) from every study that
    declares ``pooled`` and every archived table, for pooling by configuration."""
    runs = [r for study in evidence.studies if study.pooled for r in evidence.runs.get(study.name, [])]
    return [r for r in distinct(runs + evidence.archived) if r.config and paper_configuration(r)]


def comparison_checks(runs: list[Run]) -> list[Check]:
    """The comparison's claims (:mod:`recipes.compare.paper_check`) on the paper configuration's runs."""
    return paper_check.check_claims(rows_of([r for r in runs if paper_configuration(r)]), tuned_ik())


def sets(evidence: Evidence) -> dict[str, list[Check]]:
    """The comparison's claims on each set of the project's runs of the paper's configurations on its own
    (:data:`REPLICATING`, the archived :data:`ARCHIVED_SET` table) and on all of them pooled."""
    runs = {name: evidence.runs.get(name, []) for name in REPLICATING}
    runs[ARCHIVED_SET] = [r for r in evidence.archived if r.folder == ARCHIVED_SET]
    out = {name: paper_check.check_claims(rows_of([r for r in found if r.config and paper_configuration(r)]),
                                          tuned_ik())
           for name, found in runs.items() if found}
    out["pooled"] = paper_check.check_claims(rows_of(pooled_runs(evidence)), tuned_ik())
    return out


def comparison_job(evidence: Evidence, robot: str, side: str) -> tuple[tuple, str, list[float]]:
    """The job a new seed of ``side`` (``"<method>:<setting>[:<profile>]"``) runs: a comparison job of its method,
    which covers the normal and legs-disabled settings and all three tasks (the damage study's jobs of the robot's
    own profile are the same jobs)."""
    method, _, rest = side.partition(":")
    profile = rest.partition(":")[2] or "own"
    runs = [r for r in evidence.runs.get("adverse", []) if r.method == method and r.robot == robot
            and r.profile == profile and "/samples/" not in r.record and r.setting in ("normal", "legs_disabled")]
    if profile == "own":
        runs += [r for r in evidence.runs.get("compare_full", []) if r.method == method and r.robot == robot]
    words = f"{method} comparison job" + (f" ({profile})" if profile != "own" else "")
    return ("comparison", method, profile), words, job_minutes(runs)


def design_counts(evidence: Evidence) -> list[str]:
    """The data each method used, counted from the comparison's records: high-level samples per task for SAC and
    SAC-SAC (``report.json``), CoM transitions for LAT (its stage key), for the paper's "3 times as much data"."""
    from hierloco.pipeline import records as job_records

    lines = []
    runs = evidence.runs.get("compare_full", [])
    for method in ("sac", "sac_sac"):
        records = sorted({r.record for r in runs if r.method == method})
        frames = []
        for record in records:
            try:
                report = job_records.read(record)["report"]
            except job_records.RecordError:
                continue
            frames.append(sum(int(report[f"sac_{t}"]["frames"]) for t in TASKS if f"sac_{t}" in report))
        if frames:
            span = f"{min(frames)}" if min(frames) == max(frames) else f"{min(frames)}-{max(frames)}"
            lines.append(f"{method}: {span} high-level samples per job ({len(frames)} jobs; one high level trained "
                         f"per task, {len(TASKS)} tasks)")
    transitions = sorted({r.factor("num_transitions") for r in runs if r.method == "lat" and r.setting == "normal"
                          and r.factor("num_transitions")})
    if transitions:
        lines.append(f"lat: {', '.join(map(str, transitions))} CoM transitions per setting, one model for every task")
    return lines


def _other_faults(checks: dict) -> str:
    """Beside the paper's damage claim: where the damage study's faults and profiles the paper did not test are
    decided (the study's own questions, not counted in the ledger)."""
    if not checks.get("adverse"):
        return ""
    return ("\nOther faults and actuator profiles (not the paper's setting) are the damage study's own questions: "
            "`adverse/verdicts.md`, not counted here.")


def tuned(check: Check) -> bool:
    """Whether an IK check is of the IK tuned on the robot's training targets (:func:`tuned_ik`), the one each
    robot's entry counts."""
    return check.key.partition(":")[2] == tuned_ik().get(check.robot)


def _tuned_words() -> str:
    laws = {"ik": "our integral footstep law", "ik_plain": "the plain footstep law"}
    return ", ".join(f"{laws.get(law, law)} on {robot.upper() if robot == 'a1' else robot.capitalize()}"
                     for robot, law in sorted(tuned_ik().items()))


TUNED = (f"(ours: the IK tuned on each robot's training targets, `tune_ik/`: {_tuned_words()}; the other law shown as "
         "an extra)")
NOT_TUNED = "extra (not counted): not the IK tuned on this robot's training targets"


STUDY = Study(
    "compare_full", order=10, records=("compare_full/records",),
    command="hierloco study compare 'robots=[a1,daisy]' 'seeds=[0,1,2]' records=results/compare_full/records",
    archived=("compare_model_based", "compare_model_based_rerun", "compare_seed0_with_sac"),
    variants=variants(), names=method_names(), pooled=True,
    checks=lambda evidence: comparison_checks(evidence.runs["compare_full"]),
    causes=paper_check.load_causes, paper_column=paper_check.PAPER_COLUMN)

POOLED = Source(
    "pooled", order=10, checks=lambda evidence: paper_check.check_claims(rows_of(pooled_runs(evidence)), tuned_ik()),
    folders=lambda evidence: folders_of(pooled_runs(evidence)), sets=sets,
    job=comparison_job,
    note="The comparison's claims use every run of the paper's configurations (the same stage keys) wherever it was "
         "made: `compare_full`, the same jobs run again in `adverse` and (LAT on Daisy) `ablations`, and the archived "
         "tables of the same study (`compare_model_based*`); a seed run on several machines counts once, with the "
         "mean of its runs (`fragile_claims.md`).",
    pooling="Tables kept without records (`compare_model_based*`, `compare_seed0_with_sac`) are declared the same "
            "configurations as `compare_full`'s records with the same labels, which no key can check.")

# The comparison on fair held-out targets (issue 45; docs/tasks.md, "Fair targets"): every model-free method's
# held-out targets drawn from the distribution of its training targets, and a fast, curvy path beside the random one.
# The claims the paper's split decides (its held-out goals are the diagonals, the held-out half of its S path mirrors
# the trained half: sections 1 and 4) are decided here; the paper's targets are shown beside them, not counted.
FAIR = "compare_fair"
FAIR_TASKS = (*TASKS, "trajectory_tracking_fast")
FAIR_COMMAND = ("hierloco study compare targets=fair 'robots=[a1,daisy]' 'seeds=[0,1,2]' "
                "'methods=[lat,lib,ik,ik_plain,sac,sac_sac_2x512]' records=results/compare_fair/records "
                "out_dir=results/compare_fair")


def fair_checks(evidence: Evidence) -> list[Check]:
    """The comparison's claims on its runs on fair targets (the four tasks of ``targets=fair``)."""
    return paper_check.check_claims(rows_of(evidence.runs.get(FAIR, [])), tuned_ik(), FAIR_TASKS)


def fair_job(evidence: Evidence, robot: str, side: str) -> tuple[tuple, str, list[float]]:
    """The job a new seed of ``side`` runs on fair targets: a comparison job of its method with ``targets=fair``."""
    method = side.partition(":")[0]
    runs = [r for r in evidence.runs.get(FAIR, []) if r.method == method and r.robot == robot]
    return ("comparison_fair", method), f"{method} comparison job on fair targets", job_minutes(runs)


def on_paper_targets(key: str, why: str) -> Callable:
    """A claim's note: its entries as the paper's targets decide them (the pooled runs), shown and not counted."""
    def note(checks: dict) -> str:
        paper = [c for c in checks.get("pooled", []) if c.key.split(":")[0] == key]
        robots = sorted({c.robot for c in paper})
        if not robots:
            return ""
        entries = [f"{robot} {verdict_text(entry_check(key, robot, [c for c in paper if c.robot == robot]))}"
                   for robot in robots]
        return (f"\nOn the paper's targets (the pooled runs of `compare_full`; not counted: {why}): "
                + "; ".join(entries) + ". `compare_full/verdicts.md` has their rows.")
    return note


PAPER_SPLIT = ("the paper's held-out goals are the diagonals, reachable at 0.42 m/s where the training goals need 0.3, "
               "and the held-out half of its S path mirrors the trained half")

FAIR_STUDY = Study(
    FAIR, order=10.5, records=("compare_fair/records",), command=FAIR_COMMAND, variants=variants(),
    names=method_names(), checks=fair_checks, causes=paper_check.load_causes, paper_column=paper_check.PAPER_COLUMN)

FAIR_SOURCE = Source(
    "fair", order=10.5, checks=fair_checks, folder=lambda check: FAIR, study=lambda check: FAIR, job=fair_job,
    alias=lambda name: f"{name}:fair",
    note="Sections 1 and 4 are decided on fair held-out targets (`compare_fair`, `docs/tasks.md`): each model-free "
         "method's held-out targets are drawn from the distribution of its training targets, fixed before the runs; "
         "the paper's targets are shown beside them and not counted.")

A1_GOALS = "A1 (Fig. 7b, Sec. IV-B): goal reaching LAT 0.34 +- 0.02, SAC 0.57 +- 0.06, SAC-SAC 0.92 +- 0.04"
A1_VELOCITY = "A1 (Fig. 7b, Sec. IV-B): velocity tracking LAT 0.16 +- 0.10, LIB 0.58 +- 0.01"
A1_DAMAGED = "A1 (Fig. 7d, Sec. IV-C): legs disabled, velocity tracking LAT 0.62 +- 0.06, IK 0.91 +- 0.06"

PAPER_CLAIMS = (
    Claim(order=1, words="\"our framework outperforms the learned baselines in all test tasks\" (LIB, SAC, SAC-SAC) "
                         "(ours: on fair held-out targets, the four tasks of `targets=fair`)",
          where="Abstract; Sec. IV-B; Fig. 7a (Daisy), 7b (A1)", paper=f"{A1_GOALS}; {A1_VELOCITY}",
          source="fair", key="learned_best", needs=f"the comparison on fair targets: `{FAIR_COMMAND}`",
          note=on_paper_targets("learned_best", PAPER_SPLIT)),
    Claim(order=2, words="LIB \"incurs a high cost\" at velocity tracking, LAT \"a much lower cost\"",
          where="Sec. IV-B; Fig. 7a, 7b", paper=A1_VELOCITY, source="pooled", key="lib_worse"),
    Claim(order=3, words="LIB \"generalizes well to goal reaching\" (read: within 20 % of LAT's cost)",
          where="Sec. IV-B; Fig. 7a, 7b", source="pooled", key="lib_goals_close"),
    Claim(order=4, words="\"SAC and SAC-SAC fail to generalize to new targets\" (held-out goals against training "
                         "goals; ours: on fair held-out targets, goals drawn from one distribution)",
          where="Sec. IV-B", paper="A1 (Fig. 7b): goal reaching SAC 0.57 +- 0.06, SAC-SAC 0.92 +- 0.04 over all 8 "
                               "goals, trained on 4", source="fair", key="heldout_worse",
          needs=f"the comparison on fair targets: `{FAIR_COMMAND}`",
          note=on_paper_targets("heldout_worse", PAPER_SPLIT)),
    Claim(order=5, words="SAC-SAC's \"user-defined high-level action space ... performs poorly[er] than the learned "
                         "action space\" of SAC",
          where="Sec. IV-B; Fig. 7a, 7b", paper="A1 (Fig. 7b): goal reaching SAC 0.57 +- 0.06, SAC-SAC 0.92 +- 0.04",
          source="pooled", key="sac_sac_worse"),
    Claim(order=6, words="\"our fully-learned approach is close to IK in the normal setting\" (\"performs similar\") "
                         + TUNED,
          where="Sec. IV-C; Sec. VI; Fig. 7c (Daisy), 7d (A1)", source="pooled", key="close", counted=tuned,
          extra=NOT_TUNED),
    Claim(order=7, words="with two hind legs disabled \"IK's performance deteriorates significantly\" (a sanity check: "
                         "damage hurts IK)",
          where="Sec. IV-C; Fig. 7c, 7d", paper="A1 (Fig. 7d, Sec. IV-C): IK 0.91 +- 0.06 at velocity tracking",
          source="pooled", key="ik_deteriorates", counted=tuned, extra=NOT_TUNED, page=SANITY_PAGE),
    Claim(order=8, words="LAT \"outperforms IK in adverse settings on both A1 and Daisy\" (two hind legs disabled) "
                         + TUNED,
          where="Abstract; Sec. IV-C; Sec. VI; Fig. 7c, 7d", paper=A1_DAMAGED, source="pooled", key="damaged",
          note=_other_faults, counted=tuned, extra=NOT_TUNED),
)

DATA_USED = Counted(
    order=1, words="\"SAC and SAC-SAC are re-trained for new tasks, hence using 3 times as much data as our "
                   "approach\" (Sec. IV-B), counted from the comparison's records: ", count=design_counts)

CLAIMS.add(STUDY, POOLED, FAIR_STUDY, FAIR_SOURCE, *PAPER_CLAIMS, DATA_USED)
