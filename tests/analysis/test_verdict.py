"""The rule that calls a paper finding reproduced (nao_analysis/verdict.py) and docs/reproduction.md
made from Table 2 JSON files (`--reproduction-from`), on fixture files with known answers."""

import contextlib
import io
import json
import os
import shutil
import tempfile
import unittest

import run_fixture  # noqa: F401  (puts toolchain/analysis on sys.path)
from nao_analysis import JOINT_NAMES, cli, verdict
from nao_analysis.paper import PAPER_FINDINGS
from nao_analysis.table_json import SCHEMA, row_json

MOVEMENTS = ("whole_arm", "elbow", "wrist")


def row(movement, joint, rho, lo, hi):
    """A Table 2 row with the given Spearman rho and interval; the rest plausible filler."""
    r = {"movement": movement, "joint": joint, "n_runs": 16, "n_units": 3, "n_ticks": 450, "n_dropped": 0,
         "block_len": 9, "n_shifts": 200, "detrend": "linear", "mi_null_median": 0.1, "mi_null_q95": 0.2,
         "mi_excess": 0.05, "mi_above_null": 0}
    for s in ("pearson_r", "spearman_rho", "kendall_tau", "mi_bits"):
        r[s], r[s + "_ci_lo"], r[s + "_ci_hi"], r[s + "_p"] = 0.1, -0.1, 0.3, 0.4
    r["spearman_rho"], r["spearman_rho_ci_lo"], r["spearman_rho_ci_hi"] = rho, lo, hi
    return r


def document(seed, rho_of):
    """A seed's JSON document; rho_of(movement, joint) -> (rho, lo, hi)."""
    rows = [row_json(row(m, j, *rho_of(m, j))) for m in MOVEMENTS for j in JOINT_NAMES]
    return {"schema": SCHEMA, "training_seed": seed, "models": [{"path": "m%d.bin" % seed, "checksum": "0x%x" % seed,
                                                                 "conditioning": "autonomous"}],
            "command": "toolchain/nao analyze --training-seed %d --table-json seed_%d.json RUNS" % (seed, seed),
            "method": {"detrend": "linear", "bootstrap": 1000, "analysis_seed": 1, "ksg_k": 3, "permutations": 200,
                       "unit_dtw_m": 0.001, "resampling_unit": "distinct rollout"},
            "movements": {m: {"n_runs": 16, "n_units": 3, "n_ticks": 450, "units": [["a"], ["b"], ["c"]],
                              "max_dtw_within_unit_m": 0.0, "min_dtw_between_units_m": 0.005} for m in MOVEMENTS},
            "table2": {"att": rows}, "attention_offsets": {}, "attention_mass": {}, "ablation": {}}


STRONG = (0.7, 0.55, 0.85)
WEAK = (0.3, 0.2, 0.4)          # the sign, the interval above 0, but not strong
WIDE = (0.6, -0.05, 0.8)       # strong, but the interval reaches 0
NEGATIVE = (-0.6, -0.8, -0.4)   # strong, opposite to the paper's sign


def seed_rows(seed_docs):
    from nao_analysis.reproduction import seed_rows as rows_of
    return {d["training_seed"]: rows_of(d) for d in seed_docs}


def verdicts(seed_docs):
    return {f["id"]: f["verdict"] for f in verdict.judge(seed_rows(seed_docs))}


class Rule(unittest.TestCase):
    def test_every_named_row_strong_on_three_seeds_is_reproduced(self):
        docs = [document(s, lambda m, j: STRONG) for s in (1, 2, 3)]
        self.assertEqual(verdicts(docs), {"i": "reproduced", "ii": "reproduced", "iii": "reproduced"})

    def test_a_single_failing_row_seed_pair_makes_a_finding_partly(self):
        docs = [document(s, lambda m, j: STRONG) for s in (1, 2)]
        docs.append(document(3, lambda m, j: WIDE if (m, j) == ("elbow", "RElbowYaw") else STRONG))
        self.assertEqual(verdicts(docs), {"i": "reproduced", "ii": "partly", "iii": "reproduced"})

    def test_weak_wide_or_opposite_rows_on_every_seed_are_not_reproduced(self):
        for case in (WEAK, WIDE, NEGATIVE):
            docs = [document(s, lambda m, j: case) for s in (1, 2, 3)]
            self.assertEqual(set(verdicts(docs).values()), {"not reproduced"}, case)

    def test_rows_the_finding_does_not_name_do_not_count(self):
        named = {p for f in PAPER_FINDINGS for p in f[3]}
        docs = [document(s, lambda m, j: STRONG if (m, j) in named else NEGATIVE) for s in (1, 2, 3)]
        self.assertEqual(set(verdicts(docs).values()), {"reproduced"})

    def test_fewer_than_three_seeds_give_at_most_partly(self):
        docs = [document(s, lambda m, j: STRONG) for s in (1, 2)]
        self.assertEqual(set(verdicts(docs).values()), {"partly"})

    def test_row_holds_names_each_reason(self):
        self.assertEqual(verdict.row_holds(row("wrist", "RElbowYaw", *STRONG), 1), (True, "holds"))
        self.assertEqual(verdict.row_holds(row("wrist", "RElbowYaw", *WEAK), 1)[1], "not strong: below 0.5")
        self.assertEqual(verdict.row_holds(row("wrist", "RElbowYaw", *WIDE), 1)[1], "interval not above 0")
        self.assertIn("opposite sign", verdict.row_holds(row("wrist", "RElbowYaw", *NEGATIVE), 1)[1])
        # A strong ρ of the wrong sign fails on its sign and interval, not on its strength.
        self.assertEqual(verdict.row_holds(row("wrist", "RElbowYaw", -0.6, -0.7, -0.5), 1),
                         (False, "opposite sign, interval not above 0"))
        self.assertTrue(verdict.row_holds(row("wrist", "RElbowYaw", *NEGATIVE), -1)[0])
        nan = float("nan")
        self.assertEqual(verdict.row_holds(row("wrist", "RElbowYaw", 0.7, nan, nan), 1), (False, "no interval"))
        self.assertEqual(verdict.row_holds(None, 1), (False, "not analysed"))


class ReproductionFrom(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.mkdtemp(prefix="nao-verdict-")

    def tearDown(self):
        shutil.rmtree(self.tmp)

    def write(self, doc, name):
        path = os.path.join(self.tmp, name)
        with open(path, "w") as f:
            json.dump(doc, f)
        return path

    def run_cli(self, argv):
        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            status = cli.main(argv)
        return status, out.getvalue(), err.getvalue()

    def test_the_page_prints_the_criterion_the_verdicts_and_what_is_not_reproduced(self):
        paths = [self.write(document(1, lambda m, j: STRONG), "seed_1.json"),
                 self.write(document(2, lambda m, j: WEAK if m == "wrist" else STRONG), "seed_2.json"),
                 self.write(document(3, lambda m, j: STRONG), "seed_3.json")]
        page = os.path.join(self.tmp, "reproduction.md")
        status, out, err = self.run_cli(["--reproduction-from"] + paths + ["--out", page])
        self.assertEqual(status, 0, err)
        self.assertIn("(iii) partly", out)
        with open(page) as f:
            text = f.read()
        self.assertIn(verdict.CRITERION, text)
        self.assertIn("### (i) attention tracks the primary driving joints: **reproduced**", text)
        self.assertIn("### (iii) in the wrist movement the elbow carries the motion: **partly**", text)
        self.assertIn("wrist RElbowYaw seed 2 (not strong: below 0.5)", text)
        self.assertIn("Not measured: no analysed run has `ablation.csv`.", text)
        for s in (1, 2, 3):
            self.assertIn("### Seed %d" % s, text)
        # The same files give the same page (which quotes its own command line).
        self.run_cli(["--reproduction-from"] + paths + ["--out", page + "2"])
        with open(page + "2") as f:
            self.assertEqual(f.read().replace(page + "2", page), text)

    def test_two_files_of_one_seed_or_a_foreign_file_are_refused_in_one_line(self):
        a = self.write(document(1, lambda m, j: STRONG), "a.json")
        b = self.write(document(1, lambda m, j: STRONG), "b.json")
        bad = self.write({"schema": "other"}, "bad.json")
        broken = document(2, lambda m, j: STRONG)
        del broken["table2"]["att"][0]["spearman_rho"]
        broken = self.write(broken, "broken.json")
        for files, fragment in (([a, b], "training seed 1 appears in two files"), ([bad], "not a Table 2 file"),
                                ([broken], "malformed Table 2 file")):
            status, _, err = self.run_cli(["--reproduction-from"] + files + ["--out", os.path.join(self.tmp, "x.md")])
            self.assertEqual(status, 1, err)
            self.assertEqual(len(err.strip().splitlines()), 1, err)
            self.assertIn(fragment, err)
            self.assertFalse(os.path.exists(os.path.join(self.tmp, "x.md")))


if __name__ == "__main__":
    unittest.main()
