// Subcommands of the `digitize` tool. Each Add*Command registers its flags on `app` and, when
// chosen, stores its exit code in `exit_code` (0 ok, 1 bad input or failure; CLI11 uses 2+ for
// usage errors). Tools stay thin: flags -> options -> library call -> exit code.
#pragma once

#include <CLI/CLI.hpp>
#include <string>

#include "digitize/preprocess.h"

namespace digitize::cli {

void AddSynthCommand(CLI::App& app, int& exit_code);
void AddPreprocessCommand(CLI::App& app, int& exit_code);
void AddFitCommand(CLI::App& app, int& exit_code);
void AddDemoCommand(CLI::App& app, int& exit_code);

// Flags for every preprocessing threshold (shared by preprocess, demo and later run).
void AddPreprocessFlags(CLI::App* command, PreprocessOptions& options);

// Prints "digitize <command>: error: <message>" on stderr and returns 1.
int Fail(const std::string& command, const std::string& message);

}  // namespace digitize::cli
