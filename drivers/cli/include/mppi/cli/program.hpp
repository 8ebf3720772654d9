// What mppid's small programs share around their work (the daemon has its own main thread):
// their options parsed by CLI11 with the project's exit statuses, SIGINT and SIGTERM as a
// stop flag, and an exception that ends a run printed under the program's name.
#pragma once

#include <CLI/CLI.hpp>

#include <csignal>
#include <functional>
#include <optional>

namespace mppi::cli {

constexpr int kExitError = 1;  // the run failed (a file, the bus, the settings)
constexpr int kExitUsage = 2;  // a bad option or value

// Parses argv into the options `app` declares: std::nullopt to go on, else the exit status
// (0 after --help has been printed; kExitUsage after the bad option or value has been named
// on stderr under the app's name, CLI::App{description, name}).
std::optional<int> parse(CLI::App& app, int argc, char** argv);

// A number in [lo, hi) (CLI11's Range includes both ends).
CLI::Validator in_half_open(double lo, double hi);
// A number in (lo, hi).
CLI::Validator in_open(double lo, double hi);

// From now on SIGINT and SIGTERM raise the returned flag and call `also` (when given; it
// runs in the signal handler, so it must be async-signal-safe). The run polls the flag,
// stops and still writes what it has.
const volatile std::sig_atomic_t* stop_on_signals(void (*also)() = nullptr);

// body()'s exit status; an exception it throws is printed as "<program>: <what>" on stderr
// and ends with kExitError.
int run_reporting(const char* program, const std::function<int()>& body);

}  // namespace mppi::cli
