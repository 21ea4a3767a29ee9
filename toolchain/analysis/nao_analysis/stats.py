"""Statistics of Table 2: trend removal, correlations, KSG mutual information, block length,
circular block bootstrap and circular-shift permutation test (docs/analysis.md says why each).

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


def ksg_core_bits(x, y, k=KSG_K, origin=None):
    """KSG estimator 1 in bits on prepared series (ksg_prepare), max-norm, no clipping at 0.

    I = psi(k) + psi(N) - < psi(n_x + 1) + psi(n_y + 1) >, where eps_i is the max-norm
    distance from point i to its k-th neighbour in the joint space and n_x(i) counts the points
    j != i with |x_j - x_i| < eps_i.

    origin: (n,) ints or None. In a bootstrap resample the same tick appears several times; a
    copy sits at distance 0 and would fake dependence, so copies of the same origin never count
    as each other's neighbours (and are left out of n_x, n_y). None: all points distinct."""
    n = len(x)
    if n <= k or not (np.isfinite(x).all() and np.isfinite(y).all()):
        return math.nan
    z = np.column_stack([x, y])
    tree = cKDTree(z)
    if origin is None:
        d, _ = tree.query(z, k=k + 1, p=np.inf)  # the first neighbour is the point itself
        eps = d[:, k]
        self_copies = np.ones(n)
    else:
        origin = np.asarray(origin)
        self_copies = np.bincount(origin)[origin].astype(float)
        kq = min(n, k + int(self_copies.max()))
        d, nb = tree.query(z, k=kq, p=np.inf)
        d = np.where(origin[nb] == origin[:, None], np.inf, d)
        d.sort(axis=1)
        eps = d[:, k - 1]
        if not np.isfinite(eps).all():
            return math.nan  # fewer than k distinct ticks
    # Strictly closer than eps: query the closed ball of the next smaller double.
    r = np.nextafter(eps, 0)
    nx = cKDTree(x[:, None]).query_ball_point(x[:, None], r, p=np.inf, return_length=True) - self_copies
    ny = cKDTree(y[:, None]).query_ball_point(y[:, None], r, p=np.inf, return_length=True) - self_copies
    mi = digamma(k) + digamma(n) - np.mean(digamma(nx + 1) + digamma(ny + 1))
    return float(mi / math.log(2))


def ksg_mi_bits(x, y, k=KSG_K, seed=0):
    """Mutual information of two 1-D series in bits (KSG estimator 1, k neighbours)."""
    xp, yp = ksg_prepare(x, y, seed)
    return ksg_core_bits(xp, yp, k)


# --- all four at once, for the resampling loops ----------------------------------------------

def all_stats_prepared(x, y, xp, yp, origin=None):
    """(pearson_r, spearman_rho, kendall_tau, mi_bits) of x, y; xp, yp: ksg_prepare(x, y)."""
    return np.array([pearson(x, y), spearman(x, y), kendall_tau_b(x, y), ksg_core_bits(xp, yp, KSG_K, origin)])


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


# Statistics whose bootstrap distribution is re-centred on the estimate before the percentile
# interval is read off. A resample repeats ticks, and the KSG estimator reads repeated (and,
# in smooth series, their adjacent) ticks as a denser neighbourhood: its resampled values sit
# above the estimate (medians 0.06-0.37 bit higher on the demo runs) while their spread stays usable
# (conservative in simulations of autocorrelated Gaussian pairs; docs/analysis.md).
RECENTRED = ("mi_bits",)


def bootstrap_ci(x, y, b, n_boot, seed, level=0.95):
    """Percentile intervals of the four statistics: (4, 2) array [lo, hi], nan if undefined.

    Correlations: the plain percentile interval. MI (RECENTRED): the percentile interval of the
    resampled values shifted so that their median is the estimate, [est + q_lo - q_50,
    est + q_hi - q_50]."""
    rng = np.random.default_rng(seed)
    xp, yp = ksg_prepare(x, y, seed)
    n = len(x)
    reps = np.empty((n_boot, len(STAT_NAMES)))
    for i in range(n_boot):
        idx = circular_block_indices(n, b, rng)
        reps[i] = all_stats_prepared(x[idx], y[idx], xp[idx], yp[idx], origin=idx)
    alpha = (1.0 - level) / 2.0
    out = np.full((len(STAT_NAMES), 2), math.nan)
    for s in range(len(STAT_NAMES)):
        r = reps[:, s][np.isfinite(reps[:, s])]
        # A statistic undefined in more than 1 % of the resamples gets no interval.
        if r.size >= 0.99 * n_boot:
            lo, mid, hi = np.quantile(r, [alpha, 0.5, 1.0 - alpha])
            if STAT_NAMES[s] in RECENTRED:
                est = ksg_core_bits(xp, yp)  # RECENTRED holds only the MI
                lo, hi = est + lo - mid, est + hi - mid
            out[s] = lo, hi
    return out


def _shift_p(obs, null, two_sided):
    """p = (1 + #{null >= observed}) / (1 + shifts) per column; |.| first when two-sided."""
    obs = np.abs(obs) if two_sided else obs
    null = np.abs(null) if two_sided else null
    # A hair of tolerance so that a shift giving the same value up to rounding counts as >=.
    ge = null >= obs - 1e-12 * np.maximum(1.0, np.abs(obs))
    p = (1.0 + ge.sum(axis=0)) / (1.0 + null.shape[0])
    return np.where(np.isfinite(obs), p, math.nan)


def circular_shifts(n, min_shift):
    """The shifts of the permutation test: min_shift <= s <= n - min_shift."""
    return np.arange(min_shift, n - min_shift + 1)


def circular_shift_pvalue(stat, x, y, min_shift, two_sided=True):
    """Circular-shift permutation p-value of one statistic stat(x, y) (shift_pvalues explains)."""
    null = np.array([[stat(x, np.roll(y, s))] for s in circular_shifts(len(x), min_shift)])
    return float(_shift_p(np.array([stat(x, y)]), null.reshape(-1, 1), two_sided)[0]) if len(null) else math.nan


def shift_null(x, y, min_shift, seed):
    """The four statistics of x, y (4,) and of x against every circular shift s of y with
    min_shift <= s <= n - min_shift ((n_shifts, 4); empty when there is none)."""
    xp, yp = ksg_prepare(x, y, seed)
    obs = all_stats_prepared(x, y, xp, yp)
    shifts = circular_shifts(len(x), min_shift)
    null = np.array([all_stats_prepared(x, np.roll(y, s), xp, np.roll(yp, s)) for s in shifts]).reshape(-1, 4)
    return obs, null


def null_pvalues(obs, null):
    """p-values of the four statistics against null draws (n, 4): correlations two-sided (|stat|),
    MI one-sided (larger = more dependence); p = (1 + #{null >= observed}) / (1 + n)."""
    if len(null) == 0:
        return np.full(len(STAT_NAMES), math.nan)
    return np.r_[_shift_p(obs[:3], null[:, :3], True), _shift_p(obs[3:], null[:, 3:], False)]


def mi_null_quantiles(null_mi):
    """(median, 95 % quantile) of the MI under the null; nan when undefined."""
    v = np.asarray(null_mi, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return math.nan, math.nan
    med, q95 = np.quantile(v, [0.5, 0.95])
    return float(med), float(q95)


def shift_pvalues(x, y, min_shift, seed):
    """Circular-shift permutation p-values of the four statistics, and the number of shifts.

    Every circular shift s of y with min_shift <= s <= n - min_shift is one draw of the null:
    it keeps both series' autocorrelation and breaks only their alignment. All shifts are used
    (no randomness). Correlations are two-sided (|stat|), MI one-sided (larger = more
    dependence). p = (1 + #{null >= observed}) / (1 + shifts), so p >= 1 / (1 + shifts)."""
    obs, null = shift_null(x, y, min_shift, seed)
    return null_pvalues(obs, null), len(null)
