// Subcommands of the `digitize` tool (one cmd_*.cpp each; what they share is cli_common.cpp). Each
// Add*Command registers its flags on `app` and, when chosen, stores its exit code in `exit_code`: 0
// ok, 1 bad input or failure. Usage errors (an unknown flag or command, a missing required option,
// a value of the wrong type) exit 1 too, with CLI11's message (main.cpp maps its 105, 106, 109, ...
// onto 1); `--help` and `--version` exit 0; 3 is an internal error (a broken invariant). Tools stay
// thin: flags -> options -> library call
// -> exit code.
#pragma once

#include <CLI/CLI.hpp>
#include <optional>
#include <string>
#include <vector>

#include "digitize/pipeline.h"

namespace digitize::cli {

void AddSynthCommand(CLI::App& app, int& exit_code);
void AddPreprocessCommand(CLI::App& app, int& exit_code);
void AddFitCommand(CLI::App& app, int& exit_code);
void AddDemoCommand(CLI::App& app, int& exit_code);
void AddPackCommand(CLI::App& app, int& exit_code);
void AddInspectCommand(CLI::App& app, int& exit_code);
void AddVerifyCommand(CLI::App& app, int& exit_code);
void AddRunCommand(CLI::App& app, int& exit_code);
void AddRtiCommand(CLI::App& app, int& exit_code);
void AddTilesCommand(CLI::App& app, int& exit_code);

// --- shared by several commands (cli_common.cpp) ---

// For an RTI capture: its pixel pitch and where it came from, on stdout; a warning on stderr
// when it was assumed (the physical size is then made up). Nothing for a calibration.
void PrintRtiPitch(const std::string& command, const PhotoSet& set);
// "PATH: WxH texels (w x h mm), N boxes, encoding, B bytes/texel (N bytes)"
void PrintPackSummaryLine(const std::string& path, const PackSummary& summary);

// Pack flags (--quantised, --*-bits) shared by pack and run.
void AddPackWriteFlags(CLI::App* command, PackWriteOptions& options, bool& quantised);
// Photo-set flags (--rti-pitch-mm, --allow-outside-paths) shared by fit and run.
void AddPhotoSetFlags(CLI::App* command, PhotoSetOptions& options);
// The fit's flags (groups Fit, Samples, Photos' --saturation, Performance's --tile-texels), shared
// by fit and tiles plan. Returns --dark-outlier-ratio's option (whether the user gave it).
CLI::Option* AddFitFlags(CLI::App* command, ReflectanceFitOptions& options, PhotoSetOptions& photo);
// The photo check's warnings, and one line with its brief.
void PrintPhotoCheck(const std::string& command, const std::optional<PhotoResidualReport>& check);
// --no-photo-check and --held-out-out, as fit and run take them.
void AddPhotoCheckAndRelitFlags(CLI::App* command, bool& check_photos, std::string& held_out_out);
// --rti-flat, --rti-no-height, --rti-no-intensities: how an RTI capture becomes a canvas.
void AddRtiCanvasFlags(CLI::App* command, RtiCanvasOptions& options);
// The scan input flags (--mask, --grid WIDTH HEIGHT) folded into the read options.
ScanReadOptions ScanReadOptionsOf(ScanReadOptions read, const std::string& mask,
                                  const std::vector<int>& grid);
// --method (fast or ceres) and --threads into the fit options.
void SetFitMethod(ReflectanceFitOptions& options, const std::string& method, int threads);

// Flags for every preprocessing threshold (shared by preprocess, demo and run).
void AddPreprocessFlags(CLI::App* command, PreprocessOptions& options);

// Transform of a folder option: the value without trailing slashes ("synth/" -> "synth"; "/"
// stays), so that printed paths read "synth/scan.exr", not "synth//scan.exr".
inline CLI::Validator FolderPath() {
  return CLI::Validator(
      [](std::string& path) {
        while (path.size() > 1 && path.back() == '/') path.pop_back();
        return std::string();
      },
      "");
}

// Prints "digitize <command>: error: <message>" on stderr and returns 1.
int Fail(const std::string& command, const std::string& message);
// Prints "digitize <command>: warning: <message>" on stderr (the command goes on).
void Warn(const std::string& command, const std::string& message);

}  // namespace digitize::cli
