// The pipeline end to end: what the `digitize` commands run, so that each command only parses its
// flags into these options and calls one function here (docs/architecture.md).
//
// Layer: pipeline (everything below it: scan_io, preprocess, photo_set, reflectance_fit, pack).
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "digitize/core.h"
#include "digitize/pack.h"
#include "digitize/photo_residuals.h"
#include "digitize/photo_set.h"
#include "digitize/preprocess.h"
#include "digitize/preprocess_tiled.h"
#include "digitize/reflectance_fit.h"
#include "digitize/rti_canvas.h"
#include "digitize/scan_io.h"

namespace digitize {

// A photo set file: by its .lp (or .LP) extension an RTI capture (ReadRtiCapture), otherwise a
// calibration JSON (ReadCalibration).
Result<PhotoSet> ReadPhotoSetFile(const std::filesystem::path& path, const PhotoSetOptions& options,
                                  const ProgressCallback& progress = nullptr);

// Every scan read with `options` (mask and grid included); options validated first. Errors name
// the file or the option.
Result<std::vector<Scan>> ReadScans(const std::vector<std::string>& paths,
                                    const ScanReadOptions& options);

// What the fit and the pack take from a preprocess result (as ReadPreprocessOutputs reads it
// from its folder).
PreprocessedCanvas CanvasFromPreprocess(const PreprocessResult& result);

// The flat canvas of an RTI capture's image grid (FlatCanvasForRti), normals straight up, no
// boxes. Error: not an RTI capture, or its images disagree in size.
Result<PreprocessedCanvas> FlatCanvasFor(const PhotoSet& rti);

// The canvas `digitize fit` fits on: the canvas folder, or with none an RTI capture's flat
// canvas. Error: neither (a calibration file needs a canvas), or the folder's read error.
Result<PreprocessedCanvas> LoadFitCanvas(const std::filesystem::path& canvas_dir,
                                         const PhotoSet& set);

// RTI captures have uncalibrated light intensities (a hand-held light's distance varies), so a
// dim light looks like a shadow to the unmodelled-shadow test: for them it is off unless the
// user chose a ratio. Calibrated sets keep `options` as they are.
ReflectanceFitOptions FitOptionsFor(const PhotoSet& set, ReflectanceFitOptions options,
                                    bool dark_outlier_ratio_chosen);

// `digitize pack`: a canvas folder and a fit folder -> a pack file at `out` (written atomically,
// never over an input), its provenance from the folders. Returns the written pack's summary.
Result<PackSummary> PackFromFolders(const std::filesystem::path& canvas_dir,
                                    const std::filesystem::path& fit_dir,
                                    const std::filesystem::path& out,
                                    const PackWriteOptions& options);

// `digitize preprocess`: scan(s) -> a canvas folder.
struct PreprocessFolderOptions {
  std::vector<std::string> scans;  // exposures of one pose
  // Or a patch list (ReadPatchList): overlapping scans of one painting, registered and merged
  // (PreprocessPatches); then scans must be empty and read.mask unset.
  std::string patches;
  PatchRegistrationOptions registration;
  ScanReadOptions read;  // mask and PLY grid included
  PreprocessOptions preprocess;
  // Set: one XYZ scan preprocessed in tiles in bounded memory (preprocess_tiled.h), for scans
  // too large to hold; not with exposures, patches or a mask.
  std::optional<TiledPreprocessOptions> tiled;
  std::string out;  // the canvas folder
};

// Order: options checked; the folder checked against the inputs (scans, mask) before anything is
// read; the scans read, preprocessed, and written (WritePreprocessOutputs) into `out`, which is
// replaced only on success. Errors name the file or option.
Result<PreprocessResult> PreprocessToFolder(const PreprocessFolderOptions& options,
                                            const ProgressCallback& progress = nullptr);

// `digitize fit`: a canvas folder (or an RTI capture alone) + photos -> a fit folder.
struct FitFolderOptions {
  std::string canvas;        // a canvas folder; empty: an RTI capture's flat canvas
  std::string photos;        // calibration JSON or RTI .lp
  std::string held_out;      // optional: photos not fitted, relit from the fit
  std::string held_out_out;  // optional (needs held_out): a folder of the relit held-out photos
  PhotoSetOptions photo;
  RtiCanvasOptions rti;  // an RTI capture without a canvas: its normals, height, intensities
  ReflectanceFitOptions fit;
  bool check_photos = true;  // after the fit: each photo's gain and shift (CheckPhotoResiduals)
  PhotoResidualOptions photo_check;
  bool dark_outlier_ratio_chosen = false;  // FitOptionsFor
  std::string out;                         // the fit folder
};

struct FitFolderResult {
  PhotoSet photos;
  std::optional<RtiCanvas> rti;  // an RTI capture fitted without a canvas
  ReflectanceFitReport fit;
  std::optional<PhotoResidualReport> photo_check;  // with check_photos
  std::optional<HeldOutScore> held_out;
};

// Order: options checked; an incomplete canvas folder refused before the photos are loaded (a
// moment, not a minute); photos read, then the held-out ones (a bad file fails before minutes of
// work); the folders checked against every input; the canvas; the fit; the held-out score; the
// folder written (WriteReflectanceOutputs), replaced only on success; the relit held-out photos
// (WriteRelitImages) into held_out_out, likewise.
Result<FitFolderResult> FitToFolder(const FitFolderOptions& options,
                                    const ProgressCallback& progress = nullptr);

// `digitize run`: scan(s) + photos -> pack in one go.
struct PipelineOptions {
  std::vector<std::string> scans;  // none: an RTI capture, packed on its flat canvas
  ScanReadOptions read;            // mask and PLY grid included
  PreprocessOptions preprocess;
  std::string photos;        // calibration JSON or RTI .lp
  std::string held_out;      // optional: photos not fitted, relit from the written pack
  std::string held_out_out;  // optional (needs held_out): a folder of the relit held-out photos
  PhotoSetOptions photo;
  RtiCanvasOptions rti;  // an RTI capture without a scan: its normals, height, intensities
  ReflectanceFitOptions fit;
  bool check_photos = true;  // after the fit: each photo's gain and shift (CheckPhotoResiduals)
  PhotoResidualOptions photo_check;
  bool dark_outlier_ratio_chosen = false;  // FitOptionsFor
  PackWriteOptions pack;
  std::string out;   // the pack file
  std::string work;  // optional: the canvas/ and fit/ folders are also written here
  // Each part's Validate, in the order the run would need them; the message says which.
  Status Validate() const;
};

struct PipelineResult {
  std::optional<PreprocessResult> preprocessed;  // empty for an RTI capture without a scan
  std::optional<RtiCanvas> rti;                  // an RTI capture without a scan
  PhotoSet photos;
  ReflectanceFitReport fit;
  std::optional<PhotoResidualReport> photo_check;  // with check_photos
  std::optional<HeldOutScore> held_out;  // relit from the pack as written (what a user gets)
  PackSummary pack;                      // of the written file
};

// Order: options checked; photos read (a bad calibration fails before minutes of
// preprocessing), then the held-out ones; every output checked against every input; the canvas
// (preprocessed scans, or an RTI capture's flat canvas); the fit; the provenance (every input
// file hashed, named relative to the photo set's folder, and every stage's options); the --work
// folders; the pack; the held-out score from the pack file. Errors name the file or option; the
// pack is replaced only on success.
Result<PipelineResult> RunPipeline(const PipelineOptions& options,
                                   const ProgressCallback& progress = nullptr);

}  // namespace digitize
