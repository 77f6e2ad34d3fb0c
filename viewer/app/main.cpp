// digitize-viewer: opens packs in a virtual gallery (viewer/README.md). A thin program: flags ->
// options, the library does the work.
//
//   digitize-viewer [PACK.pack.exr ...] [--synthetic] [--technique adaptive]
//                   [--mode relit|light|specular|normals|raking]
//                   [--style realistic|watercolor|binary|collage|hatching|painterly]
//                   [--screenshot shot.png [--camera-path path.json | --close-up near.png]
//                    [--tour N [--video tour.mp4]] [--size 1280x720] [--exposure 1]]
//
// With a display: a GLFW window (OpenGL 4.5 core), walk with W/A/S/D (Q/E down/up, shift
// faster), look by dragging with the right mouse button; in the light and specular modes the
// left mouse button drags the light over the painting (the cursor's place in the window picks a
// direction on the hemisphere); a Dear ImGui panel for technique, view mode, K / eps,
// screen-space error, box overlay, alpha heat map, lights, frame time and boxes drawn.
// Without a display (or with --screenshot): headless (EGL surfaceless) screenshots.
// Packs that fail to load are listed (stderr and the panel); the others are shown.
#include <epoxy/gl.h>
// epoxy before GLFW: GLFW must not pull in another GL header.
#include <GLFW/glfw3.h>
#include <imgui.h>
#include <imgui_impl_glfw.h>
#include <imgui_impl_opengl3.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "digitize/image_io.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/truth_pack.h"
#include "digitize_viewer/gallery.h"
#include "digitize_viewer/painting_setup.h"
#include "digitize_viewer/renderer.h"

using namespace digitize;
using namespace digitize::viewer;

namespace {

struct Walker {  // walk-through camera: position, yaw / pitch (rad), world Z up
  Vec3d eye;
  double yaw = 0, pitch = 0;
  Vec3d Forward() const {
    return {std::cos(pitch) * std::sin(yaw), std::cos(pitch) * std::cos(yaw), std::sin(pitch)};
  }
};

// max_frames > 0: close after that many frames, first writing the window (panel included) to
// window_shot when given -- how the windowed path is checked under xvfb-run.
int RunWindow(const std::vector<std::pair<std::string, Pack>>& packs,
              const std::vector<std::string>& streamed, std::vector<std::string> errors,
              RenderOptions options, int max_frames, const std::string& window_shot) {
  if (!glfwInit()) {
    std::fprintf(stderr, "digitize-viewer: GLFW cannot initialise (no display?)\n");
    return 1;
  }
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 4);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 5);
  glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
  glfwWindowHint(GLFW_SRGB_CAPABLE, GLFW_TRUE);
  GLFWwindow* window = glfwCreateWindow(1280, 720, "digitize viewer", nullptr, nullptr);
  if (!window) {
    std::fprintf(stderr, "digitize-viewer: no OpenGL 4.5 core window\n");
    glfwTerminate();
    return 1;
  }
  glfwMakeContextCurrent(window);
  glfwSwapInterval(0);
  IMGUI_CHECKVERSION();
  ImGui::CreateContext();
  // No imgui.ini: the viewer writes nothing into the user's folder, and the panel starts the
  // same way every time.
  ImGui::GetIO().IniFilename = nullptr;
  ImGui_ImplGlfw_InitForOpenGL(window, true);
  ImGui_ImplOpenGL3_Init("#version 450");

  auto renderer = Renderer::Create();
  if (!renderer) {
    std::fprintf(stderr, "digitize-viewer: %s\n", renderer.error().message.c_str());
    return 1;
  }
  // A pack the viewer refuses is listed (stderr and the panel); the others hang without a gap.
  // Tiled packs stream: each frame uploads the tiles its view needs (pyramid_stream.h).
  std::vector<std::string> refused;
  GalleryScene scene = HangInRenderer(**renderer, packs, {streamed.begin(), streamed.end()},
                                      StreamOptions{}, refused);
  Gallery& g = scene.gallery;
  for (const std::string& e : refused) std::fprintf(stderr, "digitize-viewer: %s\n", e.c_str());
  errors.insert(errors.end(), refused.begin(), refused.end());
  (*renderer)->SetRoom(g.room);
  Walker walker;
  walker.eye = g.start.eye_mm;
  const Vec3d f0 = (g.start.target_mm - g.start.eye_mm).normalized();
  walker.yaw = std::atan2(f0.x(), f0.y());
  walker.pitch = std::asin(f0.z());
  double last_x = 0, last_y = 0;
  bool dragging = false;
  auto last = std::chrono::steady_clock::now();
  double frame_ms = 0;
  FrameStats stats;
  int technique = int(options.technique);
  int mode = int(options.mode);
  int style = int(options.style);
  int frame = 0;
  bool shot_failed = false;  // --window-shot not written: exit 1
  float exposure_ambient = float(options.ambient);
  float exposure_ui = float(options.exposure);

  while (!glfwWindowShouldClose(window)) {
    glfwPollEvents();
    const auto now = std::chrono::steady_clock::now();
    const double dt = std::chrono::duration<double>(now - last).count();
    last = now;
    frame_ms = 0.9 * frame_ms + 0.1 * dt * 1000;
    ImGuiIO& io = ImGui::GetIO();
    if (!io.WantCaptureKeyboard) {
      const double speed = (glfwGetKey(window, GLFW_KEY_LEFT_SHIFT) ? 3000 : 1000) * dt;  // mm/s
      const Vec3d fwd(std::sin(walker.yaw), std::cos(walker.yaw), 0);
      const Vec3d right(fwd.y(), -fwd.x(), 0);
      if (glfwGetKey(window, GLFW_KEY_W)) walker.eye += speed * fwd;
      if (glfwGetKey(window, GLFW_KEY_S)) walker.eye -= speed * fwd;
      if (glfwGetKey(window, GLFW_KEY_D)) walker.eye += speed * right;
      if (glfwGetKey(window, GLFW_KEY_A)) walker.eye -= speed * right;
      if (glfwGetKey(window, GLFW_KEY_E)) walker.eye.z() += speed;
      if (glfwGetKey(window, GLFW_KEY_Q)) walker.eye.z() -= speed;
      if (glfwGetKey(window, GLFW_KEY_ESCAPE)) glfwSetWindowShouldClose(window, 1);
    }
    double mx, my;
    glfwGetCursorPos(window, &mx, &my);
    const bool right_down = glfwGetMouseButton(window, GLFW_MOUSE_BUTTON_RIGHT) == GLFW_PRESS;
    if (right_down && !io.WantCaptureMouse) {
      if (dragging) {
        walker.yaw += 0.004 * (mx - last_x);
        walker.pitch = std::clamp(walker.pitch - 0.004 * (my - last_y), -1.5, 1.5);
      }
      dragging = true;
    } else {
      dragging = false;
    }
    last_x = mx;
    last_y = my;
    // The RTI tools' light: drag with the left button, the cursor over the window is the light's
    // place on the unit disc (right = canvas +x, up = canvas +y), lifted onto the hemisphere.
    const bool left_down = glfwGetMouseButton(window, GLFW_MOUSE_BUTTON_LEFT) == GLFW_PRESS;
    const ViewMode current = ViewMode(mode);
    if (left_down && !io.WantCaptureMouse &&
        (current == ViewMode::kLight || current == ViewMode::kSpecular)) {
      int ww, wh;
      glfwGetWindowSize(window, &ww, &wh);
      if (ww > 0 && wh > 0) {
        const double side = std::min(ww, wh);
        options.light_direction =
            HemisphereLightDirection((2 * mx - ww) / side, (wh - 2 * my) / side);
      }
    }
    // Keep the walker inside the room.
    walker.eye.x() = std::clamp(walker.eye.x(), 50.0, g.width_mm - 50);
    walker.eye.y() = std::clamp(walker.eye.y(), 50.0, g.depth_mm - 50);
    walker.eye.z() = std::clamp(walker.eye.z(), 50.0, g.height_mm - 50);

    int w, h;
    glfwGetFramebufferSize(window, &w, &h);
    if (w > 0 && h > 0) {
      ViewCamera cam;
      cam.eye_mm = walker.eye;
      cam.target_mm = walker.eye + walker.Forward();
      cam.up = Vec3d::UnitZ();
      cam.fov_y_deg = 50;
      cam.width = w;
      cam.height = h;
      cam.near_mm = 5;
      cam.far_mm = 4 * (g.width_mm + g.depth_mm + g.height_mm);
      options.technique = Technique(technique);
      options.mode = ViewMode(mode);
      options.style = Style(style);
      options.ambient = exposure_ambient;
      if (options.Validate().ok() && cam.Validate().ok()) {
        glBindFramebuffer(GL_FRAMEBUFFER, 0);
        // The display values (the screenshots' tone curve), encoded to sRGB on write.
        RenderOptions window_options = options;
        window_options.display_output = true;
        window_options.exposure = exposure_ui;
        glEnable(GL_FRAMEBUFFER_SRGB);
        stats = (*renderer)->Draw(cam, g.lights, window_options);
        for (const std::string& e : stats.stream_errors) {  // a tile that failed its checks
          std::fprintf(stderr, "digitize-viewer: %s\n", e.c_str());
          errors.push_back(e);
        }
        glDisable(GL_FRAMEBUFFER_SRGB);
      }
    }

    ImGui_ImplOpenGL3_NewFrame();
    ImGui_ImplGlfw_NewFrame();
    ImGui::NewFrame();
    // Collapsed at start (a title bar that opens it), so the first painting is seen whole;
    // open when a pack failed to load, to show why.
    ImGui::SetNextWindowPos(ImVec2(8, 8), ImGuiCond_FirstUseEver);
    ImGui::SetNextWindowSize(ImVec2(440, 620), ImGuiCond_FirstUseEver);
    ImGui::SetNextWindowCollapsed(errors.empty(), ImGuiCond_FirstUseEver);
    ImGui::SetNextWindowBgAlpha(0.75f);
    ImGui::Begin("digitize viewer");
    ImGui::Text("%.1f ms/frame (%.0f Hz)", frame_ms, 1000.0 / std::max(frame_ms, 1e-3));
    ImGui::Text("boxes drawn %d of %d (%d blended)", stats.boxes_drawn, stats.boxes_total,
                stats.boxes_blended);
    if (stats.tiles_needed > 0)
      ImGui::Text("streamed tiles: %d drawn, %d of %d needed loading, %.0f MB on the GPU",
                  stats.tiles_drawn, stats.tiles_missing, stats.tiles_needed,
                  stats.stream_bytes / 1048576.0);
    const char* names[] = {"mesh",   "relief everywhere", "bump",
                           "hybrid", "hybrid + adaptive", "screen-space error"};
    ImGui::Combo("technique", &technique, names, 6);
    const char* modes[] = {"relit (gallery lights)", "light (drag: left button)",
                           "specular enhancement", "normals", "raking light"};
    ImGui::Combo("mode", &mode, modes, 5);
    const char* styles[] = {"realistic",
                            "watercolor (seed 003)",
                            "binary, pen and ink (seed 003)",
                            "collage (seed 003)",
                            "hatching, tonal art maps (seed 004)",
                            "painterly strokes (seed 002)"};
    ImGui::Combo("style", &style, styles, 6);
    if (ViewMode(mode) == ViewMode::kLight || ViewMode(mode) == ViewMode::kSpecular) {
      const Vec3d& d = options.light_direction;
      ImGui::Text("light: azimuth %.0f deg, elevation %.0f deg",
                  std::atan2(d.y(), d.x()) * 180 / kPi,
                  std::asin(std::clamp(d.z(), -1.0, 1.0)) * 180 / kPi);
    }
    if (ViewMode(mode) == ViewMode::kRaking) {
      float az = float(options.raking_azimuth_deg), el = float(options.raking_elevation_deg);
      ImGui::SliderFloat("raking azimuth (deg)", &az, -180.0f, 180.0f, "%.0f");
      ImGui::SliderFloat("raking elevation (deg)", &el, 1.0f, 45.0f, "%.0f");
      options.raking_azimuth_deg = az;
      options.raking_elevation_deg = el;
    }
    if (ViewMode(mode) == ViewMode::kSpecular) {
      float sd = float(options.specular_diffuse), sg = float(options.specular_gain),
            ss = float(options.specular_sharpen);
      ImGui::SliderFloat("diffuse (grey)", &sd, 0.0f, 1.0f);
      ImGui::SliderFloat("specular gain", &sg, 0.0f, 10.0f);
      ImGui::SliderFloat("sharpen", &ss, 1.0f, 8.0f);
      options.specular_diffuse = sd;
      options.specular_gain = sg;
      options.specular_sharpen = ss;
    }
    float k = float(options.k), emin = float(options.eps_min), emax = float(options.eps_max);
    float px = float(options.max_error_px);
    ImGui::SliderFloat("K", &k, 0.1f, 10.0f, "%.2f", ImGuiSliderFlags_Logarithmic);
    ImGui::SliderFloat("eps min", &emin, 0.0f, 0.05f, "%.4f");
    ImGui::SliderFloat("eps max", &emax, 0.0001f, 0.1f, "%.4f");
    ImGui::SliderFloat("max error (px)", &px, 0.1f, 10.0f);
    options.k = k;
    options.eps_min = emin;
    options.eps_max = std::max(emax, emin + 1e-4f);
    options.max_error_px = px;
    ImGui::Checkbox("bump slab search", &options.bump_slab_search);
    ImGui::SliderInt("bump parallax steps", &options.bump_parallax_iterations, 0, 8);
    ImGui::Checkbox("relief self-shadowing", &options.shadows);
    ImGui::Checkbox("prefiltered reflectance", &options.filter_reflectance);
    ImGui::Checkbox("box overlay", &options.show_boxes);
    ImGui::Checkbox("alpha heat map", &options.alpha_heatmap);
    ImGui::SliderFloat("ambient", &exposure_ambient, 0.0f, 0.5f);
    ImGui::SliderFloat("exposure", &exposure_ui, 0.25f, 4.0f, "%.2f", ImGuiSliderFlags_Logarithmic);
    for (size_t i = 0; i < g.lights.size(); ++i) {
      ImGui::PushID(int(i));
      float pos[3] = {float(g.lights[i].position_mm.x()), float(g.lights[i].position_mm.y()),
                      float(g.lights[i].position_mm.z())};
      if (ImGui::DragFloat3("light (mm)", pos, 10.0f))
        g.lights[i].position_mm = Vec3d(pos[0], pos[1], pos[2]);
      float scale = g.lights[i].intensity.x() / 1e6f;
      if (ImGui::SliderFloat("intensity (1e6)", &scale, 0.0f, 50.0f))
        g.lights[i].intensity = Vec3f::Constant(scale * 1e6f);
      ImGui::PopID();
    }
    for (const std::string& e : errors)
      ImGui::TextColored(ImVec4(1, 0.4f, 0.3f, 1), "%s", e.c_str());
    ImGui::End();
    ImGui::Render();
    ImGui_ImplOpenGL3_RenderDrawData(ImGui::GetDrawData());
    if (max_frames > 0 && ++frame >= max_frames) {
      if (!window_shot.empty()) {
        Grid<std::array<uint8_t, 3>> img(w, h);
        std::vector<uint8_t> rgb(size_t(w) * h * 3);
        glPixelStorei(GL_PACK_ALIGNMENT, 1);
        glReadBuffer(GL_BACK);
        glReadPixels(0, 0, w, h, GL_RGB, GL_UNSIGNED_BYTE, rgb.data());
        for (int y = 0; y < h; ++y)
          for (int x = 0; x < w; ++x)
            for (int c = 0; c < 3; ++c) img(x, y)[c] = rgb[(size_t(h - 1 - y) * w + x) * 3 + c];
        if (Status s = WriteRgb8(window_shot, img); !s.ok()) {
          std::fprintf(stderr, "digitize-viewer: %s\n", s.message().c_str());
          shot_failed = true;
        }
      }
      glfwSetWindowShouldClose(window, 1);
    }
    glfwSwapBuffers(window);
  }
  renderer->reset();
  ImGui_ImplOpenGL3_Shutdown();
  ImGui_ImplGlfw_Shutdown();
  ImGui::DestroyContext();
  glfwDestroyWindow(window);
  glfwTerminate();
  return shot_failed ? 1 : 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"digitize-viewer: packs in a virtual gallery (OpenGL 4.5)"};
  std::vector<std::string> paths;
  bool synthetic = false;
  std::string technique = "adaptive", screenshot, camera_path, size = "1280x720", window_shot;
  int window_frames = 0;
  app.add_option("packs", paths, "texture packs (.pack.exr)");
  app.add_flag("--synthetic", synthetic, "also hang a synthetic painting (ground-truth pack)");
  bool no_stream = false;
  app.add_flag("--no-stream", no_stream,
               "read tiled packs whole (relief boxes, shadows) instead of streaming their tiles; "
               "only for packs of at most 8192 x 8192 texels");
  app.add_option("--technique", technique, "mesh, relief, bump, hybrid, adaptive, screen-error");
  app.add_option("--screenshot", screenshot,
                 "render headless into this image (.png, .jpg, .tif, .exr) and exit");
  app.add_option("--camera-path", camera_path, "JSON camera path: one screenshot per frame");
  app.add_option("--size", size, "screenshot size WxH");
  std::string mode = "relit", style = "realistic", close_up;
  double exposure = 1.0;
  app.add_option("--style", style,
                 "look: realistic, or a stylised mode over room and paintings: watercolor, "
                 "binary (pen and ink), collage, hatching (tonal art maps), painterly (strokes)");
  app.add_option("--close-up", close_up,
                 "with --screenshot: also a close view of the first painting, into this image");
  app.add_option("--exposure", exposure, "screenshots: exposure before the tone curve");
  int tour = 0;
  std::string video;
  app.add_option("--tour", tour,
                 "with --screenshot: a scripted walk past every painting in N frames "
                 "(shot_000.png ...)")
      ->check(CLI::Range(2, 100000));
  app.add_option("--video", video,
                 "with --tour or --camera-path: also encode the frames into this video (.mp4; "
                 "needs Debian's ffmpeg)");
  double light_azimuth = 135, light_elevation = 45, raking_azimuth = 180, raking_elevation = 10;
  app.add_option("--mode", mode,
                 "view mode: relit (the gallery's lights), light (a directional light: the left "
                 "mouse button drags it; --light-azimuth/--light-elevation), specular (specular "
                 "enhancement under that light), normals (n * 0.5 + 0.5 as RGB), raking (a raking "
                 "light: --raking-azimuth/--raking-elevation)");
  app.add_option("--light-azimuth", light_azimuth,
                 "light/specular: the light's azimuth in the painting's frame, deg (0 = from the "
                 "right, 90 = from the top)");
  app.add_option("--light-elevation", light_elevation,
                 "light/specular: the light's elevation above the painting, deg");
  app.add_option("--raking-azimuth", raking_azimuth, "raking: azimuth, deg (180 = from the left)");
  app.add_option("--raking-elevation", raking_elevation, "raking: elevation, deg");
  bool heatmap = false, show_boxes = false, shadows = false, point_sampled = false;
  app.add_flag("--heatmap", heatmap, "colour relief by its box's alpha (blue 0 .. red 1)");
  app.add_flag("--show-boxes", show_boxes, "outline the boxes drawn");
  app.add_flag("--shadows", shadows, "relief self-shadowing");
  app.add_flag("--point-sampled", point_sampled,
               "one texel per pixel even where a pixel covers several (no prefiltered "
               "reflectance: far views alias, as the Embree reference)");
  app.add_option("--window-frames", window_frames, "window: close after this many frames (tests)");
  app.add_option("--window-shot", window_shot,
                 "window: write the last frame (panel included) here (.png, .jpg, .tif, .exr)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help is exit 0; every usage error is 1, as for `digitize`.
    return app.exit(e) == 0 ? 0 : 1;
  }

  RenderOptions options;
  options.ambient = 0.05;
  auto t = ParseTechnique(technique);
  if (!t) {
    std::fprintf(stderr, "digitize-viewer: %s\n", t.error().message.c_str());
    return 1;
  }
  options.technique = *t;
  auto m = ParseViewMode(mode);
  if (!m) {
    std::fprintf(stderr, "digitize-viewer: %s\n", m.error().message.c_str());
    return 1;
  }
  options.mode = *m;
  auto st = ParseStyle(style);
  if (!st) {
    std::fprintf(stderr, "digitize-viewer: %s\n", st.error().message.c_str());
    return 1;
  }
  options.style = *st;
  options.exposure = exposure;
  options.light_direction = LightDirectionFromAngles(light_azimuth, light_elevation);
  options.raking_azimuth_deg = raking_azimuth;
  options.raking_elevation_deg = raking_elevation;
  if (Status valid = options.Validate(); !valid.ok()) {
    std::fprintf(stderr, "digitize-viewer: %s\n", valid.message().c_str());
    return 1;
  }
  options.alpha_heatmap = heatmap;
  options.show_boxes = show_boxes;
  options.shadows = shadows;
  options.filter_reflectance = !point_sampled;

  if (paths.empty() && !synthetic) {
    std::fprintf(stderr,
                 "digitize-viewer: no pack given; usage: digitize-viewer PAINTING.pack.exr [...], "
                 "or digitize-viewer --synthetic for a synthetic painting (--help for more)\n");
    return 1;
  }
  std::vector<std::pair<std::string, Pack>> packs;
  std::vector<std::string> errors, streamed;
  for (const std::string& p : paths) {
    if (!no_stream && IsTiledPack(p)) {  // opened by the renderer's stream, tile by tile
      streamed.push_back(p);
      continue;
    }
    auto pack = LoadPackForViewer(p);
    if (pack) {
      packs.emplace_back(p, std::move(*pack));
    } else {
      errors.push_back(pack.error().message);
      std::fprintf(stderr, "digitize-viewer: %s\n", pack.error().message.c_str());
    }
  }
  if (synthetic) {
    synth::PaintingOptions po;
    po.resolution_px = 768;
    po.impasto_count = 24;
    synth::TruthPackOptions tpo;
    tpo.relief.delta0_fraction = 0.10;
    packs.emplace_back("synthetic", synth::MakeTruthPack(synth::MakePainting(po), tpo));
  }
  if (packs.empty() && streamed.empty()) {  // an empty room would hide that nothing was read
    std::fprintf(stderr,
                 "digitize-viewer: none of the %zu pack(s) could be loaded; nothing shown "
                 "or written\n",
                 paths.size());
    return 1;
  }

  const bool has_display = std::getenv("DISPLAY") || std::getenv("WAYLAND_DISPLAY");
  if (screenshot.empty() && (!camera_path.empty() || !has_display)) {
    // Headless needs a file to write: a default name could overwrite a user's file.
    std::fprintf(stderr, "digitize-viewer: %s; give --screenshot FILE.png to render headless\n",
                 has_display ? "--camera-path writes screenshots"
                             : "no display (DISPLAY and WAYLAND_DISPLAY are unset)");
    return 1;
  }
  if (!screenshot.empty()) {
    GalleryShotOptions shot;
    shot.render = options;
    shot.exposure = exposure;
    shot.close_up = close_up;
    shot.streamed.assign(streamed.begin(), streamed.end());
    shot.inputs.assign(paths.begin(), paths.end());
    if (!camera_path.empty()) shot.inputs.emplace_back(camera_path);
    if (std::sscanf(size.c_str(), "%dx%d", &shot.width, &shot.height) != 2 || shot.width <= 0 ||
        shot.height <= 0) {
      std::fprintf(stderr, "digitize-viewer: --size must be WxH, got '%s'\n", size.c_str());
      return 1;
    }
    if (tour > 0 && !camera_path.empty()) {
      std::fprintf(stderr,
                   "digitize-viewer: --tour and --camera-path are two camera paths; give one\n");
      return 1;
    }
    if (!video.empty() && tour == 0 && camera_path.empty()) {
      std::fprintf(stderr, "digitize-viewer: --video needs --tour N or --camera-path\n");
      return 1;
    }
    if (!video.empty()) {
      std::error_code ec;
      if (std::filesystem::exists(video, ec)) {  // before anything is rendered
        std::fprintf(stderr,
                     "digitize-viewer: %s: already exists (a video is never written over "
                     "a file)\n",
                     video.c_str());
        return 1;
      }
      shot.inputs.emplace_back(video);  // never a screenshot onto it
    }
    std::vector<ViewCamera> path;
    if (tour > 0) {
      std::vector<Eigen::Vector2d> sizes;
      for (const std::string& p : streamed)
        if (auto s = InspectPack(p); s.ok())
          sizes.emplace_back(s->width * s->pitch_mm, s->height * s->pitch_mm);
      path = GalleryTour(HangPaintings(packs, {}, sizes).gallery, tour, shot.width, shot.height);
    }
    if (!camera_path.empty()) {
      auto p = ReadCameraPath(camera_path);
      if (!p) {
        std::fprintf(stderr, "digitize-viewer: %s\n", p.error().message.c_str());
        return 1;
      }
      path = *p;
    }
    const size_t loaded = errors.size();
    const Status shot_status = RenderGalleryScreenshots(packs, screenshot, path, shot, &errors);
    for (size_t i = loaded; i < errors.size(); ++i)
      std::fprintf(stderr, "digitize-viewer: %s\n", errors[i].c_str());
    if (!shot_status.ok()) {
      std::fprintf(stderr, "digitize-viewer: %s\n", shot_status.message().c_str());
      return 1;
    }
    const size_t frames = std::max<size_t>(path.size(), 1);
    std::printf("wrote %s", ScreenshotPath(screenshot, 0, frames).c_str());
    if (frames > 1)
      std::printf(" .. %s (%zu images)", ScreenshotPath(screenshot, frames - 1, frames).c_str(),
                  frames);
    std::printf(" (%zu painting(s), %zu failed to load)\n",
                packs.size() + streamed.size() - (errors.size() - loaded), errors.size());
    if (!video.empty()) {
      if (Status v = WriteVideo(screenshot, frames, video); !v.ok()) {
        std::fprintf(stderr, "digitize-viewer: %s\n", v.message().c_str());
        return 1;
      }
      std::printf("wrote %s (%zu frames, 24 fps)\n", video.c_str(), frames);
    }
    return errors.empty() ? 0 : 1;
  }
  return RunWindow(packs, streamed, errors, options, window_frames, window_shot);
}
