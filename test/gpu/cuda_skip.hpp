// SKIP_WITHOUT_CUDA(): a CUDA test skips (with the reason) where no CUDA device can run this
// build's kernels, as on CI.
#pragma once

#include <gtest/gtest.h>

#include <string>

#include "mppi/gpu/cuda_backend.hpp"

#define SKIP_WITHOUT_CUDA()                                                             \
  do {                                                                                  \
    std::string why_;                                                                   \
    if (!::mppi::cuda_device_available(&why_)) GTEST_SKIP() << "no CUDA device: " << why_; \
  } while (0)
