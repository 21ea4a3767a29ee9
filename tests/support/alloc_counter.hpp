// The counting allocator moved to runtime/support (nao_rt counts its allocations too); the
// test suites keep including it by this name.
#pragma once

#include "../../runtime/support/alloc_counter.hpp"
