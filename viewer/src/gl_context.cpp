// EGL surfaceless context through libepoxy (which resolves both EGL and GL entry points; GLEW's
// Debian build cannot, under EGL).
#include "digitize_viewer/gl_context.h"

#include <epoxy/egl.h>
#include <epoxy/gl.h>

#include <mutex>
#include <sstream>

namespace digitize::viewer {
namespace {
// EGL displays are per process and eglTerminate is not reference counted: with two contexts on
// the same surfaceless display, terminating it for one would pull it from under the other.
std::mutex display_mutex;
int display_users = 0;

std::string EglError(const char* step) {
  std::ostringstream s;
  s << "EGL: " << step << " failed (error 0x" << std::hex << eglGetError() << ")";
  return s.str();
}
}  // namespace

Result<std::unique_ptr<HeadlessContext>> HeadlessContext::Create() {
  EGLDisplay display = EGL_NO_DISPLAY;
  // The surfaceless platform needs no display server; fall back to the default display.
  if (epoxy_has_egl_extension(EGL_NO_DISPLAY, "EGL_MESA_platform_surfaceless")) {
    display = eglGetPlatformDisplayEXT(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
  }
  if (display == EGL_NO_DISPLAY) display = eglGetDisplay(EGL_DEFAULT_DISPLAY);
  if (display == EGL_NO_DISPLAY) return Error{EglError("eglGetDisplay (no surfaceless platform)")};
  // Whatever context the caller had current comes back when this one goes.
  const EGLDisplay previous_display = eglGetCurrentDisplay();
  const EGLContext previous_context = eglGetCurrentContext();
  const EGLSurface previous_draw = eglGetCurrentSurface(EGL_DRAW);
  const EGLSurface previous_read = eglGetCurrentSurface(EGL_READ);
  std::lock_guard<std::mutex> lock(display_mutex);
  EGLint major = 0, minor = 0;
  if (!eglInitialize(display, &major, &minor)) return Error{EglError("eglInitialize")};
  auto fail = [&](const char* step) -> Error {
    Error e{EglError(step)};
    if (display_users == 0) eglTerminate(display);
    return e;
  };
  if (!eglBindAPI(EGL_OPENGL_API)) return fail("eglBindAPI(OpenGL)");
  const EGLint config_attribs[] = {EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT, EGL_NONE};
  EGLConfig config = nullptr;
  EGLint count = 0;
  if (!eglChooseConfig(display, config_attribs, &config, 1, &count) || count < 1) config = nullptr;
  const EGLint context_attribs[] = {EGL_CONTEXT_MAJOR_VERSION,
                                    4,
                                    EGL_CONTEXT_MINOR_VERSION,
                                    5,
                                    EGL_CONTEXT_OPENGL_PROFILE_MASK,
                                    EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT,
                                    EGL_NONE};
  EGLContext context = eglCreateContext(display, config ? config : EGL_NO_CONFIG_KHR,
                                        EGL_NO_CONTEXT, context_attribs);
  if (context == EGL_NO_CONTEXT) return fail("eglCreateContext (OpenGL 4.5 core)");
  if (!eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, context)) {
    eglDestroyContext(display, context);
    return fail("eglMakeCurrent (surfaceless)");
  }
  std::unique_ptr<HeadlessContext> out(new HeadlessContext());
  out->display_ = display;
  out->context_ = context;
  out->previous_display_ = previous_display;
  out->previous_context_ = previous_context;
  out->previous_draw_ = previous_draw;
  out->previous_read_ = previous_read;
  ++display_users;
  return out;
}

HeadlessContext::~HeadlessContext() {
  auto display = static_cast<EGLDisplay>(display_);
  std::lock_guard<std::mutex> lock(display_mutex);
  if (eglGetCurrentContext() == static_cast<EGLContext>(context_)) {
    if (previous_context_ != EGL_NO_CONTEXT) {
      eglMakeCurrent(
          static_cast<EGLDisplay>(previous_display_), static_cast<EGLSurface>(previous_draw_),
          static_cast<EGLSurface>(previous_read_), static_cast<EGLContext>(previous_context_));
    } else {
      eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    }
  }
  eglDestroyContext(display, static_cast<EGLContext>(context_));
  // The display stays initialised for the life of the process (eglInitialize on an initialised
  // display is a no-op): terminating it makes Mesa unload its driver and the shaders it compiled,
  // and what they still held is then reported by LeakSanitizer at exit against an unknown module,
  // which no suppression can name. The next context reuses it, cheaper than a re-initialisation.
  if (--display_users == 0 && previous_context_ == EGL_NO_CONTEXT) eglReleaseThread();
}

std::string HeadlessContext::Description() const {
  const auto* renderer = reinterpret_cast<const char*>(glGetString(GL_RENDERER));
  const auto* version = reinterpret_cast<const char*>(glGetString(GL_VERSION));
  return std::string(renderer ? renderer : "?") + "; " + (version ? version : "?");
}

}  // namespace digitize::viewer
