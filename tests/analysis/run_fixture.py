"""Writes small nao_rt run directories in the documented formats (docs/nao_rt.md,
docs/attention_bin.md), independently of the analysis' reader: struct for the header, a
byte-wise FNV-1a for the checksums. The tests then break them on purpose.

A fixture run: n ticks at 10 Hz, smooth joint motion inside the URDF limits, attention scores
that are noise except for one planted joint whose score follows that joint's velocity.
"""

import json
import math
import os
import struct
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.normpath(os.path.join(HERE, "..", ".."))
ANALYSIS = os.path.join(REPO, "toolchain", "analysis")
if ANALYSIS not in sys.path:
    sys.path.insert(0, ANALYSIS)

JOINTS = ("RShoulderPitch", "RShoulderRoll", "RElbowYaw", "RElbowRoll", "RWristYaw")
HEADER_FORMAT = "<8sIIQQQQQ8IQ"  # docs/attention_bin.md, 96 bytes
FAULT_HUMAN_TIMEOUT = 2


def fnv1a64(data):
    h = 0xCBF29CE484222325
    for b in data:
        h = ((h ^ b) * 0x100000001B3) & 0xFFFFFFFFFFFFFFFF
    return h


def _f(x):
    return "nan" if not np.isfinite(x) else repr(float(x))


def make_series(n, seed, planted_joint):
    """Joint angles q (n, 5), attention scores att (n, 5, float32) and t_s (n,)."""
    rng = np.random.default_rng(seed)
    t = 0.1 * np.arange(n)
    centre = np.array([0.5, -0.5, 0.0, 0.8, 0.0])
    amp = np.array([0.8, 0.4, 1.0, 0.5, 1.2])
    freq = np.array([0.23, 0.31, 0.17, 0.41, 0.29])
    q = centre + amp * np.sin(2 * np.pi * freq * t[:, None] + rng.uniform(0, 2 * np.pi, 5))
    v = np.gradient(q, t, axis=0)
    att = 12.0 + 2.0 * rng.standard_normal((n, 5))
    if planted_joint is not None:
        vj = v[:, planted_joint]
        att[:, planted_joint] = 12.0 + 3.0 * vj / vj.std() + 0.3 * rng.standard_normal(n)
    return t, q, att.astype(np.float32)


def ar1(n, phi, rng, burn=200):
    """(n,) AR(1) series x_i = phi x_{i-1} + e_i with unit-variance innovations, after a burn-in."""
    e = rng.standard_normal(n + burn)
    x = np.zeros(n + burn)
    for i in range(1, n + burn):
        x[i] = phi * x[i - 1] + e[i]
    return x[burn:]


def ar1_rollout(n, rng, phi=0.9, planted_joint=None):
    """(t_s, q, att) of one smooth "rollout": every joint's velocity an AR(1) series (phi, about
    0.3 rad/s), q its integral; every score an AR(1) series of its own, independent of the motion
    unless planted_joint names a joint whose score then follows that joint's velocity."""
    t = 0.1 * np.arange(n)
    centre = np.array([0.5, -0.5, 0.0, 0.8, 0.0])
    v = np.column_stack([ar1(n, phi, rng) for _ in range(5)]) * 0.3 * math.sqrt(1 - phi * phi)
    q = centre + 0.1 * np.cumsum(v, axis=0)
    att = 12.0 + 2.0 * math.sqrt(1 - phi * phi) * np.column_stack([ar1(n, phi, rng) for _ in range(5)])
    if planted_joint is not None:
        vj = np.gradient(q[:, planted_joint], t)
        att[:, planted_joint] = 12.0 + 3.0 * vj / vj.std() + 0.5 * rng.standard_normal(n)
    return t, q, att.astype(np.float32)


def write_near_copy_runs(root, movement, seed, n_series=3, n_runs=16, planted_joint=None, min_len=100,
                         max_len=150):
    """The near-copy protocol on independent series: n_series AR(1) rollouts (ar1_rollout), cut
    into n_runs run directories root/<movement>_<k> (run k is series k mod n_series, its first
    100..150 ticks), as nao_rt's autonomous runs from a few start poses are. Returns the paths."""
    rng = np.random.default_rng(seed)
    series = [ar1_rollout(max_len, rng, planted_joint=planted_joint) for _ in range(n_series)]
    paths = []
    for k in range(n_runs):
        n = int(rng.integers(min_len, max_len + 1))
        t, q, att = series[k % n_series]
        paths.append(write_run(os.path.join(root, "%s_%02d" % (movement, k)), movement, n=n, seed=seed + k,
                               series=(t[:n], q[:n], att[:n])))
    return paths


def write_run(path, movement, n=80, seed=0, planted_joint=3, bypass=(), layers=1, heads=2, d_model=8, series=None,
              ablation=None):
    """Writes ticks.csv, attention.bin, summary.json into path (created). Ticks in `bypass`
    get fault human_timeout (the policy bypassed) and a stale score of 0. series: (t_s, q, att)
    to write instead of make_series(n, seed, planted_joint). ablation: (mass (n, 5), delta (n, 5))
    written as ablation.csv, the masses also as attention.bin's mass."""
    os.makedirs(path, exist_ok=True)
    t, q, att = series if series is not None else make_series(n, seed, planted_joint)
    att = np.array(att, dtype=np.float32)
    n = len(t)
    fault = np.zeros(n, dtype=np.int64)
    for i in bypass:
        fault[i] = FAULT_HUMAN_TIMEOUT
        att[i] = 0.0
    from nao_analysis import kinematics  # hand points only; the reader never checks them

    arm = kinematics.load_arm_model()
    ee = kinematics.hand_position(arm, q)
    q_ref = q + 0.05
    r = np.round(q_ref * 2) / 2  # piecewise-constant "key poses"
    ee_ref = kinematics.hand_position(arm, r)
    a = np.vstack([np.diff(q, axis=0), np.zeros((1, 5))])
    cols = (["tick", "t_s"] + ["%s_%d" % (c, j) for c in ("q_ref", "r", "a", "q_cmd", "q") for j in range(5)]
            + ["ee_x", "ee_y", "ee_z", "ee_ref_x", "ee_ref_y", "ee_ref_z"] + ["att_%d" % j for j in range(5)]
            + ["fault", "tick_us", "retarget_us", "policy_us", "sim_us"])
    with open(os.path.join(path, "ticks.csv"), "w") as f:
        f.write(",".join(cols) + "\n")
        for i in range(n):
            vals = ([str(i), _f(t[i])] + [_f(x) for x in q_ref[i]] + [_f(x) for x in r[i]] + [_f(x) for x in a[i]]
                    + [_f(x) for x in q[i] + a[i]] + [_f(x) for x in q[i]] + [_f(x) for x in ee[i]]
                    + [_f(x) for x in ee_ref[i]] + [_f(x) for x in att[i]] + [str(fault[i]), "0", "0", "0", "0"])
            f.write(",".join(vals) + "\n")

    # attention.bin: payload format 2 with a small architecture and a window of 4 ticks.
    rng = np.random.default_rng(seed + 100)
    T, W = 5, 4
    data_bytes = 16 + 4 * (T + T + W + layers * heads * T * T + T * d_model)
    pad = (8 - data_bytes % 8) % 8
    payload = data_bytes + pad + 8
    records = []
    for i in range(n):
        logits = rng.standard_normal((layers, heads, T, T))
        alpha = np.exp(logits) / np.exp(logits).sum(axis=-1, keepdims=True)
        mass = alpha[-1].mean(axis=(0, 1)) if ablation is None else np.asarray(ablation[0][i], dtype=float)
        ages = rng.random(W)
        body = (struct.pack("<QII", i, int(fault[i]), 0) + att[i].astype("<f4").tobytes()
                + mass.astype("<f4").tobytes() + (ages / ages.sum()).astype("<f4").tobytes()
                + alpha.astype("<f4").tobytes()
                + (rng.standard_normal((T, d_model)) + 0.01 * i).astype("<f4").tobytes() + b"\0" * pad)
        records.append(body + struct.pack("<Q", fnv1a64(body)))
    header = struct.pack(HEADER_FORMAT, b"NAOATTN1", 1, 96, n, 0, payload, 1024, n,
                         2, layers, heads, T, d_model, W, 0, 0, 0)
    assert len(header) == 96 and all(len(rec) == payload for rec in records)
    with open(os.path.join(path, "attention.bin"), "wb") as f:
        f.write(header + b"".join(records))

    summary = {"ticks": n, "period_s": 0.1, "duration_s": 0.1 * n,
               "faults": {"no_human": 0, "human_timeout": len(bypass), "nonfinite_keypoints": 0,
                          "ik_not_converged": 0, "policy_nonfinite": 0, "overrun": 0, "command_limited": 0},
               "ee_rmse_m": float(np.sqrt(np.mean(np.sum((ee - ee_ref) ** 2, axis=1)))), "ee_rmse_ticks": n,
               "model": {"path": "compiled-in", "checksum": "0x0", "conditioning": "reference"},
               "reference": "synthetic:%s (seed 1000001, index 0)" % movement, "movement": movement, "seed": 1,
               "realtime": False, "zero_timing": True,
               "attention": {"file": "attention.bin", "shm": None, "records_written": n, "first_record": 0,
                             "record_count": n}}
    with open(os.path.join(path, "summary.json"), "w") as f:
        json.dump(summary, f, indent=2)
    if ablation is not None:
        with open(os.path.join(path, "ablation.csv"), "w") as f:
            f.write(",".join(["tick"] + ["mass_%d" % j for j in range(5)] + ["delta_%d" % j for j in range(5)]) + "\n")
            for i in range(n):
                f.write(",".join([str(i)] + [repr(float(np.float32(x))) for x in ablation[0][i]]
                                 + [_f(x) for x in ablation[1][i]]) + "\n")
    return path
