#include "digitize/output_dir.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
#include <string>

#include "digitize/image_io.h"
#include "json_fields.h"

namespace digitize {
namespace fs = std::filesystem;

fs::path ResolvePath(const fs::path& p) {
  std::error_code ec;
  fs::path r = fs::weakly_canonical(fs::absolute(p, ec), ec);
  if (ec) r = fs::absolute(p).lexically_normal();
  if (!r.has_filename() && r.has_parent_path() && r != r.root_path()) r = r.parent_path();
  return r;
}

bool IsWithinFolder(const fs::path& inner, const fs::path& outer) {
  auto i = inner.begin();
  for (auto o = outer.begin(); o != outer.end(); ++o, ++i) {
    if (o->empty()) continue;  // a trailing separator
    if (i == inner.end() || *i != *o) return false;
  }
  return true;
}

namespace {

bool SameFile(const fs::path& a, const fs::path& b) {
  std::error_code ec;
  return a == b || (fs::exists(a, ec) && fs::exists(b, ec) && fs::equivalent(a, b, ec));
}

// Every entry below `dir`, relative, folders with a trailing '/', sorted; the marker left out.
Result<std::vector<std::string>> ListEntries(const fs::path& dir) {
  std::vector<std::string> entries;
  std::error_code ec;
  for (fs::recursive_directory_iterator it(dir, ec), end; it != end; it.increment(ec)) {
    if (ec) break;
    std::string rel = it->path().lexically_relative(dir).generic_string();
    if (rel == kOutputMarkerName) continue;
    if (it->is_directory(ec) && !it->is_symlink(ec)) rel += "/";
    entries.push_back(std::move(rel));
  }
  if (ec) return Error{dir.string() + ": cannot list the folder: " + ec.message()};
  std::sort(entries.begin(), entries.end());
  return entries;
}

Status WriteMarker(const fs::path& dir, const FolderOutput& output) {
  auto entries = ListEntries(dir);
  if (!entries.ok()) return Status(entries.error());
  const nlohmann::json marker = {{"format", kOutputMarkerFormat},
                                 {"version", 1},
                                 {"command", output.command},
                                 {"content", output.content},
                                 {"files", *entries}};
  return WriteTextFile(dir / kOutputMarkerName, marker.dump(1) + "\n");
}

// What an output marker records (WriteMarker); nullopt when `path` is none: unreadable, not JSON,
// another format, or a field of the wrong type.
struct Marker {
  std::string command, content;
  std::set<std::string> files;
};
std::optional<Marker> ReadMarker(const fs::path& path) {
  auto text = ReadTextFile(path, "output marker");
  if (!text) return std::nullopt;
  try {
    const nlohmann::json doc = ParseJson(*text, path.string());
    const Fields f(doc, path.string());
    if (!f.Has("format") || f.String("format") != kOutputMarkerFormat) return std::nullopt;
    Marker marker;
    marker.content = f.Has("content") ? f.String("content") : "";
    marker.command = f.Has("command") ? f.String("command") : "?";
    for (const nlohmann::json& file : f.Array("files"))
      if (file.is_string()) marker.files.insert(file.get<std::string>());
    return marker;
  } catch (const BadInput&) {
    return std::nullopt;
  }
}

}  // namespace

Status CheckOutputPath(const fs::path& out, const std::vector<fs::path>& inputs) {
  if (out.empty()) return Error{"the output path is empty"};
  const fs::path target = ResolvePath(out);
  const std::string name = out.string();
  for (const fs::path& input : inputs) {
    if (input.empty()) continue;
    const fs::path in = ResolvePath(input);
    if (SameFile(target, in))
      return Error{name + ": is the input " + input.string() +
                   "; refusing to write an output over an input"};
    if (IsWithinFolder(in, target))
      return Error{name + ": holds the input " + input.string() +
                   "; refusing to write an output over it"};
    if (IsWithinFolder(target, in))
      return Error{name + ": lies inside the input " + input.string() +
                   "; refusing to write an output into an input"};
  }
  std::error_code ec;
  const fs::path cwd = ResolvePath(fs::current_path(ec));
  if (!ec && IsWithinFolder(cwd, target))
    return Error{name + ": is " + (SameFile(cwd, target) ? "" : "above ") +
                 "the current directory; refusing to replace it (name a folder inside it)"};
  return Status::Ok();
}

Status CheckReplaceable(const fs::path& dir, const std::string& content) {
  const std::string name = dir.string();
  std::error_code ec;
  const fs::file_status status = fs::status(dir, ec);
  if (!fs::exists(status)) return Status::Ok();
  if (!fs::is_directory(status))
    return Error{name + ": exists and is not a folder; refusing to replace it"};
  auto entries = ListEntries(dir);
  if (!entries.ok()) return Status(entries.error());
  const bool has_marker = fs::is_regular_file(dir / kOutputMarkerName, ec);
  if (entries->empty() && !has_marker) return Status::Ok();
  const std::string advice = "; refusing to replace it (choose a new or empty folder)";
  if (!has_marker)
    return Error{name + ": holds '" + entries->front() + "' and was not written by digitize" +
                 advice};
  const std::optional<Marker> marker = ReadMarker(dir / kOutputMarkerName);
  if (!marker)
    return Error{name + ": its " + kOutputMarkerName + " is not a digitize output marker" + advice};
  if (marker->content != content)
    return Error{name + ": holds the " + marker->content + " output of `digitize " +
                 marker->command + "`, not a " + content + " output" + advice};
  for (const std::string& entry : *entries)
    if (!marker->files.count(entry))
      return Error{name + ": holds '" + entry + "', which digitize did not write" + advice};
  return Status::Ok();
}

Status CheckFolderOutput(const fs::path& dir, const FolderOutput& output) {
  if (Status s = CheckOutputPath(dir, output.inputs); !s.ok()) return s;
  return CheckReplaceable(dir, output.content);
}

Status WriteDirectoryAtomically(const fs::path& dir, const FolderOutput& output,
                                const std::function<Status(const fs::path& temp_dir)>& write) {
  static std::atomic<int> counter{0};
  const fs::path target = dir.has_filename() ? dir : dir.parent_path();  // "out/" -> "out"
  if (Status s = CheckFolderOutput(target, output); !s.ok()) return s;
  std::error_code ec;
  const fs::path parent = target.has_parent_path() ? target.parent_path() : fs::path(".");
  fs::create_directories(parent, ec);
  if (ec) return Error{parent.string() + ": cannot create the folder: " + ec.message()};

  const std::string stem = "." + target.filename().string();
  // A killed writer's temporaries are garbage once the target holds a complete output (before
  // the swap, or after it); while it does not, a stale ".old" may hold the only complete set.
  auto remove_stale = [&] {
    RemoveStaleTemporaries(parent, stem + ".partial-");
    RemoveStaleTemporaries(parent, stem + ".old-");
  };
  if (fs::is_directory(target, ec)) remove_stale();

  const std::string tag = std::to_string(::getpid()) + "-" + std::to_string(counter++);
  const fs::path temp = parent / (stem + ".partial-" + tag);
  const fs::path old = parent / (stem + ".old-" + tag);
  fs::remove_all(temp, ec);
  fs::create_directory(temp, ec);
  if (ec) return Error{temp.string() + ": cannot create a temporary folder: " + ec.message()};

  Status status = write(temp);
  if (status.ok()) status = WriteMarker(temp, output);
  if (!status.ok()) {
    fs::remove_all(temp, ec);
    return status;
  }
  // Two renames: the old set stays complete until the new one is in place.
  const bool had_old = fs::exists(target, ec);
  if (had_old) {
    fs::rename(target, old, ec);
    if (ec) {
      const std::string why = ec.message();  // before remove_all clears ec
      fs::remove_all(temp, ec);
      return Error{target.string() + ": cannot move the previous output aside: " + why};
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
  remove_stale();
  return Status::Ok();
}

}  // namespace digitize
