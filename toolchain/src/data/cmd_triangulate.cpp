// nao_toolchain triangulate: OpenPose keypoints of >= 2 calibrated cameras -> 3D skeleton CSV.
#include "nao/tools/command.hpp"
#include "nao/tools/openpose.hpp"
#include "nao/tools/skeleton_csv.hpp"
#include "nao/tools/triangulate.hpp"

#include <cstdio>
#include <unistd.h>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

namespace nao::tools {
namespace {

struct TriangulateArgs {
  std::string demo;
  std::vector<std::string> keypoints;
  std::string calibration;
  std::string format = "body25";
  double fps = 30.0;
  double rate = 10.0;
  double min_confidence = 0.05;
  double outlier_px = 10.0;
  double max_gap = 0.2;
  bool no_bone_check = false;
  double smooth = recordingOptions().zero_lag_sigma_s;
  double bone_fit = recordingOptions().bone_fit_px_per_m;
  std::string out;
};

void run(const TriangulateArgs& args) {
  if (args.demo.empty() && (args.keypoints.empty() || args.calibration.empty()))
    throw UserError("give either --demo DEMO_DIR, or --keypoints CAM_DIR (once per camera) and --calibration FILE");
  if (!args.demo.empty() && (!args.keypoints.empty() || !args.calibration.empty()))
    throw UserError("--demo reads the recording's own cam*/ folders and its calibration (calibration.json or .toml "
                    "in it or the folder above); "
                    "do not combine it with --keypoints or --calibration");
  if (args.demo.empty() && args.keypoints.size() < 2)
    throw UserError("triangulation needs at least 2 cameras: give --keypoints once per camera folder");

  TriangulateOptions opt;
  opt.format = parsePoseFormat(args.format);
  opt.fps = args.fps;
  opt.rate_hz = args.rate;
  opt.min_confidence = args.min_confidence;
  opt.outlier_px = args.outlier_px;
  opt.max_gap_s = args.max_gap;
  opt.check_bone_lengths = !args.no_bone_check;
  opt.zero_lag_sigma_s = args.smooth;
  opt.bone_fit_px_per_m = args.bone_fit;
  // On a terminal one line updated in place every 10 %; in a log one line every 25 %.
  const bool tty = isatty(fileno(stderr)) != 0;
  const int step = tty ? 10 : 25;
  int last_step = -1;
  opt.progress = [tty, step, &last_step](int done, int total) {
    const int percent = 100 * done / total;
    if (percent / step == last_step) return;
    last_step = percent / step;
    std::cerr << (tty ? "\r" : "") << "triangulating frame " << done << "/" << total << " (" << percent << "%)"
              << (tty && done < total ? "" : "\n") << std::flush;
  };

  const std::vector<std::string> dirs = args.demo.empty() ? args.keypoints : demoCameraDirs(args.demo);
  const std::string calibration = args.demo.empty() ? args.calibration : demoCalibration(args.demo);
  std::cerr << "reading " << dirs.size() << " camera folders (" << args.format << "), calibration " << calibration
            << "\n";
  TriangulationReport report;
  const Skeleton skeleton = triangulateFolders(dirs, calibration, opt, &report);
  // A skeleton without a single point is no result: say so instead of writing it and exiting 0.
  if (report.n_points_valid == 0)
    throw UserError("no valid 3D point in " + std::to_string(report.n_frames) +
                    " frames (no subject seen by two consistent cameras; check the calibration " + calibration +
                    " and the keypoint folders); " + args.out + " not written");
  writeSkeletonCsv(args.out, skeleton, true);

  const int n_points = report.n_points_valid + report.n_points_missing + report.n_points_interpolated;
  std::printf("%d capture frames at %g Hz -> %zu samples at %g Hz in %s\n", report.n_frames, args.fps,
              skeleton.size(), args.rate, args.out.c_str());
  if (report.n_frames_absent > 0 || report.n_frames_incomplete > 0)
    std::printf("frame indices missing from every camera %d, from some cameras %d\n", report.n_frames_absent,
                report.n_frames_incomplete);
  std::printf("valid points %d/%d (%.1f%%), frames without a subject %d, inconsistent points %d, "
              "outlier observations rejected %d, bone-length rejections %d, median reprojection error %.2f px\n",
              report.n_points_valid, n_points, n_points > 0 ? 100.0 * report.n_points_valid / n_points : 0.0,
              report.n_frames_without_subject, report.n_points_inconsistent, report.n_observations_rejected,
              report.n_bone_rejections, report.median_reprojection_px);
  std::printf("points interpolated across gaps of at most %g s: %d (written with _ok = 2)\n", args.max_gap,
              report.n_points_interpolated);
  std::printf("arm refitted to its bone lengths in %d frames; zero-lag low-pass sigma %g s\n", report.n_arm_bone_fits,
              args.smooth);
}

void setup(CLI::App& app) {
  auto args = std::make_shared<TriangulateArgs>();
  CLI::App* cmd = app.add_subcommand(
      "triangulate",
      "Triangulate OpenPose keypoints from two or more calibrated cameras into a 3D skeleton CSV\n"
      "(confidence-weighted DLT, per point the cameras that agree by reprojection error, Ceres refinement;\n"
      "points seen by fewer than two consistent cameras are missing; the arm refitted to consistent bone\n"
      "lengths, a zero-lag low-pass over time; gaps up to --max-gap are interpolated and flagged _ok = 2,\n"
      "longer ones stay missing).");
  auto* demo = cmd->add_option("--demo", args->demo,
                               "recording folder (docs/formats.md): reads its cam*/ folders (sorted) and calibration.json or .toml from it or from the folder above");
  auto* kp = cmd->add_option("--keypoints", args->keypoints,
                             "OpenPose JSON folder of one camera; repeat once per camera, in calibration order");
  auto* calib = cmd->add_option("--calibration", args->calibration, "calibration file, our .json or Anipose-style .toml");
  demo->excludes(kp)->excludes(calib);
  cmd->add_option("--format", args->format, "keypoint layout of pose_keypoints_2d")
      ->check(CLI::IsMember({"body25", "body25b"}))
      ->capture_default_str();
  cmd->add_option("--fps", args->fps, "capture rate of the keypoint files, Hz")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--rate", args->rate, "output sample rate, Hz")->check(CLI::PositiveNumber)->capture_default_str();
  cmd->add_option("--min-confidence", args->min_confidence, "ignore detections with a lower confidence")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  cmd->add_option("--outlier-px", args->outlier_px, "max reprojection error of an accepted camera observation, px (for 1920x1080; scaled up with larger images)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--max-gap", args->max_gap,
                  "interpolate a point missing for at most this long (s) and flag it _ok = 2; 0: never")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_flag("--no-bone-check", args->no_bone_check, "do not mark points whose bone lengths jump as missing");
  cmd->add_option("--smooth", args->smooth,
                  "zero-lag low-pass of the measured points: a line fitted over time with Gaussian weights of this\n"
                  "sigma (s; -3 dB near 0.13/sigma Hz: 2.6 Hz at the default); 0: none")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  cmd->add_option("--bone-fit", args->bone_fit,
                  "arm bone-length consistency: shoulder, elbow and wrist refitted to their reprojections plus this\n"
                  "many px per m that the upper arm or forearm is off its median length; 0: none")
      ->check(CLI::Range(0.0, 1e5))
      ->capture_default_str();
  cmd->add_option("--out", args->out, "skeleton CSV to write (docs/formats.md)")->required();
  cmd->callback([args] { run(*args); });
}

}  // namespace
}  // namespace nao::tools

NAO_REGISTER_COMMAND(triangulate, nao::tools::setup)
