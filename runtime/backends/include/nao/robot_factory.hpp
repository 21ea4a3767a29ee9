// The robot backend a run drives, built from its name (nao_rt --robot): the one place that
// knows which backends exist.
//   ode         the in-process ODE arm (sim_arm.hpp), at rest at the start pose
//   lola        a NAO V6 through LoLA at LolaParams::socket_path (lola_backend.hpp)
//   lola:PATH   the same at PATH
#pragma once

#include "nao/arm_model.hpp"
#include "nao/lola_backend.hpp"
#include "nao/robot_backend.hpp"
#include "nao/sim_arm.hpp"

#include <memory>
#include <string>

namespace nao {

/// The names makeRobotBackend takes, for messages.
inline constexpr const char* kRobotBackendNames = "ode, lola or lola:SOCKET";

/// True when `name` is one makeRobotBackend builds (a command line checks it before configuring).
bool isRobotBackendName(const std::string& name);

/// Builds the robot named `name` for `arm` (which must outlive it): the ODE arm (`sim`) at rest at
/// q_start (clamped to the limits), or LoLA with `lola` (its socket path from the name when
/// given; SIGINT/SIGTERM then ask it for a safe stop, installLolaStopSignals). Configure time:
/// allocates, connects; throws std::invalid_argument for an unknown name, std::runtime_error
/// when the robot cannot be reached.
std::unique_ptr<RobotBackend> makeRobotBackend(const std::string& name, const ArmModel& arm,
                                               const JointVector& q_start, const SimParams& sim,
                                               const LolaParams& lola);

}  // namespace nao
