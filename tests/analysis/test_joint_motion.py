"""toolchain/analysis/joint_motion.py on evaluate-shaped directories whose answers are known in
closed form: sinusoids of known amplitude and frequency, and a drift."""

import os
import shutil
import tempfile
import unittest

import numpy as np

import run_fixture  # noqa: F401  (puts toolchain/analysis on the path)
import joint_motion as jm


def write_q(path, q, with_t=False):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w", encoding="utf-8") as fh:
        cols = (["t_s"] if with_t else []) + ["q_%d" % j for j in range(5)]
        fh.write(",".join(cols) + "\n")
        for i, row in enumerate(q):
            vals = ([0.1 * i] if with_t else []) + list(row)
            fh.write(",".join(repr(float(v)) for v in vals) + "\n")


def sines(n, amp, freq_hz, phase=0.0):
    """(n, 5): joint j is amp[j] sin(2π f_j t + phase) at 10 Hz."""
    t = 0.1 * np.arange(n)[:, None]
    return np.asarray(amp)[None, :] * np.sin(2 * np.pi * np.asarray(freq_hz)[None, :] * t + phase)


class JointMotion(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.mkdtemp(prefix="nao_joint_motion_")

    def tearDown(self):
        shutil.rmtree(self.tmp)

    def test_middle_stretch_is_evaluates(self):
        q = np.arange(10, dtype=float)[:, None].repeat(5, axis=1)
        np.testing.assert_array_equal(jm.middle(q)[:, 0], [2, 3, 4, 5, 6, 7])
        q = np.arange(11, dtype=float)[:, None].repeat(5, axis=1)
        np.testing.assert_array_equal(jm.middle(q)[:, 0], [2, 3, 4, 5, 6, 7, 8])

    def test_velocity_and_amplitude_of_a_sinusoid(self):
        # Whole periods of 20 ticks: 500 ticks give a middle stretch of 300 points (15 periods),
        # 501 ticks one of 301 points, whose 300 steps are 15 periods. The standard deviation of
        # A sin is A/√2, the RMS of its finite-difference velocity 2A sin(π f T)/(T √2).
        amp = np.array([0.1, 0.2, 0.3, 0.05, 0.4])
        f = 0.5
        np.testing.assert_allclose(jm.amplitude(sines(500, amp, np.full(5, f))), amp / np.sqrt(2), rtol=1e-9)
        q = sines(501, amp, np.full(5, f))
        want_v = 2 * amp * np.sin(np.pi * f * 0.1) / (0.1 * np.sqrt(2))
        np.testing.assert_allclose(jm.velocity(q), want_v, rtol=1e-9)

    def test_ratios_per_joint_from_an_evaluate_directory(self):
        amp = np.array([0.1, 0.2, 0.3, 0.05, 0.4])
        freq = np.array([0.5, 0.5, 0.25, 0.5, 0.5])
        m = os.path.join(self.tmp, "wrist")
        for k in range(4):
            write_q(os.path.join(m, "demos", "d%d.csv" % k), sines(400, amp, freq, phase=0.3 * k), with_t=True)
            # The runs: joint 0 at twice the amplitude, joint 2 at twice the frequency, joint 4
            # still; joints 1 and 3 as demonstrated.
            ra = amp * np.array([2.0, 1.0, 1.0, 1.0, 0.0])
            rf = freq * np.array([1.0, 1.0, 2.0, 1.0, 1.0])
            write_q(os.path.join(m, "autonomous", "d%d" % k, "ticks.csv"), sines(400, ra, rf, phase=0.3 * k))
        r = jm.eval_motion(self.tmp)["wrist"]
        self.assertEqual((r["runs"], r["demos"]), (4, 4))
        np.testing.assert_allclose(r["amplitude_ratio"], [2, 1, 1, 1, 0], atol=0.02)
        # Twice the frequency: the finite-difference velocity grows by sin(2πfT)/sin(πfT).
        v2 = np.sin(2 * np.pi * 0.25 * 0.1) / np.sin(np.pi * 0.25 * 0.1)
        np.testing.assert_allclose(r["velocity_ratio"], [2, 1, v2, 1, 0], atol=0.02)

    def test_a_drift_counts_in_the_amplitude_not_as_a_circle(self):
        n = 200
        demo = np.zeros((n, 5))
        run = np.zeros((n, 5))
        run[:, 1] = np.linspace(0.0, 0.6, n)  # a steady drift of joint 1
        m = os.path.join(self.tmp, "elbow")
        write_q(os.path.join(m, "demos", "a.csv"), demo + 1e-3 * sines(n, np.ones(5), np.full(5, 0.5)), with_t=True)
        write_q(os.path.join(m, "autonomous", "a", "ticks.csv"), run + 1e-3 * sines(n, np.ones(5), np.full(5, 0.5)))
        r = jm.eval_motion(self.tmp)["elbow"]
        self.assertGreater(r["amplitude_ratio"][1], 50)
        self.assertAlmostEqual(r["amplitude_ratio"][0], 1.0, places=6)

    def test_an_empty_or_foreign_directory_is_an_error(self):
        with self.assertRaises(jm.MotionError):
            jm.eval_motion(self.tmp)
        write_q(os.path.join(self.tmp, "m", "autonomous", "r", "ticks.csv"), np.zeros((5, 5)))
        with self.assertRaises(jm.MotionError):  # runs but no demonstrations
            jm.eval_motion(self.tmp)
        bad = os.path.join(self.tmp, "m", "demos", "x.csv")
        os.makedirs(os.path.dirname(bad))
        with open(bad, "w", encoding="utf-8") as fh:
            fh.write("t_s,a,b\n0,1,2\n")
        with self.assertRaises(jm.MotionError):
            jm.eval_motion(self.tmp)
        self.assertEqual(jm.main(["joint_motion.py", self.tmp]), 1)


if __name__ == "__main__":
    unittest.main()
