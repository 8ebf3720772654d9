// The `mppi.cuda` section of a settings file (drivers/controller's parser): every field read,
// every bad value an error naming its field, the task files' defaults the backend's own
// choices, and the `cuda:` variant's section its own. No device needed.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <vector>

#include "mppi/app/config.hpp"
#include "mppi/gpu/cuda_settings.hpp"
#include "source_dir.hpp"

namespace mppi {
namespace {

app::AppConfig load(const std::string& task, const std::vector<std::string>& overrides) {
  return app::load_config(app::default_config_path(task), overrides);
}

// The message of the ConfigError that loading with `overrides` throws ("" if none).
std::string error_of(const std::string& task, const std::vector<std::string>& overrides) {
  try {
    load(task, overrides);
  } catch (const app::ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(CudaSettingsFile, EveryFieldIsRead) {
  const app::AppConfig c = load("quadrotor_forest", {"mppi.cuda={kernel: lanes, chunk_steps: 8, warps: 2, noise: inline, "
                                                     "controls: redraw, lanes: 4, grid: host, pdl: off, graph: false}"});
  const CudaSettings& s = c.cuda_launch;
  EXPECT_EQ(s.kernel, CudaSettings::Kernel::kLanes);
  EXPECT_EQ(s.chunk_steps, 8);
  EXPECT_EQ(s.warps, 2);
  EXPECT_EQ(s.noise, CudaSettings::Noise::kInline);
  EXPECT_EQ(s.controls, CudaSettings::Controls::kRedraw);
  EXPECT_EQ(s.lanes, 4);
  EXPECT_EQ(s.grid, CudaSettings::Grid::kHost);
  EXPECT_EQ(s.pdl, CudaSettings::Switch::kOff);
  EXPECT_FALSE(s.graph);
  EXPECT_EQ(load("quadrotor_forest", {"mppi.cuda.pdl=on", "mppi.cuda.kernel=chunked"}).cuda_launch.pdl,
            CudaSettings::Switch::kOn);
}

TEST(CudaSettingsFile, BadValuesNameTheirField) {
  struct {
    const char* task;
    const char* override_;
    const char* error;  // the message starts with it
  } cases[] = {
      {"quadrotor_forest", "mppi.cuda.kernel=lane", "mppi.cuda.kernel: must be auto, chunked or lanes"},
      {"quadrotor_forest", "mppi.cuda.noise=keep", "mppi.cuda.noise: must be auto, prepass or inline"},
      {"quadrotor_forest", "mppi.cuda.controls=inline", "mppi.cuda.controls: must be auto, keep or redraw"},
      {"quadrotor_forest", "mppi.cuda.grid=gpu", "mppi.cuda.grid: must be device or host"},
      {"quadrotor_forest", "mppi.cuda.pdl=maybe", "mppi.cuda.pdl: must be auto, on or off"},
      {"quadrotor_forest", "mppi.cuda.graph=sometimes", "mppi.cuda.graph: "},
      {"quadrotor_forest", "mppi.cuda.chunk_steps=four", "mppi.cuda.chunk_steps: cannot read 'four'"},
      {"quadrotor_forest", "mppi.cuda.chunk_steps=-2", "mppi.cuda.chunk_steps: must be >= 1"},
      {"quadrotor_forest", "mppi.cuda.warps=12", "mppi.cuda.warps: must be 1 to 8 for one vehicle"},
      {"team9_forest", "mppi.cuda.warps=17", "mppi.cuda.warps: must be 1 to 16 for a team"},
      {"quadrotor_forest", "mppi.cuda.lanes=3", "mppi.cuda.lanes: must be 1, 2, 4 or 8"},
      {"quadrotor_forest", "mppi.cuda.threads=4", "mppi.cuda.threads: unknown field"},
      {"quadrotor_forest", "mppi.cuda=3", "mppi.cuda: expected a map"},
      // In the `cuda:` variant, the variant's name comes first.
      {"quadrotor_forest", "cuda.mppi.cuda.kernel=fast", "cuda: mppi.cuda.kernel: must be auto, chunked or lanes"},
  };
  for (const auto& c : cases) {
    const std::string msg = error_of(c.task, {c.override_});
    EXPECT_EQ(msg.rfind(c.error, 0), 0u) << c.override_ << " gave: " << msg;
  }
  // A team may have 12 warps a block.
  EXPECT_EQ(load("team3_forest", {"mppi.cuda.warps=12"}).cuda_launch.warps, 12);
}

// No task file sets `mppi.cuda`: every one flies the backend's own choices, as before the section.
TEST(CudaSettingsFile, TaskFilesKeepTheBackendsChoices) {
  int files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(mppi::testing::source_dir() + "/config/tasks")) {
    if (entry.path().extension() != ".yaml") continue;
    const app::AppConfig c = app::load_config(entry.path().string());
    EXPECT_EQ(c.cuda_launch, CudaSettings{}) << entry.path();
    EXPECT_EQ(c.for_backend("cuda").cuda_launch, CudaSettings{}) << entry.path();
    ++files;
  }
  EXPECT_GE(files, 8);
}

// The `cuda:` variant may set its own; the file's stay; a live update keeps both.
TEST(CudaSettingsFile, TheCudaVariantHasItsOwn) {
  const app::AppConfig c = load("quadrotor_forest", {"cuda.mppi.cuda.kernel=lanes", "cuda.mppi.cuda.lanes=2"});
  EXPECT_EQ(c.cuda_launch.kernel, CudaSettings::Kernel::kAuto);
  ASSERT_TRUE(c.cuda);
  EXPECT_EQ(c.cuda->cuda_launch.kernel, CudaSettings::Kernel::kLanes);
  EXPECT_EQ(c.cuda->cuda_launch.lanes, 2);
  const app::AppConfig live = c.with_mppi(c.cuda->mppi);
  EXPECT_EQ(live.for_backend("cuda").cuda_launch.lanes, 2);
}

}  // namespace
}  // namespace mppi
