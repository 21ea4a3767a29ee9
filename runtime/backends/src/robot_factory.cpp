// The robot backend factory (nao/robot_factory.hpp).
#include "nao/robot_factory.hpp"

#include <stdexcept>

namespace nao {
namespace {

// The socket of a lola name; false for any other name.
bool lolaSocket(const std::string& name, const std::string& default_socket, std::string& socket) {
  if (name == "lola") {
    socket = default_socket;
    return true;
  }
  if (name.rfind("lola:", 0) == 0 && name.size() > 5) {
    socket = name.substr(5);
    return true;
  }
  return false;
}

}  // namespace

bool isRobotBackendName(const std::string& name) {
  std::string socket;
  return name == "ode" || lolaSocket(name, "", socket);
}

std::unique_ptr<RobotBackend> makeRobotBackend(const std::string& name, const ArmModel& arm,
                                               const JointVector& q_start, const SimParams& sim,
                                               const LolaParams& lola) {
  if (name == "ode") return std::make_unique<OdeArmBackend>(arm, sim, clampToLimits(arm, q_start));
  LolaParams params = lola;
  if (lolaSocket(name, lola.socket_path, params.socket_path)) {
    installLolaStopSignals();
    return std::make_unique<LolaBackend>(arm, params);
  }
  throw std::invalid_argument("--robot '" + name + "': expected " + kRobotBackendNames);
}

}  // namespace nao
