#include "mppi/app/config.hpp"

#include <cmath>
#include <cstdint>
#include <initializer_list>
#include <set>
#include <type_traits>
#include <utility>

#include "mppi/app/vehicle.hpp"
#include "mppi/params.hpp"
#include "mppi/settings_table.hpp"
#include "mppi/simd.hpp"
#include "mppi/tasks.hpp"

namespace mppi::app {
namespace {

[[noreturn]] void fail(const std::string& field, const std::string& why) { throw ConfigError(field + ": " + why); }

template <class T>
T scalar(const YAML::Node& node, const std::string& field) {
  if (!node.IsScalar()) fail(field, "expected a scalar");
  try {
    return node.as<T>();
  } catch (const YAML::Exception&) {
    fail(field, "cannot read '" + node.Scalar() + "' as a number");
  }
}

std::vector<float> floats(const YAML::Node& node, const std::string& field) {
  if (!node.IsSequence()) fail(field, "expected a list of numbers");
  std::vector<float> out;
  for (std::size_t i = 0; i < node.size(); ++i) {
    const double v = scalar<double>(node[i], field + "[" + std::to_string(i) + "]");
    if (!std::isfinite(v)) fail(field + "[" + std::to_string(i) + "]", "must be finite");
    out.push_back(static_cast<float>(v));
  }
  return out;
}

// The name of a map key; a key that is itself a list or a map (YAML's "? [a, b]: ...") is
// an error naming the section it is in, not a yaml-cpp conversion error naming nothing.
std::string key_name(const YAML::Node& key, const std::string& section) {
  if (!key.IsScalar())
    fail(section, "keys must be plain names (line " + std::to_string(key.Mark().line + 1) + " is a " +
                      (key.IsSequence() ? "list" : key.IsMap() ? "map" : "null") + ")");
  return key.Scalar();
}

// Applies "a.b.c=value" to the tree.
void apply_override(YAML::Node root, const std::string& text) {
  const auto eq = text.find('=');
  if (eq == std::string::npos || eq == 0) fail(text, "override must look like key.path=value");
  const std::string key = text.substr(0, eq);
  YAML::Node value;
  try {
    value = YAML::Load(text.substr(eq + 1));
  } catch (const YAML::Exception& e) {
    fail(key, std::string("override value is not valid YAML: ") + e.what());
  }
  std::vector<YAML::Node> path{root};
  std::size_t start = 0;
  while (true) {
    const auto dot = key.find('.', start);
    const std::string part = key.substr(start, dot == std::string::npos ? std::string::npos : dot - start);
    if (part.empty()) fail(key, "empty path element");
    if (dot == std::string::npos) {
      path.back()[part] = value;
      return;
    }
    YAML::Node next = path.back()[part];
    if (!next || next.IsNull()) {
      path.back()[part] = YAML::Node(YAML::NodeType::Map);
      next = path.back()[part];
    }
    if (!next.IsMap()) fail(key, "'" + part + "' is not a section");
    path.push_back(next);
    start = dot + 1;
  }
}

// The fields of a map section ("mppi", "ddp"): a key not in `known` is an error
// ("mppi.foo: unknown field"), before any value is read; read() takes a field's value, as
// the field's type, when the section gives it (else the default stays), and its errors name
// the field ("ddp.mu_init: ...").
class Fields {
 public:
  Fields(const YAML::Node& node, std::string section, const std::set<std::string>& known)
      : node_(node), section_(std::move(section)) {
    for (const auto& kv : node_) {
      const auto name = key_name(kv.first, section_);
      if (!known.count(name)) fail(section_ + "." + name, "unknown field");
    }
  }

  std::string path(const char* field) const { return section_ + "." + field; }

  template <class T>
  void read(const char* field, T& out) const {
    if (node_[field]) read_value(node_[field], path(field), out);
  }

 private:
  template <class T>
  static void read_value(const YAML::Node& n, const std::string& field, T& out) {
    out = scalar<T>(n, field);
  }
  static void read_value(const YAML::Node& n, const std::string& field, std::vector<float>& out) {
    out = floats(n, field);
  }

  const YAML::Node& node_;
  std::string section_;
};

// A value of the optimizer's table (mppi/settings.hpp), as the field's type.
template <class T>
void read_setting(const YAML::Node& n, const std::string& field, T& out) {
  out = scalar<T>(n, field);
}
void read_setting(const YAML::Node& n, const std::string& field, std::vector<float>& out) { out = floats(n, field); }
void read_setting(const YAML::Node& n, const std::string& field, Weighting& out) {
  if (!parse_weighting(scalar<std::string>(n, field), &out)) fail(field, "must be cost_to_go or trajectory");
}

// The keys of the `mppi:` section: the optimizer's table and the CUDA backend's `cuda:` map.
const std::set<std::string>& mppi_keys() {
  static const std::set<std::string> keys = [] {
    std::set<std::string> k{"cuda"};
    const MppiSettings defaults;
    visit_settings(defaults, [&](const SettingSpec& r, const auto&) { k.insert(r.name); });
    return k;
  }();
  return keys;
}

// The `mppi:` section through the optimizer's table: an unknown key, then a missing one,
// then a bad value is an error naming it; a key not given keeps its default.
void read_mppi(const YAML::Node& m, MppiSettings& s) {
  if (!m || !m.IsMap()) fail("mppi", "missing section");
  const Fields f(m, "mppi", mppi_keys());
  visit_settings(s, [&](const SettingSpec& r, const auto&) {
    if (r.required && !m[r.name]) fail(f.path(r.name), "missing");
  });
  visit_settings(s, [&](const SettingSpec& r, auto& field) {
    if (const YAML::Node n = m[r.name]) read_setting(n, f.path(r.name), field);
  });
}

void read_ddp(const YAML::Node& m, DdpSettings& d) {
  if (!m.IsMap()) fail("ddp", "expected a map");
  static const std::set<std::string> known = {
      "max_iterations", "line_search_steps", "mu_init", "mu_min", "mu_max", "mu_factor", "fd_step",
      "fd_hessian_step", "convexify", "r", "initial_plan", "obstacle_weight", "obstacle_margin", "obstacle_softness",
      "ground_weight", "ground_margin", "ground_softness", "speed_weight", "speed_limit", "exp_cap", "obstacle_reach"};
  const Fields f(m, "ddp", known);
  f.read("max_iterations", d.max_iterations);
  f.read("line_search_steps", d.line_search_steps);
  f.read("mu_init", d.mu_init);
  f.read("mu_min", d.mu_min);
  f.read("mu_max", d.mu_max);
  f.read("mu_factor", d.mu_factor);
  f.read("fd_step", d.fd_step);
  f.read("fd_hessian_step", d.fd_hessian_step);
  f.read("convexify", d.convexify);
  f.read("r", d.r);
  f.read("initial_plan", d.initial_plan);
  f.read("obstacle_weight", d.obstacle_weight);
  f.read("obstacle_margin", d.obstacle_margin);
  f.read("obstacle_softness", d.obstacle_softness);
  f.read("ground_weight", d.ground_weight);
  f.read("ground_margin", d.ground_margin);
  f.read("ground_softness", d.ground_softness);
  f.read("speed_weight", d.speed_weight);
  f.read("speed_limit", d.speed_limit);
  f.read("exp_cap", d.exp_cap);
  f.read("obstacle_reach", d.obstacle_reach);
}

void read_params(const YAML::Node& root, const char* section, AppConfig& c) {
  const YAML::Node node = root[section];
  if (!node) return;
  if (!node.IsMap()) fail(section, "expected a map of name: number");
  for (const auto& kv : node) {
    const std::string key = std::string(section) + "." + key_name(kv.first, section);
    c.params.emplace_back(key, scalar<double>(kv.second, key));
  }
}

// The task's hover control (one vehicle's channels; zeros for a model without one), from its
// model parameters as the tree gives them (the vehicle's merged in). Bad values are reported
// later, by the parameter check.
std::vector<float> hover_of(const std::string& task, const YAML::Node& root) {
  std::vector<float> hover;
  visit_task(task, [&](auto tag) {
    using T = typename decltype(tag)::type;
    typename T::Params p{};
    if (const YAML::Node m = root["model"]; m && m.IsMap())
      for (const auto& kv : m)
        if (kv.first.IsScalar() && kv.second.IsScalar()) {
          try {
            set_task_param<T>(p, "model." + kv.first.Scalar(), kv.second.as<double>());
          } catch (const YAML::Exception&) {
          }
        }
    hover.assign(static_cast<std::size_t>(T::kVehicleNu), 0.0f);
    if constexpr (has_external_accel<typename T::Vehicle::Params>) T::Vehicle::hover_control(p.vehicle, hover.data());
  });
  return hover;
}

// `hover` in mppi.u_init and mppi.u_nominal: that channel of the model's hover control (for a
// team, of each vehicle's), so a task file need not repeat its vehicle's mass.
void resolve_hover(YAML::Node root, const std::string& task) {
  const YAML::Node m = root["mppi"];
  if (!m || !m.IsMap()) return;
  std::vector<float> hover;
  for (const char* list : {"u_init", "u_nominal"}) {
    YAML::Node u = m[list];
    if (!u || !u.IsSequence()) continue;
    for (std::size_t i = 0; i < u.size(); ++i) {
      if (!u[i].IsScalar() || u[i].Scalar() != "hover") continue;
      if (hover.empty()) hover = hover_of(task, root);
      const std::size_t j = hover.empty() ? 0 : i % hover.size();
      if (hover.empty() || hover[j] == 0.0f)
        fail(std::string("mppi.") + list + "[" + std::to_string(i) + "]",
             "`hover` names a thrust or motor channel of a quadrotor task");
      u[i] = hover[j];
    }
  }
}

// The settings' vehicle: `vehicle: FILE` relative to the settings file's folder; given by an
// override (--set vehicle=FILE), relative to the working folder, as a command line's paths are.
std::shared_ptr<const VehicleFile> vehicle_of(const YAML::Node& root, const YAML::Node& file, const std::string& dir) {
  const YAML::Node n = root["vehicle"];
  if (!n || n.IsNull()) return nullptr;
  std::string path = scalar<std::string>(n, "vehicle");
  if (path.empty()) fail("vehicle", "expected a file name");
  const YAML::Node own = file["vehicle"];
  const bool from_file = own && own.IsScalar() && own.Scalar() == path;
  if (path[0] != '/' && from_file && !dir.empty()) path = dir + "/" + path;
  return std::make_shared<const VehicleFile>(load_vehicle(path));
}

}  // namespace

namespace {

// An enumerated field of mppi.cuda, by its names (cuda_settings.hpp).
template <class E>
void read_choice(const YAML::Node& m, const char* field, const char* names, E* out) {
  if (!m[field]) return;
  const std::string path = std::string("mppi.cuda.") + field;
  const YAML::Node& n = m[field];
  // `on`/`off`/`true`/`false` read as the text given (yaml-cpp keeps the scalar's text).
  if (!parse_cuda_setting(scalar<std::string>(n, path), out)) fail(path, std::string("must be ") + names);
}

}  // namespace

CudaSettings read_cuda_settings(const YAML::Node& m, const std::string& task) {
  CudaSettings s;
  if (!m || m.IsNull()) return s;
  if (!m.IsMap()) fail("mppi.cuda", "expected a map");
  static const std::set<std::string> known = {"kernel", "chunk_steps", "warps", "noise", "controls",
                                              "lanes",  "grid",        "pdl",   "graph"};
  const Fields f(m, "mppi.cuda", known);
  read_choice(m, "kernel", "auto, chunked or lanes", &s.kernel);
  f.read("chunk_steps", s.chunk_steps);
  f.read("warps", s.warps);
  read_choice(m, "noise", "auto, prepass or inline", &s.noise);
  read_choice(m, "controls", "auto, keep or redraw", &s.controls);
  f.read("lanes", s.lanes);
  read_choice(m, "grid", "device or host", &s.grid);
  read_choice(m, "pdl", "auto, on or off", &s.pdl);
  f.read("graph", s.graph);
  int vehicles = 1;
  visit_task(task, [&](auto tag) { vehicles = decltype(tag)::type::kVehicles; });
  if (const std::string err = validate(s, vehicles); !err.empty()) throw ConfigError("mppi.cuda." + err);
  return s;
}

namespace {

// A copy of `root` with `section`'s maps merged in, key by key (mppi, model, cost, daemon),
// and without the variant sections (`cuda:`, `cpu_targets:`): a variant has none of its own.
// Errors name the part; the caller puts the variant's name in front.
YAML::Node merged_with(const YAML::Node& root, const YAML::Node& section) {
  YAML::Node out = YAML::Clone(root);
  out.remove("cuda");
  out.remove("cpu_targets");
  for (const auto& kv : section) {
    const auto part = kv.first.as<std::string>();
    if (part != "mppi" && part != "model" && part != "cost" && part != "daemon")
      fail(part, "unknown section (mppi, model, cost, daemon)");
    if (!kv.second.IsMap()) fail(part, "expected a map");
    if (!out[part] || out[part].IsNull()) out[part] = YAML::Node(YAML::NodeType::Map);
    // The file's own section must be a map to merge into (the daemon section is checked only
    // here before mppid parses it; fuzz_settings found `daemon: 1` escaping as YAML::BadSubscript).
    if (!out[part].IsMap()) fail(part, "expected a map");
    for (const auto& f : kv.second) out[part][f.first.as<std::string>()] = YAML::Clone(f.second);
  }
  return out;
}

// Where a settings tree came from: its name in messages and the folder its paths are relative to.
struct Source {
  std::string label = "the settings";
  std::string dir;
};

// The vehicle's limits and hover against the parsed settings (for a team, every vehicle's).
void check_vehicle(const AppConfig& c, const YAML::Node& root, const Source& src) {
  int vehicles = 1;
  visit_task(c.task, [&](auto tag) { vehicles = decltype(tag)::type::kVehicles; });
  const std::vector<float> one = hover_of(c.task, root);
  std::vector<float> hover;
  for (int j = 0; j < vehicles; ++j) hover.insert(hover.end(), one.begin(), one.end());
  check_vehicle_fits(*c.vehicle, hover, c.mppi.u_min, c.mppi.u_max, c.mppi.u_init, c.mppi.u_nominal, src.label);
}

AppConfig parse_impl(YAML::Node root, const std::vector<std::string>& overrides, bool variant, const Source& src);

// The task's per-channel lists spread over a team, its model and cost parameters checked,
// the optimizer and DDP settings validated against its control size.
void check_against_task(AppConfig& c, const YAML::Node& root, const Source& src) {
  int nu = -1;
  std::string param_error;
  const bool known = visit_task(c.task, [&](auto tag) {
    using T = typename decltype(tag)::type;
    nu = T::kNu;
    // A team's per-channel lists may be given for one vehicle: every vehicle gets them.
    visit_settings(c.mppi, [](const SettingSpec&, auto& v) {
      if constexpr (std::is_same_v<std::decay_t<decltype(v)>, std::vector<float>>) {
        if (T::kVehicles > 1 && static_cast<int>(v.size()) == T::kVehicleNu) {
          const std::vector<float> one = v;
          for (int j = 1; j < T::kVehicles; ++j) v.insert(v.end(), one.begin(), one.end());
        }
      }
    });
    typename T::Params p{};
    for (const auto& [key, value] : c.params) {
      const std::string err = set_task_param<T>(p, key, value);
      if (!err.empty() && param_error.empty()) param_error = err;
    }
  });
  if (!known) fail("task", "unknown task '" + c.task + "'");
  if (!param_error.empty()) throw ConfigError(param_error);
  const std::string err = validate(c.mppi, nu);
  if (!err.empty()) throw ConfigError("mppi." + err);
  if (c.vehicle) check_vehicle(c, root, src);
  if (const std::string e = validate(c.ddp, nu); !e.empty()) throw ConfigError(e);
}

// One variant section (`cuda:`, `cpu_targets.avx2:`) merged into the file and parsed with
// the overrides `rest`. Errors name the variant: "cuda.sim: unknown section" (its own keys),
// "cuda: mppi.rollouts: must be >= 1" (the merged settings).
std::shared_ptr<const AppConfig> parse_variant(const YAML::Node& file, const YAML::Node& section,
                                               const std::string& name, const std::vector<std::string>& rest,
                                               const Source& src) {
  const Source vsrc{src.label + " (" + name + ")", src.dir};
  if (!section.IsMap()) fail(name, "expected a map of mppi/model/cost/daemon overrides");
  YAML::Node merged;
  try {
    merged = merged_with(file, section);
  } catch (const ConfigError& e) {
    throw ConfigError(name + "." + e.what());
  }
  try {
    return std::make_shared<const AppConfig>(parse_impl(merged, rest, true, vsrc));
  } catch (const ConfigError& e) {
    throw ConfigError(name + ": " + e.what());
  }
}

// The SIMD target an entry of `cpu_targets:` names (by its canonical name), once.
std::string cpu_target_of(const std::string& target, const AppConfig& c) {
  simd::Target t{};
  if (target == "off" || target == "auto" || !simd::parse_setting(target, &t))
    fail("cpu_targets." + target, "not a SIMD target (scalar, " + simd::target_names() + ")");
  if (c.cpu_targets.count(simd::name(t))) fail("cpu_targets." + target, "given twice");
  return simd::name(t);
}

// The variants (`cuda:`, each entry of `cpu_targets:`): the file with that section (after the
// overrides: --set cuda.x=... works) merged in, then the other overrides again (so a
// command-line --set wins over the section). Parsed, and so validated, now, whatever the
// machine; after the file itself, so an error of the file (or of an override both share) is
// reported as the file's.
void parse_variants(const YAML::Node& root, const YAML::Node& file, const std::vector<std::string>& overrides,
                    const Source& src, AppConfig* c) {
  std::vector<std::string> rest;
  for (const auto& o : overrides)
    if (o.rfind("cuda.", 0) != 0 && o.rfind("cpu_targets.", 0) != 0) rest.push_back(o);
  if (const YAML::Node section = root["cuda"]; section) c->cuda = parse_variant(file, section, "cuda", rest, src);
  const YAML::Node targets = root["cpu_targets"];
  if (!targets || targets.IsNull()) return;
  if (!targets.IsMap()) fail("cpu_targets", "expected a map of SIMD target: {mppi/model/cost/daemon overrides}");
  for (const auto& kv : targets) {
    const std::string target = key_name(kv.first, "cpu_targets");
    const std::string name = cpu_target_of(target, *c);
    c->cpu_targets[name] = parse_variant(file, kv.second, "cpu_targets." + target, rest, src);
  }
}

// Every top-level key a known section.
void check_sections(const YAML::Node& root) {
  static const std::set<std::string> sections = {"task", "backend", "mppi", "model", "cost", "daemon", "sim", "offline",
                                                 "description", "cuda", "cpu_targets", "controller", "ddp", "vehicle"};
  for (const auto& kv : root) {
    const auto name = key_name(kv.first, "(file)");
    if (!sections.count(name)) fail(name, "unknown section");
  }
}

// A text of the top level (task, backend, controller) among its choices ("" if any text).
void read_text(const YAML::Node& root, const char* field, std::initializer_list<const char*> choices,
               const char* names, std::string* out) {
  if (root[field]) *out = scalar<std::string>(root[field], field);
  if (choices.size() == 0) return;
  for (const char* c : choices)
    if (*out == c) return;
  fail(field, std::string("must be ") + names);
}

// The optimizers' sections: mppi (with its cuda map) and ddp.
void read_optimizers(const YAML::Node& root, AppConfig* c) {
  read_mppi(root["mppi"], c->mppi);
  const YAML::Node& mppi_section = root["mppi"];
  c->cuda_launch = read_cuda_settings(mppi_section["cuda"], c->task);
  read_text(root, "controller", {"mppi", "ddp"}, "mppi or ddp", &c->controller);
  if (const YAML::Node d = root["ddp"]; d && !d.IsNull()) {
    read_ddp(d, c->ddp);
    c->has_ddp = true;
  }
}

AppConfig parse_impl(YAML::Node root, const std::vector<std::string>& overrides, bool variant, const Source& src) {
  if (!root || !root.IsMap()) fail("(file)", "expected a YAML map at the top level");
  const YAML::Node file = YAML::Clone(root);
  for (const auto& o : overrides) apply_override(root, o);
  check_sections(root);
  AppConfig c;
  c.root = root;
  if (!root["task"]) fail("task", "missing");
  read_text(root, "task", {}, "", &c.task);
  c.vehicle = vehicle_of(root, file, src.dir);
  if (c.vehicle) merge_vehicle(*c.vehicle, root, file, c.task, src.label);
  resolve_hover(root, c.task);
  read_text(root, "backend", {"cpu", "cuda", "auto"}, "cpu, cuda or auto", &c.backend);
  read_optimizers(root, &c);
  read_params(root, "model", c);
  read_params(root, "cost", c);
  check_against_task(c, root, src);
  if (!variant) parse_variants(root, file, overrides, src, &c);
  return c;
}

}  // namespace

// The variant a backend takes here and its section name, or null (the file's own settings).
const AppConfig* AppConfig::variant(const std::string& resolved, std::string* name) const {
  const AppConfig* v = nullptr;
  std::string n;
  if (resolved == "cuda" && cuda) {
    v = cuda.get();
    n = "cuda";
  } else if (resolved == "cpu" && !cpu_targets.empty()) {
    simd::Target t{};
    // A setting this machine cannot run is CpuBackend's error to report, with the file's settings.
    if (simd::parse_setting(mppi.simd, &t) && simd::supported(t)) {
      if (const auto it = cpu_targets.find(simd::name(t)); it != cpu_targets.end()) {
        v = it->second.get();
        n = std::string("cpu_targets.") + it->first;
      }
    }
  }
  if (name != nullptr) *name = n;
  return v;
}

std::string AppConfig::variant_for(const std::string& resolved) const {
  std::string name;
  variant(resolved, &name);
  return name;
}

const AppConfig& AppConfig::for_backend(const std::string& resolved) const {
  const AppConfig* v = variant(resolved, nullptr);
  return v != nullptr ? *v : *this;
}

AppConfig parse_config(YAML::Node root, const std::vector<std::string>& overrides, const std::string& dir) {
  return parse_impl(root, overrides, false, Source{"the settings", dir});
}

AppConfig load_config(const std::string& file, const std::vector<std::string>& overrides) {
  YAML::Node root;
  try {
    root = YAML::LoadFile(file);
  } catch (const YAML::BadFile&) {
    throw ConfigError(file + ": cannot open");
  } catch (const YAML::Exception& e) {
    throw ConfigError(file + ": " + e.what());
  }
  const auto slash = file.rfind('/');
  AppConfig c = parse_impl(root, overrides, false, Source{file, slash == std::string::npos ? "" : file.substr(0, slash)});
  c.path = file;
  return c;
}

}  // namespace mppi::app
