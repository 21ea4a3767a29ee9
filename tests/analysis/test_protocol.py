"""The paper's protocol in the analysis (nao_analysis/protocol.py): several runs per movement pooled
with the distinct rollout as the resampling unit, and the attention offsets."""

import argparse
import os
import shutil
import tempfile
import unittest

import numpy as np
import scipy.stats

import run_fixture
from nao_analysis import JOINT_NAMES, cli, protocol, stats, units
from nao_analysis.rundir import read_run

PLANTED = 3  # RElbowRoll: its score follows its velocity in the fixtures


class ProtocolTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.mkdtemp(prefix="nao_protocol_")
        cls.runs = [read_run(run_fixture.write_run(os.path.join(cls.tmp, "elbow_%d" % i), "elbow", n=60, seed=i,
                                                   planted_joint=PLANTED)) for i in range(4)]

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.tmp, ignore_errors=True)

    def test_several_runs_of_a_movement_switch_to_the_pooled_protocol(self):
        self.assertTrue(protocol.is_protocol(self.runs))
        self.assertFalse(protocol.is_protocol(self.runs[:1]))

    def test_pooled_rows_find_the_planted_joint_with_unit_bootstrap_intervals(self):
        units, _ = protocol.movement_units(self.runs)
        self.assertEqual(len(units["elbow"]), 4, "four fixture runs with four different paths are four units")
        rows = protocol.pooled_rows(units["elbow"], "elbow", "linear", 100, 1)
        self.assertEqual([r["joint"] for r in rows], list(JOINT_NAMES))
        planted = rows[PLANTED]
        self.assertEqual(planted["run"], "pooled:4")
        self.assertEqual((planted["n_runs"], planted["n_units"]), (4, 4))
        self.assertEqual(planted["n_ticks"], 4 * 60)
        self.assertEqual(planted["mi_above_null"], 1)
        self.assertGreater(planted["mi_excess"], 0.5)
        self.assertGreater(planted["pearson_r_ci_lo"], 0.0)
        self.assertLess(planted["pearson_r_p"], 0.05)
        for r in rows:
            for s in stats.STAT_NAMES[:3]:
                self.assertLessEqual(r[s + "_ci_lo"], r[s + "_ci_hi"])
                self.assertEqual(r[s + "_p"] < 0.05, r[s + "_ci_lo"] > 0 or r[s + "_ci_hi"] < 0, (r["joint"], s))
            self.assertTrue(np.isnan(r["mi_bits_ci_lo"]), "the MI is judged by its null, not an interval")
            self.assertEqual(r["mi_above_null"], int(r["mi_bits_p"] < 0.05))
        # Deterministic: the same runs give the same rows.
        # (repr: the MI's interval is nan, which no nan equals.)
        self.assertEqual(repr(rows), repr(protocol.pooled_rows(units["elbow"], "elbow", "linear", 100, 1)))

    def test_pooled_kendall_is_the_own_tau_b(self):
        x = np.random.default_rng(3).standard_normal(150)
        y = x + np.random.default_rng(4).standard_normal(150)
        self.assertAlmostEqual(scipy.stats.kendalltau(x, y, variant="b").statistic, stats.kendall_tau_b(x, y), 12)

    def test_offsets_are_shares_of_ticks(self):
        share, mean, total = protocol.attention_offsets(self.runs)
        self.assertAlmostEqual(float(share.sum()), 1.0, 12)
        self.assertEqual(total, 4 * 60)


class Robustness(unittest.TestCase):
    """What --table-json --robustness adds: the groupings at every threshold and Table 2 under
    the other choices."""

    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.mkdtemp(prefix="nao_robust_")
        paths = [run_fixture.write_run(os.path.join(cls.tmp, "elbow_%d" % i), "elbow", n=60, seed=i,
                                       planted_joint=PLANTED) for i in range(3)]
        t, q, att = run_fixture.make_series(60, 0, PLANTED)
        # A fourth run repeating the first one's beginning: one unit with it at every threshold.
        paths.append(run_fixture.write_run(os.path.join(cls.tmp, "elbow_3"), "elbow", seed=0,
                                           series=(t[:45], q[:45], att[:45])))
        cls.runs = [read_run(p) for p in paths]
        cls.groups = protocol.group_runs(cls.runs)
        cls.groupings = protocol.movement_groupings(cls.runs, units.ROBUSTNESS_DTW_M)
        cls.units = {m: g[units.UNIT_DTW_M][0] for m, g in cls.groupings.items()}
        cls.args = argparse.Namespace(detrend="linear", bootstrap=100, seed=1)
        cls.rows = protocol.pooled_rows(cls.units["elbow"], "elbow", "linear", 100, 1)
        cls.variants = cli.robustness_variants(cls.args, cls.groupings, cls.rows)

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.tmp, ignore_errors=True)

    def test_the_groupings_of_every_threshold_hold_every_run_once(self):
        separation = {m: g[units.UNIT_DTW_M][1] for m, g in self.groupings.items()}
        e = cli.movements_json(self.groups, self.units, separation, self.groupings)["elbow"]
        self.assertEqual((e["n_runs"], e["n_units"]), (4, 3))
        self.assertEqual(e["units"], [["elbow_0", "elbow_3"], ["elbow_1"], ["elbow_2"]], "the longest run first")
        self.assertEqual([g["unit_dtw_m"] for g in e["groupings"]], list(units.ROBUSTNESS_DTW_M))
        for g in e["groupings"]:
            self.assertEqual(g["units"], e["units"])
            self.assertEqual(g["max_dtw_within_unit_m"], 0.0)

    def test_table2_under_the_other_thresholds_and_trend_removals(self):
        self.assertEqual([(v["unit_dtw_m"], v["detrend"]) for v in self.variants],
                         [(0.0005, "linear"), (0.002, "linear"), (0.001, "highpass"), (0.001, "none")])
        for v in self.variants:
            rows = v["table2"]["att"]
            self.assertEqual([r["joint"] for r in rows], list(JOINT_NAMES))
            self.assertEqual({r["detrend"] for r in rows}, {v["detrend"]})
            if v["detrend"] == "linear":
                self.assertIs(rows[0], self.rows[0], "units unchanged by the threshold: the same rows")
            else:
                self.assertNotEqual(rows[PLANTED]["pearson_r"], self.rows[PLANTED]["pearson_r"])
                self.assertGreater(rows[PLANTED]["pearson_r_ci_lo"], 0.0, "the planted joint under any trend removal")


if __name__ == "__main__":
    unittest.main()
