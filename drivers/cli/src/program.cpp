#include "mppi/cli/program.hpp"

#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>

namespace mppi::cli {
namespace {

volatile std::sig_atomic_t g_stop = 0;
void (*g_also)() = nullptr;

void on_stop_signal(int) {
  g_stop = 1;
  if (g_also != nullptr) g_also();
}

// The number `text` holds, or why not; `inside` says whether it lies in the interval.
template <class Inside>
std::string check_number(const std::string& text, const std::string& interval, Inside inside) {
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || *end != '\0') return "'" + text + "' is not a number";
  if (!inside(v)) return "'" + text + "' is outside " + interval;
  return {};
}

std::string interval_text(char open, double lo, double hi, char close) {
  char text[64];
  std::snprintf(text, sizeof text, "%c%g, %g%c", open, lo, hi, close);
  return text;
}

}  // namespace

std::optional<int> parse(CLI::App& app, int argc, char** argv) {
  app.failure_message([](const CLI::App* a, const CLI::Error& e) {
    return a->get_name() + ": " + CLI::FailureMessage::simple(a, e);
  });
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == static_cast<int>(CLI::ExitCodes::Success) ? 0 : kExitUsage;
  }
  return std::nullopt;
}

CLI::Validator in_half_open(double lo, double hi) {
  const std::string interval = interval_text('[', lo, hi, ')');
  return CLI::Validator(
      [=](std::string& text) { return check_number(text, interval, [=](double v) { return v >= lo && v < hi; }); },
      "NUMBER in " + interval);
}

CLI::Validator in_open(double lo, double hi) {
  const std::string interval = interval_text('(', lo, hi, ')');
  return CLI::Validator(
      [=](std::string& text) { return check_number(text, interval, [=](double v) { return v > lo && v < hi; }); },
      "NUMBER in " + interval);
}

const volatile std::sig_atomic_t* stop_on_signals(void (*also)()) {
  g_also = also;
  std::signal(SIGINT, on_stop_signal);
  std::signal(SIGTERM, on_stop_signal);
  return &g_stop;
}

int run_reporting(const char* program, const std::function<int()>& body) {
  try {
    return body();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: %s\n", program, e.what());
    return kExitError;
  }
}

}  // namespace mppi::cli
