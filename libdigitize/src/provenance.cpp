// Provenance of a texture pack (provenance.h), and its JSON form in the pack header (pack_exr.h).
#include "digitize/provenance.h"

#include <OpenImageIO/hash.h>

#include <algorithm>
#include <chrono>
#include <ctime>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <system_error>

#include "digitize/image_io.h"
#include "digitize/pack.h"
#include "json_fields.h"
#include "options_json.h"
#include "pack_exr.h"

namespace digitize {

namespace fs = std::filesystem;
using nlohmann::json;

namespace pack_exr {

json ProvenanceToJson(const PackProvenance& p) {
  json inputs = json::array();
  for (const PackInput& in : p.inputs)
    inputs.push_back({{"name", in.name}, {"sha1", in.sha1}, {"bytes", in.bytes}});
  json options = json::object();
  if (!p.options_json.empty()) {
    options = json::parse(p.options_json, nullptr, /*allow_exceptions=*/false);
    if (options.is_discarded()) options = p.options_json;  // kept as text rather than lost
  }
  return {{"tool_version", p.tool_version},
          {"created_utc", p.created_utc},
          {"fit_brief", p.fit_brief},
          {"options", options},
          {"inputs", inputs}};
}

Result<PackProvenance> ParseProvenance(const std::string& file, const std::string& text) {
  const json doc = json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (doc.is_discarded() || !doc.is_object())
    return Error{file + ": digitize:provenance is not a JSON object"};
  if (doc.contains("inputs") && !doc["inputs"].is_array())
    return Error{file + ": digitize:provenance inputs is not an array"};
  return CatchBadInput([&] {
    const Fields top(doc, file + ": digitize:provenance");
    auto text_of = [](const Fields& f, const char* key) { return f.Has(key) ? f.String(key) : ""; };
    PackProvenance p;
    p.tool_version = text_of(top, "tool_version");
    p.created_utc = text_of(top, "created_utc");
    p.fit_brief = text_of(top, "fit_brief");
    if (top.Has("options")) p.options_json = top.Get("options").dump();
    if (top.Has("inputs")) {
      const json& inputs = top.Array("inputs");
      for (size_t i = 0; i < inputs.size(); ++i) {
        const Fields in(inputs[i], top.At("inputs[" + std::to_string(i) + "]"));
        PackInput input;
        input.name = in.String("name");
        input.sha1 = text_of(in, "sha1");
        if (in.Has("bytes"))
          input.bytes =
              static_cast<uint64_t>(in.Integer("bytes", 0, std::numeric_limits<int64_t>::max()));
        p.inputs.push_back(std::move(input));
      }
    }
    return p;
  });
}

}  // namespace pack_exr

Result<std::string> FileSha1(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error{path.string() + ": cannot open to hash"};
  OIIO::SHA1 sha;
  std::vector<char> buf(1 << 20);
  while (in) {
    in.read(buf.data(), static_cast<std::streamsize>(buf.size()));
    if (in.gcount() > 0) sha.append(buf.data(), static_cast<size_t>(in.gcount()));
  }
  if (in.bad()) return Error{path.string() + ": read failed while hashing"};
  return sha.digest();
}

PackProvenance NewProvenance() {
  PackProvenance p;
  p.tool_version = std::string("digitize ") + DIGITIZE_VERSION;
  const std::time_t now = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  std::tm utc{};
  gmtime_r(&now, &utc);
  char when[32];
  std::strftime(when, sizeof when, "%Y-%m-%dT%H:%M:%SZ", &utc);
  p.created_utc = when;
  return p;
}

namespace {

// The name provenance records for `file` (AddProvenanceInputs).
std::string ProvenanceName(const fs::path& file, const fs::path& relative_to) {
  if (relative_to.empty()) return (file.is_absolute() ? file.filename() : file).generic_string();
  std::error_code ec;
  const fs::path a = fs::absolute(file, ec).lexically_normal();
  const fs::path b = fs::absolute(relative_to, ec).lexically_normal();
  const fs::path rel = a.lexically_relative(b);
  return (rel.empty() ? file.filename() : rel).generic_string();
}

}  // namespace

Status AddProvenanceInputs(PackProvenance& provenance, const std::vector<fs::path>& files,
                           const fs::path& relative_to) {
  for (const fs::path& f : files) {
    auto sha = FileSha1(f);
    if (!sha.ok()) return sha.error();
    std::error_code ec;
    provenance.inputs.push_back(
        {ProvenanceName(f, relative_to), *sha, static_cast<uint64_t>(fs::file_size(f, ec))});
  }
  return Status::Ok();
}

Result<PackProvenance> ProvenanceFromOutputs(const fs::path& canvas_dir, const fs::path& fit_dir,
                                             const PackWriteOptions& pack_options) {
  PackProvenance p = NewProvenance();
  json options = json::object();
  options["pack"] = ToJson(pack_options);
  for (const auto& [stage, dir] :
       {std::pair<const char*, fs::path>{"preprocess", canvas_dir}, {"fit", fit_dir}}) {
    if (dir.empty()) continue;
    std::error_code ec;
    if (!fs::is_directory(dir, ec)) return Error{dir.string() + ": not a folder"};
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(dir, ec))
      if (e.is_regular_file() && e.path().filename().string().front() != '.')
        files.push_back(e.path());
    if (ec) return Error{dir.string() + ": cannot list: " + ec.message()};
    std::sort(files.begin(), files.end());
    for (const fs::path& f : files) {
      auto sha = FileSha1(f);
      if (!sha.ok()) return sha.error();
      p.inputs.push_back(
          {(dir.filename().empty() ? dir.parent_path().filename() : dir.filename()).string() + "/" +
               f.filename().string(),
           *sha, static_cast<uint64_t>(fs::file_size(f, ec))});
    }
    const std::string report_path = (dir / "report.json").string();
    auto text = ReadTextFile(dir / "report.json", std::string(stage) + " report");
    if (!text.ok())
      return Error{report_path + ": cannot open (not a " + stage + " output folder?)"};
    const json doc = json::parse(*text, nullptr, false);
    if (doc.is_discarded() || !doc.is_object()) return Error{report_path + ": not JSON"};
    const bool is_fit = std::string(stage) == "fit";
    const Result<bool> typed = CatchBadInput([&] {
      const Fields report(doc, report_path);
      if (report.Has("inputs")) (void)report.Array("inputs");
      if (report.Has("options")) (void)report.Object("options");
      if (is_fit && report.Has("brief")) (void)report.String("brief");
      return true;
    });
    if (!typed.ok()) return typed.error();
    json inputs = doc.value("inputs", json::array());
    for (json& in : inputs)
      if (in.is_string()) in = ProvenanceName(in.get<std::string>(), {});
    json entry = {{"options", doc.value("options", json::object())}, {"inputs", inputs}};
    options[stage] = entry;
    if (is_fit) p.fit_brief = doc.value("brief", "");
  }
  p.options_json = options.dump(-1, ' ', false, json::error_handler_t::replace);
  return p;
}

}  // namespace digitize
