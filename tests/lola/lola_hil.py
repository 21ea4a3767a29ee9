#!/usr/bin/python3
"""Hardware-in-the-loop tests of nao_rt's LoLA backend (docs/lola.md), one CTest test per case.

    lola_hil.py --nao-rt BIN [--slow-rt BIN] --sim BIN --toolchain BIN CASE

The human references are recorded ones: demonstration 0 of run seed 1000001 (toolchain/nao demo's),
synthesised and triangulated by nao_toolchain into the case's temporary directory.

CASE:
  movement:M   nao_lola_sim + `nao_rt --robot lola:PATH --reference file:SKELETON --movement M` against
               the in-process run of the same reference: hand RMSE, allocations, answers within the
               cycle, the stiffness ramps, no joint but the right arm's commanded away from start.
  fault:F      one injected fault (drop, delay, garbage, bad_length, heat, misread, close, silence,
               sigterm, no_robot): it ends as docs/lola.md specifies, never a crash or a hang.
  peer:sim     python3-msgpack (an independent MessagePack implementation) as LoLA client
               of nao_lola_sim: keys, lengths, joint order.
  peer:client  python3-msgpack as the LoLA robot that nao_rt talks to: keys, lengths, joint
               order, and a malformed packet counted and skipped.
  io:M         movement:M with --lola-io-thread (the I/O on a thread of its own) and --realtime
               (SCHED_FIFO + mlockall, inherited by the I/O thread).
  iofault:F    fault:F with --lola-io-thread.
  slow:io_thread  ticks 30 ms longer (--slow-rt, nao_rt_slow_cpu: nao_rt on a slower CPU): late
               answers on one thread, none with --lola-io-thread.

Every process runs under a timeout; a hang fails the test.
"""
import argparse
import csv
import hashlib
import json
import os
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time

import msgpack

# lola.md: the 25 joints, the right arm at 18..22, the two packets' keys and lengths.
JOINTS = ["HeadYaw", "HeadPitch", "LShoulderPitch", "LShoulderRoll", "LElbowYaw", "LElbowRoll", "LWristYaw",
          "LHipYawPitch", "LHipRoll", "LHipPitch", "LKneePitch", "LAnklePitch", "LAnkleRoll", "RHipRoll",
          "RHipPitch", "RKneePitch", "RAnklePitch", "RAnkleRoll", "RShoulderPitch", "RShoulderRoll",
          "RElbowYaw", "RElbowRoll", "RWristYaw", "LHand", "RHand"]
ARM = [18, 19, 20, 21, 22]
SENSOR_KEYS = {"Position": 25, "Stiffness": 25, "Temperature": 25, "Current": 25, "Status": 25,
               "Accelerometer": 3, "Gyroscope": 3, "Angles": 2, "FSR": 8, "Touch": 14, "Sonar": 2,
               "Battery": 4, "RobotConfig": 4}
ACTUATOR_KEYS = {"Position": 25, "Stiffness": 25, "Chest": 3, "LEar": 10, "REar": 10, "LEye": 24, "REye": 24,
                 "LFoot": 3, "RFoot": 3, "Skull": 12, "Sonar": 2}
CYCLE_S = 0.012
HOME = [1.40, -0.20, 1.20, 0.50, 0.00]  # nao_rt's home pose = nao_lola_sim's default arm start
RAMP_CYCLES = 42                        # >= 0.5 s of 12 ms cycles
ARM_STIFFNESS, HOLD_STIFFNESS, HOT_SCALE = 1.0, 0.6, 0.5  # LolaParams defaults (docs/lola.md)

failures = []


def check(cond, what):
    print(("ok    " if cond else "FAIL  ") + what, flush=True)
    if not cond:
        failures.append(what)


def f32(x):
    return struct.unpack("f", struct.pack("f", x))[0]


class Sim:
    """nao_lola_sim on a temporary socket; stop() returns its summary and received packets."""

    def __init__(self, exe, tmp, args=(), seconds=120):
        self.path = os.path.join(tmp, "lola.sock")
        self.log = os.path.join(tmp, "sim_rx.csv")
        self.summary = os.path.join(tmp, "sim_summary.json")
        self.proc = subprocess.Popen([exe, "--socket", self.path, "--seconds", str(seconds), "--log", self.log,
                                      "--summary", self.summary, *args])
        for _ in range(500):
            if os.path.exists(self.path):
                return
            time.sleep(0.01)
        raise RuntimeError("nao_lola_sim did not create its socket")

    def stop(self):
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        self.proc.wait(timeout=20)
        with open(self.summary) as f:
            summary = json.load(f)
        with open(self.log) as f:
            rows = list(csv.DictReader(f))
        return summary, rows


def reference(a, tmp, movement):
    """nao_rt's arguments for the recorded reference of `movement`: made once per case, or once for
    all cases under --references (named by the SHA-256 of the nao_toolchain that made it, so another
    build makes its own; written beside and renamed into place, so a reader never sees half of one)."""
    if a.references:
        with open(a.toolchain, "rb") as f:
            root = os.path.join(a.references, hashlib.sha256(f.read()).hexdigest()[:16])
    else:
        root = os.path.join(tmp, "references")
    skeleton = os.path.join(root, movement + "_000", "skeleton.csv")
    if not os.path.exists(skeleton):
        os.makedirs(root, exist_ok=True)
        work = tempfile.mkdtemp(prefix=movement + ".", dir=root)
        demo = os.path.join(work, movement + "_000")
        for cmd in ([a.toolchain, "synth", "--movement", movement, "--per-movement", "1", "--seed", "1000001", "--out",
                     work],
                    [a.toolchain, "triangulate", "--demo", demo, "--max-gap", "0", "--out",
                     os.path.join(demo, "skeleton.csv")]):
            p = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
            if p.returncode != 0:
                raise SystemExit("reference of %s: %s failed: %s" % (movement, " ".join(cmd), p.stderr[-1000:]))
        try:
            os.rename(demo, os.path.dirname(skeleton))
        except OSError:
            if not os.path.exists(skeleton):  # not another case's, made meanwhile
                raise
        shutil.rmtree(work, ignore_errors=True)
    return ["--reference", "file:" + skeleton, "--movement", movement]


def run_rt(exe, args, timeout):
    t0 = time.monotonic()
    p = subprocess.run([exe, *args], capture_output=True, text=True, timeout=timeout)
    print(p.stdout + p.stderr, end="", flush=True)
    return p.returncode, time.monotonic() - t0


def summary_of(d):
    with open(os.path.join(d, "summary.json")) as f:
        return json.load(f)


def pos(row, i):
    return float(row["pos_" + JOINTS[i]])


def stiff(row, i):
    return float(row["stiff_" + JOINTS[i]])


def own_late(lola):
    """nao_rt's late answers that its own work made: the others (late_descheduled) waited for a
    CPU, which measures the machine's load, not the code (docs/lola.md)."""
    return lola["late"] - lola["late_descheduled"]


def check_answers(rows, label, lola):
    """>= 99 % of the sensor packets between the first and the last answer answered within their
    cycle, not counting those nao_rt answered late while it waited for a CPU."""
    cycles = [int(r["cycle"]) for r in rows]
    first, last = min(cycles), max(cycles)
    in_cycle = sum(int(r["in_cycle"]) for r in rows)
    total = last - first + 1
    check(in_cycle + lola["late_descheduled"] >= 0.99 * total,
          f"{label}: {in_cycle} of {total} sensor packets answered within their 12 ms cycle, "
          f"{lola['late_descheduled']} late for want of a CPU (>= 99 % together)")


def check_start_and_stop(rows, label, expect_stop_ramp=True):
    # Start: the first answer commands back what was measured, at low stiffness; the stiffness
    # rises monotonically to nominal over >= 0.5 s; the arm's positions are held during the ramp.
    first = rows[0]
    check(all(stiff(first, i) <= 0.05 for i in range(25)),
          f"{label}: first answer's stiffness <= 0.05 (max {max(stiff(first, i) for i in range(25)):.3f})")
    full = next((k for k, r in enumerate(rows) if abs(stiff(r, ARM[0]) - ARM_STIFFNESS) < 1e-6), None)
    check(full is not None and full >= RAMP_CYCLES,
          f"{label}: arm stiffness reaches {ARM_STIFFNESS} after {full} cycles (>= {RAMP_CYCLES}, 0.5 s)")
    if full is not None:
        mono = all(stiff(rows[k + 1], i) >= stiff(rows[k], i) for k in range(full) for i in range(25))
        check(mono, f"{label}: stiffness never falls during the start ramp")
        held = all(pos(rows[k], i) == pos(first, i) for k in range(full + 1) for i in range(25))
        check(held, f"{label}: every joint commanded at its measured start position during the ramp")
    # No joint other than the right arm's is ever commanded away from its start.
    moved = [JOINTS[i] for i in range(25) if i not in ARM and any(pos(r, i) != pos(first, i) for r in rows)]
    check(not moved, f"{label}: no joint outside the right arm commanded away from its start (moved: {moved})")
    if expect_stop_ramp:
        last = rows[-1]
        check(all(stiff(last, i) == 0.0 for i in range(25)), f"{label}: the last answer has stiffness 0 everywhere")
        tail = [stiff(r, ARM[0]) for r in rows[-RAMP_CYCLES:]]
        check(all(b <= a for a, b in zip(tail, tail[1:])) and tail[0] > 0.5 * ARM_STIFFNESS,
              f"{label}: the arm's stiffness ramps down to 0 over the last {RAMP_CYCLES} answers")
        hold = all(pos(r, i) == pos(rows[-RAMP_CYCLES], i) for r in rows[-RAMP_CYCLES:] for i in ARM)
        check(hold, f"{label}: the arm holds its position while the stiffness ramps down")


def check_realtime(s, asked):
    """--realtime on LoLA: SCHED_FIFO + mlockall taken before the I/O thread starts, so the I/O
    thread runs SCHED_FIFO too; where the machine refuses it, both stay as they were and the run
    goes on (one warning). Without --realtime nothing is changed."""
    check(s["realtime"] == asked, f"summary.json realtime {s['realtime']} (asked: {asked})")
    io = s["lola"]["io_thread_scheduling"]
    if not asked:
        check(io in (None, "SCHED_OTHER 0"), f"without --realtime the I/O thread is SCHED_OTHER ({io})")
        return
    granted = s["realtime_scheduling"] == "SCHED_FIFO + mlockall"
    print(f"info  --realtime on LoLA: {s['realtime_scheduling']}; I/O thread {io}")
    check(s["skipped_periods"] == 0, "LoLA's clock paces the run: no 100 ms grid, no skipped period")
    if s["lola"]["io_thread"]:
        want = "SCHED_FIFO 50" if granted else "SCHED_OTHER 0"
        check(io == want, f"the I/O thread inherits the control thread's scheduling: {io} (expected {want})")


def case_movement(a, movement, tmp, flags=()):
    ode_dir, hil_dir = os.path.join(tmp, "ode"), os.path.join(tmp, "hil")
    rc, _ = run_rt(a.nao_rt, [*reference(a, tmp, movement), "--log", ode_dir], 300)
    check(rc == 0, f"in-process run exits 0 (got {rc})")
    ode = summary_of(ode_dir)
    ticks = ode["ticks"]
    sim = Sim(a.sim, tmp)
    rc, wall = run_rt(a.nao_rt, ["--robot", "lola:" + sim.path, *reference(a, tmp, movement),
                                 "--ticks", str(ticks), "--log", hil_dir, *flags], ticks * 0.1 + 60)
    ss, rows = sim.stop()
    check(rc == 0, f"LoLA run exits 0 (got {rc})")
    hil = summary_of(hil_dir)
    check(hil["robot"] == "lola" and ode["robot"] == "ode", "summary.json robot: lola / ode")
    check(hil["ticks"] == ticks, f"LoLA run completes {ticks} ticks (got {hil['ticks']})")
    d = abs(hil["ee_rmse_m"] - ode["ee_rmse_m"])
    print(f"info  hand RMSE: LoLA {hil['ee_rmse_m'] * 1e3:.3f} mm, in process {ode['ee_rmse_m'] * 1e3:.3f} mm, "
          f"difference {d * 1e3:.3f} mm; lola {hil['lola']}; sim {ss}")
    # LoLA applies a command one 12 ms cycle after the packet it answers; the in-process arm
    # applies it at once. With the residual default model and the calibrated human scale that
    # cycle costs 0.38-0.58 mm of RMSE (measured on the three movements; it was 1.5-2.4 mm when the
    # arm tracked 5-13 mm off): the 1 mm and 1 cm are hard bounds now.
    check(d < 1e-3, f"hand RMSE within 1 mm of the in-process run's (difference {d * 1e3:.3f} mm)")
    check(hil["ee_rmse_m"] < 0.01, f"hand RMSE < 1 cm (got {hil['ee_rmse_m'] * 1e3:.2f} mm)")
    check(hil["allocations_after_activate"] == 0,
          f"0 allocations after activate (got {hil['allocations_after_activate']})")
    lola = hil["lola"]
    if "--lola-io-thread" in flags:
        check(lola["io_thread"] and lola["io_allocations"] == 0 and lola["overrun_ticks"] == 0,
              f"the I/O thread ran, counted 0 allocations of its own and no tick overran: {lola}")
    else:
        check(lola["io_thread_scheduling"] is None, "one thread: no I/O thread scheduling reported")
    check_realtime(hil, "--realtime" in flags)
    check(lola["malformed"] == 0 and lola["gaps"] == 0 and lola["tracking_cycles"] == 0 and lola["hot_cycles"] == 0
          and lola["cycles"] > ticks * 8, f"no robot fault counted without an injected one: {lola}")
    check(own_late(lola) <= 0.01 * lola["cycles"],
          f"nao_rt counts <= 1 % late answers of its own making ({own_late(lola)} of {lola['cycles']}; "
          f"{lola['late_descheduled']} more waited for a CPU)")
    if "--lola-io-thread" not in flags:
        # One thread: the cache is warmed before every tick's packet unless that packet came
        # first (the sim's 12 ms clock; a late previous packet makes the next one early).
        check(lola["warm"] and lola["warm_skipped"] <= 0.5 * ticks,
              f"the policy's memory warmed before most ticks' packets (skipped {lola['warm_skipped']} of {ticks})")
    check_answers(rows, movement, lola)
    check_start_and_stop(rows, movement)


FAULTS = {
    # name: (sim flags, expected nao_rt exit status, check(summary, sim summary, rows))
    "drop": (["--drop", "500:6"], 0, lambda s, ss, rows: (
        check(s["faults"]["robot_packet_gap"] >= 1 and s["lola"]["gaps"] >= 1,
              f"6 dropped packets are a counted packet gap ({s['faults']['robot_packet_gap']} ticks, {s['lola']['gaps']} gaps)"))),
    "delay": (["--delay", "500:45"], 0, lambda s, ss, rows: (
        check(s["faults"]["robot_packet_gap"] >= 1, "a packet 45 ms late is a counted packet gap"))),
    "garbage": (["--garbage", "500:300", "--garbage", "620:7"], 0, lambda s, ss, rows: (
        check(s["lola"]["malformed"] >= 2 and s["faults"]["robot_malformed_packet"] >= 1,
              f"garbage is counted as malformed and skipped ({s['lola']['malformed']})"))),
    "bad_length": (["--bad-length", "500:3"], 0, lambda s, ss, rows: (
        check(s["lola"]["malformed"] == 3, f"3 packets with a 24-entry Position counted malformed ({s['lola']['malformed']})"))),
    "heat": (["--heat", "21:500"], 0, lambda s, ss, rows: (
        check(s["faults"]["joint_hot"] >= 1 and s["lola"]["hot_cycles"] >= 1, "a joint at 80 degC is a counted fault"),
        check(any(abs(stiff(r, 21) - ARM_STIFFNESS * HOT_SCALE) < 1e-6 and abs(stiff(r, 20) - ARM_STIFFNESS) < 1e-6
                  for r in rows), "the hot joint (RElbowRoll) is commanded at half stiffness, its neighbour at full"),
        check(all(stiff(r, 21) <= ARM_STIFFNESS * HOT_SCALE + 1e-6 for r in rows if int(r["cycle"]) > 502),
              "once hot, RElbowRoll never gets more than half stiffness"))),
    "misread": (["--misread", "500:10"], 0, lambda s, ss, rows: (
        check(s["faults"]["tracking_error"] >= 1 and s["lola"]["tracking_cycles"] >= 3,
              f"RElbowRoll read 0.5 rad off for 10 cycles is a counted tracking error "
              f"({s['lola']['tracking_cycles']} cycles, {s['faults']['tracking_error']} ticks)"))),
    "close": (["--close-at", "500"], 3, lambda s, ss, rows: (
        check(s["faults"]["robot_link_lost"] >= 1 and s["lola"]["stop"] == "link_lost",
              "a closed socket is a link-lost safe stop in summary.json"),
        check(s["ticks"] < 70, f"the run ends early ({s['ticks']} ticks)"))),
    "silence": (["--drop", "500:100000"], 3, lambda s, ss, rows: (
        check(s["lola"]["stop"] == "link_lost" and s["faults"]["robot_packet_gap"] >= 1,
              "a robot that stops sending is a packet gap, then a link-lost stop"))),
}


def case_fault(a, name, tmp, extra=()):
    log = os.path.join(tmp, "run")
    ref = reference(a, tmp, "elbow")
    base = [*ref, "--ticks", "70", "--log", log, *extra]
    if name == "no_robot":
        rc, wall = run_rt(a.nao_rt, ["--robot", "lola:" + os.path.join(tmp, "nobody.sock"), *base], 60)
        check(rc == 1 and wall < 30, f"no LoLA socket: configure error, exit 1 (got {rc} after {wall:.1f} s)")
        return
    if name == "sigterm":
        sim = Sim(a.sim, tmp)
        p = subprocess.Popen([a.nao_rt, "--robot", "lola:" + sim.path, *ref, "--ticks", "600", "--log", log, *extra])
        time.sleep(6.0)
        p.send_signal(signal.SIGTERM)
        rc = p.wait(timeout=30)
        ss, rows = sim.stop()
        s = summary_of(log)
        check(rc == 4, f"SIGTERM: safe stop, exit 4 (got {rc})")
        check(s["lola"]["stop"] == "signal" and 0 < s["ticks"] < 600, f"summary.json says signal ({s['ticks']} ticks)")
        check_start_and_stop(rows, "sigterm")
        return
    flags, want, checks = FAULTS[name]
    sim = Sim(a.sim, tmp, flags)
    rc, wall = run_rt(a.nao_rt, ["--robot", "lola:" + sim.path, *base], 120)
    ss, rows = sim.stop()
    check(rc == want, f"{name}: nao_rt exits {want} (got {rc})")
    s = summary_of(log)
    print(f"info  lola {s['lola']}; faults {s['faults']}; sim {ss}")
    if name != "misread":
        check(s["lola"]["tracking_cycles"] == 0, f"{name}: no tracking error where the arm tracks")
    if want == 0:
        check(s["ticks"] == 70, f"{name}: the run recovers and completes its 70 ticks (got {s['ticks']})")
        check(s["allocations_after_activate"] == 0, f"{name}: 0 allocations after activate")
        check_start_and_stop(rows, name)
    else:
        check_start_and_stop(rows, name, expect_stop_ramp=False)
    checks(s, ss, rows)


def read_one(unpacker, sock, timeout=2.0):
    sock.settimeout(timeout)
    while True:
        for obj in unpacker:
            return obj
        data = sock.recv(65536)
        if not data:
            return None
        unpacker.feed(data)


def case_peer_sim(a, tmp):
    """python3-msgpack as the client of nao_lola_sim."""
    sim = Sim(a.sim, tmp, seconds=30)
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    s.connect(sim.path)
    up = msgpack.Unpacker(raw=False)
    pkt = read_one(up, s)
    check(isinstance(pkt, dict) and set(pkt) == set(SENSOR_KEYS),
          f"sensor packet: a map with exactly lola.md's keys (got {sorted(pkt) if isinstance(pkt, dict) else type(pkt)})")
    for k, n in SENSOR_KEYS.items():
        check(isinstance(pkt.get(k), list) and len(pkt[k]) == n, f"sensor {k}: array of {n}")
    check(all(isinstance(x, str) for x in pkt["RobotConfig"]), "sensor RobotConfig: 4 strings")
    check(all(isinstance(x, float) for k in SENSOR_KEYS if k != "RobotConfig" for x in pkt[k]), "sensor values are floats")
    check(all(abs(pkt["Position"][i] - f32(HOME[j])) < 1e-6 for j, i in enumerate(ARM)),
          f"the right arm (LoLA 18-22) reads nao_lola_sim's arm start {HOME}: {pkt['Position'][18:23]}")
    start = pkt["Position"]
    # Command RShoulderPitch (18) 0.3 rad up and hold everything else, at full stiffness, with
    # doubles (python's default) for positions and booleans for Sonar.
    target = list(start)
    target[18] = start[18] - 0.3
    act = {"Position": target, "Stiffness": [1.0] * 25, "Chest": [0.0] * 3, "LEar": [0.0] * 10, "REar": [0.0] * 10,
           "LEye": [0.0] * 24, "REye": [0.0] * 24, "LFoot": [0.0] * 3, "RFoot": [0.0] * 3, "Skull": [0.0] * 12,
           "Sonar": [True, True]}
    last = pkt
    for _ in range(60):  # 0.72 s: answer every packet
        s.sendall(msgpack.packb(act))
        last = read_one(up, s)
        check_ok = isinstance(last, dict) and set(last) == set(SENSOR_KEYS)
        if not check_ok:
            break
    check(last is not None and abs(last["Position"][18] - target[18]) < 0.02,
          f"RShoulderPitch (18) follows its command to {target[18]:.3f} (at {last['Position'][18]:.3f})")
    others = [JOINTS[i] for i in range(25) if i != 18 and abs(last["Position"][i] - start[i]) > 0.02]
    check(not others, f"no other joint moved (moved: {others})")
    check(abs(last["Stiffness"][18] - 1.0) < 1e-6, "the sensor packet reports the commanded stiffness")
    s.close()
    ss, rows = sim.stop()
    check(len(rows) >= 50 and all(abs(pos(r, 18) - f32(target[18])) < 1e-6 for r in rows),
          f"nao_lola_sim decoded python-msgpack's actuator packets ({len(rows)} received, Position[18] as sent)")


def sensor_packet(position, temperature=35.0, drop_key=None):
    p = {"Position": position, "Stiffness": [0.0] * 25, "Temperature": [temperature] * 25, "Current": [0.0] * 25,
         "Status": [0.0] * 25, "Accelerometer": [0.0, 0.0, -9.81], "Gyroscope": [0.0] * 3, "Angles": [0.0] * 2,
         "FSR": [0.0] * 8, "Touch": [0.0] * 14, "Sonar": [2.55, 2.55], "Battery": [0.9, -1.0, 0.0, 33.0],
         "RobotConfig": ["P0000074A05S94700017", "6.0.0", "P0000073A03S94600016", "6.0.0"]}
    if drop_key:
        del p[drop_key]
    return msgpack.packb(p, use_single_float=True)


def case_peer_client(a, tmp):
    """python3-msgpack as the LoLA robot: a 12 ms server nao_rt talks to."""
    path = os.path.join(tmp, "robot.sock")
    srv = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    srv.bind(path)
    srv.listen(1)
    log = os.path.join(tmp, "run")
    p = subprocess.Popen([a.nao_rt, "--robot", "lola:" + path, *reference(a, tmp, "elbow"), "--ticks", "10",
                          "--log", log])
    srv.settimeout(60)
    c, _ = srv.accept()
    up = msgpack.Unpacker(raw=False)
    # Distinct values per joint: an answer in another order cannot pass. The arm at nao_rt's home.
    position = [0.01 * (i + 1) for i in range(25)]
    for j, i in enumerate(ARM):
        position[i] = HOME[j]
    answers = []
    bad_sent = 0
    cycle = 0
    t_next = time.monotonic()
    while p.poll() is None and cycle < 5000:
        try:  # nao_rt closes the socket when its run ends: a send may then fail
            if cycle == 20:  # one packet without "Temperature": counted, skipped, not answered
                c.sendall(sensor_packet(position, drop_key="Temperature"))
                bad_sent += 1
                ans = {}
            else:
                c.sendall(sensor_packet(position))
                ans = read_one(up, c, timeout=1.0)
        except (socket.timeout, ConnectionResetError, BrokenPipeError):
            ans = None
        if ans is None:
            break
        if ans:
            answers.append(ans)
            for i in ARM:  # an ideal servo: the arm is where it was commanded
                position[i] = ans["Position"][i]
        cycle += 1
        t_next += CYCLE_S
        time.sleep(max(0.0, t_next - time.monotonic()))
    c.close()
    rc = p.wait(timeout=30)
    srv.close()
    check(rc == 0, f"nao_rt exits 0 against the python LoLA robot (got {rc})")
    check(len(answers) > 50, f"{len(answers)} actuator packets received")
    keys_ok = all(isinstance(x, dict) and set(x) == set(ACTUATOR_KEYS) for x in answers)
    check(keys_ok, "every actuator packet is a map with exactly lola.md's keys")
    lens_ok = all(isinstance(x[k], list) and len(x[k]) == n for x in answers for k, n in ACTUATOR_KEYS.items())
    check(lens_ok, "every actuator array has lola.md's length")
    check(all(isinstance(v, bool) for x in answers for v in x["Sonar"]), "Sonar is sent as booleans")
    check(all(isinstance(v, float) for x in answers for k in ACTUATOR_KEYS if k != "Sonar" for v in x[k]),
          "every other value is a float")
    first = answers[0]
    check(all(abs(first["Position"][i] - f32(position[i] if i not in ARM else HOME[ARM.index(i)])) < 1e-6
              for i in range(25)),
          "the first answer commands back, joint by joint in LoLA order, the positions it read")
    check(all(abs(x["Position"][i] - f32(0.01 * (i + 1))) < 1e-6 for x in answers for i in range(25) if i not in ARM),
          "no joint outside the right arm is ever commanded away from what the robot measured at start")
    check(max(first["Stiffness"]) <= 0.05 and abs(first["Stiffness"][0] - first["Stiffness"][0]) == 0,
          f"the first answer's stiffness is low ({max(first['Stiffness']):.3f})")
    check(abs(answers[RAMP_CYCLES + 10]["Stiffness"][18] - ARM_STIFFNESS) < 1e-6 and
          abs(answers[RAMP_CYCLES + 10]["Stiffness"][0] - HOLD_STIFFNESS) < 1e-6,
          f"after the ramp: arm stiffness {ARM_STIFFNESS}, every other joint {HOLD_STIFFNESS}")
    s = summary_of(log)
    check(s["lola"]["malformed"] == bad_sent, f"the packet without Temperature counted malformed ({s['lola']['malformed']})")
    check(s["lola"]["cycles"] == len(answers), f"nao_rt counts {s['lola']['cycles']} cycles, the robot got {len(answers)} answers")


SLOW_TICK_MS = 30  # the Atom's tick is estimated at 10-27 ms (docs/embedded.md): longer than a cycle


def case_slow(a, tmp):
    """Ticks 30 ms longer (nao_rt_slow_cpu: a slower CPU): on one thread the packets that come
    during a tick wait (late answers); with --lola-io-thread every packet is still answered within
    its cycle."""
    results = {}
    for mode, flags in (("one thread", ["--lola-answer-first"]), ("io thread", ["--lola-io-thread"])):
        d = os.path.join(tmp, mode.replace(" ", "_"))
        os.makedirs(d)
        sim = Sim(a.sim, d)
        rc, _ = run_rt(a.slow_rt, [str(SLOW_TICK_MS), "--robot", "lola:" + sim.path, *reference(a, tmp, "elbow"),
                                   "--ticks", "60", "--log", os.path.join(d, "run"), *flags], 80)
        ss, rows = sim.stop()
        check(rc == 0, f"{mode}: exits 0 (got {rc})")
        s = summary_of(os.path.join(d, "run"))
        cycles = [int(r["cycle"]) for r in rows]
        total = max(cycles) - min(cycles) + 1
        in_cycle = sum(int(r["in_cycle"]) for r in rows)
        results[mode] = (s, rows, in_cycle, total)
        print(f"info  {mode}, {SLOW_TICK_MS} ms ticks: {in_cycle} of {total} answered within the cycle, "
              f"hand RMSE {s['ee_rmse_m'] * 1e3:.2f} mm, lola {s['lola']}")
    s, rows, in_cycle, total = results["one thread"]
    # The premise: without the thread a tick this long makes answers late (this check failing
    # would mean the emulated tick no longer emulates anything).
    # The busy-waited tick is the thread's own work, so its late answers are its own.
    check(own_late(s["lola"]) >= 0.05 * s["lola"]["cycles"] and in_cycle < 0.97 * total,
          f"one thread: a {SLOW_TICK_MS} ms tick makes answers late of its own making ({own_late(s['lola'])} "
          f"late, {s['lola']['late_descheduled']} more waited for a CPU, {in_cycle} of {total} within the cycle)")
    s, rows, in_cycle, total = results["io thread"]
    check_answers(rows, "io thread", s["lola"])
    check(own_late(s["lola"]) <= 0.01 * s["lola"]["cycles"],
          f"io thread: <= 1 % late answers of its own making ({own_late(s['lola'])}; "
          f"{s['lola']['late_descheduled']} more waited for a CPU)")
    check(s["lola"]["io_thread"] and s["allocations_after_activate"] == 0 and s["lola"]["io_allocations"] == 0,
          f"io thread: 0 allocations after activate on either thread ({s['allocations_after_activate']}, "
          f"{s['lola']['io_allocations']})")
    check(s["lola"]["overrun_ticks"] == 0, f"io thread: every command before its boundary ({s['lola']['overrun_ticks']})")
    check(s["ticks"] == 60 and s["ee_rmse_m"] < 0.01,
          f"io thread: 60 ticks, hand RMSE < 1 cm ({s['ee_rmse_m'] * 1e3:.2f} mm)")
    check_start_and_stop(rows, "io thread")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--nao-rt", required=True)
    ap.add_argument("--slow-rt", help="nao_rt_slow_cpu (the slow:io_thread case)")
    ap.add_argument("--sim", required=True)
    ap.add_argument("--toolchain", required=True, help="nao_toolchain (synth, triangulate: the references)")
    ap.add_argument("--references", help="folder the cases share their references in (default: one case's own)")
    ap.add_argument("case")
    a = ap.parse_args()
    kind, _, arg = a.case.partition(":")
    with tempfile.TemporaryDirectory(prefix="nao_lola_") as tmp:
        if kind == "movement":
            case_movement(a, arg, tmp)
        elif kind == "io":
            case_movement(a, arg, tmp, ["--lola-io-thread", "--realtime"])
        elif kind == "iofault":
            case_fault(a, arg, tmp, ["--lola-io-thread"])
        elif kind == "slow" and arg == "io_thread":
            if not a.slow_rt:
                raise SystemExit("slow:io_thread needs --slow-rt (nao_rt_slow_cpu)")
            case_slow(a, tmp)
        elif kind == "fault":
            case_fault(a, arg, tmp)
        elif kind == "peer" and arg == "sim":
            case_peer_sim(a, tmp)
        elif kind == "peer" and arg == "client":
            case_peer_client(a, tmp)
        else:
            print("unknown case " + a.case)
            return 2
    if failures:
        print(f"{len(failures)} check(s) failed:\n  " + "\n  ".join(failures))
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
