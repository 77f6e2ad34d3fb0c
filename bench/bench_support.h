// What the stand-alone benchmarks share: a wall clock, `--name=value` options, and the synthetic
// painting photographed under point lights that the fit and pack benchmarks measure on.
#pragma once

#include <chrono>
#include <string>

#include "digitize_synth/painting.h"
#include "digitize_synth/photo_sim.h"
#include "digitize_synth/scan_sim.h"

namespace digitize::bench {

using Clock = std::chrono::steady_clock;
inline double Since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

// The value of `--name=value`, else `fallback`. A benchmark takes a handful of numbers from a
// script (bench/run.sh), so no option library.
inline std::string Arg(int argc, char** argv, const std::string& name,
                       const std::string& fallback) {
  const std::string prefix = "--" + name + "=";
  for (int i = 1; i < argc; ++i)
    if (std::string(argv[i]).rfind(prefix, 0) == 0)
      return std::string(argv[i]).substr(prefix.size());
  return fallback;
}

struct Photographed {
  synth::Painting painting;
  synth::PhotoSimOptions options;
  synth::SyntheticPhotoSet photos;
  double seconds_render = 0;
};

// A painting of `long_side` pixels in its default frame, photographed straight on under `lights`
// point lights at `pixels_per_texel`.
inline Photographed PhotographPainting(int long_side, int lights, double pixels_per_texel) {
  Photographed p;
  synth::PaintingOptions po;
  po.resolution_px = long_side;
  p.painting = synth::MakePainting(po);
  const synth::Scene scene(p.painting, synth::FrameOptions{});
  p.options.lights = lights;
  p.options.pixels_per_texel = pixels_per_texel;
  const auto t0 = Clock::now();
  p.photos = synth::SimulatePhotoSet(scene, RigidTransform{}, p.options);
  p.seconds_render = Since(t0);
  return p;
}

}  // namespace digitize::bench
