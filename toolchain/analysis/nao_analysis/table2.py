"""Paper Table 2 for every movement x joint: statistics between joint angular velocity and the
per-body-part attention score; the correlations with block-bootstrap intervals and the p-values
of those intervals, the MI beside its circular-shift null.

The pair for joint j (contract, docs/analysis.md): velocity = numpy.gradient(q_j, t_s) over
every tick of ticks.csv; attention = att_j. Ticks where the policy was bypassed are dropped
after the gradient (rundir.Run.policy_mask); both series are then detrended the same way.
"""

import csv
import io
import math
import zlib

import numpy as np

from . import JOINT_NAMES, AnalysisError
from . import stats

MIN_TICKS = 20
DEFAULT_BOOTSTRAP = 1000
DEFAULT_SEED = 1

# One manifest of the table's columns: table2.csv, table2.md and the report walk it.
CI_COLUMNS = tuple("%s_ci_%s" % (s, e) for s in stats.STAT_NAMES for e in ("lo", "hi"))
P_COLUMNS = tuple("%s_p" % s for s in stats.STAT_NAMES)
# The MI beside its circular-shift null: the null's median and 95 % quantile, the excess over
# the median, and whether the MI lies above the 95 % quantile (1/0).
MI_NULL_COLUMNS = ("mi_null_median", "mi_null_q95", "mi_excess", "mi_above_null")
COLUMNS = (("movement", "joint") + stats.STAT_NAMES + CI_COLUMNS + P_COLUMNS + MI_NULL_COLUMNS
           + ("n_ticks", "n_dropped", "block_len", "n_shifts", "detrend", "run", "n_runs", "n_units"))


def joint_series(run, j, detrend_spec):
    """(t_s, velocity rad/s, attention) of joint j over the ticks the policy answered, detrended."""
    t = run.columns["t_s"]
    v = np.gradient(run.columns["q_%d" % j], t)
    att = run.columns["att_%d" % j]
    keep = run.policy_mask()
    t, v, att = t[keep], v[keep], att[keep]
    return t, stats.detrend(t, v, detrend_spec), stats.detrend(t, att, detrend_spec)


def row_seed(movement, joint, base_seed):
    """Seed of one row's random draws: fixed by its name, not by the order of the run dirs."""
    return zlib.crc32(("%s/%s/%d" % (movement, joint, base_seed)).encode())


def table2_rows(run, label, detrend_spec, n_boot=DEFAULT_BOOTSTRAP, base_seed=DEFAULT_SEED, progress=None):
    """Five rows (one per joint) for one run: dicts keyed by COLUMNS."""
    keep = run.policy_mask()
    n_used = int(keep.sum())
    if n_used < MIN_TICKS:
        raise AnalysisError("%s: only %d tick(s) with the policy's own attention (of %d); Table 2 needs at least %d"
                            % (run.path, n_used, run.n_ticks, MIN_TICKS))
    rows = []
    for j, joint in enumerate(JOINT_NAMES):
        if progress:
            progress("%s %s: statistics, %d bootstrap resamples, circular shifts" % (label, joint, n_boot))
        t, v, att = joint_series(run, j, detrend_spec)
        seed = row_seed(run.movement, joint, base_seed)
        b = stats.pair_block_length(v, att)
        reps = stats.bootstrap_correlations(v, att, b, n_boot, seed)
        mi, null = stats.mi_shift_null(v, att, b, seed)
        point = np.r_[stats.pearson(v, att), stats.spearman(v, att), stats.kendall_tau_b(v, att), mi]
        row = {"movement": run.movement, "joint": joint, "n_ticks": n_used, "n_dropped": run.n_ticks - n_used,
               "block_len": b, "n_shifts": len(null), "detrend": detrend_spec, "run": label, "n_runs": 1,
               "n_units": 1}
        rows.append(fill_row(row, stats.row_result(point, reps, null)))
    return rows


def fill_row(row, res):
    """row (the identifying columns) completed with the statistics of res: point, ci_lo, ci_hi,
    p ((4,) each, stats.STAT_NAMES order), mi_null_median, mi_null_q95."""
    for s, name in enumerate(stats.STAT_NAMES):
        row[name] = float(res["point"][s])
        row[name + "_ci_lo"], row[name + "_ci_hi"] = float(res["ci_lo"][s]), float(res["ci_hi"][s])
        row[name + "_p"] = float(res["p"][s])
    mi, med, q95 = row["mi_bits"], res["mi_null_median"], res["mi_null_q95"]
    row["mi_null_median"], row["mi_null_q95"] = med, q95
    row["mi_excess"] = mi - med if math.isfinite(mi) and math.isfinite(med) else math.nan
    row["mi_above_null"] = int(math.isfinite(mi) and math.isfinite(q95) and mi > q95)
    return row


def _cell(value):
    if isinstance(value, (float, np.floating)):
        return "nan" if not math.isfinite(value) else "%.6f" % value
    return str(value)


def table2_csv(rows):
    """table2.csv text: COLUMNS, fixed 6-decimal floats (byte-identical for identical inputs)."""
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(COLUMNS)
    for r in rows:
        w.writerow([_cell(r[c]) for c in COLUMNS])
    return out.getvalue()
