"""Does the attention point where the action depends? The ablation check (docs/analysis.md).

nao_rt writes, per autonomous run, `ablation.csv`: every tick the last decoder layer's
cross-attention mass of each body part (mass_j, as in attention.bin) and ||delta a||, rad, the
change of the executed action when body part j's cross-attention logits are set to -inf in
every decoder layer over the whole window (delta_j). If attention explains the action, the
body parts that get more mass move the action more when masked. Per movement:

- per tick, Spearman rho between the five masses and the five deltas; its median over the
  ticks, with a bootstrap interval over distinct rollouts (units.py);
- how often the most-attended body part is the one whose masking moves the action most (the
  match rate), beside its chance level: the rate at which the two would agree if the attention's
  pick and the ablation's were independent, sum_j P(attention picks j) P(masking j moves the
  action most), each P the share of the movement's ticks. A uniform 1/5 would be wrong
  wherever one body part is favoured: too low where both favour the same one, too high where
  they favour different ones.

Every interval comes from one bootstrap over distinct rollouts: the match rate and the chance
level are recomputed on the same resampled rollouts, and the match rate lies "above chance"
only when the 95 % interval of their difference lies above 0. Attention "predicts the ablation"
only when, besides, the median rho's interval lies above 0.

Everything is computed from per-run counts (run_record), which the Table 2 JSON keeps, so that
docs/reproduction.md recomputes it for any grouping of the runs into distinct rollouts.
"""

import csv
import math
import os

import numpy as np

from . import N_JOINTS, AnalysisError
from . import stats

FILE = "ablation.csv"
COLUMNS = ("tick",) + tuple("mass_%d" % j for j in range(N_JOINTS)) + tuple("delta_%d" % j for j in range(N_JOINTS))
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


def run_record(run):
    """The counts of one run's ablation that every summary needs, over its ticks whose attention
    is the policy's own, whose ablation row is finite and whose per-tick rho is defined; None
    when the run has no ablation.csv. A dict (JSON-ready): n_ticks, matches (ticks where the
    top body parts agree), attention_top and ablation_top (5 each: ticks in which body part j
    has the most mass / whose masking moves the action most), tick_rho ([[rho, ticks], ...] in
    increasing rho: per-tick Spearman rho takes few distinct values over five body parts)."""
    read = read_ablation(run)
    if read is None:
        return None
    tick, mass, delta = read
    keep = run.policy_mask()[tick] & np.isfinite(mass).all(axis=1) & np.isfinite(delta).all(axis=1)
    mass, delta = mass[keep], delta[keep]
    rho = tick_rho(mass, delta)
    ok = np.isfinite(rho)
    mass, delta, rho = mass[ok], delta[ok], rho[ok]
    values, counts = np.unique(rho, return_counts=True)
    return {"n_ticks": int(len(rho)), "matches": int(top_match(mass, delta).sum()),
            "attention_top": np.bincount(np.argmax(mass, axis=1), minlength=N_JOINTS).astype(int).tolist(),
            "ablation_top": np.bincount(np.argmax(delta, axis=1), minlength=N_JOINTS).astype(int).tolist(),
            "tick_rho": [[float(v), int(c)] for v, c in zip(values, counts)]}


class _Counts:
    """The records of a movement's units as arrays, for resampling whole units."""

    def __init__(self, records):
        self.values = np.unique(np.array([v for r in records for v, _ in r["tick_rho"]], dtype=float))
        self.rho = np.zeros((len(records), len(self.values)), dtype=np.int64)
        for u, r in enumerate(records):
            for v, c in r["tick_rho"]:
                self.rho[u, np.searchsorted(self.values, v)] += c
        self.n = np.array([r["n_ticks"] for r in records], dtype=np.int64)
        self.matches = np.array([r["matches"] for r in records], dtype=np.int64)
        self.attention = np.array([r["attention_top"] for r in records], dtype=np.int64)
        self.ablation = np.array([r["ablation_top"] for r in records], dtype=np.int64)

    def stats(self, pick):
        """(median rho, match rate, chance level) of the units `pick` (repeats allowed) pooled."""
        hist = self.rho[pick].sum(axis=0)
        n = int(hist.sum())
        cum = np.cumsum(hist)
        # numpy.median of the pooled ticks: the middle one, or the mean of the middle two.
        lo = self.values[np.searchsorted(cum, (n - 1) // 2, side="right")]
        hi = self.values[np.searchsorted(cum, n // 2, side="right")]
        total = float(self.n[pick].sum())
        chance = float(np.sum(self.attention[pick].sum(axis=0) / total * (self.ablation[pick].sum(axis=0) / total)))
        return (lo + hi) / 2, float(self.matches[pick].sum()) / total, chance


def summary_from_records(records, n_boot, seed, min_units=2):
    """The movement's ablation statistics from the run_record of each distinct rollout's
    representative (None for one without ablation.csv), or None when none has one. Returns a
    dict: n_units (with ablation.csv), n_units_total, n_ticks, rho_median, rho_ci [lo, hi],
    top_match_rate, top_match_ci, chance, chance_ci, excess (match rate - chance), excess_ci,
    above_chance (excess_ci above 0), predicts (above chance and rho_ci above 0); the intervals
    nan below min_units units. The bootstrap draws units with replacement from a generator
    seeded by seed."""
    have = [r for r in records if r is not None and r["n_ticks"]]
    if not have:
        return None
    counts = _Counts(have)
    n = len(have)
    rho_med, rate, chance = counts.stats(np.arange(n))
    rho_ci = rate_ci = chance_ci = excess_ci = (math.nan, math.nan)
    if n >= min_units:
        rng = np.random.default_rng(seed)
        boot = np.array([counts.stats(rng.integers(0, n, n)) for _ in range(n_boot)])
        rho_ci, rate_ci, chance_ci = (stats.percentile_interval(boot[:, k]) for k in range(3))
        excess_ci = stats.percentile_interval(boot[:, 1] - boot[:, 2])
    above = bool(excess_ci[0] > 0)
    return {"n_units": n, "n_units_total": len(records), "n_ticks": int(counts.n.sum()),
            "rho_median": float(rho_med), "rho_ci": list(rho_ci), "top_match_rate": rate, "top_match_ci": list(rate_ci),
            "chance": chance, "chance_ci": list(chance_ci), "excess": rate - chance, "excess_ci": list(excess_ci),
            "above_chance": above, "predicts": bool(above and rho_ci[0] > 0)}


def ablation_summary(units, n_boot, seed, min_units=2):
    """summary_from_records of the units' representatives (each unit's first run)."""
    return summary_from_records([run_record(u[0]) for u in units], n_boot, seed, min_units)


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
