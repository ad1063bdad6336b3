"""Verdicts on the paper's claims, from the committed job records: each study's, the whole paper's, the fragile ones.

    hierloco verdicts                  # writes the files below under results/
    hierloco verdicts --check          # exit 1 (naming them) if any file is not what the records give

Reads every study's job records (``hierloco.evidence``: per-episode rows, stage keys, build times) and decides each
claim with the tests of :mod:`hierloco.stats` (``docs/statistics.md``), then writes:

- ``<study>/verdicts.md`` for the comparison, the damage study, the two hardware studies, the ablations and
  navigation: that study's own runs only;
- ``paper_check.md``: every claim of the paper (Li et al., RA-L 2021), where the paper makes it, the numbers it
  states (with robot and figure), ours (one number per configuration, with the folders its runs come from), the
  test and the verdict; the runs of one configuration found in several studies (the same stage keys) are pooled,
  a seed's runs on different machines averaged into one value per seed (:func:`hierloco.evidence.seed_values`);
  claims nothing measures yet are named with the study they need;
- ``fragile_claims.md``: every claim that is inconclusive, or whose verdict differs between the project's runs of
  the same configuration, with the seeds a power estimate asks for and the compute they take (``builds.json``),
  and every configuration that gave different numbers when run again.

Example (on a copy of the results, writing elsewhere):
    >>> from pathlib import Path
    >>> evidence = load(Path("results"))             # doctest: +SKIP
    >>> write_all(evidence, Path("/tmp/verdicts"))    # doctest: +SKIP
"""

from __future__ import annotations

import math
import re
from collections import defaultdict
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import yaml

from hierloco import stats
from hierloco.evidence import (Run, adopt_configs, distinct, read_findings, read_records, read_stage_reports,
                               read_table, replicates, rows_of, seed_values, select)
from hierloco.io import write_text
from hierloco.recipes.ablations import paper_check as ablation_check
from hierloco.recipes.compare import paper_check as compare_check
from hierloco.recipes.compare.paper_check import NOT_MEASURED, TASKS, Check, counts_line

COMMAND = "hierloco verdicts"
ROOT = Path(__file__).resolve().parents[2]
# the paper preset's sizes (docs/index.md): a run with other values is another configuration; the ablations vary
# LAT's, the sample-efficiency study also SAC's high-level steps per task
DEFAULTS = {"latent_dim": 3, "num_experts": 50, "num_transitions": 10000}
PAPER_SIZES = {**DEFAULTS, "high_level_frames": 10000}
FALLBACK_TUNED_IK = {"a1": "ik", "daisy": "ik_plain"}


@dataclass(frozen=True)
class Study:
    """A study folder under ``results/`` and where its job records may be (the first that exists is read), or a
    per-episode ``table`` where it kept no records."""

    name: str
    records: tuple[str, ...] = ()
    table: str = ""
    command: str = ""
    robot: str = ""     # only this robot's runs (a records folder may hold other robots')
    gait_profile: str = ""  # a gait study's speed-profile table (one row per action, its gait and the gaits its
                            # target needs: recipes/gaits), read in place of records


STUDIES = (
    Study("compare_full", ("compare_full/records",),
          command="hierloco study compare 'robots=[a1,daisy]' 'seeds=[0,1,2]' "
                  "records=results/compare_full/records"),
    Study("adverse", ("adverse/records",),
          command="hierloco study adverse records=results/adverse/records out_dir=results/adverse"),
    Study("hardware_a1", ("hardware_a1/records",),
          command="hierloco study hardware 'robots=[a1]' records=results/hardware_a1/records", robot="a1"),
    Study("hardware_daisy", ("hardware_daisy/records",), table="hardware_daisy/hardware.csv",
          command="hierloco study hardware 'robots=[daisy]' 'methods=[lat,ik]' 'seeds=[0,1,2,3,4]' "
                  "records=results/hardware_daisy/records out_dir=results/hardware_daisy", robot="daisy"),
    Study("ablations", ("ablations/records",),
          command="hierloco study ablations records=results/ablations/records out_dir=results/ablations"),
    Study("ablations/no_turn", ("ablations/no_turn/records",),
          command="hierloco study ablations trials=3 run=[latent_dim] 'ablations.latent_dim.values=[2,3]' "
                  "(experts that do not turn)"),
    Study("sample_efficiency", ("sample_efficiency/records",),
          command="hierloco study sample_efficiency records=results/sample_efficiency/records "
                  "out_dir=results/sample_efficiency"),
    Study("navigation", ("navigation/records",),
          command="hierloco study navigation records=results/navigation/records out_dir=results/navigation"),
    Study("latent_map", ("latent_map/records",),
          command="hierloco study latent_map records=results/latent_map/records out_dir=results/latent_map"),
    Study("gaits/daisy_speeds", gait_profile="gaits/daisy_speeds/profile.csv", robot="daisy",
          command="hierloco study gaits robot=daisy own=tripod '~gaits' '+gaits={tripod: [[FL, MR, RL], "
                  "[FR, ML, RR]], ripple: [[FL, MR], [ML, RR], [RL, FR]]}' 'gait_boxes={ripple: {command_low: "
                  "[-0.1, -0.1, -0.2], command_high: [0.1, 0.1, 0.2]}}' tag=speeds records=results/gaits/records "
                  "out_dir=results/gaits/daisy_speeds"),
)
CONTINUITY_STAGE = "latent_continuity"  # the stage whose report the latent-space claim reads
# comparison tables of earlier runs of compare_full's study, kept without records (per-episode rows only): declared
# the same configurations as compare_full's records with the same labels (hierloco.evidence.adopt_configs)
ARCHIVED = ("compare_model_based", "compare_model_based_rerun", "compare_seed0_with_sac")


def locate(results: Path, relative: str) -> Path | None:
    """``results/<relative>``, or the same under ``results/archive/``, or ``None``."""
    for base in (results, results / "archive"):
        if (base / relative).exists():
            return base / relative
    return None


@dataclass
class Evidence:
    """Every study's runs (``runs[name]``), its findings (jobs not evaluable), where each was read from, and the
    archived tables' runs."""

    results: Path
    runs: dict[str, list[Run]] = field(default_factory=dict)
    findings: dict[str, list[dict]] = field(default_factory=dict)
    sources: dict[str, str] = field(default_factory=dict)
    archived: list[Run] = field(default_factory=list)
    compute_tables: dict[str, dict] = field(default_factory=dict)
    continuity: list[dict] = field(default_factory=list)  # the latent_continuity reports (recipes/latent_map)
    gait_profiles: dict[str, list[dict]] = field(default_factory=dict)  # study -> its speed-profile rows

    def pooled(self) -> list[Run]:
        """The runs of the paper's configurations (robot's own profile, the paper preset's sizes) from every study
        and archived table that has them, for pooling by configuration."""
        runs = [r for name in ("compare_full", "adverse", "ablations") for r in self.runs.get(name, [])]
        return [r for r in distinct(runs + self.archived) if r.config and paper_configuration(r)]


def paper_configuration(run: Run) -> bool:
    """Whether a run is of the paper preset's configuration: the robot's own profile and the preset's sizes (a
    factor a method does not have is no difference)."""
    factors = dict(run.factors)
    return (run.profile == "own" and "command_low" not in factors
            and all(factors.get(name, value) == value for name, value in PAPER_SIZES.items()))


def _wallclock(path: Path) -> dict:
    """``(method, robot) -> minutes per job`` from a study's ``wallclock.md`` (for a study without records)."""
    table = {}
    if path.is_file():
        for match in re.finditer(r"^\| (\w+) \| (\w+) \| \d+ \| ([\d.]+) \| [\d.]+ \|$", path.read_text(), re.M):
            table[(match[1], match[2])] = float(match[3])
    return table


def load(results: Path, names: dict | None = None) -> Evidence:
    """Reads every study of :data:`STUDIES` and the archived tables under ``results``, each run's method under its
    name in the tables and claims (``names``: method -> name; default :func:`method_names`)."""
    results = Path(results)
    evidence = Evidence(results)
    names = method_names() if names is None else dict(names)
    for study in STUDIES:
        found = next((p for p in (locate(results, r) for r in study.records) if p is not None), None)
        if study.gait_profile:
            if (table := locate(results, study.gait_profile)) is not None:
                from hierloco.results import read_csv

                evidence.gait_profiles[study.name] = [{**row, "robot": study.robot} for row in read_csv(table)]
                evidence.sources[study.name] = (_shown(table, results) + " (the gait study's table of every "
                                                "action, made from its runs' evaluations: no records)")
        elif found is not None:
            evidence.runs[study.name] = [r for r in read_records(found, folder=study.name)
                                         if not study.robot or r.robot == study.robot]
            evidence.findings[study.name] = read_findings(found)
            evidence.sources[study.name] = _shown(found, results)
            if study.name == "latent_map":
                evidence.continuity = read_stage_reports(found, CONTINUITY_STAGE)
        elif study.table and (table := locate(results, study.table)) is not None:
            evidence.runs[study.name] = [r for r in read_table(table, folder=study.name)
                                         if not study.robot or r.robot == study.robot]
            evidence.findings[study.name] = []
            evidence.sources[study.name] = _shown(table, results) + " (a table: no records)"
            if (clock := locate(results, f"{study.name}/wallclock.md")) is not None:
                evidence.compute_tables[study.name] = _wallclock(clock)
    reference = evidence.runs.get("compare_full", [])
    for name in ARCHIVED:
        table = locate(results, f"{name}/comparison.csv")
        if table is not None:
            evidence.archived += adopt_configs(read_table(table, folder=name), reference)
            evidence.sources[name] = _shown(table, results) + " (archived table: same configuration as compare_full)"
    if names:
        evidence.runs = {study: [replace(r, method=names.get(r.method, r.method)) for r in runs]
                         for study, runs in evidence.runs.items()}
        evidence.archived = [replace(r, method=names.get(r.method, r.method)) for r in evidence.archived]
    return evidence


def _shown(path: Path, results: Path) -> str:
    try:
        return (Path(results.name) / path.relative_to(results)).as_posix()
    except ValueError:
        return path.as_posix()


def _compare_config(key: str):
    path = ROOT / "recipes" / "compare" / "config.yaml"
    return (yaml.safe_load(path.read_text()) or {}).get(key) if path.is_file() else None


def tuned_ik() -> dict:
    """The IK law tuned on the training targets per robot: ``tuned_ik`` of the comparison's config."""
    found = _compare_config("tuned_ik")
    return found if isinstance(found, dict) else dict(FALLBACK_TUNED_IK)


def method_names() -> dict:
    """Each method's name in the tables and claims where it is not its own: ``names`` of the comparison's config
    (say SAC-SAC at the paper's 2 x 512 named ``sac_sac``, the 2 x 256 runs ``sac_sac_2x256``)."""
    found = _compare_config("names")
    return dict(found) if isinstance(found, dict) else {}


# --- the claims of each study --------------------------------------------------------------------------------------

def comparison_checks(runs: list[Run]) -> list[Check]:
    """The comparison's claims (:mod:`recipes.compare.paper_check`) on the paper configuration's runs."""
    return compare_check.check_claims(rows_of([r for r in runs if paper_configuration(r)]), tuned_ik())


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
    return ablation_check.check_claims(ablation_rows(runs))


PROFILES = ("own", "stiff", "stiff_servos")
FAULTS = ("legs_disabled", "one_leg_locked", "rear_limp")
SAMPLES = (200, 500, 1000, 2000)


def _means(runs, **labels) -> np.ndarray:
    """The pooled per-seed mean costs of the runs with these labels (``S``)."""
    return seed_values(select(runs, **labels))[1]


def _text(name: str, values) -> str:
    return f"{name} {np.mean(values):.2f} +- {np.std(values):.2f}"


def adverse_checks(runs: list[Run], findings: list[dict]) -> list[Check]:
    """The damage study: per robot, profile and fault, "LAT beats IK" (our integral law, and the paper's plain law)
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
                    lat = _means(chosen, method="lat", setting=setting, task=task)
                    for ik in compare_check.IK_METHODS:
                        base = _means(chosen, method=ik, setting=setting, task=task)
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
                            checks.append(compare_check.decided(
                                key, claim, robot, where, task, f"{_text('lat', lat)}, {_text(ik, base)}", "-",
                                [compare_check.part(f"lat vs {ik}", lat, base, kind,
                                                    names=(f"lat:{setting}:{profile}", f"{ik}:{setting}:{profile}"))],
                                "Sec. IV-C"))
        for method in ("lat", "ik"):
            chosen = [r for r in runs if r.robot == robot and r.profile == "own" and r.method == method]
            for task in TASKS:
                full = _means(chosen, setting="legs_disabled", task=task, num_transitions=10000)
                for count in SAMPLES:
                    few = _means(chosen, setting="legs_disabled", task=task, num_transitions=count)
                    if few.size and full.size:
                        checks.append(compare_check.decided(
                            "samples", f"{method.upper()} re-learned from {count} samples is close to 10,000 (within "
                            f"{stats.EQUIV_MARGIN_REL:.0%})", robot, "legs_disabled (own)", task,
                            f"{_text(str(count), few)}, {_text('10000', full)}", "-",
                            [compare_check.part(f"{count} vs 10000", few, full, "close",
                                                names=(f"{method}:samples={count}", f"{method}:samples=10000"))],
                            "Sec. IV-D (2000 samples)"))
    return checks


HARDWARE_PAPER = {"velocity_tracking": "Daisy hardware (Sec. IV-D, Fig. 10a): 0.56 +- 0.015",
                  "goal_reaching": "Daisy hardware (Sec. IV-D): all goals reached in 16.0 +- 1.4 steps",
                  "trajectory_tracking": "Daisy hardware (Sec. IV-D, Fig. 10a): 0.57 +- 0.05"}


def hardware_checks(runs: list[Run]) -> list[Check]:
    """The hardware protocol in simulation (the low level learned on the nominal robot and kept, the CoM model
    learned again on a perturbed copy from 2000 samples): per robot and task, LAT solves the task on the perturbed
    robot (better than standing still), and does worse there than on the nominal robot (the paper's "worse than in
    simulation"), seed by seed; and two questions of the study, not the paper's: re-learning the model helps, and
    LAT beats IK on the perturbed robot."""
    checks = []
    for robot in sorted({r.robot for r in runs}):
        mine = [r for r in runs if r.robot == robot]
        for task in TASKS:
            nominal = _means(mine, method="lat", setting="normal", task=task)
            perturbed = _means(mine, method="lat", setting="hardware", task=task)
            unadapted = _means(mine, method="lat", setting="hardware_unadapted", task=task)
            ik = _means(mine, method="ik", setting="hardware", task=task)
            reached = _goals(mine, "lat", "hardware") if task == "goal_reaching" else ""
            paper = HARDWARE_PAPER[task]
            if perturbed.size:
                checks.append(compare_check.decided(
                    "hardware_solves", "LAT solves the task on the perturbed robot, model re-learned from 2000 "
                    "samples (better than standing still)", robot, "hardware", task,
                    _text("lat", perturbed) + reached, paper,
                    [compare_check.part("lat vs standing still", perturbed, 1.0, "better",
                                        names=("lat:hardware", "standing still"))], "Sec. IV-D, Fig. 8, Fig. 10a"))
            if perturbed.size and nominal.size == perturbed.size:
                checks.append(compare_check.decided(
                    "hardware_worse", "LAT does worse on the perturbed robot than on the nominal one", robot,
                    "hardware", task, f"nominal {_text('lat', nominal)}, perturbed {_text('lat', perturbed)}", paper,
                    [compare_check.part("nominal vs perturbed", nominal, perturbed, "better", paired=True,
                                        names=("lat:normal", "lat:hardware"))], "Sec. IV-D"))
            if perturbed.size and unadapted.size == perturbed.size:
                checks.append(compare_check.decided(
                    "hardware_relearn", "(this study's question) re-learning the CoM model on the perturbed robot "
                    "helps LAT", robot, "hardware", task,
                    f"nominal model {_text('lat', unadapted)}, re-learned {_text('lat', perturbed)}", "-",
                    [compare_check.part("re-learned vs nominal model", perturbed, unadapted, "better", paired=True,
                                        names=("lat:hardware", "lat:hardware_unadapted"))], "-"))
            if perturbed.size and ik.size:
                checks.append(compare_check.decided(
                    "hardware_vs_ik", "(this study's question) LAT beats IK on the perturbed robot", robot,
                    "hardware", task, f"{_text('lat', perturbed)}, {_text('ik', ik)}", "-",
                    [compare_check.part("lat vs ik", perturbed, ik, "better", names=("lat:hardware", "ik:hardware"))],
                    "-"))
    return checks


NAVIGATION_PREFIX = "navigation_arena"  # the navigation study's tasks (recipes/navigation/run.py)


def navigation_checks(runs: list[Run]) -> list[Check]:
    """The navigation claim per robot, over seeds (each seed's value: its mean over the arenas): LAT follows the
    planned path (normalised cost better than standing still) and reaches the goal (the CoM's distance to it at the
    end significantly below the 0.2 m success radius); both parts must hold."""
    from hierloco.envs.tasks import SUCCESS_RADIUS

    checks = []
    for robot in sorted({r.robot for r in runs}):
        mine = select(runs, method="lat", robot=robot, setting="normal",
                      task=lambda t: t.startswith(NAVIGATION_PREFIX))
        if not mine:
            continue
        _, costs, _ = seed_values(mine)
        _, errors, _ = seed_values(mine, value=lambda r: float(np.nanmean(r.final_error)))
        success = [s for r in distinct(mine) for s in r.success if not math.isnan(s)]
        closest = [c for r in distinct(mine) for c in r.clearance if not math.isnan(c)]
        arenas = sorted({int(r.task.removeprefix(NAVIGATION_PREFIX)) for r in mine})
        ours = (f"{_text('lat', costs)}; goals reached {int(sum(success))}/{len(success)} (arenas "
                f"{', '.join(map(str, arenas))}); goal error {errors.mean():.2f} +- {errors.std():.2f} m"
                + (f"; closest CoM to a box {min(closest):.2f} m" if closest else ""))
        checks.append(compare_check.decided(
            "navigation", "LAT follows a planned path through clutter to the goal (cost better than standing "
            "still, and the goal error below the 0.2 m success radius)", robot, "normal", "navigation", ours, "-",
            [compare_check.part("lat vs standing still", costs, 1.0, "better",
                                names=("lat:navigation", "standing still")),
             compare_check.part(f"goal error vs {SUCCESS_RADIUS} m", errors, SUCCESS_RADIUS, "better",
                                names=("goal error (m)", f"{SUCCESS_RADIUS} m"))], "Sec. I, Fig. 2"))
    return checks


CONTINUITY_EFFECT = 0.5  # neighbours must differ by at most half what the average pair of lattice points does


def continuity_checks(reports: list[dict]) -> list[Check]:
    """The latent-space claim per robot, over seeds (Sec. III-B, Fig. 4): on a lattice of latents held from
    standing, the CoM velocities of lattice neighbours differ significantly less than those of all pairs, by at
    least half (``CONTINUITY_EFFECT``; a linear map on a 7-point lattice gives about a third, a map that jumps
    between neighbours about 1), paired by seed."""
    checks = []
    for robot in sorted({r["robot"] for r in reports if r["method"] == "lat"}):
        mine = sorted((r for r in reports if r["method"] == "lat" and r["robot"] == robot), key=lambda r: r["seed"])
        near = np.array([r["neighbour_difference"] for r in mine], dtype=float)
        pair = np.array([r["pair_difference"] for r in mine], dtype=float)
        ratio = near / pair
        ours = (f"neighbours {near.mean():.3f} +- {near.std():.3f} m/s, all pairs {pair.mean():.3f} +- "
                f"{pair.std():.3f} m/s (ratio {ratio.mean():.2f} +- {ratio.std():.2f}; n={len(mine)}; "
                f"{mine[0]['grid']}-point lattice over a {mine[0]['latent_dim']}-D latent, "
                f"{100 * np.mean([r['fell_fraction'] for r in mine]):.0f} % fell)")
        checks.append(compare_check.decided(
            "latent_continuity", "Latents one lattice step apart move the CoM alike: their velocities differ by at "
            f"most {CONTINUITY_EFFECT:.0%} of what the average pair's do", robot, "normal", "latent lattice", ours,
            "-", [compare_check.part("neighbours vs all pairs", near, pair, "better", paired=True,
                                     names=("neighbour velocity difference (m/s)", "pair velocity difference (m/s)"),
                                     options={"min_effect_rel": CONTINUITY_EFFECT})], "Sec. III-B, Fig. 4"))
    return checks


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
        checks.append(compare_check.decided(
            "gait_needed", "The planner picks the gait a target needs: where only some gaits reach the target, its "
            f"actions walk them at least {NEEDED_GAIT_EFFECT:.0%} more often than where any gait will do", robot,
            "normal", "speed profile", ours, "-",
            [compare_check.part("where needed vs where any will do", 1.0 - fast, 1.0 - slow, "better", paired=True,
                                names=("other gaits' share where needed", "other gaits' share where any will do"),
                                options={"min_effect_rel": 0.0, "min_effect_abs": NEEDED_GAIT_EFFECT,
                                         "not_testable": math.inf})], "Sec. V, Fig. 9"))
    return checks


def _goals(runs, method, setting) -> str:
    """How many goals the runs reached, and in how many steps."""
    chosen = distinct(select(runs, method=method, setting=setting, task="goal_reaching"))
    success = [s for r in chosen for s in r.success if not math.isnan(s)]
    steps = [s for r in chosen for s in r.steps_to_goal if not math.isnan(s)]
    if not success:
        return ""
    text = f"; goals reached {int(sum(success))}/{len(success)}"
    return text + (f" in {np.mean(steps):.1f} +- {np.std(steps):.1f} steps" if steps else "")


def study_checks(evidence: Evidence) -> dict[str, list[Check]]:
    """Each study's checks on its own runs."""
    out = {}
    runs = evidence.runs
    if "compare_full" in runs:
        out["compare_full"] = comparison_checks(runs["compare_full"])
    if "adverse" in runs:
        out["adverse"] = adverse_checks(runs["adverse"], evidence.findings.get("adverse", []))
    for name in ("hardware_a1", "hardware_daisy"):
        if name in runs:
            out[name] = hardware_checks(runs[name])
    for name in ("ablations", "ablations/no_turn"):
        if name in runs:
            out[name] = [c for c in ablation_checks(runs[name])
                         if name == "ablations" or c.verdict != NOT_MEASURED]  # no_turn varies the latent only
    if "navigation" in runs:
        out["navigation"] = navigation_checks(runs["navigation"])
    if evidence.continuity:
        out["latent_map"] = continuity_checks(evidence.continuity)
    for name, rows in evidence.gait_profiles.items():
        out[name] = gait_checks(rows)
    return out


# --- pages ---------------------------------------------------------------------------------------------------------

UNDECIDED = (stats.DOES_NOT_HOLD, stats.INCONCLUSIVE, stats.NOT_TESTABLE)
CRITERIA = (f"Each claim is decided by a test over seeds (`docs/statistics.md`; `hierloco.stats`), alpha = "
            f"{stats.ALPHA}: \"better\" holds when the cost is significantly lower (one-sided Welch t; paired by "
            f"seed where both sides are the same seed's runs) by at least {stats.MIN_EFFECT_REL:.0%} of the other's "
            f"mean cost (and {stats.MIN_EFFECT_ABS}), and does not hold when the gain is significantly below that; "
            f"\"close\" is an equivalence test (TOST) within {stats.EQUIV_MARGIN_REL:.0%} of the reference's mean "
            f"cost (at least {stats.EQUIV_MARGIN_ABS}), and does not hold when the difference is significantly "
            f"outside that, either way; a comparison of methods all at {stats.NOT_TESTABLE_COST} of standing still's "
            f"cost or worse is not testable here; a claim neither established nor refuted is inconclusive at this "
            f"many seeds. A claim of several comparisons holds when each does, and does not hold when one is refuted "
            f"at alpha / comparisons. d: the difference of the means (better: the cost saved) with its "
            f"{1 - 2 * stats.ALPHA:.0%} interval, p: the one-sided p-value that would establish the claim.")


def _generated(source: str) -> str:
    return (f"Generated by `{COMMAND}` from {source}; do not edit, run it again. {CRITERIA}")


def _causes(results: Path, name: str, loader):
    path = locate(results, f"{name}/causes.yaml")
    return loader(path) if path is not None else []


def study_page(name: str, checks: list[Check], evidence: Evidence) -> str:
    """``<study>/verdicts.md``: the study's claims on its own runs, with the causes we checked (its
    ``causes.yaml``, where it has one)."""
    study = next(s for s in STUDIES if s.name == name)
    causes, paper_column = [], "the paper"
    if name == "compare_full":
        causes = _causes(evidence.results, name, compare_check.load_causes)
        paper_column = "paper (A1's numbers: Fig. 7b, Sec. IV-B; legs disabled Fig. 7d, Sec. IV-C)"
    elif name == "ablations":
        causes = _causes(evidence.results, name, ablation_check.load_causes)
        paper_column = "the paper (Sec. IV-E, Fig. 10b-d, Daisy)"
    elif name.startswith("hardware"):
        paper_column = "the paper (real Daisy; ours: a perturbed copy in simulation)"
    body = compare_check.paper_check_markdown(checks, title="x", causes=causes, criteria="",
                                              paper_column=paper_column,
                                              with_causes=name in ("compare_full", "ablations"))
    table = body[body.index("| claim |"):]
    findings = evidence.findings.get(name, [])
    note = (f"\n{len(findings)} jobs ended in a finding about their setting (not evaluable; their claims are not "
            f"testable here): " + "; ".join(sorted({f"{f['method']} on {f['robot']} ({f['profile']}) "
                                                    f"{f['settings']}" for f in findings})) + ".\n"
            if findings else "")
    return (f"# Verdicts: {name}\n\nThe study: `{study.command}`. {_generated('`' + evidence.sources[name] + '`')} "
            f"Numbers: mean +- std over seeds of each seed's mean normalised cost (a fallen robot's cost counts as "
            f"1).\n\n**{counts_line(checks)}.**\n{note}\n{table}")


def _figure_claims():
    """The paper's claims, in the order of the paper: (words, where, the paper's numbers, what decides it)."""
    a1_goals = "A1 (Fig. 7b, Sec. IV-B): goal reaching LAT 0.34 +- 0.02, SAC 0.57 +- 0.06, SAC-SAC 0.92 +- 0.04"
    a1_velocity = "A1 (Fig. 7b, Sec. IV-B): velocity tracking LAT 0.16 +- 0.10, LIB 0.58 +- 0.01"
    a1_damaged = "A1 (Fig. 7d, Sec. IV-C): legs disabled, velocity tracking LAT 0.62 +- 0.06, IK 0.91 +- 0.06"
    daisy_hw = ("Daisy hardware (Sec. IV-D, Fig. 10a): velocity tracking 0.56 +- 0.015, trajectory tracking "
                "0.57 +- 0.05, all goals reached in 16.0 +- 1.4 steps (4 goals x 3 trials)")
    return [
        ("\"our framework outperforms the learned baselines in all test tasks\" (LIB, SAC, SAC-SAC)",
         "Abstract; Sec. IV-B; Fig. 7a (Daisy), 7b (A1)", f"{a1_goals}; {a1_velocity}", ("pooled", "learned_best")),
        ("LIB \"incurs a high cost\" at velocity tracking, LAT \"a much lower cost\"", "Sec. IV-B; Fig. 7a, 7b",
         a1_velocity, ("pooled", "lib_worse")),
        ("LIB \"generalizes well to goal reaching\" (read: within 20 % of LAT's cost)", "Sec. IV-B; Fig. 7a, 7b",
         "-", ("pooled", "lib_goals_close")),
        ("\"SAC and SAC-SAC fail to generalize to new targets\" (held-out goals against training goals)",
         "Sec. IV-B", "A1 (Fig. 7b): goal reaching SAC 0.57 +- 0.06, SAC-SAC 0.92 +- 0.04 over all 8 goals, trained "
         "on 4", ("pooled", "heldout_worse")),
        ("SAC-SAC's \"user-defined high-level action space ... performs poorly[er] than the learned action space\" "
         "of SAC", "Sec. IV-B; Fig. 7a, 7b", "A1 (Fig. 7b): goal reaching SAC 0.57 +- 0.06, SAC-SAC 0.92 +- 0.04",
         ("pooled", "sac_sac_worse")),
        ("\"our fully-learned approach is close to IK in the normal setting\" (\"performs similar\")",
         "Sec. IV-C; Sec. VI; Fig. 7c (Daisy), 7d (A1)", "-", ("pooled", "close")),
        ("with two hind legs disabled \"IK's performance deteriorates significantly\"", "Sec. IV-C; Fig. 7c, 7d",
         "A1 (Fig. 7d, Sec. IV-C): IK 0.91 +- 0.06 at velocity tracking", ("pooled", "ik_deteriorates")),
        ("LAT \"outperforms IK in adverse settings on both A1 and Daisy\" (two hind legs disabled)",
         "Abstract; Sec. IV-C; Sec. VI; Fig. 7c, 7d", a1_damaged, ("pooled", "damaged")),
        ("on hardware LAT, its low level kept from simulation and its dynamics learned from 2000 samples, "
         "\"achieves multiple locomotion tasks\" (ours: a perturbed robot in simulation)",
         "Abstract; Sec. IV-D; Fig. 1, 8, 10a", daisy_hw, ("hardware", "hardware_solves")),
        ("on hardware \"its performance was worse than in simulation\"", "Sec. IV-D", daisy_hw,
         ("hardware", "hardware_worse")),
        ("latent dimension 2, 3, 4: \"no significant effect on the performance\"", "Sec. IV-E; Fig. 10b (Daisy)",
         "-", ("ablations", "latent_dim_no_effect")),
        ("\"as the number of experts increases the performance on each task improves\" (10 to 30)",
         "Sec. IV-E; Fig. 10c (Daisy)", "-", ("ablations", "experts_10_30_better")),
        ("\"the difference from 30 to 50 [experts] is minor\"", "Sec. IV-E; Fig. 10c (Daisy)", "-",
         ("ablations", "experts_30_50_minor")),
        ("\"a significant improvement in performance when the dynamics is learned from 2000 data points versus "
         "1000\"", "Sec. IV-E; Fig. 10d (Daisy)", "-", ("ablations", "samples_1000_2000_better")),
        ("\"no significant difference in performance between 2000 and 5000 data points\"",
         "Sec. IV-E; Fig. 10d (Daisy)", "-", ("ablations", "samples_2000_5000_minor")),
        ("sample-efficient: tasks solved \"with only 2000 hardware samples\" (ours: after damage, the dynamics "
         "re-learned from 2000 samples against 10,000)", "Abstract; Sec. IV-D; Sec. VI", "-",
         ("adverse", "samples", "2000")),
        ("\"this model-based planner outperforms model-free approaches ... in sample-efficiency\"; SAC is "
         "\"re-trained for new tasks, hence using 3 times as much data\" (ours: LAT with N CoM transitions in all "
         "against SAC with N high-level steps per task, at N = 2000, 5000 and the comparison's 10,000)",
         "Sec. I; Sec. III-C; Sec. IV-B", "-", ("sample_efficiency", "sample_efficient")),
        ("\"Our method can directly be used with waypoint navigation methods to reach a desired goal\" (ours: "
         "cluttered arenas, an A* path inflated by the robot's footprint, LAT's trajectory tracking along it)",
         "Sec. I; Fig. 2 (Daisy in iGibson)", "-", ("navigation", "navigation")),
        ("\"Close-by samples in the latent space lead to continuously varying CoM motion\" (ours: a lattice of 2-D "
         "latents over the learned box, each held from standing; neighbours' CoM velocities against all pairs')",
         "Sec. III-B; Fig. 4", "-", ("latent_map", "latent_continuity")),
        ("\"Our learned latent space can induce gait transitions in the low-level if needed by the task\" (Fig. 9); "
         "\"the high-level latent action space can be used to transit between gaits, if needed by the task\" (ours: Daisy's experts in tripod over its whole command box and in a ripple that walks only slowly, one "
         "latent space over both; a speed profile whose fast targets only the tripod reaches)",
         "Sec. V; Fig. 9", "-", ("gaits", "gait_needed")),
    ]


NOT_MEASURED_YET = [
    ("the same results on the real Daisy (Fig. 8, 10a)", "Sec. IV-D",
     "a real robot: the hardware studies here perturb a simulated copy (mass, motors, friction, latency, CoM "
     "noise), which is what they measure"),
]


def _values_text(values, n_folders: str) -> str:
    return f"{np.mean(values):.3f} (n={len(values)}; {n_folders})"


def _folders(runs: list[Run]) -> dict:
    """``(method, robot, setting, task) -> the folders its runs come from``."""
    found = defaultdict(set)
    for run in runs:
        found[(run.method, run.robot, run.setting, run.task)].add(run.folder)
    return found


def ours_text(check: Check, folders: dict | None = None, folder: str = "") -> str:
    """One number per configuration of the check's comparisons: its mean over seeds, the seeds, and the folders
    its runs come from (``folders``: ``(method, robot, setting, task) -> folders``, for pooled runs; else
    ``folder``)."""
    seen, parts = set(), []
    for part in check.parts:
        for name, values in zip(part.names, (part.a, part.b)):
            if name in seen or np.ndim(values) == 0:
                continue
            seen.add(name)
            where = folder
            if folders is not None:
                method, _, rest = name.partition(":")
                setting = rest.split(":")[0] if rest else check.setting
                setting = "normal" if setting in ("training", "held-out") else setting
                where = ", ".join(sorted(folders.get((method, check.robot, setting, check.task), ()))) or "?"
            parts.append(f"{name} {_values_text(values, where)}")
    return "; ".join(parts) if parts else check.ours


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


def sample_efficiency_checks(evidence: Evidence) -> list[Check]:
    """The sample-efficiency study's claims (:func:`recipes.sample_efficiency.run.check_claims`) on its records, its
    full budgets being the comparison's LAT and SAC runs of the paper's configuration for the seeds it ran (as the
    study itself takes them, from the comparison's records)."""
    from hierloco.recipes.sample_efficiency.run import check_claims, curves_of

    own = evidence.runs.get("sample_efficiency", [])
    seeds = {(r.robot, r.seed) for r in own}
    full = [r for r in evidence.runs.get("compare_full", []) if r.method in ("lat", "sac") and r.setting == "normal"
            and (r.robot, r.seed) in seeds and r.config and paper_configuration(r)]
    return check_claims(curves_of(own + full, TASKS), DEFAULTS["num_transitions"]) if own else []


def paper_checks(evidence: Evidence) -> dict[str, list[Check]]:
    """The checks that decide the paper's claims: the comparison on the pooled runs of the paper's configurations;
    the ablations with their default runs pooled with the same configurations' runs elsewhere; the hardware and
    damage studies on their own runs; the sample-efficiency study on its runs and the comparison's."""
    pooled = evidence.pooled()
    out = {"pooled": compare_check.check_claims(rows_of(pooled), tuned_ik())}
    extra = [r for r in pooled if (r.method, r.robot, r.setting) == ("lat", "daisy", "normal")
             and r.folder != "ablations"]
    if "ablations" in evidence.runs:
        out["ablations"] = ablation_checks(evidence.runs["ablations"] + extra)
    if "ablations/no_turn" in evidence.runs:
        out["ablations/no_turn"] = ablation_checks(evidence.runs["ablations/no_turn"])
    out["hardware"] = [c for name in ("hardware_a1", "hardware_daisy") if name in evidence.runs
                       for c in hardware_checks(evidence.runs[name])]
    if "adverse" in evidence.runs:
        out["adverse"] = adverse_checks(evidence.runs["adverse"], evidence.findings.get("adverse", []))
    out["sample_efficiency"] = sample_efficiency_checks(evidence)
    out["navigation"] = navigation_checks(evidence.runs.get("navigation", []))
    out["latent_map"] = continuity_checks(evidence.continuity)
    out["gaits"] = [c for rows in evidence.gait_profiles.values() for c in gait_checks(rows)]
    return out


def paper_claims(checks: dict[str, list[Check]]) -> list[tuple]:
    """Each claim of :func:`_figure_claims` with the checks that decide it: ``(number, words, where, the paper's
    numbers, source, key, checks)``."""
    out = []
    for number, (words, where, paper_numbers, (source, key, *rest)) in enumerate(_figure_claims(), 1):
        chosen = [c for c in checks.get(source, []) if c.key.split(":")[0] == key
                  and (not rest or (c.claim.startswith("LAT") and f"from {rest[0]} samples" in c.claim))]
        out.append((number, words, where, paper_numbers, source, key, chosen))
    return out


def _folder_of(source: str, check: Check) -> str:
    if source == "hardware":
        return f"hardware_{check.robot}"
    if source == "sample_efficiency" and any(name.endswith(f":{DEFAULTS['num_transitions']}")
                                             for part in check.parts for name in part.names):
        return "compare_full"   # the full budgets are the comparison's runs (sample_efficiency_checks)
    if source == "gaits":
        return next(s.name for s in STUDIES if s.gait_profile and s.robot == check.robot)
    return {"pooled": "pooled", "ablations": "ablations", "adverse": "adverse",
            "sample_efficiency": "sample_efficiency", "navigation": "navigation", "latent_map": "latent_map"}[source]


def paper_page(evidence: Evidence, checks: dict[str, list[Check]]) -> str:
    """``paper_check.md``: every claim of the paper with its verdicts."""
    folders = _folders(evidence.pooled())
    lines = [f"# The paper's claims, judged with statistics\n",
             "Li, Calandra, Pathak, Tian, Meier, Rai, *Planning in Learned Latent Action Spaces for Generalizable "
             "Legged Locomotion*, RA-L 2021: every claim its text and figures make (figures numbered in the order of "
             "the paper's source), the numbers it states with their robot and figure (its normalisation is not "
             "ours: orderings and ratios compare, absolute values do not), ours, the test and the verdict.",
             f"\n{_generated('the job records of ' + ', '.join(f'`{v}`' for v in evidence.sources.values()))}\n",
             "**Ours**: per configuration, the mean over seeds of each seed's mean normalised cost, the number of "
             "seeds and the folders under `results/` its runs come from. The comparison's claims use every run of "
             "the paper's configurations (the same stage keys) wherever it was made: `compare_full`, the same jobs "
             "run again in `adverse` and (LAT on Daisy) `ablations`, and the archived tables of the same study "
             "(`compare_model_based*`); a seed run on several machines counts once, with the mean of its runs "
             "(`fragile_claims.md`). Each study's verdicts on its own runs: `<study>/verdicts.md`.\n"]
    everything = []
    for number, words, where, paper_numbers, source, key, chosen in paper_claims(checks):
        everything += chosen
        lines.append(f"## {number}. {words}\n\n{where}. The paper's numbers: {paper_numbers}.\n")
        if not chosen:
            lines.append(f"**not measured yet** (no runs of the study it needs: `{source}`).\n")
            continue
        lines.append(f"Verdicts: {counts_line(chosen)}.\n")
        lines.append("| robot | setting | task | claim tested | ours (per configuration) | test | verdict | folder |")
        lines.append("|---|---|---|---|---|---|---|---|")
        for check in chosen:
            folder = _folder_of(source, check)
            ours = ours_text(check, folders) if source == "pooled" else ours_text(check, folder=folder)
            if check.task in ("goal_reaching", "navigation") and "goals reached" in check.ours:
                ours += check.ours[check.ours.index(";"):]
            lines.append(f"| {check.robot} | {check.setting} | {check.task} | {check.claim} | {ours} | "
                         f"{check.detail or '-'} | **{check.verdict}** | {folder} |")
        if source == "ablations" and key == "latent_dim_no_effect" and checks.get("ablations/no_turn"):
            turn = [c for c in checks["ablations/no_turn"] if c.key == key]
            lines.append("\nWith experts that do not turn (`ablations/no_turn`, latent dimension 2 and 3 only): "
                         + "; ".join(f"{c.task} **{c.verdict}** ({c.ours})" for c in turn) + ".")
        if key == "damaged" and checks.get("adverse"):
            other = [c for c in checks["adverse"] if c.key.startswith("damaged:")
                     and c.setting != "legs_disabled (own)"]
            lines.append(f"\nOther faults and actuator profiles (`adverse/verdicts.md`, not the paper's setting): "
                         f"{counts_line(other)}.")
        lines.append("")
    lines.append("## Claims not measured yet\n")
    lines.append("| claim | where | verdict | the study it needs |")
    lines.append("|---|---|---|---|")
    lines += [f"| {words} | {where} | not measured yet | {needs} |" for words, where, needs in NOT_MEASURED_YET]
    counted = design_counts(evidence)
    if counted:
        lines.append("\n## Statements about the design, counted rather than tested\n")
        lines.append("\"SAC and SAC-SAC are re-trained for new tasks, hence using 3 times as much data as our "
                     "approach\" (Sec. IV-B), counted from the comparison's records: " + "; ".join(counted) + ".")
    unmeasured = len(NOT_MEASURED_YET) + sum(not chosen for *_, chosen in paper_claims(checks))
    lines.insert(4, f"**All claims tested: {counts_line(everything)}** (plus {unmeasured} not measured yet).\n")
    return "\n".join(lines) + "\n"


# --- fragile claims ------------------------------------------------------------------------------------------------

def source_checks(evidence: Evidence) -> dict[str, list[Check]]:
    """The comparison's claims on each set of the project's runs of the paper's configurations on its own:
    ``compare_full``, the same jobs in ``adverse``, the archived ``compare_model_based`` table, and all pooled."""
    runs = {"compare_full": evidence.runs.get("compare_full", []),
            "adverse": evidence.runs.get("adverse", []),
            "compare_model_based": [r for r in evidence.archived if r.folder == "compare_model_based"]}
    out = {name: compare_check.check_claims(rows_of([r for r in found if r.config and paper_configuration(r)]),
                                            tuned_ik())
           for name, found in runs.items() if found}
    out["pooled"] = compare_check.check_claims(rows_of(evidence.pooled()), tuned_ik())
    return out


def _identity(check: Check) -> tuple:
    return check.key, check.robot, check.setting, check.task, tuple(p.label for p in check.parts)


@dataclass
class Need:
    """The seeds that would decide a check: ``needed`` per method (``None`` when no count up to 100 reaches the
    power, or when ``spread_unknown``: a side measured on one seed, so no power can be estimated), ``sides`` the
    configurations compared with their seeds now, ``(name, seeds)``; ``study`` where its runs are (``pooled`` for
    the comparison's pooled runs), ``section`` whether it is a claim of the paper or one of the damage study's own,
    and why it is listed."""

    check: Check
    study: str
    needed: int | None
    sides: list = field(default_factory=list)
    reason: str = ""
    section: str = "paper"
    spread_unknown: bool = False


def seeds_for(check: Check, study: str, reason: str, section: str = "paper") -> Need:
    """How many seeds per method would decide ``check`` (:func:`hierloco.stats.seeds_needed`, the measured means
    and spreads taken as the truth): each comparison not yet decided (all of them when the verdict differs between
    runs), the fewest seeds for a comparison pointing to a refutation, else the most any comparison needs."""
    undecided = [p for p in check.parts if p.decision.verdict == stats.INCONCLUSIVE] or list(check.parts)
    undecided = [p for p in undecided if p.decision.verdict != stats.NOT_TESTABLE]
    counts, refuting = [], []
    sides = []
    for part in undecided:
        for name, values in zip(part.names, (part.a, part.b)):
            if np.ndim(values) and name not in [s[0] for s in sides]:
                sides.append((name, len(values)))
    if any(np.ndim(v) and len(v) < 2 for part in undecided for v in (part.a, part.b)):
        return Need(check, study, None, sides, reason, section, spread_unknown=True)
    for part in undecided:
        n = stats.seeds_needed(part.a, part.b, kind=part.kind, paired=part.paired, **dict(part.options))
        counts.append(n)
        d, threshold = part.decision.estimate, part.decision.threshold
        if (part.kind == "better" and d < threshold) or (part.kind == "close" and abs(d) > threshold):
            refuting.append(n)
    if any(n is not None for n in refuting):
        needed = min(n for n in refuting if n is not None)
    elif counts and all(n is not None for n in counts):
        needed = max(counts)
    else:
        needed = None
    return Need(check, study, needed, sides, reason, section)


def _minutes(runs: list[Run]) -> list[float]:
    """The compute of each distinct job among ``runs`` (minutes)."""
    return list({r.record: r.minutes for r in runs if not math.isnan(r.minutes)}.values())


def job_of(evidence: Evidence, study: str, robot: str, name: str) -> tuple[tuple, str, list[float]]:
    """The job a new seed of configuration ``name`` (a side of a comparison) runs: ``(key, words, minutes of each
    such job recorded)``. A comparison job of LAT or IK covers the normal and legs-disabled settings and all three
    tasks (the damage study's own-profile jobs are the same jobs); a fault job its fault; an ablation trial its
    value. ``key`` is ``None`` for a side that needs no job (standing still)."""
    if name == "standing still":
        return None, "-", []
    method, _, rest = name.partition(":")
    if study.startswith("ablations"):
        factor, _, value = name.partition("=")
        factor = {"dynamics_samples": "num_transitions"}.get(factor, factor)
        runs = [r for r in evidence.runs.get(study, []) if str(r.factor(factor)) == value
                and all(r.factor(f) == v for f, v in DEFAULTS.items() if f != factor)]
        return ("ablation", study, name), f"LAT trial {name} ({study})", _minutes(runs)
    if study.startswith("hardware"):
        runs = [r for r in evidence.runs.get(study, []) if r.method == method and r.robot == robot]
        minutes = _minutes(runs)
        if not minutes and (method, robot) in evidence.compute_tables.get(study, {}):
            minutes = [evidence.compute_tables[study][(method, robot)]]
        return ("hardware", study, method), f"{method} hardware job", minutes
    if study == "navigation":  # one LAT job per robot and seed evaluates every arena
        runs = [r for r in evidence.runs.get(study, []) if r.robot == robot]
        return (study, "lat"), "LAT navigation job (every arena)", _minutes(runs)
    if study == "sample_efficiency":
        from hierloco.recipes.sample_efficiency.run import BUDGET

        budget = BUDGET[method]
        runs = [r for r in evidence.runs.get(study, []) + evidence.runs.get("compare_full", [])
                if r.method == method and r.robot == robot and r.setting == "normal"
                and r.factor(budget) == int(rest)]
        return (study, method, int(rest)), f"{method} with {rest} samples (per task)", _minutes(runs)
    setting, _, profile = rest.partition(":")
    profile = profile or "own"
    adverse = evidence.runs.get("adverse", [])
    if setting.startswith("samples="):
        count = int(setting.split("=")[1])
        runs = [r for r in adverse if r.method == method and r.robot == robot and "/samples/" in r.record
                and r.factor("num_transitions") == count]
        return ("samples", method, count), f"{method} re-learned from {count} samples (rear legs locked)", \
            _minutes(runs)
    if setting in FAULTS[1:]:
        runs = [r for r in adverse if r.method == method and r.robot == robot and r.profile == profile
                and r.setting == setting]
        return ("fault", method, profile, setting), f"{method} {setting} ({profile})", _minutes(runs)
    runs = [r for r in adverse if r.method == method and r.robot == robot and r.profile == profile
            and "/samples/" not in r.record and r.setting in ("normal", "legs_disabled")]
    if profile == "own":
        runs += [r for r in evidence.runs.get("compare_full", []) if r.method == method and r.robot == robot]
    words = f"{method} comparison job" + (f" ({profile})" if profile != "own" else "")
    return ("comparison", method, profile), words, _minutes(runs)


def fragile(evidence: Evidence, checks: dict[str, list[Check]]) -> tuple[list[Need], dict]:
    """The fragile claims, each with its :class:`Need`: the paper's claims (:func:`paper_claims`) that are
    inconclusive, or (the comparison's) decided differently by the project's sets of runs of the same
    configurations (:func:`source_checks`); then the damage study's own claims that are inconclusive. Also returns
    the verdicts per set of runs where they differ."""
    needs, differ, listed = [], {}, set()
    table = defaultdict(dict)
    for name, found in source_checks(evidence).items():
        for check in found:
            table[_identity(check)][name] = check.verdict
    for _, _, _, _, source, _, chosen in paper_claims(checks):
        for check in chosen:
            study = f"hardware_{check.robot}" if source == "hardware" else source
            measured = {k: v for k, v in table.get(_identity(check), {}).items() if v != NOT_MEASURED}
            if source == "pooled" and len(set(measured.values())) > 1:
                differ[_identity(check)] = measured
                needs.append(seeds_for(check, study, "differs"))
            elif check.verdict == stats.INCONCLUSIVE:
                needs.append(seeds_for(check, study, "inconclusive"))
            listed.add(id(check))
    for source in ("ablations/no_turn", "adverse"):
        for check in checks.get(source, []):
            pooled_already = check.setting in ("normal (own)", "legs_disabled (own)") and check.key != "samples"
            if id(check) not in listed and not pooled_already and check.verdict == stats.INCONCLUSIVE:
                needs.append(seeds_for(check, source, "inconclusive", section="study"))
    return needs, differ


def _seeds_text(need: Need) -> str:
    if need.spread_unknown:
        return "unknown (a side has one seed: no spread measured)"
    return "more than 100" if need.needed is None else f"{need.needed} per method"


SECTIONS = {"paper": "The paper's claims", "study": "The studies' own questions (the damage study's other faults, "
            "actuator profiles and few-sample re-learning; experts that do not turn)"}


def fragile_page(evidence: Evidence, checks: dict[str, list[Check]]) -> str:
    """``fragile_claims.md``."""
    needs, differ = fragile(evidence, checks)
    lines = ["# Fragile claims: inconclusive, or decided differently by runs of the same configuration\n",
             _generated("the job records of " + ", ".join(f"`{v}`" for v in evidence.sources.values())) + "\n",
             "## How runs of one configuration are pooled\n",
             "A configuration is what a run's evaluation stage key names (the stage keys in the record: every stage's "
             "parameters, the robot's fingerprint and the seed). Runs with the same key are the same job run again "
             "(another study, session or machine); on another CPU the floating-point differences grow, in a closed "
             "loop, into other numbers (below). They are samples of the same configuration and seed, so they are "
             "pooled as such (`hierloco.evidence.seed_values`): each run's mean over its episodes, then each seed's "
             "mean over its distinct runs (a run found twice, say a record and a table made from it, counts once), "
             "and the test runs over the seeds. A seed never counts twice, the machines' differences enter through "
             "the per-seed values, and more runs of a seed make its value more exact, not the test more confident. "
             "Tables kept without records (`compare_model_based*`, `compare_seed0_with_sac`) are declared the same "
             "configurations as `compare_full`'s records with the same labels, which no key can check.\n",
             "**Seeds needed**: for each comparison not yet decided (every comparison of a claim whose verdict "
             "differs between sets of runs), the fewest seeds per method at which the test reaches a verdict with "
             f"probability {stats.POWER:.0%}, the measured means and spreads taken as the truth "
             "(`hierloco.stats.seeds_needed`, a shifted-t approximation); \"more than 100\" where the measured "
             "difference is too close to the minimum effect or margin for its spread, so that seeds alone will not "
             "decide it. **Compute**: the extra seeds times the measured compute of one such job (`builds.json` of "
             "its records: every stage's build time, copied stages included, 1 thread); the same job measured on "
             "different machines took different times, so the range is given.\n"]
    totals: dict = {}
    for section, heading in SECTIONS.items():
        chosen = [n for n in needs if n.section == section]
        lines.append(f"## {heading} ({len(chosen)})\n")
        lines.append("| claim | robot | setting | task | runs | verdict (per set of runs, where they differ) | "
                     "seeds that would decide it | seeds now -> needed, per configuration (+extra x min per job) |")
        lines.append("|---|---|---|---|---|---|---|---|")
        for need in chosen:
            c, extra = need.check, []
            for name, have in need.sides:
                key, words, minutes = job_of(evidence, need.study if need.study != "pooled" else "compare_full",
                                             c.robot, name)
                more = 0 if need.needed is None else max(0, need.needed - have)
                per_job = float(np.mean(minutes)) if minutes else math.nan
                extra.append(f"{name}: {have} -> {'?' if need.needed is None else max(have, need.needed)}"
                             + (f" (+{more} x {per_job:.1f})" if more and minutes else ""))
                if key is not None and need.needed is not None:
                    full = (section, c.robot, key)
                    more = max(0, more - totals.get(("paper", c.robot, key), (0,))[0]) if section != "paper" \
                        else more
                    if more > totals.get(full, (0,))[0]:
                        totals[full] = (more, words, minutes)
            verdicts = differ.get(_identity(c))
            seen = ", ".join(f"{k}: {v}" for k, v in verdicts.items()) if verdicts else c.verdict
            lines.append(f"| {c.claim} | {c.robot} | {c.setting} | {c.task} | {need.study} | {seen} | "
                         f"{_seeds_text(need)} | {'; '.join(extra) or '-'} |")
        lines.append("")
    lines.append("## The compute the extra seeds need\n")
    lines.append("Per job to run (one job of a method serves every claim on its robot, settings and tasks), the most "
                 "extra seeds any claim above asks of it, times its measured compute per job (mean, and the range "
                 "over the jobs recorded). The second table counts only the seeds beyond the first's.\n")
    for section, heading in SECTIONS.items():
        rows = sorted((k, v) for k, v in totals.items() if k[0] == section)
        if not rows:
            continue
        lines.append(f"### {heading}\n")
        lines.append("| robot | job | extra seeds | compute per job (min) | compute (min) |")
        lines.append("|---|---|---|---|---|")
        total = 0.0
        for (_, robot, _), (more, words, minutes) in rows:
            if minutes:
                mean = float(np.mean(minutes))
                spread = f"{mean:.1f} ({min(minutes):.1f}-{max(minutes):.1f}, {len(minutes)} jobs)"
                total += more * mean
                lines.append(f"| {robot} | {words} | {more} | {spread} | {more * mean:.0f} |")
            else:
                lines.append(f"| {robot} | {words} | {more} | not recorded | - |")
        lines.append(f"\nIn all {total:.0f} min ({total / 60:.1f} h) of compute at 1 thread per job for the claims a "
                     "finite number of seeds decides.\n")
    lines += replicate_section(evidence)
    return "\n".join(lines) + "\n"


def replicate_section(evidence: Evidence, shown: float = 0.02) -> list[str]:
    """The configurations run more than once whose runs differ: per configuration and seed, each run's mean cost,
    its folder and CPU; those differing by at least ``shown`` are listed."""
    runs = [r for found in evidence.runs.values() for r in found] + evidence.archived
    groups = replicates(runs)
    places = defaultdict(lambda: (set(), set()))   # one run found in several places: every folder and CPU named
    for r in runs:
        folders, cpus = places[(r.method, r.robot, r.profile, r.setting, r.task, r.seed, r.episodes)]
        folders.add(r.folder)
        cpus.update([r.cpu] if r.cpu else [])

    def where(run: Run) -> str:
        folders, cpus = places[(run.method, run.robot, run.profile, run.setting, run.task, run.seed, run.episodes)]
        return f"{', '.join(sorted(folders))}; {', '.join(sorted(cpus)) or 'CPU not recorded'}"

    spread = lambda g: max(r.cost for r in g) - min(r.cost for r in g)  # noqa: E731
    listed = sorted((g for g in groups if spread(g) >= shown), key=lambda g: -spread(g))
    lines = [f"## Configurations run more than once\n",
             f"{len(groups)} configuration-and-seed groups were run more than once with different numbers "
             f"({sum(spread(g) < 0.001 for g in groups)} of them within 0.001 of each other); the "
             f"{len(listed)} that differ by {shown} or more in mean normalised cost:\n",
             "| method | robot | profile | setting | task | seed | runs: mean cost (folders; CPU) | spread |",
             "|---|---|---|---|---|---|---|---|"]
    for group in listed:
        r = group[0]
        each = "; ".join(f"{g.cost:.3f} ({where(g)})" for g in sorted(group, key=lambda g: g.folder))
        lines.append(f"| {r.method} | {r.robot} | {r.profile} | {r.setting} | {r.task} | {r.seed} | {each} | "
                     f"{spread(group):.3f} |")
    return lines


# --- writing -------------------------------------------------------------------------------------------------------

def pages(evidence: Evidence) -> dict[str, str]:
    """Every file this module writes, relative to ``results/``, and its text."""
    out = {f"{name}/verdicts.md": study_page(name, checks, evidence)
           for name, checks in study_checks(evidence).items()}
    checks = paper_checks(evidence)
    out["paper_check.md"] = paper_page(evidence, checks)
    out["fragile_claims.md"] = fragile_page(evidence, checks)
    return out


def write_all(evidence: Evidence, out: Path) -> list[Path]:
    """Writes :func:`pages` under ``out``; returns the paths written."""
    written = []
    for relative, text in pages(evidence).items():
        path = Path(out) / relative
        write_text(path, text)
        written.append(path)
    return written


def main(argv=None) -> int:
    import argparse

    parser = argparse.ArgumentParser(prog=COMMAND, description=__doc__.split("\n\n")[0])
    parser.add_argument("--results", default="results", help="the results folder to read (default: results)")
    parser.add_argument("--out", default=None, help="where to write (default: the results folder)")
    parser.add_argument("--check", action="store_true", help="write nothing; exit 1 if a file is not up to date")
    args = parser.parse_args(argv)
    results = Path(args.results)
    if not results.is_dir():
        print(f"error: no results folder {results}")
        return 2
    evidence = load(results)
    if args.check:
        stale = [rel for rel, text in pages(evidence).items()
                 if not (results / rel).is_file() or (results / rel).read_text() != text]
        for rel in stale:
            print(f"not up to date: {results / rel}")
        return 1 if stale else 0
    for path in write_all(evidence, Path(args.out) if args.out else results):
        print(f"wrote {path}")
    return 0
