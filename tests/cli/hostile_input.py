#!/usr/bin/env python3
"""Hostile input through the release binaries (docs/formats.md "Input handling").

Every input class fuzzing and bad command lines found must end in exit status 1 or 2 (never 0,
never a signal: >= 128 or negative), with one line on stderr that names the file or the flag,
and nothing written half. Run by CTest as `hostile_input`:

    hostile_input.py NAO_RT NAO_TOOLCHAIN CORPUS_DIR

With NAO_HOSTILE_VALGRIND=1 every command also runs under valgrind (slow; a manual check):
any valgrind error fails the case.
"""
import json
import os
import shutil
import subprocess
import sys
import tempfile
import unittest

NAO_RT, NAO_TOOLCHAIN, CORPUS = sys.argv[1:4] if len(sys.argv) >= 4 else (None, None, None)
VALGRIND = os.environ.get("NAO_HOSTILE_VALGRIND") == "1"
# Lines tools print on stderr while they work; the error is the line that is not one of these.
PROGRESS = ("reading ", "triangulating frame")


def run(args, timeout=300):
    cmd = list(args)
    if VALGRIND:
        cmd = ["valgrind", "-q", "--error-exitcode=99", "--leak-check=no"] + cmd
    p = subprocess.run(cmd, capture_output=True, text=True, errors="replace", timeout=timeout)
    return p.returncode, p.stdout, p.stderr


class Hostile(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.mkdtemp(prefix="nao_hostile_")
        # One small synthetic demonstration: two cameras of OpenPose JSON and their calibration.
        code, _, err = run([NAO_TOOLCHAIN, "synth", "--movement", "elbow", "--per-movement", "1", "--seed", "1",
                            "--out", os.path.join(cls.tmp, "synth")])
        assert code == 0, err
        cls.demo = os.path.join(cls.tmp, "synth", "elbow_000")
        with open(os.path.join(cls.demo, "calibration.json")) as f:
            cls.calibration = json.load(f)
        # Its 10 Hz skeleton: the recorded reference of the nao_rt runs below.
        cls.skeleton = os.path.join(cls.demo, "skeleton.csv")
        code, _, err = run([NAO_TOOLCHAIN, "triangulate", "--demo", cls.demo, "--max-gap", "0", "--out", cls.skeleton])
        assert code == 0, err

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.tmp, ignore_errors=True)

    def path(self, name):
        return os.path.join(self.tmp, self.id().split(".")[-1] + "_" + name)

    def write(self, name, data):
        p = self.path(name)
        with open(p, "wb") as f:
            f.write(data if isinstance(data, bytes) else data.encode())
        return p

    def expect_refused(self, args, names, codes=(1, 2), timeout=300):
        """The command exits with a code in `codes` and its one error line names every item of `names`."""
        code, _, err = run(args, timeout)
        lines = [l for l in err.splitlines() if l.strip() and not l.startswith(PROGRESS)]
        what = "%s\nexit %s, stderr:\n%s" % (" ".join(args), code, err[-2000:])
        self.assertIn(code, codes, what)
        self.assertEqual(len(lines), 1, "expected one error line: " + what)
        for n in names:
            self.assertIn(n, lines[0], what)
        return lines[0]

    # ---- triangulate: calibration JSON, OpenPose JSON, --rate ---------------------------------

    def triangulate(self, calibration=None, cams=None, extra=()):
        out = self.path("skeleton.csv")
        cams = cams or [os.path.join(self.demo, "cam0"), os.path.join(self.demo, "cam1")]
        args = [NAO_TOOLCHAIN, "triangulate", "--calibration", calibration or os.path.join(self.demo, "calibration.json"),
                "--out", out]
        for c in cams:
            args += ["--keypoints", c]
        return args + list(extra), out

    def bad_calibration(self, edit):
        cal = json.loads(json.dumps(self.calibration))
        edit(cal["cameras"])
        return cal

    def check_calibration_refused(self, text, names=()):
        p = self.write("calibration.json", text)
        args, out = self.triangulate(calibration=p)
        self.expect_refused(args, [p] + list(names))
        self.assertFalse(os.path.exists(out), "a refused input must not leave an output file")

    def test_calibration_number_overflowing_a_double(self):
        # The first translation component becomes 1e400: nlohmann raises out_of_range, not parse_error.
        cal = json.dumps(self.calibration)
        i = cal.index('"translation": [') + len('"translation": [')
        j = cal.index(",", i)
        self.check_calibration_refused(cal[:i] + "1e400" + cal[j:])

    def test_calibration_rotation_vector_of_absurd_norm(self):
        def edit(cams):
            cams[0]["rotation"] = [1e200, 0, 0]
        self.check_calibration_refused(json.dumps(self.bad_calibration(edit)), ["rotation"])

    def test_calibration_tiny_focal_lengths(self):
        def edit(cams):
            cams[1]["matrix"][0][0] = 1e-300
            cams[1]["matrix"][1][1] = 1e-300
        self.check_calibration_refused(json.dumps(self.bad_calibration(edit)), ["focal"])

    def test_calibration_two_identical_cameras(self):
        def edit(cams):
            name = cams[1].get("name", "cam1")
            cams[1] = dict(cams[0], name=name)
        self.check_calibration_refused(json.dumps(self.bad_calibration(edit)), ["same place"])

    def test_calibration_nested_deeply(self):
        self.check_calibration_refused('{"cameras": ' + "[" * 200000 + "]" * 200000 + "}", ["nests deeper"])

    def test_openpose_frame_nested_a_million_deep(self):
        cams = []
        for c in ("cam0", "cam1"):
            dst = self.path(c)
            shutil.copytree(os.path.join(self.demo, c), dst)
            cams.append(dst)
        victim = sorted(os.listdir(cams[0]))[0]
        p = os.path.join(cams[0], victim)
        with open(p, "w") as f:
            f.write('{"people": [{"pose_keypoints_2d": ' + "[" * 1000000 + "]" * 1000000 + "}]}")
        args, out = self.triangulate(cams=cams)
        self.expect_refused(args, [victim, "nests deeper"])
        self.assertFalse(os.path.exists(out))

    def test_triangulate_rate_beyond_a_size_t(self):
        args, out = self.triangulate(extra=["--rate", "1e300"])
        self.expect_refused(args, ["--rate", "cap"])
        self.assertFalse(os.path.exists(out))

    def test_triangulate_rate_beyond_memory(self):
        args, out = self.triangulate(extra=["--rate", "1e12"])
        self.expect_refused(args, ["--rate", "cap"], timeout=60)
        self.assertFalse(os.path.exists(out))

    def test_triangulate_with_nothing_valid_exits_nonzero(self):
        # Every detection below the confidence floor: nothing triangulates.
        args, out = self.triangulate(extra=["--min-confidence", "1"])
        self.expect_refused(args, ["no valid 3D point", out])
        self.assertFalse(os.path.exists(out))

    # ---- nao_rt: URDF, model.bin, run length -----------------------------------------------

    def urdf(self):
        with open(os.path.join(os.path.dirname(__file__), "..", "..", "urdf", "nao_v6_right_arm.urdf")) as f:
            return f.read()

    def nao_rt(self, *args):
        return [NAO_RT, "--reference", "file:" + self.skeleton, "--movement", "elbow", "--ticks", "2"] + list(args)

    def test_urdf_nested_60000_deep(self):
        p = self.write("deep.urdf", '<?xml version="1.0"?>\n<robot name="x">' + "<a>" * 60000 + "</a>" * 60000 + "</robot>")
        self.expect_refused(self.nao_rt("--urdf", p), [p, "nests deeper"])

    def test_urdf_ending_in_a_utf8_lead_byte(self):
        data = b'<?xml version="1.0"?>\n<robot name="\xf2'
        self.assertEqual(len(data), 36)
        p = self.write("utf8.urdf", data)
        self.expect_refused(self.nao_rt("--urdf", p), [p, "UTF-8"])

    def test_urdf_joint_origin_1e308(self):
        text = self.urdf().replace('<origin xyz="0.105 -0.015 0"', '<origin xyz="1e308 -0.015 0"', 1)
        self.assertIn("1e308", text)
        p = self.write("far.urdf", text)
        self.expect_refused(self.nao_rt("--urdf", p), [p, "RElbowYaw", "origin"])

    def test_model_empty_file(self):
        p = self.write("empty.bin", b"")
        self.expect_refused(self.nao_rt("--weights", p), [p, "truncated (0 bytes"])

    def test_model_joint_lower_limit_above_upper(self):
        p = os.path.join(CORPUS, "model_file", "lower_above_upper.bin")
        self.expect_refused(self.nao_rt("--weights", p), [p, "RElbowYaw", "lower limit"])

    def test_model_joint_velocity_limit_not_positive(self):
        for name, joint in (("velocity_zero.bin", "RWristYaw"), ("velocity_negative.bin", "RShoulderPitch")):
            p = os.path.join(CORPUS, "model_file", name)
            self.expect_refused(self.nao_rt("--weights", p), [p, joint, "velocity limit"])

    def test_model_metadata_nested_deeply(self):
        # nao_rt --info parses the metadata and dumps it: deep nesting overflowed the stack.
        p = os.path.join(CORPUS, "model_file", "crash_deep_metadata.bin")
        self.expect_refused([NAO_RT, "--info", "--weights", p], [p, "metadata nests deeper"])

    def test_nao_rt_seconds_1e19(self):
        self.expect_refused([NAO_RT, "--seconds", "1e19"], ["--seconds 1e+19", "longest run"], codes=(2,))

    def test_nao_rt_ticks_1e12(self):
        # Written out, the count parses as an integer and must meet the cap before the run
        # buffers are sized by it; in exponent form the flag parser refuses it.
        self.expect_refused([NAO_RT, "--ticks", "1000000000000"], ["--ticks 1000000000000", "longest run"], codes=(2,),
                            timeout=60)
        self.expect_refused([NAO_RT, "--ticks", "1e12"], ["--ticks"], codes=(2,), timeout=60)

    # ---- cluster: retarget CSV ----------------------------------------------------------------

    def test_cluster_flags_beyond_uint32(self):
        with open(os.path.join(CORPUS, "retarget_csv", "seed_elbow.csv")) as f:
            lines = f.read().splitlines()
        header = lines[0].split(",")
        col = header.index("flags")
        row = lines[1].split(",")
        row[col] = "1e20"
        data = os.path.join(self.tmp, "cluster_data")
        os.makedirs(os.path.join(data, "elbow_000"))
        p = os.path.join(data, "elbow_000", "retarget.csv")
        with open(p, "w") as f:
            f.write("\n".join([lines[0], ",".join(row)] + lines[2:]) + "\n")
        self.expect_refused([NAO_TOOLCHAIN, "cluster", "--data", data, "--k", "1"], [p, "flags"])
        self.assertFalse(os.path.exists(os.path.join(data, "centroids.json")))


    # ---- train: recipe files ------------------------------------------------------------------

    def recipe_refused(self, text, names):
        recipe = self.write("recipe.json", text)
        out = self.path("model.bin")
        self.expect_refused([NAO_TOOLCHAIN, "train", "--recipe", recipe, "--data", os.path.join(self.tmp, "synth"),
                             "--out", out], [recipe] + names, timeout=60)
        self.assertFalse(os.path.exists(out))

    def test_train_recipe_unknown_option(self):
        self.recipe_refused('{"train": {"lr": 0.001, "learning-rate": 0.1}}', ["--learning-rate"])

    def test_train_recipe_value_out_of_range(self):
        self.recipe_refused('{"train": {"lr": -1}}', ["--lr"])

    def test_train_recipe_flag_not_boolean(self):
        # A recipe-only on/off option (the training method's: no command-line flag).
        self.recipe_refused('{"train": {"no-previous-action": 1}}', ["no-previous-action", "'1' is not true or false"])

    def test_train_recipe_only_option_out_of_range(self):
        # The training method's options keep the ranges their flags had.
        self.recipe_refused('{"train": {"chunk": 40}}', ["chunk", "1..32"])
        self.recipe_refused('{"train": {"chunk": 2.5}}', ["chunk", "1..32"])
        self.recipe_refused('{"train": {"noisy-starts": "elsewhere"}}', ["noisy-starts", "own or others"])
        self.recipe_refused('{"train": {"ema": 1}}', ["ema", "0..0.99999"])
        self.recipe_refused('{"train": {"closed-loop-lr": 0}}', ["closed-loop-lr", "positive"])

    def test_train_help_lists_at_most_25_options(self):
        # The run's options on the command line; the training method's in a recipe, and the help
        # says where they are documented.
        code, out, err = run([NAO_TOOLCHAIN, "train", "--help"], timeout=60)
        self.assertEqual(code, 0, err)
        options = [l.split()[0] for l in out.splitlines() if l.startswith("  -")]
        self.assertLessEqual(len(options), 25, "train --help lists %d options: %s" % (len(options), " ".join(options)))
        self.assertIn("--recipe", " ".join(options))
        self.assertIn("docs/training.md", out)
        for flag in ("--noisy-rollouts", "--noisy-starts", "--chunk", "--no-previous-action", "--run-latent",
                     "--latent-kl", "--ema", "--closed-loop-epochs", "--closed-loop-lr", "--closed-loop-horizon",
                     "--closed-loop-horizon-growth", "--closed-loop-starts", "--closed-loop-action-weight"):
            self.assertNotIn(flag, options)

    def test_train_recipe_not_an_object(self):
        self.recipe_refused('[{"train": {}}]', ["\"train\""])
        self.recipe_refused('{"train": {"lr": 0.001}', ["not JSON"])

    def test_train_recipe_output_in_recipe(self):
        self.recipe_refused('{"train": {"out": "elsewhere.bin"}}', ["'out'", "command line"])

    def test_train_committed_recipes_are_read(self):
        # Every option of a committed model's recipe is one train takes: the run gets past the
        # recipe and stops at the (empty) data set.
        recipes = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "models", "recipes")
        empty = os.path.join(self.tmp, "no_demonstrations")
        os.makedirs(empty, exist_ok=True)
        names = sorted(n for n in os.listdir(recipes) if n.endswith(".json"))
        self.assertIn("autonomous.json", names)
        for n in names:
            line = self.expect_refused([NAO_TOOLCHAIN, "train", "--recipe", os.path.join(recipes, n), "--data", empty,
                                        "--out", self.path(n + ".bin")], [empty], timeout=60)
            self.assertNotIn("recipe", line)


if __name__ == "__main__":
    unittest.main(argv=[sys.argv[0], "-v"] + sys.argv[4:])
