"""The attention ablation check (nao_analysis/ablation.py) on fixture runs whose ablation.csv has a
known answer: per-tick Spearman rho between masses and deltas, the top-body-part match rate, its
chance level, and their intervals over distinct rollouts."""

import json
import os
import shutil
import tempfile
import unittest

import numpy as np

import run_fixture
from nao_analysis import AnalysisError, ablation, protocol
from nao_analysis.rundir import read_run

N = 50
IDENTITY = (0, 1, 2, 3, 4)   # delta ranks = mass ranks: rho 1, top part matches
TOP_SWAPPED = (0, 1, 2, 4, 3)  # the two most-attended swapped: rho 1 - 6*2/120 = 0.9, never matches
REVERSED = (4, 3, 2, 1, 0)   # rho -1, never matches


def masses_and_deltas(seed, ranks_to_delta):
    """(mass (N, 5), delta (N, 5)): random attention shares; each body part's delta is set by
    its mass rank through the permutation ranks_to_delta."""
    rng = np.random.default_rng(seed)
    mass = rng.random((N, 5)) + 0.5
    mass = (mass / mass.sum(axis=1, keepdims=True)).astype(np.float32).astype(float)
    rank = np.argsort(np.argsort(mass, axis=1), axis=1)
    delta = 0.01 * (np.array(ranks_to_delta)[rank] + 1)
    return mass, delta


class Ablation(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.mkdtemp(prefix="nao-ablation-")

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.tmp)

    def runs(self, name, perms):
        """One run per permutation, each with its own motion (so its own distinct rollout)."""
        out = []
        for k, perm in enumerate(perms):
            path = run_fixture.write_run(os.path.join(self.tmp, name, "elbow_%d" % k), "elbow", n=N, seed=10 + k,
                                         ablation=masses_and_deltas(k, perm))
            out.append(read_run(path))
        return out

    def summary(self, runs):
        units, _ = protocol.movement_units(runs)
        self.assertEqual(len(units["elbow"]), len(runs))
        return ablation.ablation_summary(units["elbow"], 200, 1)

    def test_per_tick_rho_and_match_of_the_known_permutations(self):
        for perm, rho, match in ((IDENTITY, 1.0, 1.0), (TOP_SWAPPED, 0.9, 0.0), (REVERSED, -1.0, 0.0)):
            mass, delta = masses_and_deltas(0, perm)
            np.testing.assert_allclose(ablation.tick_rho(mass, delta), rho, atol=1e-12)
            np.testing.assert_array_equal(ablation.top_match(mass, delta), match)

    def test_attention_that_ranks_the_ablation_effect_predicts_it(self):
        s = self.summary(self.runs("faithful", (IDENTITY, IDENTITY, IDENTITY)))
        self.assertEqual((s["n_units"], s["n_ticks"]), (3, 3 * N))
        self.assertAlmostEqual(s["rho_median"], 1.0, 12)
        self.assertEqual(s["top_match_rate"], 1.0)
        self.assertAlmostEqual(s["rho_ci"][0], 1.0, 12)
        # The chance level from the masses themselves: attention and ablation pick the same part,
        # so chance = sum_j share_j^2 of the attention's top-part shares.
        top = np.concatenate([np.argmax(masses_and_deltas(k, IDENTITY)[0], axis=1) for k in range(3)])
        share = np.bincount(top, minlength=5) / len(top)
        self.assertAlmostEqual(s["chance"], float(np.sum(share ** 2)), 12)
        self.assertGreater(s["excess_ci"][0], 0)
        self.assertTrue(s["above_chance"])
        self.assertTrue(s["predicts"])

    def test_a_mixed_movement_gives_its_median_and_rate_and_no_claim(self):
        # Ticks: 50 with rho 1, 50 with 0.9, 50 with -1: median 0.9; the top part matches in 50 of 150.
        s = self.summary(self.runs("mixed", (IDENTITY, TOP_SWAPPED, REVERSED)))
        self.assertAlmostEqual(s["rho_median"], 0.9, 12)
        self.assertAlmostEqual(s["top_match_rate"], 1.0 / 3.0, 12)
        self.assertAlmostEqual(s["rho_ci"][0], -1.0, 12, "a bootstrap drawing the reversed unit three times")
        self.assertLess(s["top_match_ci"][0], 0.2)
        self.assertFalse(s["above_chance"])
        self.assertFalse(s["predicts"])

    def test_runs_without_ablation_csv_give_no_summary(self):
        run = read_run(run_fixture.write_run(os.path.join(self.tmp, "none", "elbow_0"), "elbow", n=N, seed=3))
        self.assertIsNone(ablation.read_ablation(run))
        self.assertIsNone(ablation.ablation_summary([[run]], 100, 1))
        self.assertIsNone(ablation.run_record(run))

    def test_masses_that_are_not_attention_bins_are_refused(self):
        run = self.runs("tampered", (IDENTITY,))[0]
        path = os.path.join(run.path, "ablation.csv")
        with open(path) as f:
            lines = f.read().splitlines()
        cells = lines[7].split(",")
        cells[1] = repr(float(cells[1]) + 0.01)
        lines[7] = ",".join(cells)
        with open(path, "w") as f:
            f.write("\n".join(lines) + "\n")
        with self.assertRaises(AnalysisError) as cm:
            ablation.read_ablation(run)
        self.assertIn("mass at tick 6 is not attention.bin's mass", str(cm.exception))
        with open(path, "w") as f:
            f.write("tick,mass_0\n0,0.2\n")
        with self.assertRaises(AnalysisError) as cm:
            ablation.read_ablation(run)
        self.assertIn("missing column(s) mass_1", str(cm.exception))

    def test_the_mass_spread_is_read_from_attention_bin(self):
        runs = self.runs("spread", (IDENTITY, REVERSED))
        units, _ = protocol.movement_units(runs)
        s = ablation.mass_spread(units["elbow"])
        masses = np.concatenate([masses_and_deltas(k, p)[0] for k, p in enumerate((IDENTITY, REVERSED))])
        self.assertEqual(s["n_ticks"], 2 * N)
        self.assertAlmostEqual(s["min"], masses.min(), 7)
        self.assertAlmostEqual(s["max"], masses.max(), 7)
        np.testing.assert_allclose(s["cv_over_time"], masses.std(axis=0) / masses.mean(axis=0), rtol=1e-6)



def record(attention_top, ablation_top, matches, rho=((0.0, None),)):
    """A run_record with the given per-body-part counts; tick_rho [(value, count or None = all)]."""
    n = sum(attention_top)
    assert sum(ablation_top) == n
    return {"n_ticks": n, "matches": matches, "attention_top": list(attention_top),
            "ablation_top": list(ablation_top), "tick_rho": [[v, n if c is None else c] for v, c in rho]}


class ChanceLevel(unittest.TestCase):
    """summary_from_records on counts whose chance level is known."""

    def test_concentrated_picks_raise_the_chance_level_above_one_fifth(self):
        # Attention always picks body part 4; masking part 4 moves the action most in half the
        # ticks: chance 1 * 0.5, and the match rate 0.5 is exactly chance (a uniform 0.2 would
        # call it above).
        units = [record((0, 0, 0, 0, 40), (5, 5, 5, 5, 20), 20) for _ in range(4)]
        s = ablation.summary_from_records(units, 300, 1)
        self.assertEqual((s["chance"], s["top_match_rate"], s["excess"]), (0.5, 0.5, 0.0))
        self.assertEqual(s["chance_ci"], [0.5, 0.5], "identical rollouts: no spread")
        self.assertFalse(s["above_chance"], "a match rate at its chance level is not above it")

    def test_independent_uniform_picks_give_one_fifth(self):
        units = [record((10, 10, 10, 10, 10), (10, 10, 10, 10, 10), 10)] * 3
        self.assertAlmostEqual(ablation.summary_from_records(units, 100, 1)["chance"], 0.2, 15)

    def test_the_chance_level_is_resampled_with_the_rollouts(self):
        # Two rollouts, each always picking its own body part in both: pooled shares (1/2, 1/2),
        # chance 1/2, every tick a match. A resample of one rollout twice has chance 1: with two
        # rollouts the data cannot tell agreement from a shared favourite.
        units = [record((10, 0, 0, 0, 0), (10, 0, 0, 0, 0), 10), record((0, 10, 0, 0, 0), (0, 10, 0, 0, 0), 10)]
        s = ablation.summary_from_records(units, 400, 1)
        self.assertEqual((s["chance"], s["top_match_rate"]), (0.5, 1.0))
        self.assertEqual(s["chance_ci"], [0.5, 1.0])
        self.assertEqual(s["excess_ci"][0], 0.0)
        self.assertFalse(s["above_chance"])

    def test_the_median_rho_of_pooled_counts_is_numpys_median_of_the_ticks(self):
        rng = np.random.default_rng(5)
        values = np.round(np.linspace(-1, 1, 21), 1)
        for _ in range(50):
            units = []
            ticks = []
            for _ in range(int(rng.integers(1, 5))):
                counts = rng.integers(0, 4, len(values))
                counts[0] += 1
                units.append(record((int(counts.sum()), 0, 0, 0, 0), (int(counts.sum()), 0, 0, 0, 0), 0,
                                    [(float(v), int(c)) for v, c in zip(values, counts) if c]))
                ticks.append(np.repeat(values, counts))
            s = ablation.summary_from_records(units, 100, 1, min_units=99)
            self.assertEqual(s["rho_median"], float(np.median(np.concatenate(ticks))))

    def test_a_record_survives_json_and_gives_the_summary_of_its_run(self):
        tmp = tempfile.mkdtemp(prefix="nao-ablation-rec-")
        try:
            runs = [read_run(run_fixture.write_run(os.path.join(tmp, "elbow_%d" % k), "elbow", n=N, seed=20 + k,
                                                   ablation=masses_and_deltas(k, perm)))
                    for k, perm in enumerate((IDENTITY, TOP_SWAPPED, IDENTITY))]
            records = [ablation.run_record(r) for r in runs]
            self.assertEqual(json.loads(json.dumps(records)), records)
            self.assertEqual([r["n_ticks"] for r in records], [N] * 3)
            self.assertEqual([r["matches"] for r in records], [N, 0, N])
            self.assertEqual(records[1]["tick_rho"], [[0.9, N]])
            self.assertEqual(repr(ablation.summary_from_records(records, 200, 1)),
                             repr(ablation.ablation_summary([[r] for r in runs], 200, 1)))
        finally:
            shutil.rmtree(tmp)


if __name__ == "__main__":
    unittest.main()
