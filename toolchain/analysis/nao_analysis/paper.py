"""The paper's Table 2 (Tsunekawa & Sekiyama, Machines 2025, 13, 1133, section 4.2), copied so
that docs/reproduction.md can be regenerated without the paper at hand.

The paper names the five joints (q_pitch shoulder, q_yaw shoulder, q_roll elbow, q_yaw elbow,
q_roll wrist) in NAOqi's order but with its own names; its Table 1 ranges identify them: its
"Elbow Roll" has NAO's range -119.5..+119.5 deg, which is RElbowYaw (+-2.0857 rad), and its
"Elbow Yaw" +2.0..+88.5 deg is RElbowRoll. So the paper's "Elbow roll" rows are our RElbowYaw.
"""

# movement (ours), paper's movement label, paper's joint label, our joint, rho, tau, r, MI bits
PAPER_TABLE2 = (
    ("whole_arm", "Whole-arm body movement", "Shoulder pitch", "RShoulderPitch", 0.5935, 0.3074, 0.6055, 1.453),
    ("whole_arm", "Whole-arm body movement", "Elbow roll", "RElbowYaw", 0.8465, 0.7085, 0.8162, 1.606),
    ("elbow", "Elbow-weighted body movements", "Shoulder pitch", "RShoulderPitch", 0.6769, 0.5917, 0.8231, 1.351),
    ("elbow", "Elbow-weighted body movements", "Elbow roll", "RElbowYaw", 0.7320, 0.6109, 0.5867, 1.772),
    ("wrist", "Wrist-weighted body movements", "Elbow roll", "RElbowYaw", 0.8779, 0.7027, 0.9488, 1.073),
)

CITATION = ("Y. Tsunekawa, K. Sekiyama, \"Dynamic Attention Analysis of Body Parts in Transformer-Based "
            "Human-Robot Imitation Learning with the Embodiment Gap\", Machines 13(12):1133, 2025, "
            "doi:10.3390/machines13121133")
