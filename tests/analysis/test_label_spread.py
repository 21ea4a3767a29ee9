"""toolchain/analysis/label_spread.py on execution caches written here in the trainer's layout,
with labels whose spreads are known."""

import io
import json
import os
import shutil
import tempfile
import unittest
from contextlib import redirect_stdout

import numpy as np

import run_fixture  # noqa: F401  (puts toolchain/analysis on the path)
import label_spread as ls


def write_cache(path, seqs):
    """seqs: (demo, movement, rollout, a (n, 5)); q, a(t-1) and r are filled with other values."""
    out = [float(len(seqs))]
    for demo, movement, rollout, a in seqs:
        n = len(a)
        out += [demo, movement, rollout, n + 1, n, n, n, 1e-7]
        out += list(np.full((n + 1, 5), 9.0).ravel())   # q: one more than the labels
        out += list(np.full((n, 5), -7.0).ravel())      # a(t-1)
        out += list(np.full((n, 5), 5.0).ravel())       # r
        out += list(np.asarray(a, dtype=float).ravel())
    np.asarray(out, dtype="<f8").tofile(path)


def alternating(n, amp):
    """(n, 5): ±amp[j], alternating; its standard deviation is amp[j] for even n."""
    sign = np.where(np.arange(n) % 2 == 0, 1.0, -1.0)[:, None]
    return sign * np.asarray(amp)[None, :]


class LabelSpread(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.mkdtemp(prefix="nao_label_spread_")
        self.path = os.path.join(self.tmp, "k.train")

    def tearDown(self):
        shutil.rmtree(self.tmp)

    def test_clean_and_noisy_spreads_against_the_file_wide_spread(self):
        # Movement 0 moves every joint by 0.02 when clean; its noisy rollout's labels 0.06. Movement
        # 1 holds joint 3 (0 when clean). Every series has a mean of 0 and an even length, so the
        # standard deviations are known: file-wide per joint sqrt(mean of the squares).
        m0_clean = alternating(10, [0.02] * 5)
        m0_noisy = alternating(10, [0.06] * 5)
        m1_clean = alternating(20, [0.04, 0.04, 0.04, 0.0, 0.04])
        write_cache(self.path, [(0, 0, 0, m0_clean), (0, 0, 1, m0_noisy), (1, 1, 0, m1_clean)])
        report, scale = ls.label_spread(ls.read_cache(self.path))
        want_scale = np.sqrt((10 * np.array([0.02] * 5) ** 2 + 10 * np.array([0.06] * 5) ** 2
                              + 20 * np.array([0.04, 0.04, 0.04, 0.0, 0.04]) ** 2) / 40)
        np.testing.assert_allclose(scale, want_scale, rtol=1e-12)
        np.testing.assert_allclose(report[0]["clean_ratio"], 0.02 / want_scale, rtol=1e-12)
        np.testing.assert_allclose(report[0]["noisy_ratio"], 0.06 / want_scale, rtol=1e-12)
        self.assertEqual(report[1]["clean_ratio"][3], 0.0)
        self.assertEqual((report[0]["clean_ticks"], report[0]["noisy_ticks"]), (10, 10))
        self.assertEqual(report[1]["noisy_ticks"], 0)
        self.assertTrue(all(np.isnan(report[1]["noisy_ratio"])))

    def test_broken_files_are_refused(self):
        write_cache(self.path, [(0, 0, 0, alternating(4, [0.1] * 5))])
        whole = np.fromfile(self.path, dtype="<f8")
        whole[:-3].tofile(self.path)
        with self.assertRaisesRegex(ls.CacheError, "truncated"):
            ls.read_cache(self.path)
        np.concatenate([whole, [1.0]]).tofile(self.path)
        with self.assertRaisesRegex(ls.CacheError, "trailing"):
            ls.read_cache(self.path)
        open(self.path, "wb").close()
        with self.assertRaisesRegex(ls.CacheError, "empty"):
            ls.read_cache(self.path)

    def test_command_line_names_the_movements_and_writes_json(self):
        write_cache(self.path, [(0, 0, 0, alternating(4, [0.1] * 5)), (1, 1, 1, alternating(4, [0.3] * 5))])
        out_json = os.path.join(self.tmp, "s.json")
        buf = io.StringIO()
        with redirect_stdout(buf):
            rc = ls.main(["label_spread.py", self.path, "--names", "elbow,wrist", "--json", out_json])
        self.assertEqual(rc, 0)
        self.assertIn("| elbow |", buf.getvalue())
        self.assertIn("| wrist |", buf.getvalue())
        with open(out_json, encoding="utf-8") as fh:
            got = json.load(fh)
        self.assertEqual(sorted(got["movements"]), ["elbow", "wrist"])
        self.assertEqual(got["movements"]["wrist"]["clean_ticks"], 0)
        self.assertEqual(ls.main(["label_spread.py", os.path.join(self.tmp, "missing.train")]), 1)


if __name__ == "__main__":
    unittest.main()
