// All-or-nothing output folders, and the rules that keep outputs off what the tool did not write.
// A stage that writes several files writes them into a fresh temporary folder beside the target
// and swaps it into place only when every file is written, so a failure or a kill never leaves a
// half-written set (an old complete set stays until the swap).
//
// Output safety (docs/formats.md, "Output folders"):
// - a folder is replaced only when it does not exist, is empty, or holds exactly what an earlier
//   write of the same content left: the marker file `.digitize-output` the tool writes into every
//   output folder names the command, the content and every file written;
// - no output is ever written onto, into or above an input of the run, or onto or above the
//   current directory.
#pragma once

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "digitize/core.h"

namespace digitize {

// The marker inside every output folder (JSON: format "digitize.output", version, command,
// content, files).
inline constexpr const char* kOutputMarkerName = ".digitize-output";
inline constexpr const char* kOutputMarkerFormat = "digitize.output";

// One output folder of a command.
struct FolderOutput {
  std::string command;  // "preprocess", "fit", "synth", "demo", "run": recorded in the marker
  std::string content;  // "canvas", "fit", "synth", "demo": only a folder of the same content
                        // (whichever command wrote it) is replaced
  std::vector<std::filesystem::path> inputs;  // the run's inputs (files and folders)
};

// Absolute, symbolic links resolved where the path exists, no "." / ".." / trailing separator.
std::filesystem::path ResolvePath(const std::filesystem::path& path);
// `inner` is `outer` or lies below it, component-wise ("/a/bc" is not inside "/a/b"); both as
// ResolvePath returns them.
bool IsWithinFolder(const std::filesystem::path& inner, const std::filesystem::path& outer);

// Refuses an output (file or folder) at `out` that is, lies inside or holds any of `inputs`, or
// is or holds the current directory. Paths are compared after std::filesystem::weakly_canonical
// (so "museum/./scans/.." and symlinks are seen through). The error names `out` and the input it
// would hit.
Status CheckOutputPath(const std::filesystem::path& out,
                       const std::vector<std::filesystem::path>& inputs);

// Whether `dir` may be replaced by an output of `content`: it does not exist, is an empty folder,
// or is a folder whose marker says `content` and lists every entry in it. Otherwise the error
// names the folder and one thing found in it.
Status CheckReplaceable(const std::filesystem::path& dir, const std::string& content);

// CheckOutputPath(dir, output.inputs) and CheckReplaceable(dir, output.content): what a command
// checks before its work, so a refusal costs nothing.
Status CheckFolderOutput(const std::filesystem::path& dir, const FolderOutput& output);

// Checks as CheckFolderOutput (again: the folder may have changed during the work), then calls
// write(temp_dir) on an empty temporary folder, writes the marker into it and replaces `dir`
// with it. On failure the temporary folder is removed and `dir` is left as it was. Temporary
// folders of killed writers of the same target (".NAME.partial-PID-N", ".NAME.old-PID-N" whose
// process is gone) are removed whenever `dir` holds a complete output: before the write when it
// exists, and after a successful swap.
Status WriteDirectoryAtomically(
    const std::filesystem::path& dir, const FolderOutput& output,
    const std::function<Status(const std::filesystem::path& temp_dir)>& write);

}  // namespace digitize
