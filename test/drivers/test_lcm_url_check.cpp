// Where the LCM bus goes: mppid warns at start when its URL would let traffic leave the
// host (lcm_url_check.hpp), and every URL the repository ships keeps it on the host.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <regex>
#include <string>

#include "mppi/daemon/daemon_settings.hpp"
#include "mppi/daemon/lcm_url_check.hpp"
#include "source_dir.hpp"

using mppi::daemon::lcm_url_leaves_host;

TEST(LcmUrlCheck, StaysOnTheHost) {
  for (const char* url : {"udpm://239.255.76.67:7667?ttl=0", "udpm://239.255.76.67:7667",
                          "udpm://239.1.2.3:7700?recv_buf_size=2097152&ttl=0", "mpudpm://239.255.76.67:7667?ttl=0", "memq://", "file:///tmp/log.lcm?mode=w",
                          "tcpq://localhost:7700", "tcpq://127.0.0.1:7700", "tcpq://[::1]:7700"})
    EXPECT_EQ(lcm_url_leaves_host(url), "") << url;
}

TEST(LcmUrlCheck, LeavesTheHostOrCannotTell) {
  const std::string ttl1 = lcm_url_leaves_host("udpm://239.255.76.67:7667?ttl=1");
  EXPECT_NE(ttl1.find("ttl=1: multicast datagrams leave this host"), std::string::npos) << ttl1;
  EXPECT_NE(ttl1.find("Use ttl=0"), std::string::npos) << ttl1;
  EXPECT_NE(lcm_url_leaves_host("udpm://239.255.76.67:7667?recv_buf_size=1&ttl=255"), "");
  EXPECT_NE(lcm_url_leaves_host("mpudpm://239.255.76.67:7667?ttl=3"), "");
  EXPECT_NE(lcm_url_leaves_host("tcpq://192.0.2.7:7700").find("tcpq to 192.0.2.7"), std::string::npos);
  EXPECT_NE(lcm_url_leaves_host("udpm://239.255.76.67:7667?ttl=x").find("not a number"), std::string::npos);
  EXPECT_NE(lcm_url_leaves_host("udpm://239.255.76.67:7667?ttl=-1").find("not a number"), std::string::npos);
  EXPECT_NE(lcm_url_leaves_host("zmq://a").find("unknown LCM provider 'zmq'"), std::string::npos);
  EXPECT_NE(lcm_url_leaves_host("239.255.76.67:7667").find("cannot tell"), std::string::npos);
}

// Every LCM URL the repository ships (settings, drivers, simulator, tools; the tests use
// private network namespaces and leaving URLs on purpose) stays on the host.
TEST(LcmUrlCheck, EveryShippedUrlStaysOnTheHost) {
  const std::string default_url = mppi::daemon::DaemonSettings().lcm_url;
  EXPECT_EQ(lcm_url_leaves_host(default_url), "");
  namespace fs = std::filesystem;
  const std::regex url(R"(\b(?:udpm|mpudpm|tcpq)://[^\s"'`)]+)");
  int seen = 0;
  for (const char* dir : {"config", "drivers", "sim", "tools"}) {
    for (const auto& e : fs::recursive_directory_iterator(fs::path(mppi::testing::source_dir()) / dir)) {
      if (!e.is_regular_file()) continue;
      const std::string ext = e.path().extension().string();
      if (ext != ".yaml" && ext != ".py" && ext != ".cpp" && ext != ".hpp" && ext != ".sh" && ext != ".service" &&
          !ext.empty())
        continue;
      std::ifstream f(e.path());
      const std::string text((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
      for (auto it = std::sregex_iterator(text.begin(), text.end(), url); it != std::sregex_iterator(); ++it) {
        ++seen;
        EXPECT_EQ(lcm_url_leaves_host(it->str()), "") << e.path() << ": " << it->str();
      }
    }
  }
  EXPECT_GE(seen, 6);  // the scan found the URLs it is about
}

// A daemon that takes local maps opens udpm with a receive buffer a map fits in.
TEST(LcmUrlCheck, MapsGetAReceiveBufferOnUdpmOnly) {
  using mppi::daemon::kMapReceiveBufferBytes;
  using mppi::daemon::map_receive_buffer_warning;
  using mppi::daemon::with_map_receive_buffer;
  const std::string four = std::to_string(kMapReceiveBufferBytes);
  EXPECT_EQ(with_map_receive_buffer("udpm://239.255.76.67:7667?ttl=0"), "udpm://239.255.76.67:7667?ttl=0&recv_buf_size=" + four);
  EXPECT_EQ(with_map_receive_buffer("udpm://239.255.76.67:7667"), "udpm://239.255.76.67:7667?recv_buf_size=" + four);
  EXPECT_EQ(with_map_receive_buffer("mpudpm://239.255.76.67:7667?ttl=0"), "mpudpm://239.255.76.67:7667?ttl=0&recv_buf_size=" + four);
  EXPECT_EQ(with_map_receive_buffer("udpm://239.255.76.67:7667?ttl=0&recv_buf_size=123"),
            "udpm://239.255.76.67:7667?ttl=0&recv_buf_size=123");  // the URL's own wins
  EXPECT_EQ(with_map_receive_buffer("memq://"), "memq://");
  EXPECT_EQ(with_map_receive_buffer("tcpq://127.0.0.1:7700"), "tcpq://127.0.0.1:7700");
  const std::string url = with_map_receive_buffer("udpm://239.255.76.67:7667?ttl=0");
  EXPECT_EQ(map_receive_buffer_warning(url, kMapReceiveBufferBytes), "");
  EXPECT_EQ(map_receive_buffer_warning(url, 0), "");  // unknown: nothing to say
  EXPECT_NE(map_receive_buffer_warning(url, 212992).find("net.core.rmem_max"), std::string::npos);
  EXPECT_EQ(map_receive_buffer_warning("udpm://239.255.76.67:7667?ttl=0", 212992), "");  // asks for nothing
}
