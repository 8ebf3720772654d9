// SIMD targets of the CPU backend. Each target's kernels are compiled into the binary in
// their own translation units (core/src/simd/), and the backend picks one at start-up from
// what this CPU runs (Google Highway's detection), so one binary serves every x86-64 (or
// Arm) machine. "scalar" is the one-sample-at-a-time code, the reference.
#pragma once

#include <string>

namespace mppi::simd {

enum class Target : int { kScalar = 0, kSse4, kAvx2, kAvx3, kNeon };
constexpr int kTargetCount = 5;

const char* name(Target t);        // "scalar", "sse4", "avx2", "avx3", "neon"
int lanes(Target t);               // floats per vector (1 for scalar)
bool compiled(Target t);           // this binary has kernels for it
bool supported(Target t);          // compiled, and this CPU runs it
Target best();                     // the widest supported target (scalar if none)
std::string target_names();        // "sse4, avx2, avx3, neon": what a setting may name
std::string supported_names();     // the supported targets, for messages

// Parses a setting: "auto" (best()), "off" (scalar) or a target name. False if it is none
// of them; `out` may be null (validation only).
bool parse_setting(const std::string& text, Target* out);

// The target a setting asks for on this machine; throws std::invalid_argument naming the
// setting ("simd: avx3 is not supported by this CPU (supported: sse4, avx2)").
Target resolve(const std::string& setting);

}  // namespace mppi::simd
