// Calls into the layers that link each third-party library (OpenCV, OpenImageIO, OpenMesh, TBB,
// Ceres, Embree), so a link-time dependency the installed package does not find fails to link, and
// checks what they return.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include "digitize/brdf_fit.h"
#include "digitize/height_field_tracer.h"
#include "digitize/normals.h"
#include "digitize/relief.h"
#include "digitize/scan_io.h"

namespace {

int failures = 0;

void Check(bool ok, const char* what) {
  if (!ok) {
    std::fprintf(stderr, "digitize consumer: FAILED: %s\n", what);
    ++failures;
  }
}

}  // namespace

int main() {
  using namespace digitize;

  // A 32 x 16 plane rising 0.1 mm per mm along X.
  HeightField field;
  field.pitch_mm = 0.5;
  field.height_mm = Grid<float>(32, 16, 0.0f);
  field.state = Grid<TexelState>(32, 16, TexelState::kMeasured);
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 32; ++x)
      field.height_mm(x, y) = static_cast<float>(0.1 * field.TexelCentreMm(x, y).x());

  const Grid<Vec3f> normals = ComputeNormals(field);
  const Vec3f expected = Vec3f(-0.1f, 0.0f, 1.0f).normalized();
  Check(normals.width == 32 && normals.height == 16, "ComputeNormals size");
  Check((normals(10, 8) - expected).norm() < 1e-5f, "ComputeNormals of a plane");

  HeightField flat = field;
  flat.height_mm = Grid<float>(32, 16, 0.0f);
  const ReliefResult relief = ClassifyRelief(flat, ReliefOptions{});
  Check(relief.boxes.empty(), "ClassifyRelief of a flat canvas has no boxes");

  Result<HeightFieldTracer> tracer = HeightFieldTracer::Build(field);
  Check(tracer.ok(), "HeightFieldTracer::Build");
  if (tracer.ok()) {
    const std::vector<Vec3f> origins = {Vec3f(8.0f, 4.0f, 0.8f + 0.01f)};
    const std::vector<Vec3f> up = {Vec3f(0.0f, 0.0f, 1.0f)};
    const std::vector<Vec3f> into_slope = {Vec3f(1.0f, 0.0f, 0.02f).normalized()};
    const std::vector<float> tfar = {INFINITY};
    std::vector<uint8_t> blocked = {7};
    tracer->Occluded(origins, up, tfar, blocked);
    Check(blocked[0] == 0, "a ray straight up is free");
    tracer->Occluded(origins, into_slope, tfar, blocked);
    Check(blocked[0] == 1, "a ray into the rising plane is blocked");
  }

  BrdfFitOptions fit;
  fit.method = BrdfFitMethod::kCeresReference;
  const TexelFit texel = FitBrdfTexel({}, fit);
  Check(texel.status == TexelFitStatus::kTooFewSamples, "FitBrdfTexel without samples");

  const Result<Scan> scan = ReadScan("no/such/scan.exr", ScanReadOptions{});
  Check(!scan.ok() && scan.error().message.find("no/such/scan.exr") != std::string::npos,
        "ReadScan of a missing file names it");

  if (failures == 0) std::printf("digitize consumer: ok\n");
  return failures == 0 ? 0 : 1;
}
