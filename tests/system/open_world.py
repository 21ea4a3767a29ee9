#!/usr/bin/env python3
"""A user's own movements to the robot, with no synthesiser anywhere on the path (CTest
`open_world`, labels system and slow):

  1. tests/recordings writes two movements the synthesiser does not draw (wave, reach) as
     two-camera OpenPose recordings;
  2. `toolchain/nao train --recordings` triangulates, retargets, clusters and trains the small
     configuration on them;
  3. `toolchain/nao build --model` builds the nao_rt of that model's architecture;
  4. that nao_rt runs every start of every movement (`--reference none --movement M --start I`),
     and every run stays within the demonstrations' joint range + 0.1 rad; build/'s nao_rt, which
     computes the small configuration's step beside its compiled-in model's, plays the same runs;
  5. `nao_toolchain evaluate --recordings` scores the model on its held-out recordings;
  6. neither nao_rt holds a symbol of the synthesiser, k-means or the offline triangulation.

    open_world.py ROOT BUILD_DIR
"""
import csv
import json
import os
import shutil
import subprocess
import sys
import tempfile
import unittest

ROOT, BUILD = (sys.argv[1:3] if len(sys.argv) >= 3 else (None, None))
MOVEMENTS = ("reach", "wave")
TOOLCHAIN_SYMBOLS = ("renderCamera", "sampleMotion", "kmeansPlusPlus", "triangulateFolders", "fillShortGaps",
                     "generateDemo")


def run(args, timeout=1800, cwd=None):
    p = subprocess.run(args, capture_output=True, text=True, errors="replace", timeout=timeout, cwd=cwd)
    if p.returncode != 0:
        raise AssertionError("%s exited %d\nstdout tail:\n%s\nstderr tail:\n%s" % (
            " ".join(args), p.returncode, p.stdout[-3000:], p.stderr[-3000:]))
    return p.stdout


def read_q(path):
    with open(path) as f:
        rows = list(csv.DictReader(f))
    return [[float(r["q_%d" % j]) for j in range(5)] for r in rows]


class OpenWorld(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.mkdtemp(prefix="nao_open_world_")
        cls.rec = os.path.join(cls.tmp, "recordings")
        cls.model = os.path.join(cls.tmp, "model.bin")
        run([os.path.join(BUILD, "bin", "nao_test_recordings"), "--out", cls.rec, "--movements", ",".join(MOVEMENTS),
             "--per-movement", "8", "--seed", "3"])
        # models/autonomous.bin's recipe with its closed loop cut short like its teacher-forced epochs.
        with open(os.path.join(ROOT, "models", "recipes", "autonomous.json")) as f:
            recipe = json.load(f)
        recipe["train"]["closed-loop-epochs"] = 2
        cls.recipe = os.path.join(cls.tmp, "recipe.json")
        with open(cls.recipe, "w") as f:
            json.dump(recipe, f, indent=2)
        cls.train_out = run([os.path.join(ROOT, "toolchain", "nao"), "train", "--recordings", cls.rec, "--out", cls.model,
                             "--config", "small", "--epochs", "3", "--procs", "1", "--work", os.path.join(cls.tmp, "work"),
                             "--recipe", cls.recipe])
        built = run([os.path.join(ROOT, "toolchain", "nao"), "build", "--model", cls.model])
        cls.nao_rt = built.strip().splitlines()[-1]
        cls.build_tree = os.path.dirname(os.path.dirname(cls.nao_rt))

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.tmp, ignore_errors=True)
        # The model's build tree is named by its checksum under the repository root.
        if getattr(cls, "build_tree", "").startswith(os.path.join(ROOT, "build-model-")):
            shutil.rmtree(cls.build_tree, ignore_errors=True)

    def test_the_model_holds_the_recorded_movements_and_their_starts(self):
        info = json.loads(run([self.nao_rt, "--weights", self.model, "--info"]))
        self.assertEqual(sorted(info["movements"]), sorted(MOVEMENTS), "the model holds exactly the recorded movements")
        self.assertTrue(info["runs"], "the model's own nao_rt runs it")
        built = json.loads(run([os.path.join(BUILD, "bin", "nao_rt"), "--weights", self.model, "--info"]))
        self.assertEqual((built["d_model"], built["window"]), (32, 8), "a small-configuration model")
        self.assertTrue(built["runs"], "build/'s nao_rt runs the small configuration too")
        self.assertTrue(os.path.exists(self.model[:-4] + ".md"), "the model has its card")

    def test_every_start_runs_inside_the_demonstrations_joint_range(self):
        work = os.path.join(self.tmp, "work")
        ranges = {}
        for name in os.listdir(work):
            path = os.path.join(work, name, "features.csv")
            if not os.path.exists(path):
                continue
            movement = name.rsplit("_", 1)[0]
            with open(path) as f:
                rows = list(csv.DictReader(f))
            # The recording's trajectory, and the start it begins at: q_r at its first measured sample.
            points = [[float(row["f_%d" % j]) for j in range(5)] for row in rows]
            t0 = float(next((r for r in rows if r["measured"] == "1"), rows[0])["t_s"])
            with open(os.path.join(work, name, "retarget.csv")) as f:
                points += [[float(r["qr_%d" % j]) for j in range(5)] for r in csv.DictReader(f)
                           if abs(float(r["t_s"]) - t0) <= 1e-6]
            for q in points:
                lo, hi = ranges.get(movement, (q[:], q[:]))
                ranges[movement] = ([min(a, b) for a, b in zip(lo, q)], [max(a, b) for a, b in zip(hi, q)])
        meta = json.loads(run([self.nao_rt, "--weights", self.model, "--info"]))
        for m in MOVEMENTS:
            starts = meta["starts"][m]
            self.assertGreaterEqual(len(starts), 4, "at least 4 held-out recordings of %s are starts" % m)
            for i in range(len(starts)):
                log = os.path.join(self.tmp, "runs", "%s_%d" % (m, i))
                run([self.nao_rt, "--weights", self.model, "--reference", "none", "--movement", m, "--start", str(i),
                     "--zero-timing", "--log", log])
                q = read_q(os.path.join(log, "ticks.csv"))
                self.assertEqual(len(q), starts[i]["ticks"], "a run lasts its start's demonstration")
                lo, hi = ranges[m]
                worst = max(max(max(x - h, l - x) for x, l, h in zip(row, lo, hi)) for row in q)
                self.assertLessEqual(worst, 0.1, "%s start %d leaves the demonstrations' joint range by %.3f rad" % (m, i, worst))
                with open(os.path.join(log, "summary.json")) as f:
                    s = json.load(f)
                self.assertEqual(len(s["start_q"]), 5)
                self.assertEqual(s["allocations_after_activate"], 0)
                if i == 0:
                    # build/'s nao_rt computes the small configuration's step beside its own compiled-in
                    # model's: the same run, tick for tick, as the nao_rt built with this model compiled in.
                    other = log + "_build"
                    run([os.path.join(BUILD, "bin", "nao_rt"), "--weights", self.model, "--reference", "none",
                         "--movement", m, "--start", "0", "--zero-timing", "--log", other])
                    with open(os.path.join(log, "ticks.csv"), "rb") as a, open(os.path.join(other, "ticks.csv"), "rb") as b:
                        self.assertEqual(a.read(), b.read(), "%s: build/bin/nao_rt --weights plays the run of the model's own nao_rt" % m)

    def test_evaluate_scores_the_held_out_recordings(self):
        out = os.path.join(self.tmp, "eval")
        run([os.path.join(BUILD, "bin", "nao_toolchain"), "evaluate", "--model", self.model, "--recordings", self.rec,
             "--out", out, "--nao-rt", self.nao_rt, "--jobs", "2"], timeout=3600)
        with open(os.path.join(out, "summary.json")) as f:
            s = json.load(f)
        for m in MOVEMENTS:
            self.assertIn(m, s)
            for key in ("autonomous_dtw_m", "medoid_replay_dtw_m", "neighbour_replay_dtw_m", "speed_ratio",
                        "loops_run_median", "loops_demo_median", "network_share", "distinct_runs",
                        "replay_distinct_runs", "code_fidelity_m", "replay_fidelity_m"):
                self.assertIn(key, s[m], "%s: %s" % (m, key))
            # Every run names the demonstration it plays: the medoid of the 5 training
            # recordings nearest its start, one the model trained on, and its run code's.
            with open(os.path.join(out, "detail.json")) as f:
                detail = json.load(f)[m]
            for r in detail["runs"]:
                self.assertIn(r["named_demo"], detail["training_demos"])
                with open(os.path.join(out, r["run_dir"], "summary.json")) as f:
                    self.assertEqual(json.load(f)["run_code"], r["named_demo"], "%s: the run's code" % r["start"])
            # toolchain/analysis/training_fidelity.py remakes these runs from detail.json and
            # scores them on its own (Python DTW, the data set's features): the same figures.
            mine = os.path.join(self.tmp, "fidelity_%s.json" % m)
            run(["/usr/bin/python3", os.path.join(ROOT, "toolchain", "analysis", "training_fidelity.py"), "--detail",
                 os.path.join(out, "detail.json"), "--model", self.model, "--nao-rt", self.nao_rt, "--data",
                 os.path.join(self.tmp, "work"), "--starts", "heldout", "--per-movement", "0", "--out", mine])
            with open(mine) as f:
                remade = json.load(f)[m]["runs"]
            self.assertEqual([r["named_demo"] for r in remade], [r["named_demo"] for r in detail["runs"]])
            for a, b in zip(remade, detail["runs"]):
                self.assertAlmostEqual(a["code_fidelity_m"], b["code_fidelity_m"], delta=1e-6, msg=b["start"])
            self.assertGreater(s[m]["autonomous_dtw_m"], 0.0)
            self.assertLessEqual(s[m]["joint_range_excess_rad"], 0.1)
            self.assertEqual(s[m]["network_share"], 1.0, "nothing analytic is added to an autonomous model's action")
            print("%s: DTW %.1f mm (medoid replay %.1f), speed x%.2f, loops %.1f/%.1f" % (
                m, 1e3 * s[m]["autonomous_dtw_m"], 1e3 * s[m]["medoid_replay_dtw_m"], s[m]["speed_ratio"],
                s[m]["loops_run_median"], s[m]["loops_demo_median"]))

    def test_no_nao_rt_holds_toolchain_code(self):
        for binary in (self.nao_rt, os.path.join(BUILD, "bin", "nao_rt")):
            symbols = run(["nm", "-C", binary])
            for name in TOOLCHAIN_SYMBOLS:
                self.assertNotIn(name, symbols, "%s holds %s" % (binary, name))
            self.assertNotIn("nao::tools::", symbols, "%s holds toolchain code" % binary)


if __name__ == "__main__":
    unittest.main(argv=sys.argv[:1], verbosity=2)
