"""Forward kinematics of the NAO V6 right arm, read from the project's URDF.

Used for the figures only: the robot's stick figure and the hand path of the retargeted human
reference q_ref (ticks.csv has the robot's hand point ee_* and the feature-extracted target
ee_ref_*, not the hand point of q_ref). Checked against the runtime's FK (ticks.csv ee_*) in
tests/analysis/test_kinematics.py. Frames: docs/notation.md (T torso, x forward, y left, z up).
"""

import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np

from . import JOINT_NAMES, AnalysisError

DEFAULT_URDF = os.path.normpath(os.path.join(os.path.dirname(__file__), "..", "..", "..", "urdf",
                                             "nao_v6_right_arm.urdf"))
HAND_JOINT = "RHandPoint"  # the fixed joint whose child is the hand point r_hand


@dataclass(frozen=True)
class ArmModel:
    """The chain torso -> 5 revolute joints -> hand point, in the project's joint order."""
    X_PJ: np.ndarray   # (5, 4, 4) each joint frame in its parent joint frame at q = 0
    axis_J: np.ndarray  # (5, 3) each joint's rotation axis in its own frame (unit)
    X_WH: np.ndarray   # (4, 4) hand point frame in the wrist (RWristYaw) frame
    q_min: np.ndarray  # (5,) lower position limits, rad
    q_max: np.ndarray  # (5,) upper position limits, rad


def _origin(element):
    """4x4 transform of a URDF <origin xyz rpy> (fixed-axis roll-pitch-yaw: R = Rz Ry Rx)."""
    xyz = np.zeros(3)
    rpy = np.zeros(3)
    o = element.find("origin")
    if o is not None:
        xyz = np.array([float(v) for v in o.get("xyz", "0 0 0").split()])
        rpy = np.array([float(v) for v in o.get("rpy", "0 0 0").split()])
    cr, cp, cy = np.cos(rpy)
    sr, sp, sy = np.sin(rpy)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    x = np.eye(4)
    x[:3, :3] = rz @ ry @ rx
    x[:3, 3] = xyz
    return x


def load_arm_model(path=DEFAULT_URDF):
    """Parses the URDF's right-arm chain. Raises AnalysisError when a joint is missing."""
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as e:
        raise AnalysisError("%s: cannot read the URDF: %s" % (path, e)) from None
    joints = {j.get("name"): j for j in root.findall("joint")}
    X_PJ, axes, limits = [], [], []
    parent_link = None
    for name in JOINT_NAMES:
        j = joints.get(name)
        if j is None or j.get("type") != "revolute":
            raise AnalysisError("%s: no revolute joint %s" % (path, name))
        # The chain must be serial in DESIGN order: each joint's parent is the previous child.
        if parent_link is not None and j.find("parent").get("link") != parent_link:
            raise AnalysisError("%s: joint %s does not follow the previous joint's link" % (path, name))
        parent_link = j.find("child").get("link")
        X_PJ.append(_origin(j))
        a = j.find("axis")
        axis = np.array([float(v) for v in (a.get("xyz") if a is not None else "1 0 0").split()])
        axes.append(axis / np.linalg.norm(axis))
        lim = j.find("limit")
        if lim is None:
            raise AnalysisError("%s: joint %s has no <limit>" % (path, name))
        limits.append((float(lim.get("lower")), float(lim.get("upper"))))
    hand = joints.get(HAND_JOINT)
    if hand is None or hand.find("parent").get("link") != parent_link:
        raise AnalysisError("%s: no fixed joint %s after %s" % (path, HAND_JOINT, JOINT_NAMES[-1]))
    limits = np.array(limits)
    return ArmModel(X_PJ=np.array(X_PJ), axis_J=np.array(axes), X_WH=_origin(hand),
                    q_min=limits[:, 0], q_max=limits[:, 1])


def _rotation(axis, angle):
    """Rotation matrices about a unit axis for an array of angles: (n, 3, 3) (Rodrigues)."""
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    s = np.sin(angle)[:, None, None]
    c = np.cos(angle)[:, None, None]
    return np.eye(3) + s * k + (1 - c) * (k @ k)


def arm_points(model, q):
    """Joint origins and the hand point for every row of q.

    q: (n, 5) joint angles, rad, DESIGN order. Returns p_T (n, 6, 3), m, torso frame: the
    RShoulderPitch, RShoulderRoll, RElbowYaw, RElbowRoll and RWristYaw origins, then the hand
    point H (NAOqi "RArm" effector; the runtime's ee_*)."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    n = q.shape[0]
    X = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    points = np.empty((n, len(JOINT_NAMES) + 1, 3))
    for j in range(len(JOINT_NAMES)):
        X = X @ model.X_PJ[j]
        points[:, j] = X[:, :3, 3]
        R = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
        R[:, :3, :3] = _rotation(model.axis_J[j], q[:, j])
        X = X @ R
    points[:, -1] = (X @ model.X_WH)[:, :3, 3]
    return points


def hand_position(model, q):
    """p_TH (n, 3), m: the hand point for every row of q (n, 5)."""
    return arm_points(model, q)[:, -1]
