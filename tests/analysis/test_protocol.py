"""The paper's protocol in the analysis (nao_analysis/protocol.py): several runs per movement pooled
with the distinct rollout as the resampling unit, and the attention offsets."""

import os
import shutil
import tempfile
import unittest

import numpy as np
import scipy.stats

import run_fixture
from nao_analysis import JOINT_NAMES, protocol, stats
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


if __name__ == "__main__":
    unittest.main()
