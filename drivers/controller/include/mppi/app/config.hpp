// Settings files: one YAML file per controller (task, backend, MPPI settings, model and
// cost parameters, and a free-form section per program). Everything is validated on load;
// a bad or missing field is a ConfigError whose message names it ("mppi.rollouts: ...").
#pragma once

#include <yaml-cpp/yaml.h>

#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "mppi/app/vehicle.hpp"
#include "mppi/controller.hpp"
#include "mppi/ddp/settings.hpp"
#include "mppi/gpu/cuda_settings.hpp"
#include "mppi/settings.hpp"

namespace mppi::app {

struct ConfigError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct AppConfig {
  std::string path;                                  // file it came from ("" if none)
  std::string task;                                  // a name of mppi::task_names()
  std::string backend = "auto";                      // cpu | cuda | auto
  MppiSettings mppi;
  // mppi.cuda: the CUDA backend's launch choices (mppi/gpu/cuda_settings.hpp; defaults: its own).
  CudaSettings cuda_launch;
  // The optimizer: "mppi" (the default) or "ddp", the MPC-DDP baseline, which plans with the
  // `ddp:` section's settings over mppi.horizon, mppi.dt and the limits of mppi.
  std::string controller = "mppi";
  DdpSettings ddp;
  bool has_ddp = false;                              // the file has a `ddp:` section
  std::vector<std::pair<std::string, double>> params;  // "model.NAME" / "cost.NAME" overrides
  YAML::Node root;                                   // the whole document (programs read their own section)
  // The vehicle file (`vehicle:` or --vehicle): merged into model and daemon settings, its
  // limits and hover checked (mppi/app/vehicle.hpp); null if none.
  std::shared_ptr<const VehicleFile> vehicle;
  // The settings file's `cuda:` section (mppi, model, cost overrides: what the CUDA backend
  // flies with instead, e.g. more rollouts), merged and validated at load; null if none.
  std::shared_ptr<const AppConfig> cuda;
  // The settings file's `cpu_targets:` section: per SIMD target of the CPU backend (scalar,
  // sse4, avx2, avx3, neon), what it flies with instead (e.g. fewer rollouts on a target with
  // narrower lanes, so the cycle keeps its headroom). Merged and validated at load, every
  // entry, whatever the machine; the target used is the one mppi.simd resolves to here.
  std::map<std::string, std::shared_ptr<const AppConfig>> cpu_targets;
  // The settings for a backend ("cpu" or "cuda"): *cuda for "cuda" when there is one; for
  // "cpu", the entry of cpu_targets of the SIMD target this machine runs, when there is one.
  const AppConfig& for_backend(const std::string& resolved) const;
  // Which section for_backend(resolved) takes: "cuda", "cpu_targets.<target>" or "" (the file's).
  std::string variant_for(const std::string& resolved) const;
  // The variant for_backend(resolved) takes (null: the file's settings), and its section name.
  const AppConfig* variant(const std::string& resolved, std::string* name) const;
  // This config flying the optimizer settings S whatever the backend (S comes from a running
  // controller, already the backend's own): a live update rebuilds from it. Setting only
  // `mppi` would leave the `cuda:` (or `cpu_targets:`) section's stale settings to the backend.
  AppConfig with_mppi(const MppiSettings& s) const {
    AppConfig c = *this;
    c.mppi = s;
    const auto set_mppi = [&s](std::shared_ptr<const AppConfig>& section) {  // a copy: the old one is shared
      if (!section) return;
      auto v = std::make_shared<AppConfig>(*section);
      v->mppi = s;
      section = std::move(v);
    };
    set_mppi(c.cuda);
    for (auto& entry : c.cpu_targets) set_mppi(entry.second);
    return c;
  }
};

// Loads FILE and applies overrides "dotted.key=value" (YAML scalars or flow sequences, e.g.
// "mppi.rollouts=512", "mppi.sigma=[100,100,100,100]", "vehicle=FILE") before validating. The
// file's `vehicle:` is relative to the file; one given by an override, to the working folder.
// `hover` in mppi.u_init / u_nominal stands for that channel of the model's hover control.
AppConfig load_config(const std::string& file, const std::vector<std::string>& overrides = {});
// The same from a tree; a relative vehicle file is looked up in `dir` (else the working folder).
AppConfig parse_config(YAML::Node root, const std::vector<std::string>& overrides = {}, const std::string& dir = "");

// A task's `mppi.cuda` section (null or missing: every default), validated for the task;
// errors name the field ("mppi.cuda.warps: ...").
CudaSettings read_cuda_settings(const YAML::Node& section, const std::string& task);

// The default settings file of a task, config/tasks/<task>.yaml in the source tree.
std::string default_config_path(const std::string& task);

// Builds the controller of the config's task on its backend. "auto" picks CUDA when built
// with it and a device is present. Throws ConfigError for an unusable backend. With
// controller: ddp, the DDP baseline instead (CPU; the backend setting does not apply).
std::unique_ptr<Controller> make_controller(const AppConfig& config);

// Name of the backend "auto" resolves to here, and why CUDA is not available (if so).
std::string resolve_backend(const std::string& requested, std::string* why_not_cuda = nullptr);

}  // namespace mppi::app
