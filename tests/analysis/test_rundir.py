"""A missing or malformed run directory gives one clear line and a non-zero exit; a good one
is read exactly as written (run_fixture writes the documented formats independently)."""

import contextlib
import io
import os
import struct
import shutil
import subprocess
import tempfile
import unittest

import numpy as np

import run_fixture
from nao_analysis import AnalysisError, cli
from nao_analysis.rundir import read_run
from nao_analysis.table2 import table2_rows

ANALYZE = os.path.join(run_fixture.ANALYSIS, "analyze.py")


class RunDirectory(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.mkdtemp(prefix="nao-analysis-test-")
        self.run_dir = run_fixture.write_run(os.path.join(self.tmp, "run"), "elbow", n=60, seed=3)

    def tearDown(self):
        shutil.rmtree(self.tmp)

    def path(self, name):
        return os.path.join(self.run_dir, name)

    def assert_refused(self, *fragments, subprocess_too=False):
        """read_run raises, and the command line (in process; as a process when asked) exits 1
        with one line naming the problem and writes nothing."""
        with self.assertRaises(AnalysisError) as cm:
            read_run(self.run_dir)
        for frag in fragments:
            self.assertIn(frag, str(cm.exception))
        argv = ["--out", os.path.join(self.tmp, "out"), self.run_dir]
        stderr = io.StringIO()
        with contextlib.redirect_stderr(stderr):
            status = cli.main(argv)
        results = [(status, stderr.getvalue())]
        if subprocess_too:
            p = subprocess.run(["/usr/bin/python3", ANALYZE] + argv, capture_output=True, text=True)
            results.append((p.returncode, p.stderr))
        for status, err in results:
            self.assertEqual(status, 1, err)
            errors = [line for line in err.splitlines() if "error" in line]
            self.assertEqual(len(errors), 1, err)
            self.assertTrue(errors[0].startswith("nao: error: analyze: "), errors[0])
            for frag in fragments:
                self.assertIn(frag, errors[0])
        self.assertFalse(os.path.exists(os.path.join(self.tmp, "out", "table2.csv")))

    def test_a_fixture_run_is_read_as_written(self):
        run = read_run(self.run_dir)
        t, q, att = run_fixture.make_series(60, 3, 3)
        self.assertEqual(run.movement, "elbow")
        np.testing.assert_array_equal(run.joint_matrix("q"), q)
        np.testing.assert_array_equal(run.joint_matrix("att").astype(np.float32), att)
        np.testing.assert_array_equal(run.attention.score, att)
        self.assertEqual(run.attention.cross.shape, (60, 1, 2, 5, 5))
        np.testing.assert_allclose(run.attention.cross.sum(axis=-1), 1, atol=1e-6)
        self.assertEqual(run.attention.cross_out.shape, (60, 5, 8))
        self.assertTrue(run.policy_mask().all())

    def test_missing_directory(self):
        shutil.rmtree(self.run_dir)
        self.assert_refused(self.run_dir, "not a directory", subprocess_too=True)

    def test_no_ticks_csv(self):
        os.remove(self.path("ticks.csv"))
        self.assert_refused("ticks.csv", "missing")

    def test_a_missing_column(self):
        with open(self.path("ticks.csv")) as f:
            lines = f.read().splitlines()
        header = lines[0].split(",")
        k = header.index("att_2")
        out = [",".join(x for i, x in enumerate(line.split(",")) if i != k) for line in lines]
        with open(self.path("ticks.csv"), "w") as f:
            f.write("\n".join(out) + "\n")
        self.assert_refused("ticks.csv", "missing column(s) att_2")

    def test_a_short_line(self):
        with open(self.path("ticks.csv")) as f:
            lines = f.read().splitlines()
        lines[10] = lines[10].rsplit(",", 3)[0]
        with open(self.path("ticks.csv"), "w") as f:
            f.write("\n".join(lines) + "\n")
        self.assert_refused("ticks.csv", "line 11")

    def test_a_truncated_attention_bin(self):
        size = os.path.getsize(self.path("attention.bin"))
        with open(self.path("attention.bin"), "r+b") as f:
            f.truncate(size - 100)
        self.assert_refused("attention.bin", "truncated")

    def test_a_bad_magic(self):
        with open(self.path("attention.bin"), "r+b") as f:
            f.write(b"NOTATTN1")
        self.assert_refused("attention.bin", "bad magic", subprocess_too=True)

    def test_a_flipped_byte_fails_the_record_checksum(self):
        with open(self.path("attention.bin"), "r+b") as f:
            f.seek(32)
            payload = struct.unpack("<Q", f.read(8))[0]  # payload_bytes of the header
            f.seek(96 + payload * 7 + 150)  # inside record 7's cross-attention weights
            b = f.read(1)
            f.seek(-1, os.SEEK_CUR)
            f.write(bytes([b[0] ^ 0x40]))
        self.assert_refused("attention.bin", "record 7", "checksum")

    def test_attention_bin_of_another_run(self):
        other = run_fixture.write_run(os.path.join(self.tmp, "other"), "elbow", n=60, seed=4)
        shutil.copy(os.path.join(other, "attention.bin"), self.path("attention.bin"))
        self.assert_refused("disagree at tick 0")

    def test_summary_without_movement(self):
        with open(self.path("summary.json"), "w") as f:
            f.write("{}")
        self.assert_refused("summary.json", "movement")

    def test_bypassed_ticks_are_dropped_and_counted(self):
        run = read_run(run_fixture.write_run(os.path.join(self.tmp, "bypass"), "wrist", n=60, seed=3,
                                             bypass=range(50, 60)))
        self.assertEqual(int(run.policy_mask().sum()), 50)
        rows = table2_rows(run, "wrist", "linear", n_boot=100)
        self.assertEqual([r["n_dropped"] for r in rows], [10] * 5)
        self.assertEqual([r["n_ticks"] for r in rows], [50] * 5)

    def test_too_few_usable_ticks_is_an_error_not_a_table_of_noise(self):
        run = read_run(run_fixture.write_run(os.path.join(self.tmp, "short"), "wrist", n=60, seed=3,
                                             bypass=range(10, 60)))
        with self.assertRaises(AnalysisError) as cm:
            table2_rows(run, "wrist", "linear", n_boot=100)
        self.assertIn("only 10 tick(s)", str(cm.exception))


if __name__ == "__main__":
    unittest.main()
