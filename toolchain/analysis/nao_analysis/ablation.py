"""Does the attention point where the action depends? The ablation check of DESIGN section 10.

nao_rt writes, per autonomous run, `ablation.csv`: every tick the last decoder layer's
cross-attention mass of each body part (mass_j, as in attention.bin) and ||delta a||, rad, the
change of the executed action when body part j's cross-attention logits are set to -inf in
every decoder layer over the whole window (delta_j). If attention explains the action, the
body parts that get more mass move the action more when masked. Per movement:

- per tick, Spearman rho between the five masses and the five deltas; its median over the
  ticks, with a bootstrap interval over distinct rollouts (units.py);
- how often the most-attended body part is the one whose masking moves the action most,
  beside the rate of a random pick (1/5), with the same bootstrap interval.

Attention "predicts the ablation" only when both intervals lie above chance (rho 0, rate 0.2).
"""

import csv
import math
import os

import numpy as np

from . import N_JOINTS, AnalysisError
from . import stats

FILE = "ablation.csv"
COLUMNS = ("tick",) + tuple("mass_%d" % j for j in range(N_JOINTS)) + tuple("delta_%d" % j for j in range(N_JOINTS))
CHANCE_TOP_MATCH = 1.0 / N_JOINTS
# ablation.csv's masses are attention.bin's float32 masses written as text.
MASS_TOLERANCE = 1e-6


def read_ablation(run):
    """(tick (n,), mass (n, 5), delta (n, 5)) of run's ablation.csv, or None when the run has
    none. Raises AnalysisError for a malformed file or masses that are not attention.bin's."""
    path = os.path.join(run.path, FILE)
    if not os.path.isfile(path):
        return None
    with open(path, newline="") as f:
        rows = [r for r in csv.reader(f) if r]
    if not rows:
        raise AnalysisError("%s: empty file" % path)
    header = [h.strip() for h in rows[0]]
    missing = [c for c in COLUMNS if c not in header]
    if missing:
        raise AnalysisError("%s: missing column(s) %s" % (path, ", ".join(missing)))
    if len(rows) < 2:
        raise AnalysisError("%s: no ticks after the header" % path)
    values = np.empty((len(rows) - 1, len(COLUMNS)))
    at = [header.index(c) for c in COLUMNS]
    for i, r in enumerate(rows[1:]):
        if len(r) != len(header):
            raise AnalysisError("%s: line %d has %d fields, the header %d" % (path, i + 2, len(r), len(header)))
        try:
            values[i] = [float(r[k]) for k in at]
        except ValueError as e:
            raise AnalysisError("%s: line %d: %s" % (path, i + 2, e)) from None
    tick = values[:, 0]
    if not (np.all(tick == np.round(tick)) and np.all(np.diff(tick) > 0) and tick[0] >= 0
            and tick[-1] < run.n_ticks):
        raise AnalysisError("%s: column tick is not increasing ticks of ticks.csv (0..%d)" % (path, run.n_ticks - 1))
    tick = tick.astype(np.int64)
    mass, delta = values[:, 1:1 + N_JOINTS], values[:, 1 + N_JOINTS:]
    if run.attention.mass is not None:
        rec = {int(t): k for k, t in enumerate(run.attention.tick)}
        both = [(i, rec[int(t)]) for i, t in enumerate(tick) if int(t) in rec]
        if both:
            i, k = (np.array(v) for v in zip(*both))
            a, b = mass[i], run.attention.mass[k].astype(float)
            bad = ~((np.abs(a - b) <= MASS_TOLERANCE) | (np.isnan(a) & np.isnan(b)))
            if bad.any():
                first = int(tick[i[np.flatnonzero(bad.any(axis=1))[0]]])
                raise AnalysisError("%s: mass at tick %d is not attention.bin's mass: files from different runs?"
                                    % (path, first))
    return tick, mass, delta


def tick_rho(mass, delta):
    """(n,) Spearman rho between the five masses and the five deltas of every tick (nan where
    either is constant)."""
    return np.array([stats.spearman(m, d) for m, d in zip(mass, delta)])


def top_match(mass, delta):
    """(n,) 1.0 where the most-attended body part is the one whose masking moves the action
    most, else 0.0 (the first of equal maxima, as numpy.argmax picks)."""
    return (np.argmax(mass, axis=1) == np.argmax(delta, axis=1)).astype(float)


def unit_series(run):
    """(rho (n,), match (n,)) over the run's ticks whose attention is the policy's own and whose
    ablation row is finite; None when the run has no ablation.csv."""
    read = read_ablation(run)
    if read is None:
        return None
    tick, mass, delta = read
    keep = run.policy_mask()[tick] & np.isfinite(mass).all(axis=1) & np.isfinite(delta).all(axis=1)
    rho = tick_rho(mass[keep], delta[keep])
    match = top_match(mass[keep], delta[keep])
    ok = np.isfinite(rho)
    return rho[ok], match[ok]


def ablation_summary(units, n_boot, seed, min_units=2):
    """The movement's ablation statistics from its distinct rollouts (each unit's representative,
    units[i][0]), or None when no representative has ablation.csv. Returns a dict: n_units,
    n_units_total, n_ticks, rho_median, rho_ci [lo, hi], top_match_rate, top_match_ci,
    chance_top_match, predicts (both intervals above chance), the intervals nan below
    min_units units."""
    series = [s for s in (unit_series(u[0]) for u in units) if s is not None and len(s[0])]
    if not series:
        return None
    rhos = [s[0] for s in series]
    matches = [s[1] for s in series]

    def stat(pick):
        return (float(np.median(np.concatenate([rhos[i] for i in pick]))),
                float(np.mean(np.concatenate([matches[i] for i in pick]))))

    n = len(series)
    rho_med, rate = stat(range(n))
    rho_ci = rate_ci = (math.nan, math.nan)
    if n >= min_units:
        rng = np.random.default_rng(seed)
        boot = np.array([stat(rng.integers(0, n, n)) for _ in range(n_boot)])
        lo, hi = np.percentile(boot, [2.5, 97.5], axis=0)
        rho_ci, rate_ci = (float(lo[0]), float(hi[0])), (float(lo[1]), float(hi[1]))
    predicts = bool(rho_ci[0] > 0 and rate_ci[0] > CHANCE_TOP_MATCH)
    return {"n_units": n, "n_units_total": len(units), "n_ticks": int(sum(len(r) for r in rhos)),
            "rho_median": rho_med, "rho_ci": list(rho_ci), "top_match_rate": rate, "top_match_ci": list(rate_ci),
            "chance_top_match": CHANCE_TOP_MATCH, "predicts": predicts}


def mass_spread(units):
    """How far the attention is from uniform, from attention.bin's masses (payload format 2) of
    each unit's representative: dict with n_ticks, min, max (over ticks and body parts), the
    uniform share 1/5, mean (5,) and cv_over_time (5,) (std / mean over the ticks, per body
    part); None without format-2 records."""
    masses = []
    for u in units:
        r = u[0]
        a = r.attention
        if a.mass is None or not len(a.tick):
            continue
        keep = r.policy_mask()[a.tick]
        m = a.mass[keep].astype(float)
        masses.append(m[np.isfinite(m).all(axis=1)])
    if not masses or not sum(len(m) for m in masses):
        return None
    m = np.concatenate(masses)
    mean = m.mean(axis=0)
    return {"n_ticks": len(m), "min": float(m.min()), "max": float(m.max()), "uniform": 1.0 / N_JOINTS,
            "mean": [float(x) for x in mean], "cv_over_time": [float(x) for x in m.std(axis=0) / mean]}
