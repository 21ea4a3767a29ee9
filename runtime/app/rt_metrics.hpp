// The run metrics are nao_metrics' (runtime/metrics, nao/metrics.hpp); this header forwards to
// it for the files that still include it by this name.
#pragma once

#include "nao/metrics.hpp"  // IWYU pragma: export
