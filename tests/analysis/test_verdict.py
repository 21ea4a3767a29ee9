"""The rule that calls a paper finding reproduced (nao_analysis/verdict.py) and docs/reproduction.md
made from Table 2 JSON files (`--reproduction-from`), on fixture files with known answers."""

import contextlib
import io
import json
import math
import os
import shutil
import tempfile
import unittest

import run_fixture  # noqa: F401  (puts toolchain/analysis on sys.path)
from nao_analysis import JOINT_NAMES, cli, verdict
from nao_analysis.paper import PAPER_FINDINGS
from nao_analysis.table_json import P_FROM_INTERVAL, SCHEMA, row_json
from nao_analysis.units import ROBUSTNESS_DTW_M

MOVEMENTS = ("whole_arm", "elbow", "wrist")


def row(movement, joint, rho, lo, hi, mi=0.1, q95=0.2, p=None):
    """A Table 2 row with the given Spearman rho and interval and the given MI and null 95 %
    quantile; p the correlations' p-value (default: agreeing with the filler interval, or with
    rho's); the rest plausible filler."""
    r = {"movement": movement, "joint": joint, "n_runs": 16, "n_units": 3, "n_ticks": 450, "n_dropped": 0,
         "block_len": 9, "n_shifts": 200, "detrend": "linear", "mi_null_median": q95 - 0.1, "mi_null_q95": q95,
         "mi_excess": mi - q95 + 0.1, "mi_above_null": int(mi > q95)}
    for s in ("pearson_r", "spearman_rho", "kendall_tau", "mi_bits"):
        r[s], r[s + "_ci_lo"], r[s + "_ci_hi"], r[s + "_p"] = 0.1, -0.1, 0.3, 0.4 if p is None else p
    r["spearman_rho"], r["spearman_rho_ci_lo"], r["spearman_rho_ci_hi"] = rho, lo, hi
    if p is None and (lo > 0 or hi < 0):
        r["spearman_rho_p"] = 0.01
    r["mi_bits"], r["mi_bits_ci_lo"], r["mi_bits_ci_hi"], r["mi_bits_p"] = mi, math.nan, math.nan, (
        0.01 if mi > q95 else 0.3)
    return r


def document(seed, rho_of, mi_of=lambda m, j: (0.1, 0.2), schema=SCHEMA, variants=(), p=None):
    """A seed's JSON document; rho_of(movement, joint) -> (rho, lo, hi), mi_of -> (mi, q95);
    variants: [(unit_dtw_m, detrend, rho_of)] stored as Table 2 variants."""
    def table(rho):
        return {"att": [row_json(row(m, j, *rho(m, j), *mi_of(m, j), p=p)) for m in MOVEMENTS for j in JOINT_NAMES]}

    doc = {"schema": schema, "training_seed": seed, "models": [{"path": "m%d.bin" % seed, "checksum": "0x%x" % seed,
                                                                "conditioning": "autonomous"}],
           "command": "toolchain/nao analyze --training-seed %d --table-json seed_%d.json RUNS" % (seed, seed),
           "method": {"detrend": "linear", "bootstrap": 1000, "analysis_seed": 1, "ksg_k": 3, "permutations": 200,
                      "unit_dtw_m": 0.001, "resampling_unit": "distinct rollout"},
           "movements": {m: {"n_runs": 16, "n_units": 3, "n_ticks": 450, "units": [["a"], ["b"], ["c"]],
                             "max_dtw_within_unit_m": 0.0, "min_dtw_between_units_m": 0.005} for m in MOVEMENTS},
           "table2": table(rho_of), "attention_offsets": {}, "attention_mass": {}, "ablation": {}}
    if schema == SCHEMA:
        doc["method"].update({"unit_grouping": "complete linkage", "p_values": P_FROM_INTERVAL})
        doc["variants"] = [{"unit_dtw_m": t, "detrend": d, "table2": table(rho)} for t, d, rho in variants]
        for e in doc["movements"].values():
            e["groupings"] = [{"unit_dtw_m": t, "n_units": 3, "units": [["a"], ["b"], ["c"]],
                               "max_dtw_within_unit_m": 0.0, "min_dtw_between_units_m": 0.005}
                              for t in ROBUSTNESS_DTW_M]
        doc["ablation_runs"] = {}
    return doc


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


DEPENDENT = (0.4, 0.2)      # MI above its null's 95 % quantile
INDEPENDENT = (0.15, 0.2)   # below it


def mi_verdicts(seed_docs):
    return {f["id"]: f["verdict"] for f in verdict.judge_mi(seed_rows(seed_docs))}


class MiRule(unittest.TestCase):
    def test_every_named_mi_above_its_null_and_the_elbow_largest_is_reproduced(self):
        def mi_of(m, j):
            return (0.6, 0.2) if (m, j) == ("elbow", "RElbowYaw") else DEPENDENT
        docs = [document(s, lambda m, j: WEAK, mi_of) for s in (1, 2, 3)]
        self.assertEqual(mi_verdicts(docs), {"i": "reproduced", "ii": "reproduced", "iii": "reproduced"})
        self.assertEqual(set(verdicts(docs).values()), {"not reproduced"}, "the ρ rule is judged on its own")

    def test_another_joint_with_a_larger_excess_fails_the_largest_check_only(self):
        def mi_of(m, j):
            return (0.6, 0.2) if (m, j) == ("elbow", "RWristYaw") else DEPENDENT
        docs = [document(s, lambda m, j: WEAK, mi_of) for s in (1, 2, 3)]
        self.assertEqual(mi_verdicts(docs), {"i": "reproduced", "ii": "partly", "iii": "reproduced"})
        rows = seed_rows(docs)[1]
        self.assertEqual(verdict.mi_holds(rows, "elbow", "RElbowYaw", "largest"),
                         (False, "largest excess over q95: RWristYaw (+0.40 bits against +0.20)"))
        self.assertEqual(verdict.mi_holds(rows, "elbow", "RElbowYaw", "dependent"), (True, "holds"))

    def test_an_mi_below_its_null_q95_does_not_hold_whatever_its_size(self):
        docs = [document(s, lambda m, j: STRONG, lambda m, j: (1.5, 1.6)) for s in (1, 2, 3)]
        self.assertEqual(set(mi_verdicts(docs).values()), {"not reproduced"})
        self.assertEqual(verdict.mi_holds(seed_rows(docs)[1], "wrist", "RElbowYaw", "dependent"),
                         (False, "not above the null's q95"))


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

    def page(self, docs):
        paths = [self.write(d, "seed_%d.json" % d["training_seed"]) for d in docs]
        page = os.path.join(self.tmp, "reproduction.md")
        status, _, err = self.run_cli(["--reproduction-from"] + paths + ["--out", page])
        self.assertEqual(status, 0, err)
        with open(page) as f:
            return f.read()

    def test_a_verdict_that_changes_with_the_threshold_is_reported_as_such(self):
        # At 2 mm every row is strong on every seed; at 0.5 and 1 mm the wrist row is weak.
        def at_1mm(m, j):
            return WEAK if m == "wrist" else STRONG
        variants = [(0.0005, "linear", at_1mm), (0.002, "linear", lambda m, j: STRONG),
                    (0.001, "none", at_1mm), (0.001, "highpass:0.1", at_1mm)]
        text = self.page([document(s, at_1mm, variants=variants) for s in (1, 2, 3)])
        self.assertIn("| (iii) | ρ rule | not reproduced | not reproduced | reproduced | not reproduced | "
                      "not reproduced | yes | no |", text)
        self.assertIn("| (i) | ρ rule | reproduced | reproduced | reproduced | reproduced | reproduced | no | no |",
                      text)
        self.assertIn("A verdict that changes: (iii) ρ rule changes with the threshold.", text)
        self.assertIn("| wrist | RElbowYaw | 2 | 0.30 [0.20, 0.40] ✗ | 0.30 [0.20, 0.40] ✗ | 0.70 [0.55, 0.85] ✓ |",
                      text)
        self.assertIn("p-values that contradict their own interval (`att`): 0 of 45.", text)

    def test_a_file_of_the_first_schema_renders_with_what_it_lacks_named(self):
        old = document(2, lambda m, j: STRONG, schema="nao-table2/1", p=0.001)  # p contradicting [-0.1, 0.3]
        old["ablation"] = {"wrist": {"n_units": 3, "n_units_total": 3, "n_ticks": 450, "rho_median": 0.1,
                                     "rho_ci": [0.0, 0.2], "top_match_rate": 0.25, "top_match_ci": [0.21, 0.3],
                                     "chance_top_match": 0.2, "predicts": True}}
        text = self.page([document(1, lambda m, j: STRONG), old])
        self.assertIn("Seed 2: the file's p-values come from a permutation test that holds the set of rollouts "
                      "fixed", text)
        self.assertIn("| wrist | RElbowYaw | 0.10 [-0.10, 0.30] | 0.70 [0.55, 0.85] | 0.10 [-0.10, 0.30] |", text,
                      "seed 2's cells without its p-values")
        self.assertIn("| wrist | RElbowYaw | 0.10 [-0.10, 0.30], p 0.400 |", text, "seed 1's with them")
        self.assertIn("| 2 | wrist | 3 of 3 | 450 | 0.10 [0.00, 0.20] | 0.25 [0.21, 0.30] | not in this file | – | "
                      "not in this file / not in this file / not in this file | not in this file / not in this file "
                      "/ not in this file |", text)
        self.assertIn("| 2 | wrist | 16 | not in this file | 3 | not in this file |", text)
        self.assertIn("Seeds 1, 2: not in this file (their files hold the default analysis only).", text)
        self.assertIn("- (iii) in the wrist movement the elbow carries the motion: partly. Failing: 2 of 3 seeds "
                      "analysed.", text)
        self.assertNotIn("| yes |", text.split("## Attention against ablation")[1].split("## Table 2")[0])

    def test_the_ablation_is_recomputed_from_the_per_run_counts_at_every_threshold(self):
        doc = document(1, lambda m, j: STRONG)
        # Three rollouts of 40 ticks: attention always on part 4, the ablation's top part 4 in
        # 30 of 40, ticks matching in 30: chance 0.75, the match rate 0.75, not above chance
        # although it is far above one fifth.
        rec = {"n_ticks": 40, "matches": 30, "attention_top": [0, 0, 0, 0, 40], "ablation_top": [10, 0, 0, 0, 30],
               "tick_rho": [[0.5, 40]]}
        doc["ablation_runs"] = {"wrist": {"a": rec, "b": rec, "c": rec}}
        from nao_analysis.ablation import summary_from_records
        doc["ablation"] = {"wrist": summary_from_records([rec] * 3, 1000, 1)}
        text = self.page([doc])
        self.assertIn("| 1 | wrist | 3 of 3 | 120 | 0.50 [0.50, 0.50] | 0.75 [0.75, 0.75] | 0.75 [0.75, 0.75] | "
                      "0.00 [0.00, 0.00] | no / no / no | no / no / no |", text)
        self.assertIn("- At 1 mm: 0 of 1 (seed, movement) pairs with a chance level are above it", text)

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
