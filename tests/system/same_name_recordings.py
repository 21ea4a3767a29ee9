#!/usr/bin/env python3
"""Two recording sets in folders of the same name never mix (CTest `same_name_recordings`,
labels system and slow). `toolchain/nao train --recordings DIR` prepares DIR's recordings in a
work directory named after DIR's folder; what it reuses there is keyed by content, and what is
not DIR's is dropped:

  1. set A (wave, reach) trains from .../a/<NAME>, with the default work directory;
  2. set B (side_raise and a different wave, same recording names) from .../b/<NAME> reuses
     nothing of A: A's reach is dropped, B's wave is prepared again, and the model holds only
     B's movements and splits only B's recordings;
  3. B from a clean work directory, its preparation interrupted and resumed, gives the same
     bytes as (2);
  4. one byte changed in one camera file of B: exactly that recording is prepared again.

    same_name_recordings.py ROOT BUILD_DIR
"""
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import unittest

ROOT, BUILD = (sys.argv[1:3] if len(sys.argv) >= 3 else (None, None))
NAME = "nao_test_same_name_rec"  # both sets' folder name, hence one default work directory
# models/autonomous.bin's recipe without its closed loop (written by setUpClass; the training
# method's options are recipe-only).
RECIPE = None
TRAIN = ["--config", "small", "--epochs", "2", "--procs", "1"]


def write_recipe(path, **changes):
    """models/recipes/autonomous.json with `changes` (option name with _ for -) to its training options."""
    with open(os.path.join(ROOT, "models", "recipes", "autonomous.json")) as f:
        recipe = json.load(f)
    recipe["train"].update({k.replace("_", "-"): v for k, v in changes.items()})
    with open(path, "w") as f:
        json.dump(recipe, f, indent=2)
    return path


def run(args, timeout=1800):
    p = subprocess.run(args, capture_output=True, text=True, errors="replace", timeout=timeout)
    if p.returncode != 0:
        raise AssertionError("%s exited %d\nstdout tail:\n%s\nstderr tail:\n%s" % (
            " ".join(args), p.returncode, p.stdout[-3000:], p.stderr[-3000:]))
    return p.stdout + p.stderr


def train(rec, model):
    return run([os.path.join(ROOT, "toolchain", "nao"), "train", "--recordings", rec, "--out", model, "--recipe", RECIPE] +
               TRAIN)


def train_until_first_prepared(rec, model):
    """Starts a training of rec and stops it (SIGTERM to its process group) once the first
    recording is prepared: an interruption in the middle of the preparation. Returns its output."""
    p = subprocess.Popen([os.path.join(ROOT, "toolchain", "nao"), "train", "--recordings", rec, "--out", model,
                          "--recipe", RECIPE] + TRAIN,
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, errors="replace",
                         start_new_session=True)
    out = []
    try:
        for line in p.stdout:
            out.append(line)
            if re.match(r"nao: \S+ done$", line.strip()):
                break
    finally:
        os.killpg(p.pid, signal.SIGTERM)
        p.wait(timeout=120)
        # Every process of the group gone (a worker may finish its last step after the signal)
        # before the caller counts what was prepared.
        for _ in range(600):
            try:
                os.killpg(p.pid, 0)
            except ProcessLookupError:
                break
            time.sleep(0.1)
        else:
            raise AssertionError("the interrupted training's processes did not end within a minute")
    return "".join(out)


def model_info(model):
    return json.loads(run([os.path.join(BUILD, "bin", "nao_rt"), "--weights", model, "--info"]))


def recordings_of(rec):
    return sorted(n for n in os.listdir(rec) if os.path.isdir(os.path.join(rec, n, "cam0")))


class SameNameRecordings(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        global RECIPE
        cls.tmp = tempfile.mkdtemp(prefix="nao_same_name_")
        RECIPE = write_recipe(os.path.join(cls.tmp, "recipe.json"), closed_loop_epochs=0)
        cls.work = os.path.join(ROOT, "out", "train", "recordings", NAME)
        shutil.rmtree(cls.work, ignore_errors=True)
        cls.a = os.path.join(cls.tmp, "a", NAME)
        cls.b = os.path.join(cls.tmp, "b", NAME)
        maker = os.path.join(BUILD, "bin", "nao_test_recordings")
        run([maker, "--out", cls.a, "--movements", "wave,reach", "--per-movement", "8", "--seed", "3"])
        run([maker, "--out", cls.b, "--movements", "side_raise,wave", "--per-movement", "8", "--seed", "11"])

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.tmp, ignore_errors=True)
        shutil.rmtree(cls.work, ignore_errors=True)

    def test_a_second_set_of_the_same_name_trains_on_its_own_recordings_only(self):
        a_bin, b_bin, b_clean = (os.path.join(self.tmp, n) for n in ("a.bin", "b.bin", "b_clean.bin"))
        train(self.a, a_bin)
        self.assertEqual(sorted(model_info(a_bin)["movements"]), ["reach", "wave"])

        # Set B in the work directory set A left.
        log = train(self.b, b_bin)
        self.assertRegex(log, r"dropped 8 prepared recording\(s\) of another set .*reach_000",
                         "A's reach recordings are dropped, with a line that says so")
        self.assertRegex(log, r"8 recording\(s\) changed since they were prepared .*wave_000",
                         "B's wave recordings share A's names but not their bytes: prepared again")
        self.assertIn("triangulating and retargeting 16 of 16 recordings", log)
        info = model_info(b_bin)
        self.assertEqual(sorted(info["movements"]), ["side_raise", "wave"], "the model holds only B's movements")
        b_names = set(recordings_of(self.b))
        prepared = sorted(n for n in os.listdir(self.work) if os.path.isdir(os.path.join(self.work, n)) and
                          re.match(r"^.+_[0-9]+$", n))
        self.assertEqual(set(prepared), b_names, "the work directory holds B's recordings and nothing else")
        for m, starts in info["starts"].items():
            for s in starts:
                self.assertIn(s["name"], b_names, "held-out start %s of %s is one of B's recordings" % (s["name"], m))

        # B again from a clean work directory, interrupted in the middle of its preparation.
        shutil.rmtree(self.work)
        first = train_until_first_prepared(self.b, b_clean)
        done = [n for n in b_names if os.path.exists(os.path.join(self.work, n, ".done"))]
        self.assertGreaterEqual(len(done), 1, "the interrupted run prepared a recording first:\n" + first)
        self.assertLess(len(done), len(b_names), "the interruption came before the end of the preparation")
        self.assertFalse(os.path.exists(b_clean), "the interrupted run wrote no model")
        log = train(self.b, b_clean)
        self.assertIn("triangulating and retargeting %d of 16 recordings" % (16 - len(done)), log,
                      "the resumed run prepares only what the interrupted one had not finished")
        with open(b_bin, "rb") as f, open(b_clean, "rb") as g:
            self.assertTrue(f.read() == g.read(),
                            "B trained over A's work directory equals B trained from a clean one, interrupted and resumed")

        # One byte of one camera file: exactly that recording is prepared again.
        cam = os.path.join(self.b, "wave_003", "cam1")
        frame = os.path.join(cam, sorted(os.listdir(cam))[len(os.listdir(cam)) // 2])
        with open(frame) as f:
            text = f.read()
        digit = re.search(r"[0-8](?=[,\]])", text)
        self.assertIsNotNone(digit, "a number's last digit to change in " + frame)
        with open(frame, "w") as f:
            f.write(text[:digit.start()] + str(int(digit.group()) + 1) + text[digit.end():])
        log = train_until_first_prepared(self.b, os.path.join(self.tmp, "b_edited.bin"))
        self.assertRegex(log, r"1 recording\(s\) changed since they were prepared .*: wave_003\n")
        self.assertIn("triangulating and retargeting 1 of 16 recordings", log)


if __name__ == "__main__":
    unittest.main(argv=sys.argv[:1], verbosity=2)
