"""Table 2 on the paper's protocol (docs/analysis.md): many autonomous rollouts per movement
(`nao_toolchain evaluate` writes one per held-out demonstration), pooled with the distinct
rollout as the unit.

Units. Runs that repeat one rollout (units.py: hand paths within 1 mm of every other run of
their unit, over their common ticks) are one unit, represented by its longest run. Each unit's
series (joint velocity, attention score) are detrended on their own, then the units of a
movement are concatenated; the statistic of a movement x joint is that of the pooled series.

One resampling scheme per statistic. A correlation's 95 % interval is a bootstrap over units in
two stages (draw as many units as there are, with replacement, resample each drawn unit by
circular blocks, pool them, recompute), and its p-value is read off the same resamples, so it
never contradicts the interval; with fewer than MIN_UNITS units there is neither. The MI is
judged against N_PERM permutations that keep each unit's autocorrelation: every unit's attention
series circularly shifted by its own random shift (between the unit's block length and n - block
length) and the pooled MI recomputed; it is evidence of dependence only above the null's 95 %
quantile (its permutation p below 0.05).

Scores: `att_j` (norm-based, the contract) and, when every run has them, `attm_j` (raw
cross-attention mass summed over the window), side by side.
"""

import math

import numpy as np
import scipy.stats

from . import JOINT_NAMES, N_JOINTS, AnalysisError
from . import stats
from .units import UNIT_DTW_M, distinct_units

N_PERM = 200
MIN_RUNS = 2
# A bootstrap over one unit always redraws that unit: no interval rather than a zero-width one.
MIN_UNITS = 2


def score_prefixes(runs):
    """('att',) or ('att', 'attm') when every run has the raw-mass columns."""
    has_mass = all(all(("attm_%d" % j) in r.columns for j in range(N_JOINTS)) for r in runs)
    return ("att", "attm") if has_mass else ("att",)


def group_runs(runs):
    """{movement: [runs]} in a fixed order (movement name, then run path)."""
    groups = {}
    for r in sorted(runs, key=lambda r: (r.movement, r.path)):
        groups.setdefault(r.movement, []).append(r)
    return groups


def is_protocol(runs):
    """True when some movement has several runs: Table 2 is then pooled per movement."""
    return any(len(v) >= MIN_RUNS for v in group_runs(runs).values())


def _run_series(run, j, detrend_spec, prefix):
    t = run.columns["t_s"]
    v = np.gradient(run.columns["q_%d" % j], t)
    att = run.columns["%s_%d" % (prefix, j)]
    keep = run.policy_mask() & np.isfinite(att)
    t, v, att = t[keep], v[keep], att[keep]
    return stats.detrend(t, v, detrend_spec), stats.detrend(t, att, detrend_spec)


def _pool(vs, pick, ticks):
    return np.concatenate([vs[i][t] for i, t in zip(pick, ticks)])


def _pooled_correlations(xs, ys, pick, ticks):
    """Pearson r, Spearman rho, Kendall tau-b of the units `pick` (indices into xs, ys, repeats
    allowed) pooled; ticks: per picked unit the tick indices to take (a block resample)."""
    x, y = _pool(xs, pick, ticks), _pool(ys, pick, ticks)
    tau = scipy.stats.kendalltau(x, y, variant="b").statistic if len(x) > 1 else math.nan
    return np.array([stats.pearson(x, y), stats.spearman(x, y), float(tau)])


def unit_statistics(xs, ys, n_boot, seed, n_perm=N_PERM):
    """Table 2's numbers of one movement x joint from its units' detrended series xs, ys (lists
    of (n_u,) arrays, one per distinct rollout). Returns stats.row_result's dict (point, ci_lo,
    ci_hi, p, each (4,) in stats.STAT_NAMES order; mi_null_median, mi_null_q95) and block_len
    (median over units). Below MIN_UNITS units the correlations get no interval and no p.

    The correlations' bootstrap is two-stage: draw units with replacement, then resample each
    drawn unit by circular blocks of its own block length. Units alone would see only the spread
    between a few rollouts, which can be small by chance (three independent pairs of series with
    the same spurious r give a near-zero-width interval); the blocks add each rollout's own
    sampling spread. Each correlation's p-value comes from the same resamples
    (stats.interval_pvalue)."""
    n_units = len(xs)
    every = list(range(n_units))
    whole = [np.arange(len(x)) for x in xs]
    # The KSG tie-breaking jitter, drawn once over the pooled units; a shift moves it with its tick.
    xp, yp = stats.ksg_prepare(np.concatenate(xs), np.concatenate(ys), seed)
    yps = np.split(yp, np.cumsum([len(x) for x in xs])[:-1])
    point = np.r_[_pooled_correlations(xs, ys, every, whole), stats.ksg_core_bits(xp, yp)]
    blocks = [stats.pair_block_length(x, y) for x, y in zip(xs, ys)]
    rng = np.random.default_rng(seed)
    reps = None
    if n_units >= MIN_UNITS and n_boot > 0:
        reps = np.empty((n_boot, 3))
        for k in range(n_boot):
            pick = [int(i) for i in rng.integers(0, n_units, n_units)]
            ticks = [stats.circular_block_indices(len(xs[i]), blocks[i], rng) for i in pick]
            reps[k] = _pooled_correlations(xs, ys, pick, ticks)
    null = np.empty(n_perm)
    for k in range(n_perm):
        shifts = [int(rng.integers(min(b, len(y) - 1), max(min(b, len(y) - 1), len(y) - b) + 1)) if len(y) > 1 else 0
                  for y, b in zip(ys, blocks)]
        null[k] = stats.ksg_core_bits(xp, np.concatenate([np.roll(y, s) for y, s in zip(yps, shifts)]))
    return dict(stats.row_result(point, reps, null), block_len=int(np.median(blocks)))


def pooled_rows(units, movement, detrend_spec, n_boot, base_seed, prefix="att", progress=None):
    """Five Table 2 rows (table2.COLUMNS) of one movement, for score `prefix`. units: the
    movement's runs grouped into distinct rollouts (units.distinct_units), each unit's first run
    its representative."""
    from .table2 import MIN_TICKS, fill_row, row_seed

    reps = [u[0] for u in units]
    n_runs = sum(len(u) for u in units)
    rows = []
    for j, joint in enumerate(JOINT_NAMES):
        if progress:
            progress("%s %s (%s): %d runs in %d distinct rollouts, %d unit-bootstrap resamples, %d shift "
                     "permutations" % (movement, joint, prefix, n_runs, len(units), n_boot, N_PERM))
        series = [_run_series(r, j, detrend_spec, prefix) for r in reps]
        xs = [s[0] for s in series]
        ys = [s[1] for s in series]
        n_used = sum(len(x) for x in xs)
        if n_used < MIN_TICKS:
            raise AnalysisError("%s: only %d usable ticks over %d distinct rollouts; Table 2 needs at least %d"
                                % (movement, n_used, len(units), MIN_TICKS))
        seed = row_seed(movement, joint + ("" if prefix == "att" else "/" + prefix), base_seed)
        res = unit_statistics(xs, ys, n_boot, seed)
        row = {"movement": movement, "joint": joint, "n_ticks": n_used,
               "n_dropped": sum(r.n_ticks for r in reps) - n_used, "block_len": res["block_len"],
               "n_shifts": N_PERM, "detrend": detrend_spec, "run": "pooled:%d" % n_runs,
               "n_runs": n_runs, "n_units": len(units)}
        rows.append(fill_row(row, res))
    return rows


def attention_offsets(movement_runs, prefix="att"):
    """Share of policy ticks in which each joint has the highest score, and the mean score."""
    wins = np.zeros(N_JOINTS)
    total = 0
    mean = np.zeros(N_JOINTS)
    for r in movement_runs:
        keep = r.policy_mask()
        a = np.column_stack([r.columns["%s_%d" % (prefix, j)] for j in range(N_JOINTS)])[keep]
        a = a[np.isfinite(a).all(axis=1)]
        if len(a):
            wins += np.bincount(np.argmax(a, axis=1), minlength=N_JOINTS)
            mean += a.sum(axis=0)
            total += len(a)
    return wins / max(total, 1), mean / max(total, 1), total


def movement_units(runs, threshold_m=UNIT_DTW_M):
    """({movement: units}, {movement: separation}) (units.distinct_units) of every movement at
    one threshold."""
    found = movement_groupings(runs, (threshold_m,))
    return ({m: f[threshold_m][0] for m, f in found.items()}, {m: f[threshold_m][1] for m, f in found.items()})


def movement_groupings(runs, thresholds_m):
    """{movement: {threshold: (units, separation)}} (units.distinct_units) of every movement."""
    return {m: distinct_units(v, thresholds_m) for m, v in group_runs(runs).items()}


def protocol_rows(units_by_movement, detrend_spec, n_boot, base_seed, prefixes, progress=None):
    """{prefix: rows} of every movement's pooled distinct rollouts."""
    out = {}
    for prefix in prefixes:
        rows = []
        for m in sorted(units_by_movement):
            rows += pooled_rows(units_by_movement[m], m, detrend_spec, n_boot, base_seed, prefix, progress)
        out[prefix] = rows
    return out
