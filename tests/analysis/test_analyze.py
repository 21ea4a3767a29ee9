"""End to end: `analyze.py` on two small run directories written in the documented formats
gives every output file, a Table 2 with the contract's columns and the planted dependence,
and a self-contained report; the same input gives the same bytes."""

import csv
import filecmp
import json
import os
import re
import shutil
import subprocess
import tempfile
import unittest

import numpy as np

import run_fixture
from nao_analysis import figures, stats
from nao_analysis.rundir import read_run
from nao_analysis.table2 import table2_csv, table2_rows

ANALYZE = os.path.join(run_fixture.ANALYSIS, "analyze.py")
CONTRACT = ["movement", "joint", "pearson_r", "spearman_rho", "kendall_tau", "mi_bits"]
MOVEMENTS = ("whole_arm", "wrist")
PLANTED = 3  # RElbowRoll: its score follows its velocity in the fixtures


class EndToEnd(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.mkdtemp(prefix="nao-analysis-e2e-")
        cls.runs = [run_fixture.write_run(os.path.join(cls.tmp, m), m, n=60, seed=i, planted_joint=PLANTED)
                    for i, m in enumerate(MOVEMENTS)]
        cls.out = os.path.join(cls.tmp, "out")
        cls.json = os.path.join(cls.tmp, "seed_7.json")
        cls.proc = subprocess.run(["/usr/bin/python3", ANALYZE, "--bootstrap", "100", "--out", cls.out,
                                   "--training-seed", "7", "--table-json", cls.json] + cls.runs,
                                  capture_output=True, text=True, timeout=600)

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.tmp)

    def test_the_command_succeeds_and_reports_progress_on_stderr(self):
        self.assertEqual(self.proc.returncode, 0, self.proc.stderr)
        self.assertIn("UMAP", self.proc.stderr)
        self.assertIn(self.out, self.proc.stdout)

    def test_every_output_file_exists(self):
        names = ["table2.csv", "table2.md", "findings.md", "report.html", "fig_umap.png", "fig_umap.svg"]
        for m in MOVEMENTS:
            for kind in ("ee", "attention", "motion"):
                names += ["fig_%s_%s.png" % (kind, m), "fig_%s_%s.svg" % (kind, m)]
        for name in names:
            path = os.path.join(self.out, name)
            self.assertTrue(os.path.isfile(path) and os.path.getsize(path) > 0, "missing or empty: %s" % name)

    def test_table2_has_the_contract_columns_and_five_rows_per_movement(self):
        with open(os.path.join(self.out, "table2.csv")) as f:
            rows = list(csv.reader(f))
        header = rows[0]
        self.assertEqual(header[:6], CONTRACT)
        for s in stats.STAT_NAMES:
            for extra in (s + "_ci_lo", s + "_ci_hi", s + "_p"):
                self.assertIn(extra, header)
        body = [dict(zip(header, r)) for r in rows[1:]]
        for m in MOVEMENTS:
            joints = [r["joint"] for r in body if r["movement"] == m]
            self.assertEqual(joints, list(run_fixture.JOINTS), "rows of %s" % m)
        for r in body:
            for s in CONTRACT[2:]:
                float(r[s])  # every statistic is a number

    def test_the_planted_dependence_is_found_and_significant(self):
        with open(os.path.join(self.out, "table2.csv")) as f:
            rows = list(csv.DictReader(f))
        for r in rows:
            planted = r["joint"] == run_fixture.JOINTS[PLANTED]
            if planted:
                self.assertGreater(float(r["pearson_r"]), 0.9, r)
                self.assertGreater(float(r["mi_bits"]), 1.0, r)
                for s in stats.STAT_NAMES:
                    self.assertLess(float(r[s + "_p"]), 0.05, "%s %s" % (r["movement"], s))
                for s in stats.STAT_NAMES[:3]:
                    self.assertLess(float(r[s + "_ci_lo"]), float(r[s]))
                    self.assertGreater(float(r[s + "_ci_hi"]), float(r[s]))
                self.assertEqual(r["mi_bits_ci_lo"], "nan", "the MI is judged by its null, not an interval")
                self.assertEqual(r["mi_above_null"], "1")
            else:
                self.assertLess(abs(float(r["pearson_r"])), 0.5, r)

    def test_the_table_json_has_every_row_with_its_mi_null_and_units(self):
        with open(self.json) as f:
            doc = json.load(f)
        self.assertEqual(doc["schema"], "nao-table2/2")
        self.assertEqual(doc["method"]["p_values"], "bootstrap interval")
        self.assertEqual(doc["variants"], [], "single runs: no groupings to vary")
        self.assertEqual(doc["training_seed"], 7)
        self.assertEqual(sorted(doc["movements"]), sorted(MOVEMENTS))
        for m in MOVEMENTS:
            self.assertEqual((doc["movements"][m]["n_runs"], doc["movements"][m]["n_units"]), (1, 1))
            self.assertIsNone(doc["ablation"][m], "no fixture run has ablation.csv")
            self.assertEqual(list(doc["ablation_runs"][m].values()), [None])
            self.assertEqual(len(doc["attention_mass"][m]["mean"]), 5)
        rows = doc["table2"]["att"]
        self.assertEqual(len(rows), 5 * len(MOVEMENTS))
        with open(os.path.join(self.out, "table2.csv")) as f:
            csv_rows = list(csv.DictReader(f))
        above_by_chance = 0
        for o, c in zip(rows, csv_rows):
            self.assertEqual((o["movement"], o["joint"]), (c["movement"], c["joint"]))
            for s in stats.STAT_NAMES:
                self.assertEqual(set(o[s]) >= {"estimate", "ci_lo", "ci_hi", "p"}, True, s)
                self.assertAlmostEqual(o[s]["estimate"], float(c[s]), 6)
            mi = o["mi_bits"]
            self.assertAlmostEqual(mi["excess"], mi["estimate"] - mi["null_median"], 12)
            self.assertEqual(mi["above_null_q95"], mi["estimate"] > mi["null_q95"])
            self.assertEqual(mi["above_null_q95"], mi["p"] < 0.05)
            if o["joint"] == run_fixture.JOINTS[PLANTED]:
                self.assertTrue(mi["above_null_q95"], "planted %s: MI %.2f, null q95 %.2f"
                                % (o["movement"], mi["estimate"], mi["null_q95"]))
            else:
                above_by_chance += mi["above_null_q95"]
        # Independent noise lies above its null's 95 % quantile in about 1 of 20 rows.
        self.assertLessEqual(above_by_chance, 1, "MI above the null in %d of 8 rows without dependence"
                             % above_by_chance)

    def test_findings_md_prints_the_rule_and_has_no_verdict_from_one_seed(self):
        with open(os.path.join(self.out, "findings.md")) as f:
            text = f.read()
        self.assertIn("Criterion: A finding is *reproduced* only when", text)
        self.assertIn("wrist RElbowYaw", text)
        self.assertIn("not measured: no run has ablation.csv", text)
        self.assertNotIn("reproduced.", text)

    def test_table2_md_states_the_method(self):
        with open(os.path.join(self.out, "table2.md")) as f:
            text = f.read()
        self.assertIn("Trend removal: **linear**", text)
        self.assertIn("k = 3", text)

    def test_report_is_one_self_contained_page(self):
        with open(os.path.join(self.out, "report.html")) as f:
            page = f.read()
        self.assertTrue("Table 2" in page, "no Table 2 in the report")
        self.assertTrue("How to read this page" in page, "no reading note in the report")
        self.assertIsNone(re.search(r"<script|<link|src=\"(?!data:)", page), "the report must not load anything")
        self.assertEqual(len(re.findall(r'<img [^>]*src="data:image/png;base64,', page)), 3 * len(MOVEMENTS) + 1)
        # Each run's summary.json and the command line (checked without dumping the page).
        self.assertTrue("synthetic:wrist (seed 1000001, index 0)" in page, "summary.json missing from the report")
        self.assertTrue("analyze.py --bootstrap 100 --out " in page, "command line missing from the report")


class Determinism(unittest.TestCase):
    def test_same_runs_give_byte_identical_table2_and_figures(self):
        tmp = tempfile.mkdtemp(prefix="nao-analysis-det-")
        try:
            path = run_fixture.write_run(os.path.join(tmp, "run"), "elbow", n=60, seed=5)
            texts, dirs = [], []
            for k in range(2):
                run = read_run(path)
                texts.append(table2_csv(table2_rows(run, "elbow", "linear", n_boot=100)))
                d = os.path.join(tmp, "fig%d" % k)
                os.makedirs(d)
                figures.figure_motion(run, "elbow", d)
                dirs.append(d)
            self.assertEqual(texts[0], texts[1])
            for ext in ("png", "svg"):
                name = "fig_motion_elbow." + ext
                self.assertTrue(filecmp.cmp(os.path.join(dirs[0], name), os.path.join(dirs[1], name), shallow=False),
                                name + " differs between two identical runs")
        finally:
            shutil.rmtree(tmp)

    def test_detrend_none_changes_the_numbers_and_is_named_in_the_table(self):
        tmp = tempfile.mkdtemp(prefix="nao-analysis-none-")
        try:
            run = read_run(run_fixture.write_run(os.path.join(tmp, "run"), "elbow", n=60, seed=5))
            lin = table2_rows(run, "elbow", "linear", n_boot=100)
            raw = table2_rows(run, "elbow", "none", n_boot=100)
            self.assertEqual({r["detrend"] for r in raw}, {"none"})
            self.assertNotEqual([r["pearson_r"] for r in lin], [r["pearson_r"] for r in raw])
        finally:
            shutil.rmtree(tmp)


class AutonomousHandPaths(unittest.TestCase):
    """An autonomous run has no reference: its hand-path figure draws the demonstrations evaluate
    leaves beside it (named_demo.csv; ../../demos/<run>.csv), each the forward kinematics of its
    joints, and says so in the caption."""

    @staticmethod
    def _write_trajectory(path, q):
        with open(path, "w") as f:
            f.write("t_s,q_0,q_1,q_2,q_3,q_4\n")
            for i, row in enumerate(q):
                f.write(",".join(["%.17g" % (0.1 * i)] + ["%.17g" % x for x in row]) + "\n")

    def test_the_named_and_held_out_demonstrations_are_drawn_from_their_files(self):
        from nao_analysis import kinematics
        tmp = tempfile.mkdtemp(prefix="nao-analysis-auto-")
        try:
            run_dir = run_fixture.write_run(os.path.join(tmp, "elbow", "autonomous", "elbow_000"), "elbow", n=40, seed=3)
            with open(os.path.join(run_dir, "ticks.csv")) as f:
                rows = list(csv.reader(f))
            cols = [i for i, c in enumerate(rows[0]) if c.startswith("ee_ref_")]
            for row in rows[1:]:
                for i in cols:
                    row[i] = "nan"  # as nao_rt writes an autonomous run
            with open(os.path.join(run_dir, "ticks.csv"), "w", newline="") as f:
                csv.writer(f, lineterminator="\n").writerows(rows)
            t = 0.1 * np.arange(30)[:, None]
            named = np.hstack([0.3 + 0.2 * np.sin(t), 0.1 * t, 0.2 + 0.0 * t, np.cos(t), -0.5 + 0.0 * t])
            held = named[::-1] * 0.9
            self._write_trajectory(os.path.join(run_dir, "named_demo.csv"), named)
            os.makedirs(os.path.join(tmp, "elbow", "demos"))
            self._write_trajectory(os.path.join(tmp, "elbow", "demos", "elbow_000.csv"), held)
            arm = kinematics.load_arm_model()
            run = read_run(run_dir)
            paths = figures._hand_paths(run, arm)
            self.assertEqual([p[1] for p in paths], [s[0] for s in figures.AUTONOMOUS_PATH_STYLES])
            np.testing.assert_allclose(paths[0][0], kinematics.hand_position(arm, held), atol=1e-12)
            np.testing.assert_allclose(paths[1][0], kinematics.hand_position(arm, named), atol=1e-12)
            self.assertIn("code names", figures.hand_path_caption(run, "elbow"))
            name = figures.figure_ee(run, "elbow", arm, tmp)
            with open(os.path.join(tmp, name + ".svg")) as f:
                self.assertIn("demonstration its code names", f.read())
            # Without the files: the robot's path alone; a reference run keeps its three.
            os.remove(os.path.join(run_dir, "named_demo.csv"))
            shutil.rmtree(os.path.join(tmp, "elbow", "demos"))
            self.assertEqual(len(figures._hand_paths(read_run(run_dir), arm)), 1)
            ref = read_run(run_fixture.write_run(os.path.join(tmp, "ref"), "elbow", n=40, seed=3))
            self.assertEqual([p[1] for p in figures._hand_paths(ref, arm)], [s[0] for s in figures.PATH_STYLES])
            self.assertIn("ee_ref", figures.hand_path_caption(ref, "elbow"))
        finally:
            shutil.rmtree(tmp)


if __name__ == "__main__":
    unittest.main()
