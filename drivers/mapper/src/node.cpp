#include "mapper/node.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <set>
#include <sys/select.h>
#include <stdexcept>

namespace mapper {
namespace {

using Clock = std::chrono::steady_clock;

[[noreturn]] void fail(const std::string& where, const std::string& what) {
  throw std::runtime_error("mapper settings: " + where + ": " + what);
}

template <class T>
void read(const YAML::Node& n, const char* key, const std::string& where, T& out) {
  if (!n[key]) return;
  try {
    out = n[key].as<T>();
  } catch (const YAML::Exception& e) {
    fail(where + "." + key, std::string("bad value: ") + e.what());
  }
}

void check_keys(const YAML::Node& n, const std::string& where, const std::set<std::string>& known) {
  if (!n) return;
  if (!n.IsMap()) fail(where, "expected a mapping");
  for (const auto& kv : n)
    if (known.count(kv.first.Scalar()) == 0) fail(where + "." + kv.first.Scalar(), "unknown key");
}

// "a.b=value" into the document: the value parsed as YAML (numbers, lists, strings).
void apply_set(YAML::Node& root, const std::string& kv) {
  const auto eq = kv.find('=');
  if (eq == std::string::npos || eq == 0) fail(kv, "expected key=value");
  const std::string key = kv.substr(0, eq);
  const auto dot = key.find('.');
  YAML::Node value = YAML::Load(kv.substr(eq + 1));
  if (dot == std::string::npos) {
    root[key] = value;
  } else {
    YAML::Node section = root[key.substr(0, dot)];
    section[key.substr(dot + 1)] = value;
  }
}

void read_map(const YAML::Node& m, MapSettings& s) {
  check_keys(m, "map",
             {"resolution", "size", "max_distance", "floor_z", "lead", "hit", "miss", "min_logodds", "max_logodds"});
  if (!m) return;
  read(m, "resolution", "map", s.resolution);
  std::vector<double> size;
  read(m, "size", "map", size);
  if (!size.empty()) {
    if (size.size() != 3) fail("map.size", "expected [x, y, z] metres");
    s.size = {size[0], size[1], size[2]};
  }
  read(m, "max_distance", "map", s.max_distance);
  read(m, "floor_z", "map", s.floor_z);
  read(m, "lead", "map", s.lead);
  read(m, "hit", "map", s.hit);
  read(m, "miss", "map", s.miss);
  read(m, "min_logodds", "map", s.min_logodds);
  read(m, "max_logodds", "map", s.max_logodds);
  if (!(s.hit > 0 && s.miss < 0 && s.min_logodds < 0 && s.max_logodds > 0 && s.min_logodds >= -127 &&
        s.max_logodds <= 127))
    fail("map", "hit > 0, miss < 0, min_logodds in [-127, 0), max_logodds in (0, 127]");
}

float percentile(std::vector<float> v, double p) {
  if (v.empty()) return 0.0f;
  const auto k = static_cast<std::size_t>(std::min<double>(static_cast<double>(v.size()) - 1.0,
                                                           std::floor(p * static_cast<double>(v.size()))));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

std::string timing_json(const std::vector<float>& v) {
  char buf[160];
  const float mx = v.empty() ? 0.0f : *std::max_element(v.begin(), v.end());
  std::snprintf(buf, sizeof buf, "{\"n\":%zu,\"p50\":%.3f,\"p99\":%.3f,\"max\":%.3f}", v.size(),
                static_cast<double>(percentile(v, 0.5)), static_cast<double>(percentile(v, 0.99)),
                static_cast<double>(mx));
  return buf;
}

double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

// This thread's CPU time [ms] (the work's own cost; wall time adds what preempted it).
double cpu_ms() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return 1e3 * static_cast<double>(ts.tv_sec) + 1e-6 * static_cast<double>(ts.tv_nsec);
}

std::int64_t wall_us() {
  return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

constexpr std::size_t kCloudCountOffset = 8 + 8 + 8 + 1 + 3 * 4 + 4 * 4 + 4 + 4;  // fingerprint included
constexpr std::size_t kCloudBytesPerPoint = 3 * 4 + 1;
constexpr std::size_t kTimingSamples = 1 << 18;

}  // namespace

NodeSettings load_settings(const std::string& path, const std::vector<std::string>& sets) {
  YAML::Node root;
  try {
    root = path.empty() ? YAML::Node(YAML::NodeType::Map) : YAML::LoadFile(path);
    for (const auto& kv : sets) apply_set(root, kv);
  } catch (const YAML::Exception& e) {
    fail(path.empty() ? "--set" : path, e.what());
  }
  check_keys(root, "mapper", {"map", "rate_hz", "inputs", "output", "max_ray", "lcm_url", "sensor_lcm_url"});
  NodeSettings s;
  read_map(root["map"], s.map);
  read(root, "rate_hz", "mapper", s.rate_hz);
  read(root, "inputs", "mapper", s.inputs);
  read(root, "output", "mapper", s.output);
  read(root, "max_ray", "mapper", s.max_ray);
  read(root, "lcm_url", "mapper", s.lcm_url);
  read(root, "sensor_lcm_url", "mapper", s.sensor_lcm_url);
  if (!(s.rate_hz > 0.0 && s.rate_hz <= 100.0)) fail("rate_hz", "must be in (0, 100]");
  if (s.inputs.empty()) fail("inputs", "at least one point_cloud_t channel");
  if (!(s.max_ray >= 0.0)) fail("max_ray", "must be >= 0");
  return s;
}

bool decode_cloud(const void* data, std::size_t size, mppi_lcm::point_cloud_t* m) {
  if (size < kCloudCountOffset + 4) return false;
  const auto* b = static_cast<const unsigned char*>(data) + kCloudCountOffset;
  const std::int32_t n = static_cast<std::int32_t>((std::uint32_t{b[0]} << 24) | (std::uint32_t{b[1]} << 16) |
                                                   (std::uint32_t{b[2]} << 8) | std::uint32_t{b[3]});
  if (n < 0 || size != kCloudCountOffset + 4 + kCloudBytesPerPoint * static_cast<std::size_t>(n)) return false;
  return m->decode(data, 0, static_cast<int>(size)) == static_cast<int>(size);
}

MapperNode::MapperNode(const NodeSettings& s, lcm::LCM* maps, lcm::LCM* sensors)
    : s_(s), lcm_(maps), sensors_(sensors), map_(s.map) {
  for (const auto& ch : s_.inputs) sensors_->subscribe(ch, &MapperNode::on_cloud, this);
  out_.n_cells = map_.cells();
  out_.distance_mm.reserve(static_cast<std::size_t>(map_.cells()));
  for (auto* v : {&integrate_ms_, &integrate_cpu_ms_, &publish_ms_, &publish_cpu_ms_, &age_ms_}) v->reserve(kTimingSamples);
  columns_seen_.reserve(1 << 16);
  new_columns_.reserve(static_cast<std::size_t>(map_.nx()) * static_cast<std::size_t>(map_.ny()));
}

void MapperNode::on_cloud(const lcm::ReceiveBuffer* rb, const std::string&) {
  if (!decode_cloud(rb->data, rb->data_size, &in_)) {
    ++undecodable_;
    return;
  }
  integrate(in_);
}

// The window follows the sensor, `lead` metres ahead along its horizontal motion.
void MapperNode::centre_on(const float* position) {
  const double p[3] = {position[0], position[1], position[2]};
  if (have_pos_) {
    const double dx = p[0] - last_pos_[0], dy = p[1] - last_pos_[1], d = std::hypot(dx, dy);
    if (d > 0.05) {
      heading_[0] = dx / d;
      heading_[1] = dy / d;
      std::copy(p, p + 3, last_pos_);
    }
  } else {
    std::copy(p, p + 3, last_pos_);
    have_pos_ = true;
  }
  const double c[3] = {p[0] + s_.map.lead * heading_[0], p[1] + s_.map.lead * heading_[1], p[2]};
  map_.recentre(c);
}

void MapperNode::integrate(const mppi_lcm::point_cloud_t& m) {
  const auto t0 = Clock::now();
  const double c0 = cpu_ms();
  for (float v : m.position)
    if (!std::isfinite(v)) return;
  centre_on(m.position);
  const double w = m.orientation[0], x = m.orientation[1], y = m.orientation[2], z = m.orientation[3];
  // Sensor -> world rotation matrix of the (normalised) quaternion.
  const double qn = std::sqrt(w * w + x * x + y * y + z * z);
  if (!(qn > 0.5 && qn < 2.0)) return;
  const double a = w / qn, b = x / qn, c = y / qn, d = z / qn;
  const double r[9] = {1 - 2 * (c * c + d * d), 2 * (b * c - a * d),     2 * (b * d + a * c),
                       2 * (b * c + a * d),     1 - 2 * (b * b + d * d), 2 * (c * d - a * b),
                       2 * (b * d - a * c),     2 * (c * d + a * b),     1 - 2 * (b * b + c * c)};
  const double o[3] = {m.position[0], m.position[1], m.position[2]};
  const double cut = s_.max_ray > 0.0 ? s_.max_ray : std::numeric_limits<double>::infinity();
  map_.begin_frame(o);
  for (std::int32_t i = 0; i < m.n; ++i) {
    const std::size_t k = static_cast<std::size_t>(i);
    double p[3] = {m.x[k], m.y[k], m.z[k]};
    if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) continue;
    bool hit = m.hit[k] != 0;
    const double range = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
    if (range > cut) {  // cut to a miss at max_ray
      for (double& v : p) v *= cut / range;
      hit = false;
    }
    const double e[3] = {o[0] + r[0] * p[0] + r[1] * p[1] + r[2] * p[2], o[1] + r[3] * p[0] + r[4] * p[1] + r[5] * p[2],
                         o[2] + r[6] * p[0] + r[7] * p[1] + r[8] * p[2]};
    map_.add_point(e, hit);
  }
  map_.end_frame();
  newest_utime_ = std::max(newest_utime_, m.utime);
  if (first_utime_ < 0) first_utime_ = m.utime;
  std::copy(m.position, m.position + 3, sensor_pos_);
  dirty_ = true;
  ++frames_;
  if (integrate_ms_.size() < integrate_ms_.capacity()) {
    integrate_ms_.push_back(static_cast<float>(ms_since(t0)));
    integrate_cpu_ms_.push_back(static_cast<float>(cpu_ms() - c0));
  }
}

bool MapperNode::publish() {
  if (!dirty_) return false;
  const auto t0 = Clock::now();
  const double c0 = cpu_ms();
  map_.compute_distance(&out_.distance_mm);
  out_.utime = newest_utime_;
  out_.seq = maps_++;
  const auto org = map_.origin();
  for (int i = 0; i < 3; ++i) out_.origin[i] = static_cast<float>(org[static_cast<std::size_t>(i)]);
  out_.resolution = static_cast<float>(map_.resolution());
  out_.nx = map_.nx();
  out_.ny = map_.ny();
  out_.nz = map_.nz();
  out_.max_distance = static_cast<float>(s_.map.max_distance);
  out_.n_cells = map_.cells();
  lcm_->publish(s_.output, &out_);
  dirty_ = false;
  if (sensed_ != nullptr) write_new_columns();
  if (publish_ms_.size() < publish_ms_.capacity()) {
    publish_ms_.push_back(static_cast<float>(ms_since(t0)));
    publish_cpu_ms_.push_back(static_cast<float>(cpu_ms() - c0));
  }
  // How old the map is as it leaves: its newest frame's capture to now, on the frames' clock
  // (the wall clock in real time).
  if (age_ms_.size() < age_ms_.capacity())
    age_ms_.push_back(static_cast<float>(1e-3 * static_cast<double>(wall_us() - newest_utime_)));
  return true;
}

void MapperNode::write_new_columns() {
  new_columns_.clear();
  const int nx = map_.nx(), ny = map_.ny(), nz = map_.nz();
  const auto& c = map_.corner();
  // The layers within kSensedBand of the sensor's height: where the vehicle flies.
  const double r = map_.resolution(), zs = static_cast<double>(sensor_pos_[2]);
  const int k0 = std::max(0, static_cast<int>(std::floor((zs - kSensedBand) / r)) - static_cast<int>(c[2]));
  const int k1 = std::min(nz - 1, static_cast<int>(std::floor((zs + kSensedBand) / r)) - static_cast<int>(c[2]));
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      bool occ = false;
      for (int k = k0; k <= k1 && !occ; ++k) occ = map_.occupied(i + nx * (j + ny * k));
      if (!occ) continue;
      const auto key = static_cast<std::int64_t>((static_cast<std::uint64_t>(c[0] + i) << 32) |
                                                 static_cast<std::uint32_t>(c[1] + j));
      if (columns_seen_.insert(key).second) new_columns_.push_back(key);  // a new column: rare
    }
  }
  if (new_columns_.empty()) return;
  std::fprintf(sensed_, "{\"t\":%.3f,\"utime\":%lld,\"sensor\":[%.3f,%.3f,%.3f],\"columns\":[",
               1e-6 * static_cast<double>(newest_utime_ - first_utime_), static_cast<long long>(newest_utime_),
               static_cast<double>(sensor_pos_[0]), static_cast<double>(sensor_pos_[1]), static_cast<double>(sensor_pos_[2]));
  for (std::size_t n = 0; n < new_columns_.size(); ++n) {
    const std::int64_t key = new_columns_[n];
    const auto u = static_cast<std::uint64_t>(key);
    const auto x = static_cast<double>(static_cast<std::int32_t>(static_cast<std::uint32_t>(u >> 32)));
    const auto y = static_cast<double>(static_cast<std::int32_t>(static_cast<std::uint32_t>(u & 0xFFFFFFFFu)));
    std::fprintf(sensed_, "%s[%.3f,%.3f]", n == 0 ? "" : ",", (x + 0.5) * r, (y + 0.5) * r);
  }
  std::fputs("]}\n", sensed_);
  std::fflush(sensed_);
}

// A map goes out as soon as a frame has come in and a period has passed since the last map:
// right after that frame's integration, so its age is the sensor's latency and the mapper's
// own time, not a wait for a timer.
void MapperNode::run(const volatile std::sig_atomic_t* stop) {
  const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / s_.rate_hz));
  auto last = Clock::now() - period;
  while (!*stop) {
    const auto due = last + period;
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(due - Clock::now()).count();
    wait_and_handle(dirty_ ? static_cast<int>(std::clamp<std::int64_t>(left, 0, 100)) : 100);
    const auto now = Clock::now();
    if (dirty_ && now >= due && publish()) last = now;
  }
  // Stopping loses nothing: the frames already on the bus are integrated, and the map they
  // make goes out.
  while (wait_and_handle(50) > 0) {
  }
  if (dirty_) publish();
}

// Waits up to timeout_ms for traffic on the sensor bus (and the map bus: drained, so its
// socket buffer never fills with what others publish there); handles what came.
int MapperNode::wait_and_handle(int timeout_ms) {
  if (sensors_ == lcm_) return sensors_->handleTimeout(timeout_ms);
  const int a = sensors_->getFileno(), b = lcm_->getFileno();
  fd_set fds;
  FD_ZERO(&fds);
  FD_SET(a, &fds);
  FD_SET(b, &fds);
  timeval tv{timeout_ms / 1000, static_cast<suseconds_t>((timeout_ms % 1000) * 1000)};
  const int r = select(std::max(a, b) + 1, &fds, nullptr, nullptr, &tv);
  if (r <= 0) return r;
  if (FD_ISSET(a, &fds)) sensors_->handle();
  if (FD_ISSET(b, &fds)) lcm_->handle();
  return r;
}

std::string MapperNode::stats_json() const {
  const Stats& st = map_.stats();
  char head[512];
  std::snprintf(head, sizeof head,
                "{\"frames\":%lld,\"undecodable\":%lld,\"maps\":%lld,\"rays\":%lld,\"cells_cleared\":%lld,"
                "\"cells_hit\":%lld,\"shifts\":%lld,\"cells\":%d,\"resolution\":%g,",
                static_cast<long long>(frames_), static_cast<long long>(undecodable_), static_cast<long long>(maps_),
                static_cast<long long>(st.rays), static_cast<long long>(st.cells_cleared),
                static_cast<long long>(st.cells_hit), static_cast<long long>(st.shifts), map_.cells(),
                map_.resolution());
  return std::string(head) + "\"integrate_ms\":" + timing_json(integrate_ms_) +
         ",\"integrate_cpu_ms\":" + timing_json(integrate_cpu_ms_) + ",\"publish_ms\":" + timing_json(publish_ms_) +
         ",\"publish_cpu_ms\":" + timing_json(publish_cpu_ms_) + ",\"map_age_ms\":" + timing_json(age_ms_) + "}";
}

}  // namespace mapper
