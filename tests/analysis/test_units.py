"""Distinct rollouts as the resampling unit (nao_analysis/units.py, protocol.unit_statistics):
near-copies of a few independent series no longer look like evidence of dependence, a planted
dependence still does, and the DTW that groups them is nao_rt's."""

import math
import os
import shutil
import tempfile
import unittest

import numpy as np

import run_fixture
from nao_analysis import JOINT_NAMES, protocol, units
from nao_analysis.rundir import read_run
from test_autonomous_ceiling import dtw_mean_reference  # rt::dtwMeanDistance cell by cell

PLANTED = 3  # RElbowRoll


class Dtw(unittest.TestCase):
    def test_dtw_equals_the_cell_by_cell_runtime_loop_on_random_paths_to_the_last_bit(self):
        rng = np.random.default_rng(1)
        for n, m in ((1, 1), (1, 7), (9, 4), (23, 31)):
            a, b = rng.standard_normal((n, 3)), rng.standard_normal((m, 3))
            self.assertEqual(units.dtw_mean_distance(a, b), dtw_mean_reference(a, b), "%dx%d" % (n, m))

    def test_dtw_of_a_copy_is_zero_of_a_shifted_copy_its_shift_and_of_a_time_warped_copy_zero(self):
        t = np.linspace(0, 2 * np.pi, 60)
        a = np.column_stack([np.cos(t), np.sin(t), 0 * t]) * 0.05
        self.assertEqual(units.dtw_mean_distance(a, a), 0.0)
        # Shifted off the path's plane, no alignment brings a pair closer than the shift.
        self.assertAlmostEqual(units.dtw_mean_distance(a, a + [0.0, 0.0, 0.005]), 0.005, places=12)
        warped = np.repeat(a, [1 + (i % 3 == 0) for i in range(60)], axis=0)
        self.assertEqual(units.dtw_mean_distance(a, warped), 0.0)
        self.assertTrue(math.isnan(units.dtw_mean_distance(a[:0], a)))

    def test_a_run_repeating_the_beginning_of_another_joins_its_unit(self):
        t = np.linspace(0, 4, 150)
        a = 0.05 * np.column_stack([np.cos(t), np.sin(t), 0 * t])
        b = a + [0.0, 0.0, 0.02]
        groups, dist = units.group_units([a, b[:120], a[:100], b, a[:140]])
        self.assertEqual(groups, [[0, 2, 4], [1, 3]])
        self.assertEqual(dist[0, 2], 0.0)
        self.assertGreater(dist[0, 1], 0.01)


def single_linkage_groups(dist, threshold):
    """The transitive grouping complete linkage replaces (union-find: a pair closer than the
    threshold joins their groups), written here as the contrast."""
    parent = list(range(len(dist)))

    def root(i):
        while parent[i] != i:
            i = parent[i]
        return i

    for i in range(len(dist)):
        for k in range(i + 1, len(dist)):
            if dist[i, k] < threshold:
                parent[root(k)] = root(i)
    found = {}
    for i in range(len(dist)):
        found.setdefault(root(i), []).append(i)
    return sorted(found.values(), key=lambda g: g[0])


class CompleteLinkage(unittest.TestCase):
    def test_a_chain_of_near_neighbours_does_not_join_runs_farther_apart_than_the_threshold(self):
        # Hand paths 0, 0.8 and 1.6 mm apart along z: neighbours within 1 mm, the ends 1.6 mm apart.
        t = np.linspace(0, 4, 120)
        a = 0.05 * np.column_stack([np.cos(t), np.sin(t), 0 * t])
        paths = [a + [0.0, 0.0, dz] for dz in (0.0, 0.8e-3, 1.6e-3)]
        groups, dist = units.group_units(paths, 1e-3)
        np.testing.assert_allclose([dist[0, 1], dist[1, 2], dist[0, 2]], [0.8e-3, 0.8e-3, 1.6e-3], rtol=1e-9)
        self.assertEqual(single_linkage_groups(dist, 1e-3), [[0, 1, 2]], "the chain joins all three")
        self.assertEqual(groups, [[0, 1], [2]])
        self.assertEqual(units.group_units(paths, 2e-3)[0], [[0, 1, 2]])
        self.assertEqual(units.group_units(paths, 0.5e-3)[0], [[0], [1], [2]])

    def test_two_runs_of_one_unit_are_never_farther_apart_than_the_threshold(self):
        # A transitive grouping can hold a pair farther apart than the nearest pair of different
        # units (1.025 against 1.003 mm); complete linkage cannot hold one beyond the threshold.
        dist = np.array([[0, 0.98, 1.025, 1.4],
                         [0.98, 0, 0.95, 1.003],
                         [1.025, 0.95, 0, 1.5],
                         [1.4, 1.003, 1.5, 0]]) * 1e-3
        self.assertEqual(single_linkage_groups(dist, 1e-3), [[0, 1, 2], [3]], "0 and 2 joined through 1")
        self.assertEqual(units.complete_linkage_groups(dist, 1e-3), [[0], [1, 2], [3]])
        rng = np.random.default_rng(11)
        for _ in range(200):
            n = int(rng.integers(2, 14))
            pts = rng.uniform(0, 3e-3, (n, 2))
            dist = np.sqrt(((pts[:, None] - pts[None]) ** 2).sum(axis=-1))
            groups = units.complete_linkage_groups(dist, 1e-3)
            self.assertEqual(sorted(i for g in groups for i in g), list(range(n)))
            for g in groups:
                self.assertLess(dist[np.ix_(g, g)].max(), 1e-3)
            # Each group lies inside one transitive group: complete linkage only splits.
            single = single_linkage_groups(dist, 1e-3)
            for g in groups:
                self.assertTrue(any(set(g) <= set(h) for h in single))

    def test_near_copies_are_one_unit_at_every_threshold(self):
        runs = [read_run(p) for p in run_fixture.write_near_copy_runs(tempfile.mkdtemp(prefix="nao-units-th-"),
                                                                      "elbow", seed=104, n_runs=6)]
        try:
            found = units.distinct_units(runs, units.ROBUSTNESS_DTW_M)
            self.assertEqual(sorted(found), sorted(units.ROBUSTNESS_DTW_M))
            self.assertEqual({len(found[t][0]) for t in found}, {3}, "copies at 0, others centimetres apart")
        finally:
            shutil.rmtree(os.path.dirname(runs[0].path))


class NearCopies(unittest.TestCase):
    """3 independent AR(1) rollouts cut into 16 runs, as nao_rt's runs from nearby starts can
    repeat one rollout. Taken as 16 independent runs: KSG MI 0.61-1.77 bits with the smallest
    possible p in 25 of 25 rows, and |r| called significant in 9 of 25 (5 generator seeds)."""

    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.mkdtemp(prefix="nao-units-")
        cls.runs = [read_run(p) for p in run_fixture.write_near_copy_runs(os.path.join(cls.tmp, "null"), "elbow",
                                                                          seed=104)]
        cls.planted = [read_run(p) for p in run_fixture.write_near_copy_runs(
            os.path.join(cls.tmp, "planted"), "elbow", seed=105, planted_joint=PLANTED)]
        found, cls.separation = protocol.movement_units(cls.runs)
        cls.units = found["elbow"]
        cls.rows = protocol.pooled_rows(cls.units, "elbow", "linear", 100, 1)

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.tmp)

    def test_sixteen_near_copies_of_three_series_are_three_units(self):
        self.assertEqual(len(self.runs), 16)
        self.assertEqual(len(self.units), 3)
        self.assertEqual(sorted(len(u) for u in self.units), [5, 5, 6])
        for u in self.units:
            self.assertEqual(u[0].n_ticks, max(r.n_ticks for r in u), "a unit's representative is its longest run")
        self.assertEqual(self.separation["elbow"]["max_dtw_within_unit_m"], 0.0)
        self.assertGreater(self.separation["elbow"]["min_dtw_between_units_m"], 10 * units.UNIT_DTW_M)
        self.assertEqual({(r["n_runs"], r["n_units"]) for r in self.rows}, {(16, 3)})

    def test_independent_near_copies_give_no_mi_above_its_null_and_no_significant_correlation(self):
        above = [r["joint"] for r in self.rows if r["mi_above_null"]]
        self.assertLessEqual(len(above), 1, "MI above the null's 95 %% quantile for %s" % above)
        for r in self.rows:
            self.assertLess(r["mi_bits"], 0.3, "%s: MI %.2f bits from independent series" % (r["joint"], r["mi_bits"]))
            self.assertLess(abs(r["mi_excess"]), 0.2, r["joint"])
        sig = [r["joint"] for r in self.rows if r["pearson_r_p"] < 0.05 or r["spearman_rho_p"] < 0.05]
        self.assertLessEqual(len(sig), 1, "significant correlations between independent series: %s" % sig)

    def test_the_same_runs_taken_as_independent_units_fake_the_dependence(self):
        # The contrast that shows what the units fix: every run its own unit (near-copies as
        # independent evidence) puts the MI far above its null.
        xs, ys = zip(*(protocol._run_series(r, 0, "linear", "att") for r in self.runs))
        res = protocol.unit_statistics(list(xs), list(ys), 0, 1)  # the point and the null, no interval
        self.assertGreater(res["point"][3], res["mi_null_q95"] + 0.2,
                           "runs as units: MI %.2f, null q95 %.2f" % (res["point"][3], res["mi_null_q95"]))

    def test_a_planted_dependence_among_near_copies_is_still_found(self):
        units_, _ = protocol.movement_units(self.planted)
        rows = protocol.pooled_rows(units_["elbow"], "elbow", "linear", 100, 1)
        r = rows[PLANTED]
        self.assertEqual(r["n_units"], 3)
        self.assertGreater(r["spearman_rho"], 0.5)
        self.assertGreater(r["spearman_rho_ci_lo"], 0.0)
        self.assertLess(r["pearson_r_p"], 0.05)
        self.assertEqual(r["mi_above_null"], 1, "planted MI %.2f, null q95 %.2f" % (r["mi_bits"], r["mi_null_q95"]))
        for other in rows:
            if other["joint"] != JOINT_NAMES[PLANTED]:
                self.assertLess(abs(other["spearman_rho"]), 0.4, other["joint"])


class UnitStatisticsOverSeeds(unittest.TestCase):
    def test_three_independent_pairs_are_rarely_significant_over_ten_generator_seeds(self):
        # The test's own generator: per seed three independent AR(1) pairs (phi 0.9, 100-150
        # ticks) as three units. A calibrated 5 % test rejects about 0.5 of 10.
        counts = {"p_r": 0, "ci_r": 0, "mi": 0}
        for seed in range(10):
            rng = np.random.default_rng(1000 + seed)
            lengths = rng.integers(100, 151, 3)
            xs = [run_fixture.ar1(int(n), 0.9, rng) for n in lengths]
            ys = [run_fixture.ar1(int(n), 0.9, rng) for n in lengths]
            res = protocol.unit_statistics(xs, ys, 100, seed, n_perm=100)
            counts["p_r"] += res["p"][0] < 0.05
            counts["ci_r"] += res["ci_lo"][0] > 0 or res["ci_hi"][0] < 0
            counts["mi"] += res["point"][3] > res["mi_null_q95"]
        for k, v in counts.items():
            self.assertLessEqual(v, 3, "%s: significant in %d of 10 seeds of independent series" % (k, v))

    def test_one_unit_gets_no_interval_and_no_p_value_rather_than_a_zero_width_one(self):
        rng = np.random.default_rng(3)
        x = run_fixture.ar1(120, 0.9, rng)
        res = protocol.unit_statistics([x], [x + rng.standard_normal(120)], 100, 1)
        self.assertTrue(np.isnan(res["ci_lo"]).all() and np.isnan(res["ci_hi"]).all())
        self.assertTrue(np.isnan(res["p"][:3]).all(), "a correlation's p-value comes from its interval")
        self.assertLess(res["p"][3], 0.05, "the MI's shift null still runs on one unit")
        self.assertGreater(res["point"][3], res["mi_null_q95"])

    def test_every_p_value_agrees_with_its_interval_over_units(self):
        # Pairs with a weak planted dependence, so that intervals fall on both sides of 0.
        agree = excluded = 0
        for seed in range(12):
            rng = np.random.default_rng(2000 + seed)
            xs, ys = [], []
            for n in rng.integers(80, 140, 4):
                x = run_fixture.ar1(int(n), 0.8, rng)
                xs.append(x)
                ys.append(0.25 * x + run_fixture.ar1(int(n), 0.8, rng))
            res = protocol.unit_statistics(xs, ys, 200, seed, n_perm=50)
            for s in range(3):
                out = res["ci_lo"][s] > 0 or res["ci_hi"][s] < 0
                excluded += out
                agree += (res["p"][s] < 0.05) == out
        self.assertEqual(agree, 36)
        self.assertGreater(excluded, 3)
        self.assertLess(excluded, 33)


if __name__ == "__main__":
    unittest.main()
