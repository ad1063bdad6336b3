"""The terrain study's claim of the paper (Li et al., RA-L 2021, Sec. I and II), declared for ``hierloco verdicts``
(:mod:`hierloco.claims`, ``docs/claims.md``): choosing a new latent action at every step lets the robot respond to
disturbances. The study's push sweep (``docs/terrain.md``, Pushes) measures it; it is an entry of the ledger, not
measured yet until the sweep has seeds enough for a test over seeds.
"""

from __future__ import annotations

from hierloco.claims import CLAIMS, Claim

RESPONDS_TO_DISTURBANCES = Claim(
    order=0.5, where="Sec. I (\"respond to disturbances\"), Sec. II (\"respond to online disturbances\")",
    words="planning a new latent action at every step lets the robot respond to disturbances (ours: trunk pushes "
          "of 0.25-2 m/s every 2-4 s on flat ground; per method and robot the fall rate against push size, the largest "
          "push survived and the time to recover the commanded motion, LAT against LIB, IK, SAC and SAC-SAC)",
    needs="the terrain study's push sweep (`hierloco study terrain`, `results/terrain/`) at 3 or more seeds per method "
          "and robot, for a test over seeds of LAT's largest push survived and time to recover against each other "
          "method's; measured so far at one seed (A1, seed 0, LIB, LAT and IK), which no test over seeds can decide")

CLAIMS.add(RESPONDS_TO_DISTURBANCES)
