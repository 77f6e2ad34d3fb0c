// Provenance of a texture pack: who made it, when, from which files (hashed) and with which
// options -- what a museum needs to know how a digital copy came about (docs/formats.md,
// "Texture packs", digitize:provenance).
//
// Layer: pack. Built once per pack: by RunPipeline (pipeline.h) from the options in memory, or by
// ProvenanceFromOutputs from the folders `digitize preprocess` and `digitize fit` wrote; the pack
// writer stores it, the reader parses it back.
#pragma once
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "digitize/core.h"

namespace digitize {

struct PackWriteOptions;  // pack.h

struct PackInput {
  std::string name;  // file name as given on the command line
  std::string sha1;  // hex digest of the file's bytes ("" when not hashed, e.g. in memory)
  uint64_t bytes = 0;
};

struct PackProvenance {
  std::string tool_version;       // "digitize 0.4.0"
  std::string created_utc;        // ISO 8601, "2026-11-30T09:30:00Z"
  std::string fit_brief;          // the fit's one-line brief
  std::string options_json;       // JSON object: the options of the stages that made the pack
  std::vector<PackInput> inputs;  // scan(s), calibration, photos, canvas and fit folders' files
};

// Tool version and the time now (UTC, ISO 8601); the rest empty.
PackProvenance NewProvenance();

// Appends each file with its SHA-1 and size. Names: relative to the folder `relative_to` (e.g.
// the calibration file's: "images/img_000.png", "../scans/scan.exr"), never an absolute path of
// the capturing machine (a pack is shared; its provenance should not tell where the files lay);
// with relative_to empty, a relative name as given and an absolute one as its file name.
// Error names the file.
Status AddProvenanceInputs(PackProvenance& provenance,
                           const std::vector<std::filesystem::path>& files,
                           const std::filesystem::path& relative_to = {});

// Provenance of a pack made from a `digitize preprocess` folder and a `digitize fit` folder (either
// may be empty: an RTI capture has no canvas folder): every file of both hashed (named
// "<folder>/<file>"), the fit's brief, both stages' options and their own inputs (their
// report.json; absolute paths there reduced to their file names, as AddProvenanceInputs),
// the pack's write options, the tool version and the time now (UTC).
Result<PackProvenance> ProvenanceFromOutputs(const std::filesystem::path& canvas_dir,
                                             const std::filesystem::path& fit_dir,
                                             const PackWriteOptions& pack_options);

// SHA-1 of a file's bytes (provenance), hex. Error names the file.
Result<std::string> FileSha1(const std::filesystem::path& path);

}  // namespace digitize
