"""The rule that decides whether one of the paper's findings is reproduced (docs/analysis.md).

A finding names Table 2 rows (paper.PAPER_FINDINGS: movement x joint). It is reproduced only
when every named row holds on each of N_SEEDS training seeds; a row holds on a seed when our
Spearman rho (pooled norm-based score `att`) has the paper's sign, is at least STRONG_RHO in
magnitude (the paper's "strong") and its 95 % interval excludes 0 on the paper's side. Partly:
some (row, seed) pairs hold; not: none does. A seed that was not analysed counts as not
holding, so fewer than N_SEEDS seeds can give at most "partly".

The MI statements behind each finding (paper.PAPER_MI_CLAIMS) are judged the same way, seed by
seed, against each row's circular-shift null (MI_CRITERION).
"""

import math

from . import JOINT_NAMES
from .paper import PAPER_FINDINGS, PAPER_MI_CLAIMS, paper_rho

N_SEEDS = 3
STRONG_RHO = 0.5
SCORE = "att"

CRITERION = ("A finding is *reproduced* only when, for every (movement, joint) row it names, on each of %d "
             "training seeds, our Spearman ρ (pooled norm-based score `att`) has the paper's sign, its "
             "estimate is at least %.1f in magnitude (the paper's \"strong\") and its 95 %% interval over "
             "distinct rollouts excludes 0 on that side (lower bound > 0 for the paper's positive ρ). *Partly*: "
             "some (row, seed) pairs hold; *not reproduced*: none does. A seed without an analysis counts as "
             "not holding." % (N_SEEDS, STRONG_RHO))


MI_CRITERION = ("An MI statement holds on a seed when the row's MI lies above the 95 %% quantile of its "
                "circular-shift null (the excess over that quantile is positive, the same as its permutation "
                "p < 0.05): dependence beyond what the smoothness of the two series alone gives. \"Largest\" also "
                "needs that excess to be the largest of the movement's five joints. What is judged is that the MI "
                "shows a dependence of attention and velocity; the paper's level of 1 bit is not: the KSG "
                "estimator's value on smooth series depends on their autocorrelation, so only the null can say what "
                "is information, and the magnitudes are printed beside the verdict. A statement is *reproduced* only when every check holds on each "
                "of %d training seeds; *partly*: some (check, seed) pairs hold; *not reproduced*: none does. A seed "
                "without an analysis counts as not holding." % N_SEEDS)


def _verdict(n_held, n_needed):
    if n_held == n_needed:
        return "reproduced"
    return "partly" if n_held > 0 else "not reproduced"


def paper_sign(movement, joint):
    """+1 or -1: the sign of the paper's Spearman rho of a row."""
    return 1 if paper_rho(movement, joint) >= 0 else -1


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
            sign = paper_sign(movement, joint)
            for seed in seeds:
                row = seed_rows[seed].get((movement, joint))
                holds, why = row_holds(row, sign)
                checks.append((movement, joint, seed, holds, why, row))
        n_held = sum(c[3] for c in checks)
        n_needed = len(pairs) * max(N_SEEDS, len(seeds))
        out.append({"id": fid, "title": title, "paper": paper_text, "pairs": pairs, "checks": checks,
                    "verdict": _verdict(n_held, n_needed), "n_seeds": len(seeds), "n_held": n_held,
                    "n_needed": n_needed})
    return out


def mi_excess_q95(row):
    """MI minus its null's 95 % quantile (nan when either is undefined)."""
    mi, q95 = row["mi_bits"], row["mi_null_q95"]
    return mi - q95 if math.isfinite(mi) and math.isfinite(q95) else math.nan


def mi_holds(rows, movement, joint, kind):
    """(holds, why) of one MI check (paper.PAPER_MI_CLAIMS) on one seed's rows {(movement, joint): row}."""
    row = rows.get((movement, joint))
    if row is None:
        return False, "not analysed"
    excess = mi_excess_q95(row)
    if not math.isfinite(excess):
        return False, "MI or its null undefined"
    reasons = [] if excess > 0 else ["not above the null's q95"]
    if kind == "largest":
        ranked = sorted(((mi_excess_q95(rows[(movement, j)]), j) for j in JOINT_NAMES
                         if (movement, j) in rows and math.isfinite(mi_excess_q95(rows[(movement, j)]))),
                        key=lambda e: -e[0])
        if ranked[0][0] > excess:
            reasons.append("largest excess over q95: %s (%+.2f bits against %+.2f)" % (ranked[0][1], ranked[0][0],
                                                                                       excess))
    return not reasons, ", ".join(reasons) or "holds"


def judge_mi(seed_rows):
    """Verdicts of the paper's MI statements, one per finding. seed_rows as for judge. Returns a
    list of dicts: id, statement, checks [(movement, joint, kind, seed, holds, why, row)],
    verdict, n_seeds, n_held, n_needed."""
    seeds = sorted(seed_rows)
    out = []
    for fid, *_ in PAPER_FINDINGS:
        statement, claims = PAPER_MI_CLAIMS[fid]
        checks = []
        for movement, joint, kind in claims:
            for seed in seeds:
                holds, why = mi_holds(seed_rows[seed], movement, joint, kind)
                checks.append((movement, joint, kind, seed, holds, why, seed_rows[seed].get((movement, joint))))
        n_held = sum(c[4] for c in checks)
        n_needed = len(claims) * max(N_SEEDS, len(seeds))
        out.append({"id": fid, "statement": statement, "checks": checks, "verdict": _verdict(n_held, n_needed),
                    "n_seeds": len(seeds), "n_held": n_held, "n_needed": n_needed})
    return out
