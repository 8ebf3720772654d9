// A scenario file (YAML) as mppid-sim reads it: load_scenario's parsing and validation, the
// world generation (forest, moving obstacles) and the plant built from it, stepped a few
// times with its hover command. A bad file must end in std::runtime_error naming the file
// and the field (mppid-sim exits 1 with it); any other exception is a crash. Input: the
// file's text.
#include <yaml-cpp/yaml.h>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "sim/plant.hpp"
#include "sim/scenario.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    const sim::Scenario s =
        sim::load_scenario_text(std::string(reinterpret_cast<const char*>(data), size), "fuzz.yaml", 1);
    const std::unique_ptr<sim::Plant> plant = sim::make_plant(s);
    std::vector<float> u = plant->hover();
    const double wind[3] = {s.wind.mean[0], s.wind.mean[1], s.wind.mean[2]};
    if (plant->saturate(u.data()))
      for (int i = 0; i < 5; ++i) plant->step(u.data(), wind, 1.0 / s.physics_hz);
  } catch (const YAML::Exception&) {
    throw;  // a yaml-cpp error that escaped the loader's own (a std::runtime_error too, but no field named)
  } catch (const std::runtime_error&) {
  }
  return 0;
}
