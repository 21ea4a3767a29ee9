#include "nao/triangulation.hpp"
#include "nao/median.hpp"

#include <Eigen/LU>
#include <Eigen/SVD>
#include <ceres/tiny_solver.h>
#include <ceres/tiny_solver_autodiff_function.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace nao {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kTimeEps = 1e-9;  // s; two times closer than this are the same sample

// Points that identify a person across cameras (upper body, present in both layouts).
constexpr std::array<int, 11> kSubjectPoints = {kNose,      kNeck,   kRShoulder, kRElbow, kRWrist, kLShoulder,
                                                kLElbow,    kLWrist, kMidHip,    kRHip,   kLHip};
// Points whose mean is a person's centre (torso).
constexpr std::array<int, 6> kTorsoPoints = {kNeck, kRShoulder, kLShoulder, kMidHip, kRHip, kLHip};

constexpr double kMinBoneDeviation = 0.05;  // m; absolute floor of the tolerance (hand bones are short)

// camera.hpp's project(), templated for automatic differentiation. False behind the camera.
template <typename T>
bool projectT(const Camera& cam, const T* p_W, T* px) {
  T p_C[3];
  for (int r = 0; r < 3; ++r)
    p_C[r] = T(cam.R_CW(r, 0)) * p_W[0] + T(cam.R_CW(r, 1)) * p_W[1] + T(cam.R_CW(r, 2)) * p_W[2] + T(cam.p_CW(r));
  if (p_C[2] <= T(1e-9)) return false;
  const T x = p_C[0] / p_C[2], y = p_C[1] / p_C[2];
  const double k1 = cam.dist[0], k2 = cam.dist[1], p1 = cam.dist[2], p2 = cam.dist[3], k3 = cam.dist[4];
  const T r2 = x * x + y * y;
  const T radial = T(1.0) + r2 * (T(k1) + r2 * (T(k2) + r2 * T(k3)));
  const T xd = x * radial + T(2.0 * p1) * x * y + T(p2) * (r2 + T(2.0) * x * x);
  const T yd = y * radial + T(p1) * (r2 + T(2.0) * y * y) + T(2.0 * p2) * x * y;
  px[0] = T(cam.K(0, 0)) * xd + T(cam.K(0, 1)) * yd + T(cam.K(0, 2));
  px[1] = T(cam.K(1, 1)) * yd + T(cam.K(1, 2));
  return true;
}

// Tolerances are given for a 1920 x 1080 image: a larger image scales them by its diagonal (the
// same detector error is more pixels there); a smaller one keeps them (detector noise does not
// shrink below a few pixels). Exactly 1 for 1080p, so those results do not change.
double toleranceScale(const Camera& cam) {
  static const double kReferenceDiagonal = std::hypot(1920.0, 1080.0);
  return std::max(1.0, std::hypot(static_cast<double>(cam.width), static_cast<double>(cam.height)) / kReferenceDiagonal);
}

// Consensus search over camera pairs up to this many views; beyond, greedy dropping only.
constexpr std::size_t kMaxConsensusViews = 8;

// Pixel reprojection error of p_W in one observation; infinite behind the camera.
double reprojectionError(const Camera& cam, const Eigen::Vector3d& p_W, const Eigen::Vector2d& px) {
  if (toCamera(cam, p_W).z() <= 1e-9) return kInf;
  return (project(cam, p_W) - px).norm();
}

// Residual (px) of an observation whose camera has the point behind it.
constexpr double kBehindCameraPx = 1e6;

// Confidence-weighted pixel residuals. Always succeeds: ceres::TinySolver ignores a false return
// (it would go on with stale or uninitialised residuals and could accept a step behind a
// camera), so a camera that has the point behind it writes a large finite constant instead,
// which makes any step there far worse than every step in front of all cameras.
struct ReprojectionCost {
  const CameraSet* cameras;
  const std::vector<Observation>* obs;
  int NumResiduals() const { return 2 * static_cast<int>(obs->size()); }
  template <typename T>
  bool operator()(const T* p_W, T* residual) const {
    for (std::size_t i = 0; i < obs->size(); ++i) {
      const Observation& o = (*obs)[i];
      const double w = std::sqrt(o.confidence);
      T px[2];
      if (projectT((*cameras)[static_cast<std::size_t>(o.camera)], p_W, px)) {
        residual[2 * i] = T(w) * (px[0] - T(o.px.x()));
        residual[2 * i + 1] = T(w) * (px[1] - T(o.px.y()));
      } else {
        residual[2 * i] = T(w * kBehindCameraPx);
        residual[2 * i + 1] = T(w * kBehindCameraPx);
      }
    }
    return true;
  }
};

struct Fit {
  bool ok = false;
  Eigen::Vector3d p_W = Eigen::Vector3d::Zero();
  std::vector<double> err_px;
  double max_err_px = kInf;  // largest error in 1080p pixels (err_px / toleranceScale)
};

// Per-camera reprojection errors of p_W (infinite behind a camera).
Fit evaluateFit(const CameraSet& cameras, const std::vector<Observation>& obs, const Eigen::Vector3d& p_W) {
  Fit fit;
  fit.p_W = p_W;
  fit.max_err_px = 0.0;
  for (const Observation& o : obs) {
    const Camera& cam = cameras[static_cast<std::size_t>(o.camera)];
    fit.err_px.push_back(reprojectionError(cam, p_W, o.px));
    fit.max_err_px = std::max(fit.max_err_px, fit.err_px.back() / toleranceScale(cam));
  }
  fit.ok = p_W.allFinite() && std::isfinite(fit.max_err_px);
  return fit;
}

// The refinement's objective: confidence-weighted sum of squared pixel errors (infinite when
// the point is behind a used camera).
double weightedCost(const std::vector<Observation>& obs, const Fit& fit) {
  if (!fit.ok) return kInf;
  double sum = 0.0;
  for (std::size_t i = 0; i < obs.size(); ++i) sum += obs[i].confidence * fit.err_px[i] * fit.err_px[i];
  return sum;
}

// DLT (+ optional refinement) and the per-camera reprojection errors. The refined point is kept
// only when it is in front of every used camera and its objective is not worse than the DLT
// point's: a refinement that went astray must not replace the linear estimate. (Not the largest
// error: the least-squares optimum has a larger largest error than the DLT point for ~half of
// the points under Gaussian pixel noise, and is still the better estimate.)
Fit fitPoint(const CameraSet& cameras, const std::vector<Observation>& obs, int refine_iterations) {
  const std::optional<Eigen::Vector3d> dlt = triangulateDlt(cameras, obs);
  if (!dlt) return Fit{};
  Fit fit = evaluateFit(cameras, obs, *dlt);
  if (refine_iterations > 0) {
    Fit refined = evaluateFit(cameras, obs, refineOnReprojection(cameras, obs, *dlt, refine_iterations));
    if (refined.ok && weightedCost(obs, refined) <= weightedCost(obs, fit)) fit = std::move(refined);
  }
  return fit;
}

// The consensus step of the file comment: the largest set of cameras that agree on one point,
// proposed by camera pairs. Equally large sets: the one whose point is nearest previous_W (the
// point's last estimate) when given, else the lower sum of squared errors. Returns obs
// unchanged when no pair agrees with itself.
std::vector<Observation> consensusViews(const CameraSet& cameras, const std::vector<Observation>& obs,
                                        const TriangulationParams& opt, const std::optional<Eigen::Vector3d>& previous_W) {
  const auto agreeing = [&](const Eigen::Vector3d& p_W, double* sum2) {
    std::vector<Observation> in;
    *sum2 = 0.0;
    for (const Observation& o : obs) {
      const Camera& cam = cameras[static_cast<std::size_t>(o.camera)];
      const double e = reprojectionError(cam, p_W, o.px) / toleranceScale(cam);
      if (e <= opt.outlier_px) in.push_back(o), *sum2 += e * e;
    }
    return in;
  };
  std::vector<Observation> best;
  double best_tie = kInf;
  for (std::size_t i = 0; i < obs.size(); ++i)
    for (std::size_t j = i + 1; j < obs.size(); ++j) {
      const Fit pair = fitPoint(cameras, {obs[i], obs[j]}, 0);
      if (!pair.ok || pair.max_err_px > opt.outlier_px) continue;
      double sum2 = 0.0;
      std::vector<Observation> in = agreeing(pair.p_W, &sum2);
      const double tie = previous_W ? (pair.p_W - *previous_W).norm() : sum2;
      if (in.size() > best.size() || (in.size() == best.size() && tie < best_tie)) best = std::move(in), best_tie = tie;
    }
  if (best.size() < 2) return obs;
  // Refit on the consensus and let every camera re-join or leave, until the set settles (a
  // set can only be replaced by a larger one, so this ends).
  for (std::size_t it = 0; it < obs.size(); ++it) {
    const Fit fit = fitPoint(cameras, best, opt.max_refine_iterations);
    if (!fit.ok) break;
    double sum2 = 0.0;
    std::vector<Observation> in = agreeing(fit.p_W, &sum2);
    if (in.size() <= best.size()) break;
    best = std::move(in);
  }
  return best;
}

bool usable(const Person2d& p, int i, const TriangulationParams& opt) {
  return p.detected(i) && p.confidence[i] >= opt.min_confidence && p.px[i].allFinite();
}

// A subject candidate under construction.
struct Candidate {
  std::vector<int> person;
  int score = 0;  // consistent (camera, point) detections
  double median_px = kInf;
  double off_centre = 0.0;  // mean distance of the centre's image from the image centres / diagonal
  Eigen::Vector3d centre_W = Eigen::Vector3d::Zero();
};

}  // namespace

Eigen::Vector2d undistortPixel(const Camera& cam, const Eigen::Vector2d& px) {
  const double yd = (px.y() - cam.K(1, 2)) / cam.K(1, 1);
  const double xd = (px.x() - cam.K(0, 2) - cam.K(0, 1) * yd) / cam.K(0, 0);
  const Eigen::Vector2d target(xd, yd);
  Eigen::Vector2d x = target;
  // Newton on distort(x) = target with a central-difference Jacobian.
  for (int it = 0; it < 50; ++it) {
    const Eigen::Vector2d r = distort(cam, x) - target;
    if (r.norm() < 1e-14) break;
    Eigen::Matrix2d J;
    const double h = 1e-7;
    for (int c = 0; c < 2; ++c) {
      Eigen::Vector2d dx = Eigen::Vector2d::Zero();
      dx[c] = h;
      J.col(c) = (distort(cam, x + dx) - distort(cam, x - dx)) / (2.0 * h);
    }
    const Eigen::Vector2d step = J.fullPivLu().solve(r);
    if (!step.allFinite()) break;
    x -= step;
  }
  return x;
}

std::optional<Eigen::Vector3d> triangulateDlt(const CameraSet& cameras, const std::vector<Observation>& obs) {
  if (obs.size() < 2) return std::nullopt;
  Eigen::Matrix<double, Eigen::Dynamic, 4> A(2 * static_cast<Eigen::Index>(obs.size()), 4);
  for (std::size_t i = 0; i < obs.size(); ++i) {
    const Camera& cam = cameras[static_cast<std::size_t>(obs[i].camera)];
    const Eigen::Vector2d x = undistortPixel(cam, obs[i].px);
    Eigen::Matrix<double, 3, 4> P;
    P.leftCols<3>() = cam.R_CW;
    P.col(3) = cam.p_CW;
    // Rows scaled to pixels (focal length) and by sqrt(confidence), so the algebraic error
    // approximates the same confidence-weighted pixel error the refinement minimises.
    const double w = std::sqrt(obs[i].confidence) * 0.5 * (cam.K(0, 0) + cam.K(1, 1));
    const auto r = static_cast<Eigen::Index>(2 * i);
    A.row(r) = w * (x.x() * P.row(2) - P.row(0));
    A.row(r + 1) = w * (x.y() * P.row(2) - P.row(1));
  }
  const Eigen::JacobiSVD<Eigen::Matrix<double, Eigen::Dynamic, 4>> svd(A, Eigen::ComputeFullV);
  const Eigen::Vector4d X = svd.matrixV().col(3);
  if (!X.allFinite() || std::abs(X[3]) <= 1e-12 * X.head<3>().norm()) return std::nullopt;
  return Eigen::Vector3d(X.head<3>() / X[3]);
}

Eigen::Vector3d refineOnReprojection(const CameraSet& cameras, const std::vector<Observation>& obs,
                                     const Eigen::Vector3d& p0_W, int max_iterations) {
  const ReprojectionCost cost{&cameras, &obs};
  using Function = ceres::TinySolverAutoDiffFunction<ReprojectionCost, Eigen::Dynamic, 3>;
  const Function function(cost);
  ceres::TinySolver<Function> solver;
  solver.options.max_num_iterations = max_iterations;
  solver.options.gradient_tolerance = 1e-14;
  solver.options.parameter_tolerance = 1e-14;
  solver.options.function_tolerance = 1e-14;
  Eigen::Vector3d p_W = p0_W;
  solver.Solve(function, &p_W);
  return p_W;
}

PointEstimate triangulatePoint(const CameraSet& cameras, std::vector<Observation> obs, const TriangulationParams& opt,
                               const std::optional<Eigen::Vector3d>& previous_W) {
  obs.erase(std::remove_if(obs.begin(), obs.end(),
                           [&](const Observation& o) {
                             return !(o.confidence >= opt.min_confidence && o.confidence > 0.0) || !o.px.allFinite();
                           }),
            obs.end());
  PointEstimate est;
  if (obs.size() < 2) return est;
  const std::size_t n_views = obs.size();
  bool searched = false;
  for (;;) {
    const Fit fit = fitPoint(cameras, obs, opt.max_refine_iterations);
    if (fit.ok && fit.max_err_px <= opt.outlier_px) {
      est.ok = true;
      est.p_W = fit.p_W;
      est.n_used = static_cast<int>(obs.size());
      est.n_rejected = static_cast<int>(n_views - obs.size());
      for (const Observation& o : obs)
        if (o.camera >= 0 && o.camera < 32) est.views |= std::uint32_t{1} << o.camera;
      double sum2 = 0.0;
      for (double e : fit.err_px) sum2 += e * e;
      est.rms_px = std::sqrt(sum2 / static_cast<double>(fit.err_px.size()));
      return est;
    }
    if (obs.size() <= 2) {
      est.inconsistent = true;
      est.n_rejected = static_cast<int>(n_views - obs.size());
      return est;
    }
    if (!searched && obs.size() <= kMaxConsensusViews) {
      searched = true;
      std::vector<Observation> agreeing = consensusViews(cameras, obs, opt, previous_W);
      if (agreeing.size() < obs.size()) {
        obs = std::move(agreeing);
        continue;
      }
    }
    // Drop the camera whose removal leaves the most consistent fit.
    std::size_t worst = 0;
    double best_rest = kInf;
    for (std::size_t j = 0; j < obs.size(); ++j) {
      std::vector<Observation> rest = obs;
      rest.erase(rest.begin() + static_cast<std::ptrdiff_t>(j));
      const Fit f = fitPoint(cameras, rest, opt.max_refine_iterations);
      const double score = f.ok ? f.max_err_px : kInf;
      if (score < best_rest) best_rest = score, worst = j;
    }
    obs.erase(obs.begin() + static_cast<std::ptrdiff_t>(worst));
  }
}

SubjectChoice chooseSubject(const CameraSet& cameras, const std::vector<const std::vector<Person2d>*>& people,
                            const std::optional<Eigen::Vector3d>& previous_centre_W, const TriangulationParams& opt) {
  const std::size_t n_cam = people.size();
  std::vector<Candidate> candidates;
  for (std::size_t a = 0; a < n_cam; ++a)
    for (std::size_t b = a + 1; b < n_cam; ++b)
      for (std::size_t pa = 0; pa < people[a]->size(); ++pa)
        for (std::size_t pb = 0; pb < people[b]->size(); ++pb) {
          const Person2d& A = (*people[a])[pa];
          const Person2d& B = (*people[b])[pb];
          // Upper-body points of this pairing, linear triangulation only (cheap).
          std::vector<double> errors;
          std::vector<std::pair<int, Eigen::Vector3d>> good;
          for (int k : kSubjectPoints) {
            if (!usable(A, k, opt) || !usable(B, k, opt)) continue;
            const std::vector<Observation> obs = {{static_cast<int>(a), A.px[k], A.confidence[k]},
                                                  {static_cast<int>(b), B.px[k], B.confidence[k]}};
            const Fit fit = fitPoint(cameras, obs, 0);
            errors.push_back(fit.max_err_px);
            if (fit.ok && fit.max_err_px <= opt.outlier_px) good.emplace_back(k, fit.p_W);
          }
          if (good.size() < 3 || median(errors) > opt.subject_px) continue;
          Candidate cand;
          cand.person.assign(n_cam, -1);
          cand.person[a] = static_cast<int>(pa);
          cand.person[b] = static_cast<int>(pb);
          cand.score = 2 * static_cast<int>(good.size());
          cand.median_px = median(errors);
          // Further cameras: the person whose points reproject best, if any agrees. Failing that,
          // the person with the most points that agree (>= 3 and >= 40 % of those compared): the
          // same body with some limbs mislabelled (a left/right swap in this or the pair's camera)
          // is still this person, and the per-point camera selection sorts out the limbs; someone
          // else agrees on no point.
          for (std::size_t c = 0; c < n_cam; ++c) {
            if (c == a || c == b) continue;
            int best = -1, fallback = -1;
            double best_median = kInf, fallback_median = kInf;
            int best_count = 0, fallback_count = 0;
            for (std::size_t q = 0; q < people[c]->size(); ++q) {
              const Person2d& Q = (*people[c])[q];
              std::vector<double> e;
              for (const auto& [k, p_W] : good)
                if (usable(Q, k, opt)) e.push_back(reprojectionError(cameras[c], p_W, Q.px[k]) / toleranceScale(cameras[c]));
              if (e.size() < 3) continue;
              const double m = median(e);
              const int count = static_cast<int>(std::count_if(e.begin(), e.end(), [&](double v) { return v <= opt.outlier_px; }));
              if (m <= opt.subject_px && m < best_median) best = static_cast<int>(q), best_median = m, best_count = count;
              if (count >= 3 && 5 * count >= 2 * static_cast<int>(e.size()) &&
                  (count > fallback_count || (count == fallback_count && m < fallback_median)))
                fallback = static_cast<int>(q), fallback_median = m, fallback_count = count;
            }
            if (best < 0) best = fallback, best_count = fallback_count;
            cand.person[c] = best;
            cand.score += best_count;
          }
          Eigen::Vector3d sum = Eigen::Vector3d::Zero();
          int n = 0;
          for (const auto& [k, p_W] : good)
            if (std::find(kTorsoPoints.begin(), kTorsoPoints.end(), k) != kTorsoPoints.end()) sum += p_W, ++n;
          if (n == 0)
            for (const auto& [k, p_W] : good) sum += p_W, ++n;
          cand.centre_W = sum / static_cast<double>(n);
          // The cameras frame their subject: how far from the image centres it appears.
          int n_seen = 0;
          for (std::size_t c = 0; c < n_cam; ++c) {
            if (cand.person[c] < 0) continue;
            const Camera& cam = cameras[c];
            const Eigen::Vector2d centre_px(0.5 * cam.width, 0.5 * cam.height);
            const double diagonal = std::hypot(static_cast<double>(cam.width), static_cast<double>(cam.height));
            const double d = toCamera(cam, cand.centre_W).z() > 0.0 ? (project(cam, cand.centre_W) - centre_px).norm() / diagonal
                                                                  : 1.0;
            cand.off_centre += d, ++n_seen;
          }
          cand.off_centre /= static_cast<double>(n_seen);
          candidates.push_back(cand);
        }

  SubjectChoice choice;
  if (candidates.empty()) return choice;
  // Continuity first: keep only candidates near the last subject, if there are any.
  std::vector<const Candidate*> pool;
  if (previous_centre_W)
    for (const Candidate& c : candidates)
      if ((c.centre_W - *previous_centre_W).norm() <= opt.subject_max_jump_m) pool.push_back(&c);
  if (pool.empty())
    for (const Candidate& c : candidates) pool.push_back(&c);
  // Nearly complete candidates (>= 3/4 of the best score) compete on centrality: a bystander
  // or a spurious partial body has fewer consistent points or appears off-centre.
  int max_score = 0;
  for (const Candidate* c : pool) max_score = std::max(max_score, c->score);
  const Candidate* best = nullptr;
  for (const Candidate* c : pool) {
    if (4 * c->score < 3 * max_score) continue;
    if (best == nullptr || c->off_centre < best->off_centre ||
        (c->off_centre == best->off_centre &&
         (c->score > best->score || (c->score == best->score && c->person < best->person))))
      best = c;
  }
  choice.found = true;
  choice.person = best->person;
  choice.n_points = best->score;
  choice.median_px = best->median_px;
  choice.centre_W = best->centre_W;
  return choice;
}


TriangulationState::TriangulationState() { resetTriangulationState(*this); }

void resetTriangulationState(TriangulationState& state) {
  state.previous_centre_W.reset();
  state.last_p_W.fill(Eigen::Vector3d::Zero());
  state.last_t_s.fill(-kInf);
}

FrameTriangulation triangulateFrame(const CameraSet& cameras, const std::vector<const std::vector<Person2d>*>& people,
                                    double t_s, const TriangulationParams& opt, TriangulationState& state,
                                    SkeletonFrame& out) {
  out.t_s = t_s;
  out.p_W.fill(Eigen::Vector3d::Zero());
  out.ok.fill(false);
  out.views.fill(0);
  out.reprojection_px.fill(0.0f);
  out.interpolated.fill(false);
  FrameTriangulation result;
  result.subject = chooseSubject(cameras, people, state.previous_centre_W, opt);
  if (!result.subject.found) return result;
  state.previous_centre_W = result.subject.centre_W;
  for (int i = 0; i < kNumSkeletonPoints; ++i) {
    std::vector<Observation> obs;
    for (std::size_t c = 0; c < cameras.size(); ++c) {
      if (result.subject.person[c] < 0) continue;
      const Person2d& p = (*people[c])[static_cast<std::size_t>(result.subject.person[c])];
      if (usable(p, i, opt)) obs.push_back({static_cast<int>(c), p.px[i], p.confidence[i]});
    }
    // The point's latest estimate (at most kTriangulationContinuity_s old) breaks ties between
    // equally large camera sets (two views that agree by chance along an epipolar line, as a
    // left/right swap does with a horizontal baseline, vs the right two).
    std::optional<Eigen::Vector3d> previous_W;
    if (t_s - state.last_t_s[i] <= kTriangulationContinuity_s + kTimeEps) previous_W = state.last_p_W[i];
    const PointEstimate est = triangulatePoint(cameras, obs, opt, previous_W);
    result.n_observations_rejected += est.n_rejected;
    if (est.inconsistent) ++result.n_points_inconsistent;
    if (!est.ok) continue;
    out.p_W[i] = est.p_W;
    out.ok[i] = true;
    out.views[i] = est.views;
    out.reprojection_px[i] = static_cast<float>(est.rms_px);
    result.rms_px[i] = est.rms_px;
    state.last_p_W[i] = est.p_W;
    state.last_t_s[i] = t_s;
  }
  return result;
}

void completeMidHip(SkeletonFrame& f) {
  if (!f.ok[kRHip] || !f.ok[kLHip]) return;
  f.p_W[kMidHip] = 0.5 * (f.p_W[kRHip] + f.p_W[kLHip]);
  f.ok[kMidHip] = true;
  f.interpolated[kMidHip] = f.interpolated[kRHip] || f.interpolated[kLHip];
  f.views[kMidHip] = f.views[kRHip] | f.views[kLHip];
  f.reprojection_px[kMidHip] = std::max(f.reprojection_px[kRHip], f.reprojection_px[kLHip]);
}

BoneLengths medianBoneLengths(const SkeletonFrame* frames, std::size_t n) {
  BoneLengths bones;
  std::vector<double> lengths;
  for (std::size_t b = 0; b < kSkeletonBones.size(); ++b) {
    const auto [i, j] = kSkeletonBones[b];
    lengths.clear();
    for (std::size_t k = 0; k < n; ++k)
      if (frames[k].ok[i] && frames[k].ok[j]) lengths.push_back((frames[k].p_W[i] - frames[k].p_W[j]).norm());
    bones.median_m[b] = median(lengths);
    bones.n_samples[b] = static_cast<int>(lengths.size());
    bones.checked[b] = bones.n_samples[b] >= kMinBoneSamples && bones.median_m[b] >= kMinBoneLength_m;
  }
  return bones;
}

int rejectBoneOutliers(SkeletonFrame& f, const BoneLengths& bones, double tolerance) {
  int n_marked = 0;
  for (;;) {
    std::array<int, kNumSkeletonPoints> n_bones{}, n_bad{};
    for (std::size_t b = 0; b < kSkeletonBones.size(); ++b) {
      const auto [i, j] = kSkeletonBones[b];
      if (!bones.checked[b] || !f.ok[i] || !f.ok[j]) continue;
      const double deviation = std::abs((f.p_W[i] - f.p_W[j]).norm() - bones.median_m[b]);
      const bool bad = deviation > std::max(tolerance * bones.median_m[b], kMinBoneDeviation);
      ++n_bones[i], ++n_bones[j];
      if (bad) ++n_bad[i], ++n_bad[j];
    }
    int most = 0;
    for (int p = 0; p < kNumSkeletonPoints; ++p)
      if (n_bones[p] > 0 && n_bad[p] == n_bones[p]) most = std::max(most, n_bad[p]);
    if (most == 0) break;
    // Every point with the most bad bones goes; ties cannot be told apart, so none is kept.
    for (int p = 0; p < kNumSkeletonPoints; ++p)
      if (n_bones[p] > 0 && n_bad[p] == n_bones[p] && n_bad[p] == most) f.ok[p] = false, ++n_marked;
  }
  return n_marked;
}

namespace {

constexpr std::array<int, 3> kArmPoints = {kRShoulder, kRElbow, kRWrist};
constexpr std::size_t kUpperArmBone = 4, kForearmBone = 5;  // indices into kSkeletonBones
static_assert(kSkeletonBones[kUpperArmBone].first == kRShoulder && kSkeletonBones[kUpperArmBone].second == kRElbow);
static_assert(kSkeletonBones[kForearmBone].first == kRElbow && kSkeletonBones[kForearmBone].second == kRWrist);

// Reprojection residuals of the three arm points (as ReprojectionCost) and the two bone
// residuals; parameters: shoulder, elbow, wrist (world, m).
struct ArmBoneCost {
  const CameraSet* cameras;
  const std::array<std::vector<Observation>, 3>* obs;
  double upper_m, forearm_m, px_per_m;
  int NumResiduals() const {
    return 2 * static_cast<int>((*obs)[0].size() + (*obs)[1].size() + (*obs)[2].size()) + 2;
  }
  template <typename T>
  bool operator()(const T* p, T* residual) const {
    int r = 0;
    for (std::size_t a = 0; a < 3; ++a)
      for (const Observation& o : (*obs)[a]) {
        const double w = std::sqrt(o.confidence);
        T px[2];
        if (projectT((*cameras)[static_cast<std::size_t>(o.camera)], p + 3 * a, px)) {
          residual[r++] = T(w) * (px[0] - T(o.px.x()));
          residual[r++] = T(w) * (px[1] - T(o.px.y()));
        } else {
          residual[r++] = T(w * kBehindCameraPx);
          residual[r++] = T(w * kBehindCameraPx);
        }
      }
    const auto length = [](const T* a, const T* b) {
      using std::sqrt;
      return sqrt((b[0] - a[0]) * (b[0] - a[0]) + (b[1] - a[1]) * (b[1] - a[1]) + (b[2] - a[2]) * (b[2] - a[2]));
    };
    residual[r++] = T(px_per_m) * (length(p, p + 3) - T(upper_m));
    residual[r++] = T(px_per_m) * (length(p + 3, p + 6) - T(forearm_m));
    return true;
  }
};

}  // namespace

bool fitArmBoneLengths(const FrameObservations& observations, const BoneLengths& bones, double px_per_m,
                       int max_iterations, SkeletonFrame& frame) {
  if (!(px_per_m > 0.0) || !bones.checked[kUpperArmBone] || !bones.checked[kForearmBone]) return false;
  if (observations.cameras == nullptr || observations.people == nullptr || observations.subject_person == nullptr)
    return false;
  const CameraSet& cameras = *observations.cameras;
  std::array<std::vector<Observation>, 3> obs;
  Eigen::Matrix<double, 9, 1> p;
  for (std::size_t a = 0; a < 3; ++a) {
    const int i = kArmPoints[a];
    if (!frame.ok[i] || frame.interpolated[i]) return false;
    p.segment<3>(static_cast<Eigen::Index>(3 * a)) = frame.p_W[i];
    for (std::size_t c = 0; c < cameras.size() && c < 32; ++c) {
      const int person = (*observations.subject_person)[c];
      if (((frame.views[i] >> c) & 1u) == 0u || person < 0) continue;
      const Person2d& q = (*(*observations.people)[c])[static_cast<std::size_t>(person)];
      obs[a].push_back({static_cast<int>(c), q.px[i], q.confidence[i]});
    }
    if (obs[a].size() < 2) return false;
  }
  const ArmBoneCost cost{&cameras, &obs, bones.median_m[kUpperArmBone], bones.median_m[kForearmBone], px_per_m};
  using Function = ceres::TinySolverAutoDiffFunction<ArmBoneCost, Eigen::Dynamic, 9>;
  const Function function(cost);
  const auto total = [&](const Eigen::Matrix<double, 9, 1>& x) {
    Eigen::VectorXd residual(cost.NumResiduals());
    cost(x.data(), residual.data());
    return residual.squaredNorm();
  };
  ceres::TinySolver<Function> solver;
  solver.options.max_num_iterations = max_iterations;
  solver.options.gradient_tolerance = 1e-12;
  solver.options.parameter_tolerance = 1e-12;
  solver.options.function_tolerance = 1e-12;
  Eigen::Matrix<double, 9, 1> fitted = p;
  solver.Solve(function, &fitted);
  if (!fitted.allFinite() || !(total(fitted) < total(p))) return false;
  for (std::size_t a = 0; a < 3; ++a) {
    const Eigen::Vector3d p_W = fitted.segment<3>(static_cast<Eigen::Index>(3 * a));
    for (const Observation& o : obs[a])
      if (toCamera(cameras[static_cast<std::size_t>(o.camera)], p_W).z() <= 1e-9) return false;
  }
  for (std::size_t a = 0; a < 3; ++a) frame.p_W[kArmPoints[a]] = fitted.segment<3>(static_cast<Eigen::Index>(3 * a));
  return true;
}

}  // namespace nao
