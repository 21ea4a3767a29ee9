// The run metrics are nao_metrics' (runtime/metrics/src/metrics.cpp). This file only keeps the
// library nao_rt_metrics of runtime/app/CMakeLists.txt building, as a name for nao_metrics
// (runtime/CMakeLists.txt links the two), until that file links nao_metrics itself.
#include "rt_metrics.hpp"
