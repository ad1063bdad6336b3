"""recipes.verdicts on a small results tree of job records: each study's verdicts, the paper's claims, the fragile
ones, regenerated (not hand-written) and checked for staleness."""

from hierloco.recipes.verdicts import load, main, pages
from tests.test_evidence import write_record

TASKS = ("velocity_tracking", "goal_reaching", "trajectory_tracking")
# per method and setting: the mean cost of each task; seed s adds 0.01 * s
COSTS = {("lat", "normal"): (0.12, 0.09, 0.011), ("lib", "normal"): (0.46, 0.15, 0.04),
         ("ik", "normal"): (0.17, 0.09, 0.013), ("ik_plain", "normal"): (0.38, 0.38, 0.29),
         ("lat", "legs_disabled"): (0.93, 0.86, 0.95), ("ik", "legs_disabled"): (1.01, 0.73, 0.77),
         ("ik_plain", "legs_disabled"): (0.93, 0.86, 0.92)}


def results_tree(root):
    jobs = root / "compare_full" / "records"
    for method in ("lat", "lib", "ik", "ik_plain"):
        for seed in range(3):
            costs = {(setting, task): [base[i] + 0.01 * seed] for (m, setting), base in COSTS.items() if m == method
                     for i, task in enumerate(TASKS)}
            write_record(jobs, f"{method}/paper/a1_seed{seed}", method=method, robot="a1", seed=seed, costs=costs,
                         recipe_method="ik" if method == "ik_plain" else method,
                         overrides=["controller.footstep_law=plain"] if method == "ik_plain" else [],
                         factors={"num_experts": 50, "latent_dim": 3, "num_transitions": 10000}
                         if method == "lat" else {"num_transitions": 10000}, seconds=600.0)
    # the same IK job (same stage keys) run again on another machine by the damage study: another number
    from hierloco.pipeline import records

    stages = records.read(jobs / "ik" / "paper" / "a1_seed1")["stages"]
    first = next(name for name in stages if name.startswith("evaluation/normal/velocity_tracking-"))
    key = first.split("-")[1].split(".")[0]
    write_record(root / "adverse" / "records", "ik/paper/a1_seed1", method="ik", robot="a1", seed=1,
                 costs={("normal", "velocity_tracking"): [0.31]}, keys={("normal", "velocity_tracking"): key},
                 factors={"num_transitions": 10000}, cpu="Intel", seconds=300.0)
    return root


def test_pages_decide_pool_and_name_what_is_not_measured(tmp_path):
    results = results_tree(tmp_path / "results")
    evidence = load(results)
    written = pages(evidence)
    assert set(written) == {"compare_full/verdicts.md", "adverse/verdicts.md", "paper_check.md",
                            "sanity_checks.md", "fragile_claims.md"}
    study = written["compare_full/verdicts.md"]
    assert "`hierloco verdicts`" in study and "| LIB is worse than LAT at velocity tracking | a1 |" in study
    paper = written["paper_check.md"]
    damaged = next(line for line in paper.splitlines() if line.startswith("| a1 | legs_disabled | velocity_tracking |")
                   and "LAT beats IK (the IK tuned" in line)
    assert "**not testable here**" in damaged  # LAT 0.94 against IK 1.02: both no better than standing still
    # the IK seed run twice is pooled: one value per seed (seed 1: 0.18 and 0.31 averaged), folders named
    close = next(line for line in paper.splitlines() if line.startswith("| a1 | normal | velocity_tracking |")
                 and "close to IK (the IK" in line)
    assert "ik:normal 0.202 (n=3; adverse, compare_full)" in close  # (0.17 + 0.245 + 0.19) / 3
    assert "latent dimension 2, 3, 4" in paper and "**not measured yet**" in paper  # no ablations here
    assert "gait transitions" in paper and "Fig. 9" in paper
    fragile = written["fragile_claims.md"]
    assert "| ik | a1 | own | normal | velocity_tracking | 1 | 0.310 (adverse; Intel); 0.180 (compare_full; CPU not " \
           "recorded) | 0.130 |" in fragile


def test_the_files_are_regenerated_and_checked(tmp_path, capsys):
    results = results_tree(tmp_path / "results")
    assert main(["--results", str(results), "--check"]) == 1
    assert "not up to date" in capsys.readouterr().out
    assert main(["--results", str(results)]) == 0
    assert (results / "paper_check.md").is_file() and (results / "compare_full" / "verdicts.md").is_file()
    assert main(["--results", str(results), "--check"]) == 0
    assert main(["--results", str(tmp_path / "missing")]) == 2


def test_the_sample_efficiency_claim_is_decided_from_its_records_and_the_comparisons(tmp_path):
    """The sample-efficiency study's records (smaller budgets) and the comparison's LAT and SAC runs (the full
    budgets, for the seeds the study ran) decide "LAT with N samples in all beats SAC with N per task"."""
    results = results_tree(tmp_path / "results")
    budgets = {("lat", 2000): (0.13, 0.09, 0.012), ("sac", 2000): (0.70, 0.15, 0.070),
               ("sac", 10000): (0.60, 0.06, 0.010)}
    for (method, samples), costs in budgets.items():
        factor = {"num_transitions" if method == "lat" else "high_level_frames": samples}
        for seed in range(3):
            where = (results / "compare_full" / "records", f"sac/paper/a1_seed{seed}") if samples == 10000 else (
                results / "sample_efficiency" / "records", f"a1_seed{seed}/{method}_{samples}")
            write_record(*where, method=method, robot="a1", seed=seed, factors=factor,
                         overrides=[f"sac.total_frames={samples}"] if samples != 10000 else [],
                         costs={("normal", t): [c + 0.005 * seed] for t, c in zip(TASKS, costs)})
    paper = pages(load(results))["paper_check.md"]
    section = paper[paper.index("sample-efficiency"):]
    lines = {line.split(" | ")[3] + " | " + line.split(" | ")[2]: line for line in section.splitlines()
             if line.startswith("| a1 | normal |")}
    assert "**holds**" in lines["LAT with 2000 samples in all is better than SAC with 2000 per task | "
                                "velocity_tracking"]
    assert "**holds**" in lines["LAT with 2000 samples in all is better than SAC with 2000 per task | "
                                "trajectory_tracking"]
    same = lines["LAT with 10000 samples in all is better than SAC with 10000 per task | goal_reaching"]
    assert "**does not hold**" in same and "lat:10000 0.100 (n=3; compare_full)" in same  # COSTS: 0.09 + 0.01 * seed


def test_names_make_the_2x512_sac_sac_the_one_the_claims_are_about(tmp_path):
    """With ``names`` (the comparison's config) the SAC-SAC runs at the paper's 2 x 512 are ``sac_sac`` in every
    claim and the 2 x 256 runs a labelled variant the claims do not use; without it, the 2 x 512 runs are their own
    method and never replicates of the 2 x 256 ones."""
    results = results_tree(tmp_path / "results")
    jobs = results / "compare_full" / "records"
    for name, overrides, cost in (("sac_sac", [], 0.90), ("sac_sac_2x512", ["low_level.hidden=512"], 0.30),
                                  ("sac", [], 0.50)):
        for seed in range(3):
            write_record(jobs, f"{name}/paper/a1_seed{seed}", method=name, recipe_method=name.partition("_2x")[0],
                         robot="a1",
                         seed=seed, overrides=overrides, factors={"high_level_frames": 10000},
                         costs={("normal", t): [cost + 0.01 * seed] for t in TASKS})

    def learned_best(names):  # SAC-SAC against SAC, on the paper's targets (claim 5)
        paper = pages(load(results, names=names))["paper_check.md"]
        return next(line for line in paper.splitlines() if line.startswith("| a1 | normal | velocity_tracking |")
                    and "SAC-SAC's user-defined action space does worse" in line)

    assert "sac_sac:normal 0.910 (n=3" in learned_best({})  # the 2 x 256 runs
    swapped = learned_best({"sac_sac_2x512": "sac_sac", "sac_sac": "sac_sac_2x256"})
    assert "sac_sac:normal 0.310 (n=3" in swapped and "sac_sac_2x256" not in swapped


def test_navigation_is_decided_over_seeds_on_cost_and_goal_error(tmp_path):
    """A1 follows the paths and ends within 0.05 m of the goals: holds; Daisy ends 1.5 m short: does not hold, though
    its cost is well below standing still's. The claim leaves the paper's "not measured yet" list once it has runs."""
    results = results_tree(tmp_path / "results")
    before = pages(load(results))["paper_check.md"]
    assert "**not measured yet** (no runs of the study it needs: `navigation`)" in before
    jobs = results / "navigation" / "records"
    for robot, cost, error in (("a1", 0.01, 0.03), ("daisy", 0.20, 1.5)):
        for seed in range(3):
            tasks = [("normal", f"navigation_arena{a}") for a in range(2)]
            write_record(jobs, f"runs/{robot}_seed{seed}", method="lat", robot=robot, seed=seed,
                         costs={t: [cost + 0.002 * (seed + a)] for a, t in enumerate(tasks)},
                         fields={t: {"final_error": [error + 0.01 * (seed - a)], "success": [float(error <= 0.2)],
                                     "clearance": [0.3 + 0.01 * a]} for a, t in enumerate(tasks)})
    written = pages(load(results))
    assert "navigation/verdicts.md" in written
    paper = written["paper_check.md"]
    rows = {line.split(" | ")[0][2:]: line for line in paper.splitlines() if "| normal | navigation |" in line}
    assert "**holds**" in rows["a1"] and "goals reached 6/6 (arenas 0, 1)" in rows["a1"]
    assert "**does not hold**" in rows["daisy"] and "goals reached 0/6" in rows["daisy"]
    assert "closest CoM to a box 0.30 m" in rows["a1"]
    assert "(no runs of the study it needs: `navigation`)" not in paper


def test_latent_continuity_is_decided_over_seeds_from_the_stage_s_reports(tmp_path):
    """Daisy's lattice neighbours differ by a third of the average pair's velocity difference: holds; A1's by 90 %
    of it (a map that jumps between neighbours): does not hold. The numbers come from each record's
    ``latent_continuity`` report; a record without that stage is not read as one."""
    results = results_tree(tmp_path / "results")
    assert "(no runs of the study it needs: `latent_map`)" in pages(load(results))["paper_check.md"]
    jobs = results / "latent_map" / "records"
    for robot, ratio in (("daisy", 0.33), ("a1", 0.9)):
        for seed in range(3):
            pair = 0.30 + 0.02 * seed
            measured = {"neighbour_difference": ratio * pair + 0.003 * seed, "pair_difference": pair, "grid": 7,
                        "latent_dim": 2, "fell_fraction": 0.0, "ratio": ratio}
            write_record(jobs, f"lat/paper/{robot}_seed{seed}", method="lat", robot=robot, seed=seed,
                         costs={("normal", "velocity_tracking"): [0.2]}, report={"latent_continuity": measured})
    write_record(jobs, "lat/paper/daisy_seed9", method="lat", robot="daisy", seed=9,
                 costs={("normal", "velocity_tracking"): [0.2]})  # planned no latent_continuity stage
    evidence = load(results)
    reports = evidence.reports["latent_map"]["latent_continuity"]
    assert sorted(r["seed"] for r in reports if r["robot"] == "daisy") == [0, 1, 2]
    written = pages(evidence)
    paper = written["paper_check.md"]
    rows = {line.split(" | ")[0][2:]: line for line in paper.splitlines() if "| latent lattice |" in line}
    assert "**holds**" in rows["daisy"] and "min effect 0.160" in rows["daisy"]  # half of the pairs' 0.32 m/s
    assert "**does not hold**" in rows["a1"]
    assert "ratio 0.34 +- 0.01; n=3" in written["latent_map/verdicts.md"]
    assert "(no runs of the study it needs: `latent_map`)" not in paper


def gait_records(results, found, *, tables=True):
    """The gait study's profile records of Daisy (``results/gaits/records``), one per seed of ``found`` (profile
    rows of the several-gait library, ``test_gaits_recipe.profile_found``) and its own gait's, as the study keeps
    them: each with its per-action table, or (``tables=False``) as records made before the study kept one."""
    from hierloco.pipeline import records
    from hierloco.pipeline.rundir import StageSpec

    gaits = {"ripple": [["FL", "MR"], ["ML", "RR"], ["RL", "FR"]], "tripod": [["FL", "MR", "RL"], ["FR", "ML", "RR"]]}
    for seed in sorted({r["seed"] for r in found}):
        mine = [r for r in found if r["seed"] == seed]
        for name, library, gait in ((f"daisy_seed{seed}_speeds_profile", gaits, None),
                                    (f"daisy_seed{seed}_own_profile", None, "")):
            evaluation = StageSpec("evaluation_normal_speed_profile", {"params": {
                "setting": "normal", "task_name": "speed_profile", "seed": seed}, "after": {"of": name}},
                "evaluation/normal/speed_profile-0123456789ab.npz")
            experts = StageSpec("experts", {"params": {"seed": seed, **({"gaits": library} if library else {})}},
                                "experts.npz")
            rows = [{"method": "lat", "robot": "daisy", "setting": "normal", "task": "speed_profile", "seed": seed,
                     "episode": 0, "normalized_cost": 0.2, "success": float("nan"), "final_error": 0.1}]
            table = [{"setting": "normal", "task": r["task"], "episode": r["episode"], "action": r["action"],
                      "target_speed": r["target_speed"], "speed": r["speed"],
                      **({"gait": r["gait"], "needed": r["needed"]} if library else {"gait": gait})} for r in mine]
            overrides = ["preset=paper", "robot=daisy", f"seed={seed}", *([f"experts.gaits={gaits}"] if library else [])]
            records.save(records.make_record({"method": "lat", "overrides": overrides}, [experts, evaluation],
                                             rows=rows, actions=table if tables else None),
                         results / "gaits" / "records" / "gaits" / "paper" / name)


def test_the_gait_a_target_needs_is_decided_from_the_gait_study_s_records(tmp_path):
    """A speed profile whose fast target only the tripod reaches: the tripod walked at 90-100 % of the actions there
    and at 20-40 % elsewhere holds; the same share everywhere does not. Read from the per-action tables of the gait
    study's profile records, the profile table made again from them."""
    from tests.recipes.test_gaits_recipe import profile_found

    results = results_tree(tmp_path / "results")
    paper = pages(load(results))["paper_check.md"]
    section = paper[paper.index('"Our learned latent space can induce gait transitions'):]
    assert section.split("\n## ")[0].count("**not measured yet** (the per-action table of the gait study's") == 1
    for fast, slow, verdict in (((1.0, 0.9, 1.0), (0.3, 0.4, 0.2), "**holds**"),
                                ((0.5, 0.6, 0.5), (0.5, 0.5, 0.6), "**does not hold**")):
        gait_records(results, profile_found(fast, slow))
        evidence = load(results)
        assert {r["method"] for r in evidence.rows["gaits/daisy_speeds"]} == {"2 gaits", "own gait (tripod)"}
        written = pages(evidence)
        row = next(line for line in written["paper_check.md"].splitlines() if "| speed profile |" in line)
        assert row.startswith("| daisy | normal | speed profile | The planner picks the gait a target needs")
        assert verdict in row and row.endswith("| gaits/daisy_speeds |"), row
        assert "gaits/daisy_speeds/verdicts.md" in written
    study = written["gaits/daisy_speeds/verdicts.md"]
    assert "0.30 m/s: tripod" in study and "n=3; 2 gaits" in study and "results/gaits/records" in study


def test_records_without_the_per_action_table_leave_the_gait_claim_not_measured_yet(tmp_path, capsys):
    """The gait study's records made before it kept each action's gait (every one, or one seed's): the claim is
    "not measured yet" and says what it needs, the study's command run again; no verdict, no traceback."""
    from hierloco.pipeline import records
    from hierloco.recipes.gaits.claims import COMMAND
    from tests.recipes.test_gaits_recipe import profile_found

    results = results_tree(tmp_path / "results")
    found = profile_found((1.0, 0.9, 1.0), (0.3, 0.4, 0.2))
    for older in ([0, 1, 2], [2]):
        gait_records(results, found)
        gait_records(results, [r for r in found if r["seed"] in older], tables=False)
        assert "actions" not in records.read(results / "gaits" / "records" / "gaits" / "paper" /
                                             f"daisy_seed{older[0]}_speeds_profile")
        written = pages(load(results))
        paper = written["paper_check.md"]
        section = paper[paper.index('"Our learned latent space can induce gait transitions'):].split("\n## ")[0]
        assert "**not measured yet** (the per-action table of the gait study's profile jobs" in section
        assert f"run the study again, `{COMMAND}`" in section
        assert "| speed profile |" not in section and "**holds**" not in section  # no verdict on what is there
        study = written["gaits/daisy_speeds/verdicts.md"]
        assert "| not measured | not measured yet: " in study and "without a per-action table (" in study
        assert f"daisy_seed{older[0]}_speeds_profile" in study and COMMAND in study
    assert main(["--results", str(results)]) == 0 and main(["--results", str(results), "--check"]) == 0
    assert "Traceback" not in capsys.readouterr().err


TOY_CLAIMS = '''
from hierloco.claims import CLAIMS, Claim, Source, Study, decided, describe, part, seed_costs


def walks(evidence):
    runs = evidence.runs.get("toy", [])
    return [decided("toy_walks", "LAT walks to its goals", robot, "normal", "goal_reaching",
                    describe("lat", lat := seed_costs(runs, robot=robot, method="lat", task="goal_reaching")), "-",
                    [part("lat vs standing still", lat, 1.0, "better", names=("lat:normal", "standing still"))],
                    "Sec. IV-A")
            for robot in sorted({r.robot for r in runs})]


STUDY = Study("toy", command="hierloco study toy_study", order=1000, records=("toy/records",), checks=walks)
SOURCE = Source("toy", order=1000, checks=walks)
CLAIM = Claim(order=1000, words="\\"the toy walks\\"", where="Sec. IV-A", source="toy", key="toy_walks")
UNMEASURED = Claim(order=1001, words="the toy flies", where="Sec. IV-F", needs="wings")
CLAIMS.add(STUDY, SOURCE, CLAIM, UNMEASURED)
'''


def test_a_new_study_is_its_own_folder_and_its_claims_are_judged_and_rendered(tmp_path, monkeypatch):
    """A study folder of its own (``run.py``, ``config.yaml``, ``claims.py``), outside the package, found as
    ``hierloco study ./toy_study`` finds it: its ``claims.py`` is imported, and its page, its claim in the paper's
    list and its claim not measured yet are rendered, with nothing in the verdicts command naming it."""
    import sys
    from pathlib import Path

    import hierloco.recipes.verdicts as verdicts
    from hierloco.claims import CLAIMS
    from hierloco.pipeline.methods import STUDIES

    folder = tmp_path / "studies" / "toy_study"
    folder.mkdir(parents=True)
    (folder / "run.py").write_text("def main():\n    pass\n")
    (folder / "config.yaml").write_text("seeds: [0]\n")
    (folder / "claims.py").write_text(TOY_CLAIMS)
    CLAIMS.discover()
    command, studies = Path(verdicts.__file__).read_text(), [s.name.split("/")[0] for s in CLAIMS.studies()]
    assert "compare_full" in studies and not [name for name in studies if name in command] and "toy" not in command
    results = results_tree(tmp_path / "results")
    for seed in range(3):
        write_record(results / "toy" / "records", f"a1_seed{seed}", method="lat", robot="a1", seed=seed,
                     costs={("normal", "goal_reaching"): [0.2 + 0.01 * seed, 0.3]})
    monkeypatch.syspath_prepend(str(folder.parent))
    STUDIES.find(str(folder))
    try:
        written = pages(load(results))
        assert "| LAT walks to its goals | a1 | normal | goal_reaching |" in written["toy/verdicts.md"]
        assert "`hierloco study toy_study`" in written["toy/verdicts.md"]
        paper = written["paper_check.md"]
        section = paper[paper.index('. "the toy walks"'):]
        row = next(line for line in section.splitlines() if line.startswith("| a1 | normal | goal_reaching |"))
        assert "lat:normal 0.255 (n=3; toy)" in row and "**holds**" in row and row.endswith("| toy |")
        assert "| the toy flies | Sec. IV-F | not measured yet | wings |" in paper
        assert "`results/toy/records`" in paper
    finally:
        STUDIES.unregister("toy_study")
        if (toy := sys.modules.get("toy_study.claims")) is not None:
            CLAIMS.remove(toy.STUDY, toy.SOURCE, toy.CLAIM, toy.UNMEASURED)
        for name in ("toy_study.claims", "toy_study"):
            sys.modules.pop(name, None)
    assert "toy/verdicts.md" not in pages(load(results))


def test_the_paper_page_states_its_rule_correction_seeds_and_thresholds(tmp_path):
    """Each verdict with its deciding p, its verdict after Holm's correction within its claim and at the pre-planned
    seeds; the tally raw and corrected; the tally under other thresholds with the measured noise of the floor."""
    from hierloco import stats

    paper = pages(load(results_tree(tmp_path / "results")))["paper_check.md"]
    assert "The rule is not symmetric" in paper and "Holm's correction within each claim" in paper
    rows = [line.split(" | ") for line in paper.splitlines()
            if line.startswith("| a1 |") and line.endswith(("| pooled |", "| compare_full |"))]
    assert rows and all(row[-3] in stats.VERDICTS and row[-2] in (*stats.VERDICTS, "same seeds") for row in rows)
    assert any("(p = " in row[-4] for row in rows)
    section = paper[paper.index("## How the tally depends on the thresholds"):]
    assert "| no floor (relative criteria only) |" in section and "| Benjamini-Hochberg over every check" in section
    assert "**The floor against the noise.**" in section   # LAT, LIB, IK walk the path here: their seed spread


def test_claims_nothing_here_can_test_are_listed_with_the_reason(tmp_path):
    paper = pages(load(results_tree(tmp_path / "results")))["paper_check.md"]
    listed = paper[paper.index("## Claims not measured yet, or not testable here"):]
    for words in ("gait transitions \"if needed by the task\" on A1", "interpolate, and extrapolate",
                  "learned jointly", "the hardware gap's causes", "slipping \"and other unobserved factors"):
        row = next(line for line in listed.splitlines() if words in line)
        assert "| not testable here |" in row, row


def test_the_seeds_a_fragile_claim_needs_take_only_the_options_its_power_depends_on():
    """An inconclusive part decided with ``not_testable`` (the gait claim's) once stopped the fragile page with a
    traceback: its power takes the thresholds, not the testability level."""
    import math

    from hierloco import stats
    from hierloco.recipes.verdicts import power_options

    options = {"min_effect_rel": 0.0, "min_effect_abs": 0.2, "not_testable": math.inf}
    assert power_options(options) == {"min_effect_rel": 0.0, "min_effect_abs": 0.2}
    needed = stats.seeds_needed([0.53, 0.67, 0.53], [0.90, 0.60, 0.80], kind="better", paired=True,
                                **power_options(options))
    assert needed is None or needed > 3
