#include "mppi/simd.hpp"

#ifdef MPPID_HAVE_HWY
#include <cstdint>
#include <hwy/targets.h>
#endif

#include <stdexcept>

namespace mppi::simd {
namespace {

constexpr Target kAll[kTargetCount] = {Target::kScalar, Target::kSse4, Target::kAvx2, Target::kAvx3, Target::kNeon};

#ifdef MPPID_HAVE_HWY
// Highway's bit of each target (0: none).
std::int64_t hwy_bit(Target t) {
  switch (t) {
#if HWY_ARCH_X86
    case Target::kSse4: return HWY_SSE4;
    case Target::kAvx2: return HWY_AVX2;
    case Target::kAvx3: return HWY_AVX3;
#endif
#if HWY_ARCH_ARM
    case Target::kNeon: return HWY_NEON;
#endif
    default: return 0;
  }
}
#endif

}  // namespace

const char* name(Target t) {
  switch (t) {
    case Target::kScalar: return "scalar";
    case Target::kSse4: return "sse4";
    case Target::kAvx2: return "avx2";
    case Target::kAvx3: return "avx3";
    case Target::kNeon: return "neon";
  }
  return "?";
}

int lanes(Target t) {
  switch (t) {
    case Target::kSse4: return 4;
    case Target::kAvx2: return 8;
    case Target::kAvx3: return 16;
    case Target::kNeon: return 4;
    default: return 1;
  }
}

bool compiled(Target t) {
  switch (t) {
    case Target::kScalar: return true;
#ifdef MPPID_SIMD_SSE4
    case Target::kSse4: return true;
#endif
#ifdef MPPID_SIMD_AVX2
    case Target::kAvx2: return true;
#endif
#ifdef MPPID_SIMD_AVX3
    case Target::kAvx3: return true;
#endif
#ifdef MPPID_SIMD_NEON
    case Target::kNeon: return true;
#endif
    default: return false;
  }
}

bool supported(Target t) {
  if (t == Target::kScalar) return true;
  if (!compiled(t)) return false;
#ifdef MPPID_HAVE_HWY
  const std::int64_t bit = hwy_bit(t);
  return bit != 0 && (hwy::SupportedTargets() & bit) != 0;
#else
  return false;
#endif
}

Target best() {
  for (Target t : {Target::kAvx3, Target::kAvx2, Target::kNeon, Target::kSse4})
    if (supported(t)) return t;
  return Target::kScalar;
}

std::string target_names() { return "sse4, avx2, avx3, neon"; }

std::string supported_names() {
  std::string out;
  for (Target t : kAll) {
    if (t == Target::kScalar || !supported(t)) continue;
    if (!out.empty()) out += ", ";
    out += name(t);
  }
  return out.empty() ? "none" : out;
}

bool parse_setting(const std::string& text, Target* out) {
  Target t = Target::kScalar;
  if (text == "auto") t = best();
  else if (text == "off" || text == "scalar") t = Target::kScalar;
  else {
    bool found = false;
    for (Target c : kAll) {
      if (c != Target::kScalar && text == name(c)) {
        t = c;
        found = true;
      }
    }
    if (!found) return false;
  }
  if (out != nullptr) *out = t;
  return true;
}

Target resolve(const std::string& setting) {
  Target t = Target::kScalar;
  if (!parse_setting(setting, &t))
    throw std::invalid_argument("simd: '" + setting + "' is not auto, off or a target (" + target_names() + ")");
  if (!compiled(t)) throw std::invalid_argument("simd: " + setting + " is not built into this program");
  if (!supported(t))
    throw std::invalid_argument("simd: " + setting + " is not supported by this CPU (supported: " + supported_names() +
                                ")");
  return t;
}

}  // namespace mppi::simd
