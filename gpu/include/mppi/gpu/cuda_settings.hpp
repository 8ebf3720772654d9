// The CUDA backend's launch settings: a task file's `mppi.cuda` section (parsed by
// drivers/controller's settings parser, mppi/app/config.hpp). Every field defaults to the
// backend's own choice (plan_launch, launch_plan.hpp); a value given overrides it, for
// measurements and for a device the built-in choices do not suit. The rollout costs and the
// plan are the same whatever is chosen (the CUDA parity tests run every kernel). Plain C++:
// the settings parser includes this header in builds without CUDA.
#pragma once

#include <cstddef>
#include <string>

namespace mppi {

// The most warps a block of each chunked kernel may have (its __launch_bounds__).
constexpr int kCudaChunkMaxWarps = 8;       // rollout_chunked (single vehicles)
constexpr int kCudaTeamChunkMaxWarps = 16;  // rollout_chunked_team

struct CudaSettings {
  // kernel: the chunked kernel (rollout_chunked, rollout_chunked_team) or the lane kernel
  // (rollout_single, rollout_team).
  enum class Kernel { kAuto, kChunked, kLanes };
  // noise (teams' lane kernel): drawn by a pre-pass into a buffer, or inline in the rollouts.
  enum class Noise { kAuto, kPrepass, kInline };
  // controls: the perturbed controls kept on the device for the update, or drawn again there.
  enum class Controls { kAuto, kKeep, kRedraw };
  // grid (forest tasks): the cycle's obstacle grid built on the device, or the host's searched.
  enum class Grid { kDevice, kHost };
  // pdl: programmatic dependent launches (auto: on from compute capability 9.0, Hopper).
  enum class Switch { kAuto, kOn, kOff };

  Kernel kernel = Kernel::kAuto;
  int chunk_steps = 0;  // steps a chunk of the chunked kernels; 0: the backend's choice
  int warps = 0;        // warps a block of the chunked kernels; 0: the backend's choice
  Noise noise = Noise::kAuto;
  Controls controls = Controls::kAuto;
  int lanes = 0;        // threads a rollout of the single-vehicle forest lane kernel (1, 2, 4, 8); 0: auto
  Grid grid = Grid::kDevice;
  Switch pdl = Switch::kAuto;
  bool graph = true;    // the update captured once as a CUDA graph (false: launched stream by stream)

  bool operator==(const CudaSettings& o) const {
    return kernel == o.kernel && chunk_steps == o.chunk_steps && warps == o.warps && noise == o.noise &&
           controls == o.controls && lanes == o.lanes && grid == o.grid && pdl == o.pdl && graph == o.graph;
  }
  bool operator!=(const CudaSettings& o) const { return !(*this == o); }
};

// The names the settings file uses, and back (false, *out untouched, for any other text).
namespace cuda_settings_detail {
template <class E, std::size_t N>
const char* name_of(E v, const char* const (&names)[N]) {
  const auto i = static_cast<std::size_t>(v);
  return i < N ? names[i] : "?";
}
template <class E, std::size_t N>
bool parse(const std::string& text, const char* const (&names)[N], E* out) {
  for (std::size_t i = 0; i < N; ++i)
    if (text == names[i]) {
      *out = static_cast<E>(i);
      return true;
    }
  return false;
}
inline constexpr const char* kKernel[] = {"auto", "chunked", "lanes"};
inline constexpr const char* kNoise[] = {"auto", "prepass", "inline"};
inline constexpr const char* kControls[] = {"auto", "keep", "redraw"};
inline constexpr const char* kGrid[] = {"device", "host"};
inline constexpr const char* kSwitch[] = {"auto", "on", "off"};
}  // namespace cuda_settings_detail

inline const char* to_string(CudaSettings::Kernel v) { return cuda_settings_detail::name_of(v, cuda_settings_detail::kKernel); }
inline const char* to_string(CudaSettings::Noise v) { return cuda_settings_detail::name_of(v, cuda_settings_detail::kNoise); }
inline const char* to_string(CudaSettings::Controls v) {
  return cuda_settings_detail::name_of(v, cuda_settings_detail::kControls);
}
inline const char* to_string(CudaSettings::Grid v) { return cuda_settings_detail::name_of(v, cuda_settings_detail::kGrid); }
inline const char* to_string(CudaSettings::Switch v) { return cuda_settings_detail::name_of(v, cuda_settings_detail::kSwitch); }
inline bool parse_cuda_setting(const std::string& text, CudaSettings::Kernel* out) {
  return cuda_settings_detail::parse(text, cuda_settings_detail::kKernel, out);
}
inline bool parse_cuda_setting(const std::string& text, CudaSettings::Noise* out) {
  return cuda_settings_detail::parse(text, cuda_settings_detail::kNoise, out);
}
inline bool parse_cuda_setting(const std::string& text, CudaSettings::Controls* out) {
  return cuda_settings_detail::parse(text, cuda_settings_detail::kControls, out);
}
inline bool parse_cuda_setting(const std::string& text, CudaSettings::Grid* out) {
  return cuda_settings_detail::parse(text, cuda_settings_detail::kGrid, out);
}
inline bool parse_cuda_setting(const std::string& text, CudaSettings::Switch* out) {
  return cuda_settings_detail::parse(text, cuda_settings_detail::kSwitch, out);
}

// Empty when valid for a task of `vehicles` vehicles, else "field: reason" for the first bad
// field (chunk_steps >= 0; warps 0 to the chunked kernel's most; lanes 0, 1, 2, 4 or 8).
inline std::string validate(const CudaSettings& s, int vehicles) {
  const int max_warps = vehicles > 1 ? kCudaTeamChunkMaxWarps : kCudaChunkMaxWarps;
  if (s.chunk_steps < 0) return "chunk_steps: must be >= 1, or 0 for the backend's choice";
  if (s.warps < 0 || s.warps > max_warps)
    return "warps: must be 1 to " + std::to_string(max_warps) + (vehicles > 1 ? " for a team" : " for one vehicle") +
           ", or 0 for the backend's choice";
  if (s.lanes != 0 && s.lanes != 1 && s.lanes != 2 && s.lanes != 4 && s.lanes != 8)
    return "lanes: must be 1, 2, 4 or 8, or 0 for the backend's choice";
  return {};
}

// One line, every field as the settings file writes it: "kernel=auto chunk_steps=auto ... graph=true".
inline std::string describe(const CudaSettings& s) {
  const auto count = [](int v) { return v == 0 ? std::string("auto") : std::to_string(v); };
  return std::string("kernel=") + to_string(s.kernel) + " chunk_steps=" + count(s.chunk_steps) +
         " warps=" + count(s.warps) + " noise=" + to_string(s.noise) + " controls=" + to_string(s.controls) +
         " lanes=" + count(s.lanes) + " grid=" + to_string(s.grid) + " pdl=" + to_string(s.pdl) +
         " graph=" + (s.graph ? "true" : "false");
}

}  // namespace mppi
