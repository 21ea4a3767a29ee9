"""toolchain/analysis/code_fidelity.py on an evaluate-shaped directory and a data set written here:
runs whose hand paths are known demonstrations' (distance 0, or the DTW of two known paths by a
plain transcription of the runtime's recurrence), and the errors a user meets."""

import io
import json
import os
import shutil
import tempfile
import unittest
from contextlib import redirect_stderr, redirect_stdout

import numpy as np

import run_fixture  # noqa: F401  (puts toolchain/analysis on the path)
import code_fidelity as cf
from nao_analysis.kinematics import hand_position, load_arm_model
from test_autonomous_ceiling import dtw_mean_reference


def joint_path(n, phase, centre=0.0):
    """(n, 5) a slow circle-like joint motion inside the right arm's limits."""
    t = 0.1 * np.arange(n)[:, None]
    base = np.array([1.0 + centre, -0.4, 0.9, 0.8, 0.2])[None, :]
    amp = np.array([0.25, 0.15, 0.3, 0.2, 0.4])[None, :]
    return base + amp * np.sin(2 * np.pi * 0.35 * t + phase + np.arange(5)[None, :])


def write_csv(path, header, rows):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(",".join(header) + "\n")
        for row in rows:
            fh.write(",".join(repr(float(v)) for v in row) + "\n")


class CodeFidelity(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.mkdtemp(prefix="nao_code_fidelity_")
        self.eval = os.path.join(self.tmp, "eval")
        self.data = os.path.join(self.tmp, "data")
        self.arm = load_arm_model()
        self.train = {"m_001": joint_path(60, 0.0), "m_002": joint_path(55, 1.1, 0.1)}
        for name, f in self.train.items():
            t = 0.1 * np.arange(len(f))[:, None]
            write_csv(os.path.join(self.data, name, "features.csv"), ["t_s", "label", "measured"] + ["f_%d" % j for j in range(5)],
                      np.hstack([t, np.zeros_like(t), np.ones_like(t), f]))
        self.heldout = joint_path(58, 0.4, -0.05)
        write_csv(os.path.join(self.eval, "m", "demos", "m_010.csv"), ["t_s"] + ["q_%d" % j for j in range(5)],
                  np.hstack([0.1 * np.arange(len(self.heldout))[:, None], self.heldout]))

    def tearDown(self):
        shutil.rmtree(self.tmp)

    def write_run(self, run, q, code):
        d = os.path.join(self.eval, "m", "autonomous", run)
        write_csv(os.path.join(d, "ticks.csv"), ["tick"] + ["q_%d" % j for j in range(5)] + ["ee_x", "ee_y", "ee_z"],
                  np.hstack([np.arange(len(q))[:, None], q, hand_position(self.arm, q)]))
        with open(os.path.join(d, "summary.json"), "w", encoding="utf-8") as fh:
            json.dump({} if code is None else {"run_code": code}, fh)

    def test_distances_to_the_named_and_the_nearest_held_out_demonstration(self):
        # Run a plays m_001 exactly; run b plays m_001 too, but its code names m_002.
        self.write_run("a", self.train["m_001"], "m_001")
        self.write_run("b", self.train["m_001"], "m_002")
        r = cf.eval_fidelity(self.eval, self.data)["m"]
        self.assertEqual(r["runs"], 2)
        by = {x["run"]: x for x in r["per_run"]}
        h1, h2, hh = (hand_position(self.arm, q) for q in (self.train["m_001"], self.train["m_002"], self.heldout))
        self.assertAlmostEqual(by["a"]["named_dtw_m"], 0.0, places=12)
        want_b = dtw_mean_reference(h1.tolist(), h2.tolist())
        self.assertGreater(want_b, 0.01)
        self.assertAlmostEqual(by["b"]["named_dtw_m"], want_b, places=9)
        want_h = dtw_mean_reference(h1.tolist(), hh.tolist())
        self.assertAlmostEqual(by["a"]["heldout_dtw_m"], want_h, places=9)
        self.assertAlmostEqual(r["named_dtw_m"], want_b / 2, places=9)  # the median of two
        self.assertIsNone(r["replay_dtw_m"])  # no detail.json

    def test_medoid_replay_read_from_detail_json(self):
        self.write_run("a", self.train["m_001"], "m_001")
        with open(os.path.join(self.eval, "detail.json"), "w", encoding="utf-8") as fh:
            json.dump({"m": {"runs": [{"run_dir": "m/autonomous/a", "medoid_replay_dtw_m": 0.0123}]}}, fh)
        self.assertAlmostEqual(cf.eval_fidelity(self.eval, self.data)["m"]["replay_dtw_m"], 0.0123)

    def run_main(self, *args):
        err, out = io.StringIO(), io.StringIO()
        with redirect_stderr(err), redirect_stdout(out):
            rc = cf.main(["code_fidelity.py", *args])
        return rc, out.getvalue(), err.getvalue()

    def test_cli_table_and_json(self):
        self.write_run("a", self.train["m_001"], "m_001")
        out_json = os.path.join(self.tmp, "f.json")
        rc, out, _ = self.run_main(self.eval, self.data, "--json", out_json)
        self.assertEqual(rc, 0)
        self.assertIn("| m | 1 | 0.0 |", out)
        with open(out_json, encoding="utf-8") as fh:
            self.assertEqual(json.load(fh)["m"]["per_run"][0]["run_code"], "m_001")

    def test_errors_name_the_problem(self):
        self.write_run("a", self.train["m_001"], None)
        rc, _, err = self.run_main(self.eval, self.data)
        self.assertEqual(rc, 1)
        self.assertIn("no run_code", err)
        self.write_run("a", self.train["m_001"], "m_099")
        rc, _, err = self.run_main(self.eval, self.data)
        self.assertEqual(rc, 1)
        self.assertIn("m_099", err)
        rc, _, err = self.run_main(os.path.join(self.tmp, "nowhere"), self.data)
        self.assertEqual(rc, 1)
        self.assertIn("no <movement>/autonomous/", err)


if __name__ == "__main__":
    unittest.main()
