"""The latent-space claim (Li et al., RA-L 2021, Sec. III-B, Fig. 4), declared for ``hierloco verdicts``
(:mod:`hierloco.claims`, ``docs/claims.md``): close-by latents move the CoM alike, decided per robot over seeds from
each job record's ``latent_continuity`` report.
"""

from __future__ import annotations

import numpy as np

from hierloco.claims import CLAIMS, Check, Claim, Evidence, Source, Study, decided, job_minutes, part
from hierloco.recipes.latent_map.run import STAGE  # the stage whose report the claim reads
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
        checks.append(decided(
            "latent_continuity", "Latents one lattice step apart move the CoM alike: their velocities differ by at "
            f"most {CONTINUITY_EFFECT:.0%} of what the average pair's do", robot, "normal", "latent lattice", ours,
            "-", [part("neighbours vs all pairs", near, pair, "better", paired=True,
                       names=("neighbour velocity difference (m/s)", "pair velocity difference (m/s)"),
                       options={"min_effect_rel": CONTINUITY_EFFECT})], "Sec. III-B, Fig. 4"))
    return checks


def _reports(evidence: Evidence) -> list[dict]:
    return evidence.reports.get("latent_map", {}).get(STAGE, [])


def lattice_job(evidence: Evidence, robot: str, side: str) -> tuple[tuple, str, list[float]]:
    """One LAT job per robot and seed measures the whole lattice."""
    runs = [r for r in evidence.runs.get("latent_map", []) if r.robot == robot]
    return ("latent_map", "lat"), "LAT latent-map job (the whole lattice)", job_minutes(runs)


STUDY = Study("latent_map", order=90, records=("latent_map/records",), reports=(STAGE,),
              command="hierloco study latent_map records=results/latent_map/records out_dir=results/latent_map",
              checks=lambda evidence: continuity_checks(_reports(evidence)) if _reports(evidence) else None)

SOURCE = Source("latent_map", order=80, checks=lambda evidence: continuity_checks(_reports(evidence)),
                job=lattice_job)

CONTINUOUS = Claim(
    order=19, where="Sec. III-B; Fig. 4", source="latent_map", key="latent_continuity",
    words="\"Close-by samples in the latent space lead to continuously varying CoM motion\" (ours: a lattice of 2-D "
          "latents over the learned box, each held from standing; neighbours' CoM velocities against all pairs')")

UNTESTED = (
    Claim(order=19.1, words="the low-level policy and the latent action space are learned jointly (against learning "
                            "them in turn, as Peng et al. and Li et al. 2019 do)", where="Sec. II, III-B",
          status="not testable here",
          needs="an iteratively trained latent space to compare with: no recipe here trains one, so joint against "
                "iterative training is not measured"),
    Claim(order=19.2, words="new latents \"interpolate, and extrapolate from the training experts\"",
          where="Sec. III-B", status="not testable here",
          needs="a test over seeds from job records: the midpoints of two experts are measured only in a README "
                "(`latent_map/README.md`: on Daisy they walk but land between the two experts' velocities 38-48 % of "
                "the time, no stated test); extrapolation is not measured"),
)

CLAIMS.add(STUDY, SOURCE, CONTINUOUS, *UNTESTED)
