// The error of the runtime's input parsers (calibration JSON, OpenPose frames): configure-time
// and reader-thread code only, never the control loop. The message is one
// line that names the input (file, camera, field) and the problem.
#pragma once

#include <stdexcept>

namespace nao {

class InputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace nao
