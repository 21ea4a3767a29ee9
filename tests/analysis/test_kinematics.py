"""The analysis' forward kinematics (stick figures, the human-derived hand path) against the
runtime's: ee_x/ee_y/ee_z of real nao_rt ticks.csv rows (data/ticks_fk_excerpt.csv, every 6th
tick of the three demo runs of the first analysis)."""

import csv
import os
import unittest

import numpy as np

import run_fixture
from nao_analysis import kinematics

EXCERPT = os.path.join(run_fixture.HERE, "data", "ticks_fk_excerpt.csv")


class ForwardKinematics(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.arm = kinematics.load_arm_model()

    def test_hand_point_matches_the_runtime_fk_on_real_ticks(self):
        with open(EXCERPT) as f:
            rows = list(csv.DictReader(f))
        self.assertGreater(len(rows), 50)
        q = np.array([[float(r["q_%d" % j]) for j in range(5)] for r in rows])
        ee = np.array([[float(r[c]) for c in ("ee_x", "ee_y", "ee_z")] for r in rows])
        err = np.abs(kinematics.hand_position(self.arm, q) - ee).max()
        self.assertLess(err, 1e-12, "largest difference from the runtime's hand point: %g m" % err)

    def test_zero_pose_is_the_arm_straight_forward_with_the_urdf_offsets(self):
        p = kinematics.arm_points(self.arm, np.zeros((1, 5)))[0]
        np.testing.assert_allclose(p[0], [0, -0.098, 0.100], atol=1e-15)  # shoulder
        np.testing.assert_allclose(p[2], [0.105, -0.113, 0.100], atol=1e-15)  # elbow
        np.testing.assert_allclose(p[4], [0.105 + 0.05595, -0.113, 0.100], atol=1e-15)  # wrist
        np.testing.assert_allclose(p[5], [0.105 + 0.05595 + 0.05775, -0.113, 0.100 - 0.01231], atol=1e-15)

    def test_a_shoulder_pitch_of_90_degrees_points_the_arm_down(self):
        # RShoulderPitch turns about +y: a positive angle takes the forward arm down (NAOqi).
        q = np.array([[np.pi / 2, 0, 0, 0, 0]])
        hand = kinematics.hand_position(self.arm, q)[0]
        self.assertAlmostEqual(hand[0], -0.01231, places=12)
        self.assertAlmostEqual(hand[2], 0.100 - (0.105 + 0.05595 + 0.05775), places=12)

    def test_limits_come_from_the_urdf(self):
        np.testing.assert_allclose(self.arm.q_min, [-2.08567, -1.32645, -2.08567, 0.0349066, -1.82387])
        np.testing.assert_allclose(self.arm.q_max, [2.08567, 0.314159, 2.08567, 1.54462, 1.82387])


if __name__ == "__main__":
    unittest.main()
