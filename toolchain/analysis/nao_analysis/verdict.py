"""The rule that decides whether one of the paper's findings is reproduced (DESIGN section 10).

A finding names Table 2 rows (paper.PAPER_FINDINGS: movement x joint). It is reproduced only
when every named row holds on each of N_SEEDS training seeds; a row holds on a seed when our
Spearman rho (pooled norm-based score `att`) has the paper's sign, is at least STRONG_RHO in
magnitude (the paper's "strong") and its 95 % interval excludes 0 on the paper's side. Partly:
some (row, seed) pairs hold; not: none does. A seed that was not analysed counts as not
holding, so fewer than N_SEEDS seeds can give at most "partly".
"""

import math

from .paper import PAPER_FINDINGS, paper_rho

N_SEEDS = 3
STRONG_RHO = 0.5
SCORE = "att"

CRITERION = ("A finding is *reproduced* only when, for every (movement, joint) row it names, on each of %d "
             "training seeds, our Spearman ρ (pooled norm-based score `att`) has the paper's sign, its "
             "estimate is at least %.1f in magnitude (the paper's \"strong\") and its 95 %% interval over "
             "distinct rollouts excludes 0 on that side (lower bound > 0 for the paper's positive ρ). *Partly*: "
             "some (row, seed) pairs hold; *not reproduced*: none does. A seed without an analysis counts as "
             "not holding." % (N_SEEDS, STRONG_RHO))


def row_holds(row, sign):
    """(holds, why) for one Table 2 row (dict with spearman_rho and its interval, None if
    missing) against the paper's sign (+1 or -1)."""
    if row is None:
        return False, "not analysed"
    rho, lo, hi = row["spearman_rho"], row["spearman_rho_ci_lo"], row["spearman_rho_ci_hi"]
    if not math.isfinite(rho):
        return False, "ρ undefined"
    reasons = []
    if sign * rho <= 0:
        reasons.append("opposite sign")
    # Strength is the magnitude: a strong ρ of the other sign fails on its sign alone.
    if abs(rho) < STRONG_RHO:
        reasons.append("not strong: below %.1f" % STRONG_RHO)
    bound = lo if sign > 0 else hi
    if not math.isfinite(bound):
        reasons.append("no interval")
    elif sign * bound <= 0:
        reasons.append("interval not %s 0" % ("above" if sign > 0 else "below"))
    return not reasons, ", ".join(reasons) or "holds"


def judge(seed_rows):
    """Verdicts of the paper's findings. seed_rows: {training seed: {(movement, joint): row}}
    (the `att` rows of each seed). Returns a list of dicts: id, title, paper, pairs, checks
    [(movement, joint, seed, holds, why, row)], verdict ("reproduced", "partly", "not reproduced"),
    n_seeds."""
    seeds = sorted(seed_rows)
    out = []
    for fid, title, paper_text, pairs in PAPER_FINDINGS:
        checks = []
        for movement, joint in pairs:
            sign = 1 if paper_rho(movement, joint) >= 0 else -1
            for seed in seeds:
                row = seed_rows[seed].get((movement, joint))
                holds, why = row_holds(row, sign)
                checks.append((movement, joint, seed, holds, why, row))
        n_held = sum(c[3] for c in checks)
        n_needed = len(pairs) * max(N_SEEDS, len(seeds))
        if n_held == n_needed:
            verdict = "reproduced"
        elif n_held > 0:
            verdict = "partly"
        else:
            verdict = "not reproduced"
        out.append({"id": fid, "title": title, "paper": paper_text, "pairs": pairs, "checks": checks,
                    "verdict": verdict, "n_seeds": len(seeds), "n_held": n_held, "n_needed": n_needed})
    return out
