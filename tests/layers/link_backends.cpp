// Links nao_backends alone (layer_backends_links): the ODE arm and LoLA need nao_core, ODE and
// threads, no parser and no live input.
#include "nao/lola.hpp"
#include "nao/sim_arm.hpp"

int main(int argc, char**) {
  nao::lola::SensorPacket packet;
  char buffer[4096];
  if (argc > 1) {  // linking is the test; the simulation is only built when asked
    nao::ArmModel arm{};
    nao::OdeArmBackend ode(arm, nao::SimParams{}, nao::JointVector::Zero());
    return ode.faults() == 0 ? 0 : 1;
  }
  return nao::lola::writeSensorPacket(packet, buffer, sizeof buffer) > 0 ? 0 : 1;
}
