#include "digitize/output_dir.h"

#include <unistd.h>

#include <atomic>
#include <string>

namespace digitize {
namespace fs = std::filesystem;

Status WriteDirectoryAtomically(const fs::path& dir,
                                const std::function<Status(const fs::path& temp_dir)>& write) {
  static std::atomic<int> counter{0};
  const fs::path target = dir.has_filename() ? dir : dir.parent_path();  // "out/" -> "out"
  std::error_code ec;
  if (fs::exists(target, ec) && !fs::is_directory(target, ec))
    return Error{target.string() + ": exists and is not a folder; refusing to replace it"};
  const fs::path parent = target.has_parent_path() ? target.parent_path() : fs::path(".");
  fs::create_directories(parent, ec);
  if (ec) return Error{parent.string() + ": cannot create the folder: " + ec.message()};

  const std::string tag = std::to_string(::getpid()) + "-" + std::to_string(counter++);
  const fs::path temp = parent / ("." + target.filename().string() + ".partial-" + tag);
  const fs::path old = parent / ("." + target.filename().string() + ".old-" + tag);
  fs::remove_all(temp, ec);
  fs::create_directory(temp, ec);
  if (ec) return Error{temp.string() + ": cannot create a temporary folder: " + ec.message()};

  Status status = write(temp);
  if (!status.ok()) {
    fs::remove_all(temp, ec);
    return status;
  }
  // Two renames: the old set stays complete until the new one is in place.
  const bool had_old = fs::exists(target, ec);
  if (had_old) {
    fs::rename(target, old, ec);
    if (ec) {
      fs::remove_all(temp, ec);
      return Error{target.string() + ": cannot move the previous output aside: " + ec.message()};
    }
  }
  fs::rename(temp, target, ec);
  if (ec) {
    const std::string why = ec.message();
    if (had_old) fs::rename(old, target, ec);
    fs::remove_all(temp, ec);
    return Error{target.string() + ": cannot move the new output into place: " + why};
  }
  if (had_old) fs::remove_all(old, ec);
  return Status::Ok();
}

}  // namespace digitize
