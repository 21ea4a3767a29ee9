// Retargeting, paper Algorithm 1, offline with Ceres: the same frame-level steps as the online
// fixed-size LM (runtime nao/retarget.hpp, which documents the algorithm, the IK objective and
// the parameters), each IK solve done by Ceres' bounded Levenberg-Marquardt.
//
// Ceres setup per IK solve: one parameter block q (5) with the URDF limits as bounds, an
// analytic-Jacobian SizedCostFunction<8, 5> for the hand position plus the joint-space pull
// sqrt(mu w + nu) (q - c) (IkJointTerms: posture and motion costs), and a SizedCostFunction<3, 5>
// for the pointing direction when given; the bounds are the IkJointTerms box (the joint limits,
// and from the second frame on the step bound);
// TRUST_REGION / LEVENBERG_MARQUARDT, DENSE_QR, one thread, initial trust region 1/lambda_x,
// max_num_iterations = 4 x max_inner_iterations, gradient_tolerance and parameter_tolerance from
// RetargetParams, function_tolerance 1e-16 (so it stops on optimality, not on a stalled cost).
// Ceres' bounds work by projection, which crawls once a joint sits at a limit (it stopped
// up to 1.5e-2 rad short there); so after the bounded solve, the joints at a limit whose
// gradient pushes outward are held constant (SubsetManifold) and Ceres re-solves, until that
// active set stops changing. Both solvers then converge to the same minimiser: measured
// agreement ~2e-7 rad on 1200 warm-started frames (tests/test_retarget.cpp checks 1e-4 rad).
//
// Not real-time safe: Ceres allocates on every solve. Offline use only.
#pragma once

#include "nao/retarget.hpp"
#include "nao/retarget_sequence.hpp"

#include <Eigen/Core>

#include <vector>

namespace nao::tools {

/// Workspace of the Ceres version; mirrors nao::RetargetData.
struct CeresRetargetData {
  ArmData arm;              ///< kinematics workspace of the outer loop
  ArmData arm_cost;         ///< kinematics workspace of the cost functions
  RetargetHistory history;  ///< warm start and the previous frame's poses
  IkResult ik;              ///< the last IK solve
  RetargetResult result;    ///< the last frame
};

/// Forgets the warm start and the previous frame (next frame starts from its q_target clamped).
void resetRetarget(CeresRetargetData& data);

/// One bounded IK solve with Ceres; same problem and arguments as nao::solveHandIk.
/// @return data.ik.q (rad, inside limits); data.ik holds cost, iterations, converged.
const JointVector& solveHandIkCeres(const ArmModel& model, const RetargetParams& params, CeresRetargetData& data,
                                    const Eigen::Vector3d& p_target_TH, const JointVector& q_start,
                                    const JointVector& q_anchor, const Eigen::Vector3d* u_target_TH = nullptr);

/// The same solve with explicit joint terms (pull and box), as nao::solveHandIk's second form.
const JointVector& solveHandIkCeres(const ArmModel& model, const RetargetParams& params, CeresRetargetData& data,
                                    const Eigen::Vector3d& p_target_TH, const JointVector& q_start,
                                    const IkJointTerms& terms, const Eigen::Vector3d* u_target_TH);

/// One frame of Algorithm 1 with Ceres; same arguments, result and flags as nao::solveRetarget.
const RetargetResult& solveRetargetCeres(const ArmModel& model, const RetargetParams& params,
                                         CeresRetargetData& data, const Eigen::Vector3d& p_target_TH,
                                         const JointVector& q_target, const Eigen::Vector3d* u_target_TH = nullptr);

/// One frame's targets (the runtime's, nao/retarget_sequence.hpp).
using nao::RetargetFrame;

/// A whole sequence with the online fixed-size LM, warm-started frame to frame from a fresh
/// start (first frame from its q_target clamped). One result per frame.
std::vector<RetargetResult> retargetSequenceLM(const ArmModel& model, const RetargetParams& params,
                                               const std::vector<RetargetFrame>& frames);

/// The same sequence with the Ceres version.
std::vector<RetargetResult> retargetSequenceCeres(const ArmModel& model, const RetargetParams& params,
                                                  const std::vector<RetargetFrame>& frames);

/// Largest joint differences between two runs over the same frames.
struct RetargetAgreement {
  double max_abs_q_x = 0.0;  ///< max over frames and joints of |q_x(a) - q_x(b)|, rad
  double max_abs_q_q = 0.0;  ///< same for q_q, rad
  int worst_frame = -1;      ///< frame of the larger of the two maxima (-1 if no frames)
};

/// Compares two result sequences frame by frame; throws std::invalid_argument if their lengths differ.
RetargetAgreement compareRetarget(const std::vector<RetargetResult>& a, const std::vector<RetargetResult>& b);

}  // namespace nao::tools
