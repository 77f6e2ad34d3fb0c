// Image files written through OpenImageIO with every file write checked (image_io.cpp, pack.cpp).
#pragma once

#include <OpenImageIO/imageio.h>

#include <filesystem>
#include <functional>
#include <string>

#include "digitize/core.h"

namespace digitize {

// Writes `path` atomically (WriteAtomically) through a writer of `format` ("png", "openexr",
// ...): write(out, temp) opens `out` on `temp` (the file I/O proxy is already set), writes and
// closes it. Not for multi-part OpenEXR: OpenImageIO's multi-part open ignores the proxy.
// OpenImageIO's writers do not all report a failed write (the PNG writer returns success on a
// full disk, libjpeg exits the process), so the proxy records the first failure and lets the
// writer finish; then the file is flushed, synced and closed and its size checked against the
// bytes written. A failure names `path` and its cause ("no space left on device"); the previous
// file stays.
Status WriteImageAtomically(
    const std::filesystem::path& path, const char* format,
    const std::function<Status(OIIO::ImageOutput& out, const std::string& temp)>& write);

// For a writer that cannot write through the checked file (OpenImageIO's multi-part OpenEXR opens
// its file by name): a failed `status` with "no space left on device" added when the file system
// holding `path` has no space left.
Status WithDiskFull(Status status, const std::filesystem::path& path);

}  // namespace digitize
