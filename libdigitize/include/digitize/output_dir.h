// All-or-nothing output folders: a stage that writes several files writes them into a fresh
// temporary folder beside the target and swaps it into place only when every file is written, so
// a failure or a kill never leaves a half-written set (an old complete set stays until the swap).
#pragma once

#include <filesystem>
#include <functional>

#include "digitize/core.h"

namespace digitize {

// Calls write(temp_dir) on an empty temporary folder, then replaces `dir` with it. `dir` may exist:
// it must then be a folder (a file there is an error, not overwritten). On failure the temporary
// folder is removed and `dir` is left as it was.
Status WriteDirectoryAtomically(const std::filesystem::path& dir,
                                const std::function<Status(const std::filesystem::path& temp_dir)>& write);

}  // namespace digitize
