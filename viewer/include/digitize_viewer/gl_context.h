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
  // Creates the context and makes it current on the calling thread. Errors say which EGL step
  // failed (no EGL, no surfaceless platform, no OpenGL 4.5 core) with the EGL error code.
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
};

}  // namespace digitize::viewer
