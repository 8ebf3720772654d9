// Counts every heap allocation of the program that links alloc_counter.cpp (it replaces
// the global operator new): tests assert "no allocation per cycle", benchmarks report
// start-up memory. Kept in its own translation unit so the replacement is never inlined.
#pragma once

#include <cstddef>

namespace mppi::testing {

std::size_t allocated_bytes();  // total bytes requested since start
std::size_t allocation_count(); // total calls since start

}  // namespace mppi::testing
