// A headless OpenGL 4.5 core context: EGL on Mesa's surfaceless platform (no display, no window
// system: CI, tests, benchmarks, screenshots). Rendering goes to framebuffer objects.
//
// Layer: viewer. EGL types stay in gl_context.cpp.
#pragma once

#include <memory>
#include <string>

#include "digitize/core.h"

namespace digitize::viewer {

class HeadlessContext {
 public:
  // Creates the context and makes it current on the calling thread; the context that was current
  // before (if any) is made current again when this one is destroyed, so a helper may create its
  // own (RenderGalleryScreenshots) inside a caller that has one. Errors say which EGL step failed
  // (no EGL, no surfaceless platform, no OpenGL 4.5 core) with the EGL error code.
  static Result<std::unique_ptr<HeadlessContext>> Create();
  ~HeadlessContext();
  HeadlessContext(const HeadlessContext&) = delete;
  HeadlessContext& operator=(const HeadlessContext&) = delete;

  // GL_RENDERER and GL_VERSION, e.g. "llvmpipe (LLVM 15.0.6, 256 bits); 4.5 (Core Profile) Mesa".
  std::string Description() const;

 private:
  HeadlessContext() = default;
  void* display_ = nullptr;
  void* context_ = nullptr;
  void* previous_display_ = nullptr;
  void* previous_context_ = nullptr;
  void* previous_draw_ = nullptr;
  void* previous_read_ = nullptr;
};

}  // namespace digitize::viewer
