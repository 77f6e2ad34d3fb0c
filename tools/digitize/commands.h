// Subcommands of the `digitize` tool. Each Add*Command registers its flags on `app` and, when
// chosen, stores its exit code in `exit_code`: 0 ok, 1 bad input or failure. Usage errors (an
// unknown flag or command, a missing required option, a value of the wrong type) exit 1 too, with
// CLI11's message (main.cpp maps its 105, 106, 109, ... onto 1); `--help` and `--version` exit 0;
// 3 is an internal error (a broken invariant). Tools stay thin: flags -> options -> library call
// -> exit code.
#pragma once

#include <CLI/CLI.hpp>
#include <string>

#include "digitize/pack.h"
#include "digitize/photo_set.h"
#include "digitize/preprocess.h"
#include "digitize/reflectance_fit.h"
#include "digitize/scan_io.h"

namespace digitize::cli {

void AddSynthCommand(CLI::App& app, int& exit_code);
void AddPreprocessCommand(CLI::App& app, int& exit_code);
void AddFitCommand(CLI::App& app, int& exit_code);
void AddDemoCommand(CLI::App& app, int& exit_code);
void AddPackCommand(CLI::App& app, int& exit_code);
void AddInspectCommand(CLI::App& app, int& exit_code);
void AddVerifyCommand(CLI::App& app, int& exit_code);
void AddRunCommand(CLI::App& app, int& exit_code);

// What `preprocess` and `fit` run on (also driven by `run`).
struct PreprocessArgs {
  std::vector<std::string> scans;
  std::string out;
  ScanReadOptions read;
  std::string mask;
  std::vector<int> grid;
  PreprocessOptions options;
};
int RunPreprocess(const PreprocessArgs& args);

struct FitArgs {
  std::string canvas, photos, held_out, out;
  std::string method = "fast";
  PhotoSetOptions photo;
  ReflectanceFitOptions options;
  int threads = 0;
  CLI::Option* dark_ratio_option = nullptr;  // set: the user chose it (RTI default is off)
};
int RunFit(FitArgs args);

// A calibration JSON or, by its .lp extension, an RTI capture (fit, run).
Result<PhotoSet> ReadPhotoSetFile(const std::string& path, const PhotoSetOptions& options,
                                  const ProgressCallback& progress);
// For an RTI capture: its pixel pitch and where it came from, on stdout; a warning on stderr
// when it was assumed (the physical size is then made up). Nothing for a calibration.
void PrintRtiPitch(const std::string& command, const PhotoSet& set);
// The scans of `args`, read with its input flags (preprocess, run). Errors name the file or flag.
Result<std::vector<Scan>> ReadScans(const PreprocessArgs& args);
// The pack's write options as the provenance records them (pack, run, demo).
std::string PackOptionsJson(const PackWriteOptions& options);
// "PATH: WxH texels (w x h mm), N boxes, encoding, B bytes/texel (N bytes)"
void PrintPackSummaryLine(const std::string& path, const PackSummary& summary);

// Pack flags (--quantised, --*-bits) shared by pack, run and demo.
void AddPackWriteFlags(CLI::App* command, PackWriteOptions& options, bool& quantised);
// canvas folder + fit folder -> pack file; prints the pack's one-line summary.
int PackFromFolders(const std::string& command, const std::string& canvas_dir,
                    const std::string& fit_dir, const std::string& out, PackWriteOptions options);

// Flags for every preprocessing threshold (shared by preprocess, demo and later run).
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
