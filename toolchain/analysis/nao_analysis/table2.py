"""Paper Table 2 for every movement x joint: statistics between joint angular velocity and the
per-body-part attention score, with block-bootstrap intervals and shift-test p-values.

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
COLUMNS = (("movement", "joint") + stats.STAT_NAMES + CI_COLUMNS + P_COLUMNS
           + ("n_ticks", "n_dropped", "block_len", "n_shifts", "detrend", "run"))


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
        xp, yp = stats.ksg_prepare(v, att, seed)
        point = stats.all_stats_prepared(v, att, xp, yp)
        b = stats.pair_block_length(v, att)
        ci = stats.bootstrap_ci(v, att, b, n_boot, seed)
        p, n_shifts = stats.shift_pvalues(v, att, b, seed)
        row = {"movement": run.movement, "joint": joint, "n_ticks": n_used, "n_dropped": run.n_ticks - n_used,
               "block_len": b, "n_shifts": n_shifts, "detrend": detrend_spec, "run": label}
        for s, name in enumerate(stats.STAT_NAMES):
            row[name] = point[s]
            row[name + "_ci_lo"], row[name + "_ci_hi"] = ci[s]
            row[name + "_p"] = p[s]
        rows.append(row)
    return rows


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


def read_table2_csv(path):
    """table2.csv -> list of dicts (numbers as float/int), for make_reproduction and tests."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    ints = ("n_ticks", "n_dropped", "block_len", "n_shifts")
    floats = stats.STAT_NAMES + CI_COLUMNS + P_COLUMNS
    for r in rows:
        for c in ints:
            r[c] = int(r[c])
        for c in floats:
            r[c] = float(r[c])
    return rows
