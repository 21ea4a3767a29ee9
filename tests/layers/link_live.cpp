// Links nao_live alone (layer_live_links): the live camera reference needs nao_core, nao_io's
// OpenPose and calibration readers and a thread, no robot backend.
#include "nao/live_camera.hpp"
#include "nao/skeleton_filter.hpp"

int main() {
  nao::SkeletonLowPass filter;
  nao::resetSkeletonLowPass(filter);
  nao::SkeletonFrame frame;
  nao::lowPassSkeleton(nao::SkeletonLowPassParams{}, filter, frame);
  return frame.ok[0] ? 1 : 0;
}
