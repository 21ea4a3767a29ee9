"""toolchain/analysis/autonomous_ceiling.py: its batched DTW against a plain transcription of the
runtime's rt::dtwMeanDistance (runtime/metrics/src/metrics.cpp), pair by pair, ties included; the
time warp and the hold it builds its fixed trajectories with."""

import math
import unittest

import numpy as np

import run_fixture  # noqa: F401  (puts toolchain/analysis on the path)
import autonomous_ceiling as ac


def dtw_mean_reference(a, b):
    """rt::dtwMeanDistance cell by cell: lower cost wins, then more pairs; diagonal, up, left."""
    n, m = len(a), len(b)
    cost = [[0.0] * m for _ in range(n)]
    length = [[0] * m for _ in range(n)]
    for i in range(n):
        for j in range(m):
            d = math.sqrt(sum((a[i][k] - b[j][k]) ** 2 for k in range(len(a[i]))))
            if i == 0 and j == 0:
                cost[i][j], length[i][j] = d, 1
                continue
            best, best_len = float("inf"), 0
            for ok, (pi, pj) in ((i > 0 and j > 0, (i - 1, j - 1)), (i > 0, (i - 1, j)), (j > 0, (i, j - 1))):
                if ok and (cost[pi][pj] < best or (cost[pi][pj] == best and length[pi][pj] > best_len)):
                    best, best_len = cost[pi][pj], length[pi][pj]
            cost[i][j], length[i][j] = best + d, best_len + 1
    return cost[n - 1][m - 1] / length[n - 1][m - 1]


class BatchedDtw(unittest.TestCase):
    def test_equals_the_runtimes_recurrence_on_random_paths_of_different_lengths(self):
        rng = np.random.default_rng(7)
        pairs = [(rng.normal(size=(rng.integers(1, 30), 3)), rng.normal(size=(rng.integers(1, 30), 3)))
                 for _ in range(40)]
        got = ac.dtw_batch(pairs)
        want = [dtw_mean_reference(a, b) for a, b in pairs]
        np.testing.assert_array_equal(got, want)

    def test_ties_go_to_the_longer_alignment(self):
        # Points on an integer grid: many alignments of equal total cost; the tie rule decides the
        # count, so a wrong rule changes the mean.
        rng = np.random.default_rng(3)
        pairs = [(rng.integers(0, 2, size=(rng.integers(2, 12), 3)).astype(float),
                  rng.integers(0, 2, size=(rng.integers(2, 12), 3)).astype(float)) for _ in range(60)]
        got = ac.dtw_batch(pairs)
        want = [dtw_mean_reference(a, b) for a, b in pairs]
        np.testing.assert_array_equal(got, want)
        # Only the last pair costs anything (3): of the alignments of cost 3 the longest has
        # n + m − 1 = 5 pairs, so the mean is 3/5 (the shortest, the diagonal, would give 1).
        a = np.zeros((3, 3))
        b = np.array([[0.0, 0, 0], [0, 0, 0], [0, 0, 3.0]])
        self.assertEqual(ac.dtw_batch([(a, b)])[0], dtw_mean_reference(a, b))
        self.assertAlmostEqual(ac.dtw_batch([(a, b)])[0], 3.0 / 5.0, places=15)

    def test_a_shifted_copy_is_at_the_shift(self):
        rng = np.random.default_rng(1)
        a = np.cumsum(rng.normal(size=(25, 3)), axis=0) * 10
        self.assertEqual(ac.dtw_batch([(a, a)])[0], 0.0)
        self.assertAlmostEqual(ac.dtw_batch([(a, a + [0.0, 0.0, 1e-3])])[0], 1e-3, places=15)


class Warp(unittest.TestCase):
    def test_a_trajectory_warped_onto_itself_is_itself(self):
        f = np.cumsum(np.random.default_rng(2).normal(size=(30, 5)), axis=0)
        np.testing.assert_array_equal(ac.warp_onto(f, f), f)

    def test_a_slowed_copy_is_warped_back_sample_by_sample(self):
        t = np.linspace(0, 2 * np.pi, 40)
        template = np.stack([np.cos(t), np.sin(t), t, 0 * t, 0 * t], axis=1)
        slow = np.repeat(template, 2, axis=0)  # every sample held for two ticks
        np.testing.assert_allclose(ac.warp_onto(slow, template), template, rtol=0, atol=1e-15)

    def test_hold_cuts_or_holds_the_last_sample(self):
        f = np.arange(10.0).reshape(5, 2)
        np.testing.assert_array_equal(ac.held(f, 3), f[:3])
        np.testing.assert_array_equal(ac.held(f, 7)[5:], [[8, 9], [8, 9]])


if __name__ == "__main__":
    unittest.main()
