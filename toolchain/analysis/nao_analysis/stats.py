"""Statistics of Table 2: trend removal, correlations, KSG mutual information, block length,
the circular block bootstrap with its percentile intervals and the p-values read off them, and
the MI's circular-shift null (docs/analysis.md says why each).

Every random draw comes from a numpy Generator seeded by the caller, so the same inputs give
the same numbers bit for bit.
"""

import math

import numpy as np
from scipy import signal
from scipy.spatial import cKDTree
from scipy.special import digamma

from . import AnalysisError

STAT_NAMES = ("pearson_r", "spearman_rho", "kendall_tau", "mi_bits")
KSG_K = 3
# Tie-breaking noise of the KSG estimator, relative to the standardised series (as in
# scikit-learn's mutual_info_regression): far below any real difference, enough to break ties.
KSG_JITTER = 1e-10
DEFAULT_DETREND = "linear"
DEFAULT_HIGHPASS_HZ = 0.1


# --- trend removal ---------------------------------------------------------------------------

def parse_detrend(spec):
    """'none' | 'linear' | 'highpass[:FC_HZ]' -> (name, cutoff_hz or None). AnalysisError if not."""
    name, _, arg = spec.partition(":")
    if name in ("none", "linear") and not arg:
        return name, None
    if name == "highpass":
        try:
            fc = float(arg) if arg else DEFAULT_HIGHPASS_HZ
        except ValueError:
            fc = -1.0
        if not fc > 0:
            raise AnalysisError("--detrend highpass:FC_HZ needs a positive cutoff in Hz, got '%s'" % arg)
        return name, fc
    raise AnalysisError("--detrend: unknown method '%s' (linear, highpass[:FC_HZ], none)" % spec)


def describe_detrend(spec):
    """One sentence for table2.md and the report."""
    name, fc = parse_detrend(spec)
    if name == "none":
        return "none (raw series)"
    if name == "linear":
        return "linear: the least-squares line in t_s removed from each series"
    return ("highpass: zero-phase 2nd-order Butterworth high-pass, cutoff %g Hz "
            "(scipy.signal.sosfiltfilt), on each series" % fc)


def detrend(t_s, x, spec):
    """Removes the trend of x (n,) sampled at t_s (n,) by the method spec (parse_detrend)."""
    name, fc = parse_detrend(spec)
    x = np.asarray(x, dtype=float)
    if name == "none":
        return x.copy()
    if name == "linear":
        # A line in t_s, not in the sample index: right also where bypassed ticks were dropped.
        A = np.column_stack([t_s - t_s.mean(), np.ones_like(t_s)])
        coef, *_ = np.linalg.lstsq(A, x, rcond=None)
        return x - A @ coef
    fs = 1.0 / float(np.median(np.diff(t_s)))
    if not fc < fs / 2:
        raise AnalysisError("--detrend highpass:%g: the cutoff must be below the Nyquist frequency %g Hz"
                            % (fc, fs / 2))
    sos = signal.butter(2, fc, btype="highpass", fs=fs, output="sos")
    return signal.sosfiltfilt(sos, x)


# --- correlations ----------------------------------------------------------------------------

def rankdata_average(x):
    """Ranks 1..n, ties given the average of the ranks they span (as Spearman needs)."""
    x = np.asarray(x)
    order = np.argsort(x, kind="mergesort")
    xs = x[order]
    # Runs of equal values: each run gets the mean of its positions.
    starts = np.flatnonzero(np.r_[True, xs[1:] != xs[:-1]])
    ends = np.r_[starts[1:], len(xs)]
    avg = (starts + ends + 1) / 2.0  # mean of the 1-based positions start+1 .. end
    ranks = np.empty(len(x))
    ranks[order] = np.repeat(avg, ends - starts)
    return ranks


def pearson(x, y):
    """Pearson r; nan when either series is constant."""
    x = np.asarray(x, dtype=float) - np.mean(x)
    y = np.asarray(y, dtype=float) - np.mean(y)
    den = math.sqrt(float(x @ x) * float(y @ y))
    return float(x @ y) / den if den > 0 else math.nan


def spearman(x, y):
    """Spearman rho: Pearson r of the average ranks."""
    return pearson(rankdata_average(x), rankdata_average(y))


def kendall_tau_b(x, y):
    """Kendall tau-b = (n_c - n_d) / sqrt((n0 - n_x)(n0 - n_y)) over all pairs (O(n^2))."""
    x = np.asarray(x)
    y = np.asarray(y)
    sx = np.sign(x[:, None] - x[None, :])
    sy = np.sign(y[:, None] - y[None, :])
    # The full matrices count every pair twice, numerator and denominator alike.
    den = math.sqrt(float(np.abs(sx).sum()) * float(np.abs(sy).sum()))
    return float((sx * sy).sum()) / den if den > 0 else math.nan


# --- mutual information: Kraskov, Stoegbauer, Grassberger 2004, estimator 1 ------------------

def ksg_prepare(x, y, seed):
    """Standardised x, y with the tie-breaking jitter, drawn from seed. nan arrays if constant."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    sx, sy = x.std(), y.std()
    if not (sx > 0 and sy > 0):
        return np.full_like(x, math.nan), np.full_like(y, math.nan)
    rng = np.random.default_rng(seed)
    x = x / sx
    y = y / sy
    x = x + KSG_JITTER * max(1.0, float(np.mean(np.abs(x)))) * rng.standard_normal(len(x))
    y = y + KSG_JITTER * max(1.0, float(np.mean(np.abs(y)))) * rng.standard_normal(len(y))
    return x, y


def ksg_core_bits(x, y, k=KSG_K):
    """KSG estimator 1 in bits on prepared series (ksg_prepare), max-norm, no clipping at 0.

    I = psi(k) + psi(N) - < psi(n_x + 1) + psi(n_y + 1) >, where eps_i is the max-norm
    distance from point i to its k-th neighbour in the joint space and n_x(i) counts the points
    j != i with |x_j - x_i| < eps_i."""
    n = len(x)
    if n <= k or not (np.isfinite(x).all() and np.isfinite(y).all()):
        return math.nan
    z = np.column_stack([x, y])
    d, _ = cKDTree(z).query(z, k=k + 1, p=np.inf)  # the first neighbour is the point itself
    eps = d[:, k]
    # Strictly closer than eps: query the closed ball of the next smaller double.
    r = np.nextafter(eps, 0)
    nx = cKDTree(x[:, None]).query_ball_point(x[:, None], r, p=np.inf, return_length=True) - 1
    ny = cKDTree(y[:, None]).query_ball_point(y[:, None], r, p=np.inf, return_length=True) - 1
    mi = digamma(k) + digamma(n) - np.mean(digamma(nx + 1) + digamma(ny + 1))
    return float(mi / math.log(2))


def ksg_mi_bits(x, y, k=KSG_K, seed=0):
    """Mutual information of two 1-D series in bits (KSG estimator 1, k neighbours)."""
    xp, yp = ksg_prepare(x, y, seed)
    return ksg_core_bits(xp, yp, k)


# --- block length: Politis & White (2004) with Patton, Politis & White (2009) ----------------

def _flat_top(t):
    t = np.abs(t)
    return np.where(t <= 0.5, 1.0, np.where(t <= 1.0, 2.0 * (1.0 - t), 0.0))


def block_length_pw(x):
    """Automatic block length of the circular block bootstrap for one series (real, >= 1).

    Politis & White 2004 (corrected by Patton, Politis & White 2009): b = (2 G^2 / D)^(1/3)
    n^(1/3) with G = sum lambda(k/M) |k| R(k), D = 4/3 (sum lambda(k/M) R(k))^2, flat-top
    lambda, M = 2 m_hat where m_hat is the first lag after which K_N = 5 autocorrelations in a
    row are insignificant (|rho| < 2 sqrt(log10(n)/n)); capped at min(3 sqrt(n), n/3)."""
    x = np.asarray(x, dtype=float)
    n = len(x)
    x = x - x.mean()
    kn = max(5, int(math.ceil(math.sqrt(math.log10(n)))))
    m_max = int(math.ceil(math.sqrt(n))) + kn
    b_max = math.ceil(min(3.0 * math.sqrt(n), n / 3.0))
    acv = np.array([x[:n - k] @ x[k:] / n for k in range(m_max + 1)])
    if not acv[0] > 0:
        return 1.0
    rho = acv[1:] / acv[0]  # rho[k - 1]: lag k
    insignificant = np.abs(rho) < 2.0 * math.sqrt(math.log10(n) / n)
    m_hat = m_max
    for m in range(0, m_max - kn + 1):
        if insignificant[m:m + kn].all():  # lags m+1 .. m+kn
            m_hat = m
            break
    M = min(2 * m_hat, m_max)
    if M == 0:
        return 1.0
    k = np.arange(-M, M + 1)
    lam = _flat_top(k / M)
    R = acv[np.abs(k)]
    G = float(np.sum(lam * np.abs(k) * R))
    g0 = float(np.sum(lam * R))
    D = 4.0 / 3.0 * g0 * g0
    if not D > 0:
        return float(b_max)
    b = (2.0 * G * G / D) ** (1.0 / 3.0) * n ** (1.0 / 3.0)
    return float(min(max(b, 1.0), b_max))


def pair_block_length(x, y):
    """Block length for a pair: the larger of the two series' own, rounded up."""
    return int(math.ceil(max(block_length_pw(x), block_length_pw(y))))


# --- circular block bootstrap and circular-shift permutations --------------------------------

def circular_block_indices(n, b, rng):
    """Indices of one circular block bootstrap resample (Politis & Romano 1992): ceil(n/b)
    blocks of b consecutive ticks, each starting anywhere, wrapping at the end; cut to n."""
    starts = rng.integers(0, n, size=-(-n // b))
    return ((starts[:, None] + np.arange(b)[None, :]) % n).ravel()[:n]


def bootstrap_correlations(x, y, b, n_boot, seed):
    """(n_boot, 3) Pearson r, Spearman rho and Kendall tau-b of n_boot circular block bootstrap
    resamples (block length b, the same indices for both series), drawn from seed.

    No MI: a resample repeats ticks (and, in smooth series, their near-identical neighbours),
    which the KSG estimator reads as a denser neighbourhood, so resampled MI values sit above the
    estimate by an amount of their own; the MI is judged against its circular-shift null instead."""
    rng = np.random.default_rng(seed)
    n = len(x)
    reps = np.empty((n_boot, 3))
    for i in range(n_boot):
        idx = circular_block_indices(n, b, rng)
        reps[i] = pearson(x[idx], y[idx]), spearman(x[idx], y[idx]), kendall_tau_b(x[idx], y[idx])
    return reps


# --- intervals and p-values from one set of resamples ----------------------------------------

LEVEL = 0.95


def percentile_interval(reps, level=LEVEL):
    """(lo, hi) percentile interval of the finite values of reps (numpy's linear interpolation
    between order statistics); nan when fewer than 99 % of reps are finite or fewer than 2."""
    r = np.asarray(reps, dtype=float)
    f = r[np.isfinite(r)]
    if f.size < 2 or f.size < 0.99 * r.size:
        return math.nan, math.nan
    alpha = (1.0 - level) / 2.0
    lo, hi = np.percentile(f, [100.0 * alpha, 100.0 * (1.0 - alpha)])
    return float(lo), float(hi)


def _quantile_level_of(s, value, strict):
    """For sorted s (n >= 2) and numpy's linear quantile Q(a) (h = a (n - 1)): the largest a with
    Q(a) <= value (strict False) or the smallest a with Q(a) >= value (strict True), clipped to
    [0, 1]."""
    n = len(s)
    k = int(np.searchsorted(s, value, side="left" if strict else "right"))  # #{s < value} or #{s <= value}
    if k == 0:
        return 0.0
    if k == n:
        return 1.0
    lo, hi = s[k - 1], s[k]
    return ((k - 1) + (value - lo) / (hi - lo)) / (n - 1)


def interval_pvalue(reps, null_value=0.0):
    """Two-sided p-value of "the statistic is null_value" from the same resamples as its
    percentile interval: the smallest alpha at which the (1 - alpha) percentile interval of reps
    excludes null_value, at least 1 / (n + 1) (n finite resamples cannot resolve less). By
    construction p < 1 - level exactly when percentile_interval(reps, level) excludes null_value,
    so a p-value never contradicts its interval. nan when percentile_interval gives no interval."""
    r = np.asarray(reps, dtype=float)
    if not math.isfinite(percentile_interval(r)[0]):
        return math.nan
    s = np.sort(r[np.isfinite(r)])
    # The interval's lower end passes null_value at alpha = 2 a_lo, its upper end at 2 (1 - a_hi).
    a_lo = _quantile_level_of(s, null_value, strict=False)
    a_hi = _quantile_level_of(s, null_value, strict=True)
    p = min(2.0 * a_lo, 2.0 * (1.0 - a_hi), 1.0)
    return max(p, 1.0 / (len(s) + 1))


# --- the MI against its circular-shift null --------------------------------------------------

def circular_shifts(n, min_shift):
    """The shifts of the permutation test: min_shift <= s <= n - min_shift."""
    return np.arange(min_shift, n - min_shift + 1)


def mi_shift_null(x, y, min_shift, seed):
    """(MI of x, y, (n_shifts,) MI of x against every circular shift s of y with min_shift <= s
    <= n - min_shift; empty when there is none). A shift keeps both series' autocorrelation and
    breaks only their alignment; all shifts are used (no randomness)."""
    xp, yp = ksg_prepare(x, y, seed)
    null = np.array([ksg_core_bits(xp, np.roll(yp, s)) for s in circular_shifts(len(x), min_shift)])
    return ksg_core_bits(xp, yp), null


# An MI counts as evidence of dependence only above its null's 95 % quantile: one-sided p below
# MI_ALPHA.
MI_ALPHA = 0.05


def mi_null_pvalue(mi, null_mi):
    """One-sided permutation p-value of an MI against its null draws (larger = more dependence):
    p = (1 + #{null >= mi}) / (1 + n) over the n finite draws; nan without any."""
    v = np.asarray(null_mi, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0 or not math.isfinite(mi):
        return math.nan
    return float((1.0 + np.sum(v >= mi)) / (1.0 + v.size))


def mi_null_quantiles(null_mi):
    """(median, 95 % quantile) of the MI under the null; nan when undefined. The 95 % quantile is
    the order statistic an MI must exceed for mi_null_pvalue < MI_ALPHA: the (g + 1)-th largest
    of the n draws, g = ceil((n + 1) MI_ALPHA) - 2 (the 10th largest of 200), so "above the
    null's 95 % quantile" and "p < 0.05" are one statement; nan when n is too small for any p
    below MI_ALPHA."""
    v = np.sort(np.asarray(null_mi, dtype=float))
    v = v[np.isfinite(v)]
    if v.size == 0:
        return math.nan, math.nan
    g = int(math.ceil(round((v.size + 1) * MI_ALPHA, 9))) - 2
    q95 = float(v[v.size - 1 - g]) if 0 <= g < v.size else math.nan
    return float(np.median(v)), q95


def row_result(point, reps, null_mi):
    """One Table 2 row's numbers (table2.fill_row): point (4,) in STAT_NAMES order; reps
    (n_boot, 3) resampled correlations (None: no interval), from which each correlation's 95 %
    percentile interval and its p-value (interval_pvalue) come; null_mi the MI's null draws, from
    which its p-value, median and 95 % quantile come. The MI has no bootstrap interval."""
    lo, hi, p = (np.full(len(STAT_NAMES), math.nan) for _ in range(3))
    if reps is not None and len(reps):
        for s in range(3):
            lo[s], hi[s] = percentile_interval(reps[:, s])
            p[s] = interval_pvalue(reps[:, s])
    p[3] = mi_null_pvalue(point[3], null_mi)
    med, q95 = mi_null_quantiles(null_mi)
    return {"point": np.asarray(point, dtype=float), "ci_lo": lo, "ci_hi": hi, "p": p, "mi_null_median": med,
            "mi_null_q95": q95}
