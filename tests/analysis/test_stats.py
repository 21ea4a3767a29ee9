"""Table 2's statistics against independent computations on fixtures with known answers."""

import math
import unittest

import numpy as np
from scipy import stats as sps
from sklearn.feature_selection import mutual_info_regression

import run_fixture  # noqa: F401  (puts toolchain/analysis on sys.path)
from nao_analysis import AnalysisError
from nao_analysis import stats


def gaussian_pair(n, rho, seed):
    z = np.random.default_rng(seed).multivariate_normal([0, 0], [[1, rho], [rho, 1]], size=n)
    return z[:, 0], z[:, 1]


def ar1(n, phi, rng, burn=200):
    e = rng.standard_normal(n + burn)
    x = np.zeros(n + burn)
    for i in range(1, n + burn):
        x[i] = phi * x[i - 1] + e[i]
    return x[burn:]


class Correlations(unittest.TestCase):
    def test_a_perfectly_monotone_pair_has_rho_and_tau_exactly_one(self):
        x = np.linspace(-2, 3, 200)
        y = np.exp(2 * x)  # monotone, far from linear
        self.assertEqual(stats.spearman(x, y), 1.0)
        self.assertEqual(stats.kendall_tau_b(x, y), 1.0)
        self.assertEqual(stats.spearman(x, -y), -1.0)
        self.assertEqual(stats.kendall_tau_b(x, -y), -1.0)
        self.assertLess(stats.pearson(x, y), 0.8, "Pearson r of an exponential should be well below 1")

    def test_average_ranks_match_scipy_rankdata_with_ties(self):
        x = np.random.default_rng(1).integers(0, 12, 300).astype(float)
        np.testing.assert_array_equal(stats.rankdata_average(x), sps.rankdata(x, method="average"))

    def test_pearson_spearman_kendall_match_scipy_with_and_without_ties(self):
        rng = np.random.default_rng(2)
        x = rng.standard_normal(150)
        y = 0.4 * x + rng.standard_normal(150)
        for a, b in ((x, y), (np.round(x, 1), np.round(y, 1))):
            self.assertAlmostEqual(stats.pearson(a, b), sps.pearsonr(a, b)[0], places=12)
            self.assertAlmostEqual(stats.spearman(a, b), sps.spearmanr(a, b)[0], places=12)
            self.assertAlmostEqual(stats.kendall_tau_b(a, b), sps.kendalltau(a, b, variant="b")[0], places=12)

    def test_a_constant_series_gives_nan_not_a_number_that_looks_valid(self):
        x = np.arange(50.0)
        c = np.full(50, 3.0)
        for f in (stats.pearson, stats.spearman, stats.kendall_tau_b, stats.ksg_mi_bits):
            self.assertTrue(math.isnan(f(x, c)), f.__name__)


class MutualInformation(unittest.TestCase):
    def test_ksg_matches_the_bivariate_gaussian_closed_form_within_0_1_bit(self):
        for i, rho in enumerate((0.0, 0.3, 0.6, 0.9)):
            x, y = gaussian_pair(2000, rho, seed=10 + i)
            exact = -0.5 * math.log2(1 - rho * rho)
            mi = stats.ksg_mi_bits(x, y)
            self.assertLess(abs(mi - exact), 0.1, "rho %.1f: KSG %.3f bits, closed form %.3f" % (rho, mi, exact))

    def test_ksg_agrees_with_scikit_learn_mutual_info_regression(self):
        # The same estimator (KSG 1, k = 3, standardised, max-norm), implemented independently;
        # scikit-learn answers in nats and clips at 0.
        for i, rho in enumerate((0.0, 0.4, 0.6, 0.8)):
            x, y = gaussian_pair(1000, rho, seed=20 + i)
            sk = mutual_info_regression(x[:, None], y, n_neighbors=3, random_state=0)[0] / math.log(2)
            self.assertAlmostEqual(max(0.0, stats.ksg_mi_bits(x, y)), sk, delta=1e-3)

    def test_independent_noise_has_mi_near_zero_and_no_significant_statistic(self):
        rng = np.random.default_rng(30)
        x = rng.standard_normal(300)
        y = rng.standard_normal(300)
        self.assertLess(abs(stats.pearson(x, y)), 0.15)
        self.assertLess(abs(stats.spearman(x, y)), 0.15)
        self.assertLess(abs(stats.kendall_tau_b(x, y)), 0.1)
        self.assertLess(abs(stats.ksg_mi_bits(x, y)), 0.08, "KSG bias for n = 300 is a few hundredths of a bit")
        b = stats.pair_block_length(x, y)
        self.assertLessEqual(b, 3, "white noise needs no long blocks")
        mi, null = stats.mi_shift_null(x, y, b, seed=1)
        self.assertGreater(len(null), 250)
        point = np.r_[stats.pearson(x, y), stats.spearman(x, y), stats.kendall_tau_b(x, y), mi]
        res = stats.row_result(point, stats.bootstrap_correlations(x, y, b, 400, 1), null)
        for name, pv in zip(stats.STAT_NAMES, res["p"]):
            self.assertGreater(pv, 0.05, "%s: p %.3f for independent noise" % (name, pv))

    def test_ksg_reads_smoothness_as_information_which_is_why_mi_needs_the_shift_test(self):
        # docs/reproduction.md quotes this bias: independent AR(1) pairs, phi 0.9, n 120.
        rng = np.random.default_rng(35)
        mi = [stats.ksg_mi_bits(ar1(120, 0.9, rng), ar1(120, 0.9, rng)) for _ in range(80)]
        self.assertGreater(np.mean(mi), 0.1, "mean KSG of independent smooth series: %.3f bit" % np.mean(mi))
        self.assertLess(np.mean(mi), 0.3)

class TrendRemoval(unittest.TestCase):
    t = 0.1 * np.arange(120)

    def test_linear_removes_a_line_exactly_and_keeps_the_oscillation(self):
        wave = np.sin(2 * np.pi * 0.5 * self.t)
        out = stats.detrend(self.t, 3.0 + 0.7 * self.t + wave, "linear")
        np.testing.assert_allclose(stats.detrend(self.t, 3.0 + 0.7 * self.t, "linear"), 0, atol=1e-12)
        self.assertGreater(stats.pearson(out, wave), 0.99)

    def test_linear_fits_time_not_the_sample_index_where_ticks_were_dropped(self):
        t = np.r_[self.t[:40], self.t[80:]]
        np.testing.assert_allclose(stats.detrend(t, 2.0 - 0.5 * t, "linear"), 0, atol=1e-12)

    def test_highpass_removes_a_slow_drift_and_keeps_a_1_hz_wave(self):
        wave = np.sin(2 * np.pi * 1.0 * self.t)
        out = stats.detrend(self.t, wave + 0.3 * self.t, "highpass:0.1")
        self.assertLess(np.abs(out - wave)[20:-20].max(), 0.1)

    def test_none_returns_the_series_and_bad_methods_are_refused(self):
        x = np.random.default_rng(0).standard_normal(120)
        np.testing.assert_array_equal(stats.detrend(self.t, x, "none"), x)
        for bad in ("quadratic", "highpass:abc", "highpass:-1", "linear:2"):
            with self.assertRaises(AnalysisError):
                stats.parse_detrend(bad)
        with self.assertRaises(AnalysisError):
            stats.detrend(self.t, x, "highpass:6")  # above Nyquist (5 Hz)


class Resampling(unittest.TestCase):
    def test_politis_white_block_length_follows_the_ar1_optimum(self):
        # For AR(1) the circular bootstrap's optimal block is (6 phi^2 / (1 - phi^2)^2)^(1/3) n^(1/3).
        rng = np.random.default_rng(50)
        n = 5000
        for phi in (0.5, 0.7):
            exact = (6 * phi ** 2 / (1 - phi ** 2) ** 2) ** (1 / 3) * n ** (1 / 3)
            b = stats.block_length_pw(ar1(n, phi, rng))
            self.assertLess(abs(b / exact - 1), 0.35, "phi %.1f: block %.1f, optimum %.1f" % (phi, b, exact))

    def test_circular_blocks_are_runs_of_consecutive_ticks(self):
        idx = stats.circular_block_indices(50, 7, np.random.default_rng(0))
        self.assertEqual(len(idx), 50)
        steps = np.diff(idx)[np.arange(49) % 7 != 6]  # inside a block
        self.assertTrue(np.all((steps == 1) | (steps == -49)), "a block must step by one tick, wrapping")

    def test_bootstrap_interval_covers_the_true_correlation_with_the_right_width(self):
        x, y = gaussian_pair(250, 0.5, seed=60)
        reps = stats.bootstrap_correlations(x, y, 1, 400, seed=1)
        lo, hi = stats.percentile_interval(reps[:, 0])
        self.assertLess(lo, 0.5)
        self.assertGreater(hi, 0.5)
        width = 2 * 1.96 * (1 - 0.25) / math.sqrt(250)  # normal approximation of r's spread
        self.assertLess(abs((hi - lo) / width - 1), 0.3)
        for s, est in enumerate((stats.pearson(x, y), stats.spearman(x, y), stats.kendall_tau_b(x, y))):
            lo, hi = stats.percentile_interval(reps[:, s])
            self.assertTrue(lo <= est <= hi, "%s estimate outside its interval" % stats.STAT_NAMES[s])

    def test_bootstrap_and_shift_null_are_deterministic(self):
        x, y = gaussian_pair(120, 0.3, seed=70)
        np.testing.assert_array_equal(stats.bootstrap_correlations(x, y, 5, 200, 9),
                                      stats.bootstrap_correlations(x, y, 5, 200, 9))
        np.testing.assert_array_equal(stats.mi_shift_null(x, y, 5, 9)[1], stats.mi_shift_null(x, y, 5, 9)[1])

    def test_a_strong_dependence_gets_the_smallest_p_values(self):
        rng = np.random.default_rng(80)
        x = ar1(150, 0.8, rng)
        y = x + 0.2 * rng.standard_normal(150)
        b = stats.pair_block_length(x, y)
        mi, null = stats.mi_shift_null(x, y, b, seed=1)
        self.assertEqual(stats.mi_null_pvalue(mi, null), 1.0 / (1 + len(null)))
        reps = stats.bootstrap_correlations(x, y, b, 200, seed=1)
        self.assertTrue((reps > 0).all())
        for s in range(3):
            self.assertEqual(stats.interval_pvalue(reps[:, s]), 1.0 / 201, "the smallest p 200 resamples resolve")

    def test_both_tests_hold_their_level_on_autocorrelated_series_where_an_iid_shuffle_does_not(self):
        # Independent but smooth series. The block bootstrap's p and the MI's circular-shift
        # null keep each series' autocorrelation; a null that shuffles ticks does not, and KSG
        # reads the smoothness it destroys as information.
        rng = np.random.default_rng(90)
        n_pairs, boot_rejects, shift_rejects, iid_rejects = 60, 0, 0, 0
        for k in range(n_pairs):
            x, y = ar1(120, 0.9, rng), ar1(120, 0.9, rng)
            b = stats.pair_block_length(x, y)
            boot_rejects += stats.interval_pvalue(stats.bootstrap_correlations(x, y, b, 400, k)[:, 0]) < 0.05
            mi, null = stats.mi_shift_null(x, y, b, k)
            shift_rejects += stats.mi_null_pvalue(mi, null) < 0.05
            xp, yp = stats.ksg_prepare(x, y, k)
            shuffle = np.random.default_rng(k)
            iid_rejects += stats.mi_null_pvalue(mi, [stats.ksg_core_bits(xp, shuffle.permutation(yp))
                                                     for _ in range(100)]) < 0.05
        self.assertLessEqual(boot_rejects / n_pairs, 0.12, "bootstrap p rejected %d of %d" % (boot_rejects, n_pairs))
        self.assertLessEqual(shift_rejects / n_pairs, 0.12, "shift null rejected %d of %d" % (shift_rejects, n_pairs))
        self.assertGreaterEqual(iid_rejects / n_pairs, 0.25, "iid null rejected only %d of %d" % (iid_rejects, n_pairs))


class PValuesAgreeWithIntervals(unittest.TestCase):
    """A p-value read off the resamples of its interval (stats.interval_pvalue) and the MI's
    null quantile (stats.mi_null_quantiles) on resamples whose answers are known."""

    def test_the_p_value_of_evenly_spread_resamples_is_twice_the_share_below_zero(self):
        # 401 resamples from -1 to 3 in steps of 0.01: 0 is the 100th of 400 gaps, a quarter.
        self.assertAlmostEqual(stats.interval_pvalue(np.linspace(-1, 3, 401)), 0.5, places=12)
        self.assertAlmostEqual(stats.interval_pvalue(-np.linspace(-1, 3, 401)), 0.5, places=12)
        self.assertAlmostEqual(stats.interval_pvalue(np.linspace(-1, 1, 101)), 1.0, places=12)
        # Every resample on one side: the smallest p the resamples resolve.
        self.assertEqual(stats.interval_pvalue(np.linspace(0.1, 1, 100)), 1.0 / 101)
        self.assertTrue(math.isnan(stats.interval_pvalue(np.full(100, math.nan))))

    def test_p_below_one_minus_the_level_exactly_when_the_interval_excludes_zero(self):
        rng = np.random.default_rng(7)
        n_excluded = 0
        for i in range(2000):
            n = int(rng.integers(100, 1200))
            reps = rng.standard_normal(n) * rng.uniform(0.05, 1) + rng.uniform(-2, 2)
            if i % 4 == 0:
                reps = np.round(reps, 1)  # ties, also at 0
            p = stats.interval_pvalue(reps)
            for level in (0.9, 0.95, 0.99):
                lo, hi = stats.percentile_interval(reps, level)
                excluded = lo > 0 or hi < 0
                n_excluded += excluded
                self.assertEqual(p < 1 - level, excluded, "n %d, level %g: [%g, %g] but p %g" % (n, level, lo, hi, p))
        self.assertGreater(n_excluded, 1000, "the cases must include intervals on both sides of 0")

    def test_the_mi_null_quantile_is_the_value_an_mi_must_exceed_for_p_below_0_05(self):
        null = np.arange(200.0)  # (1 + #{null >= mi}) / 201 < 0.05 needs at most 9 draws at or above mi
        med, q95 = stats.mi_null_quantiles(null)
        self.assertEqual((med, q95), (99.5, 190.0))
        self.assertLess(stats.mi_null_pvalue(190.5, null), 0.05)
        self.assertGreaterEqual(stats.mi_null_pvalue(190.0, null), 0.05)
        rng = np.random.default_rng(8)
        for _ in range(500):
            null = rng.gamma(2.0, 0.05, int(rng.integers(19, 400)))
            mi = float(rng.uniform(0, 0.4))
            q95 = stats.mi_null_quantiles(null)[1]
            self.assertEqual(stats.mi_null_pvalue(mi, null) < 0.05, math.isfinite(q95) and mi > q95)
        self.assertTrue(math.isnan(stats.mi_null_quantiles(np.arange(19.0))[1]), "19 draws cannot give p < 0.05")


if __name__ == "__main__":
    unittest.main()
