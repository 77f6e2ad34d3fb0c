// The renderer (contract in renderer.h). GL objects are created here only; every call needs the
// context the Renderer was created in.
#include "digitize_viewer/renderer.h"

#include <epoxy/gl.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <string>

#include "digitize_viewer/painterly_strokes.h"
#include "digitize_viewer/painting_setup.h"
#include "digitize_viewer/shading_pyramid.h"
#include "digitize_viewer/tonal_art_map.h"
#include "embedded_shaders.h"
#include "height_mesh.h"

namespace digitize::viewer {
namespace {

using Mat4d = Eigen::Matrix4d;
using Mat4f = Eigen::Matrix4f;

Mat4d Homogeneous(const RigidTransform& t) {
  Mat4d m = Mat4d::Identity();
  m.block<3, 3>(0, 0) = t.rotation;
  m.block<3, 1>(0, 3) = t.translation;
  return m;
}

// Clip space of the pinhole camera: NDC x = (2u + 1) / w - 1, y = 1 - (2v + 1) / h for pixel
// (u, v) of the OpenCV projection, so GL's pixel centres are the reference's pixel centres; depth
// maps [near, far] to [-1, 1].
Mat4d ClipFromWorld(const ViewCamera& view) {
  const Camera cam = ToCamera(view);
  const double w = cam.width, h = cam.height, n = view.near_mm, f = view.far_mm;
  Mat4d p = Mat4d::Zero();
  p(0, 0) = 2 * cam.fx / w;
  p(0, 2) = (2 * cam.cx + 1) / w - 1;
  p(1, 1) = -2 * cam.fy / h;
  p(1, 2) = 1 - (2 * cam.cy + 1) / h;
  p(2, 2) = (f + n) / (f - n);
  p(2, 3) = -2 * f * n / (f - n);
  p(3, 2) = 1;
  return p * Homogeneous(cam.camera_from_scan);
}

// The log's "S:L(C)" positions name a GLSL source string S, which the program's legend maps to its
// file in viewer/shaders/ (embed_shaders.cmake numbers them), hence the legend in the message.
Result<GLuint> Compile(GLenum type, const shaders::Source& source, const char* what,
                       const char* define = nullptr) {
  // A define goes right after the #version line (the #line that follows keeps the log's line
  // numbers).
  std::string text = source.text;
  if (define) {
    const size_t version = text.find("#version");
    const size_t eol = version == std::string::npos ? std::string::npos : text.find('\n', version);
    if (eol != std::string::npos) text.insert(eol + 1, std::string("#define ") + define + "\n");
  }
  const char* c_text = text.c_str();
  const GLuint s = glCreateShader(type);
  glShaderSource(s, 1, &c_text, nullptr);
  glCompileShader(s);
  GLint ok = 0;
  glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    char log[4096] = {0};
    glGetShaderInfoLog(s, sizeof(log), nullptr, log);
    glDeleteShader(s);
    return Error{std::string("viewer: shader ") + what + " does not compile: " + log +
                 "(GLSL source strings: " + source.files + ")"};
  }
  return s;
}

Result<GLuint> Link(const shaders::Source& vs, const shaders::Source& fs, const char* what,
                    const char* fragment_define = nullptr) {
  auto v = Compile(GL_VERTEX_SHADER, vs, what);
  if (!v) return v.error();
  auto f = Compile(GL_FRAGMENT_SHADER, fs, what, fragment_define);
  if (!f) {
    glDeleteShader(*v);
    return f.error();
  }
  const GLuint p = glCreateProgram();
  glAttachShader(p, *v);
  glAttachShader(p, *f);
  glLinkProgram(p);
  glDeleteShader(*v);
  glDeleteShader(*f);
  GLint ok = 0;
  glGetProgramiv(p, GL_LINK_STATUS, &ok);
  if (!ok) {
    char log[4096] = {0};
    glGetProgramInfoLog(p, sizeof(log), nullptr, log);
    glDeleteProgram(p);
    return Error{std::string("viewer: program ") + what + " does not link: " + log};
  }
  return p;
}

// Unit cube [0, 1]^3: 36 vertices (corner, outward normal), each triangle counter-clockwise seen
// from outside (checked by construction: flipped when its normal points inwards).
std::vector<float> CubeTriangles() {
  std::vector<float> out;
  for (int axis = 0; axis < 3; ++axis) {
    for (int side = 0; side < 2; ++side) {
      Eigen::Vector3f normal = Eigen::Vector3f::Zero();
      normal[axis] = side ? 1.0f : -1.0f;
      const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
      std::array<Eigen::Vector3f, 4> q;
      for (int k = 0; k < 4; ++k) {
        q[k][axis] = float(side);
        q[k][a1] = float(k == 1 || k == 2);
        q[k][a2] = float(k >= 2);
      }
      for (const auto& tri : {std::array<int, 3>{0, 1, 2}, std::array<int, 3>{0, 2, 3}}) {
        std::array<Eigen::Vector3f, 3> t = {q[tri[0]], q[tri[1]], q[tri[2]]};
        if ((t[1] - t[0]).cross(t[2] - t[0]).dot(normal) < 0) std::swap(t[1], t[2]);
        for (const auto& v : t)
          out.insert(out.end(), {v.x(), v.y(), v.z(), normal.x(), normal.y(), normal.z()});
      }
    }
  }
  return out;
}

std::vector<float> CubeEdges() {  // 12 edges as 24 line vertices (corner, zero normal)
  std::vector<float> out;
  for (int a = 0; a < 8; ++a)
    for (int bit = 0; bit < 3; ++bit)
      if (!(a & (1 << bit))) {
        const int b = a | (1 << bit);
        for (int c : {a, b})
          out.insert(out.end(), {float(c & 1), float((c >> 1) & 1), float((c >> 2) & 1), 0, 0, 0});
      }
  return out;
}

std::string Size(int w, int h) { return std::to_string(w) + "x" + std::to_string(h); }

GLuint MakeTexture(int w, int h, const std::vector<float>& rgba, bool linear,
                   GLenum format = GL_RGBA32F) {
  GLuint t = 0;
  glCreateTextures(GL_TEXTURE_2D, 1, &t);
  glTextureStorage2D(t, 1, format, w, h);
  glTextureSubImage2D(t, 0, 0, 0, w, h, GL_RGBA, GL_FLOAT, rgba.data());
  const GLint filter = linear ? GL_LINEAR : GL_NEAREST;
  glTextureParameteri(t, GL_TEXTURE_MIN_FILTER, filter);
  glTextureParameteri(t, GL_TEXTURE_MAG_FILTER, filter);
  glTextureParameteri(t, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTextureParameteri(t, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  return t;
}

// The largest footprint (major axis, texels) of a pixel on the part of the canvas in view: the
// shader's Footprint where the rays of a 17 x 17 grid over the image meet the canvas planes z = 0
// and z = top (inside the canvas), x 1.25 for the pixels between: whether the filtered programs
// are needed. Parts out of view do not count (a close-up's far corner would otherwise switch the
// whole frame to the filtered programs). Infinite when a ray runs along the canvas.
double MaxFootprintTexels(double width_mm, double height_mm, double pitch_mm, double top_mm,
                          const Vec3d& eye, const Mat3d& canvas_from_camera,
                          const ViewCamera& camera) {
  const double tan_half = std::tan(camera.fov_y_deg * kPi / 360);
  const double scale = 2 * tan_half / std::max(camera.height, 1);
  const double aspect = double(camera.width) / std::max(camera.height, 1);
  const Vec3d right = canvas_from_camera.col(0), down = canvas_from_camera.col(1),
              forward = canvas_from_camera.col(2);
  double worst = 0;
  constexpr int kGrid = 16;
  for (int iy = 0; iy <= kGrid; ++iy)
    for (int ix = 0; ix <= kGrid; ++ix) {
      const Vec3d dir = forward + (2.0 * ix / kGrid - 1) * tan_half * aspect * right +
                        (2.0 * iy / kGrid - 1) * tan_half * down;  // unit depth
      if (std::abs(dir.z()) < 1e-9) continue;
      for (double z : {0.0, top_mm}) {
        const double depth = (z - eye.z()) / dir.z();
        if (!(depth > 1e-6)) continue;
        const Vec3d p = eye + depth * dir;
        if (p.x() < -pitch_mm || p.y() < -pitch_mm || p.x() > width_mm + pitch_mm ||
            p.y() > height_mm + pitch_mm)
          continue;
        if (std::abs(dir.z()) < 1e-6) return std::numeric_limits<double>::infinity();
        const Eigen::Vector2d fx =
            (scale * depth * (right - dir * (right.z() / dir.z()))).head<2>();
        const Eigen::Vector2d fy = (scale * depth * (down - dir * (down.z() / dir.z()))).head<2>();
        const Eigen::Matrix2d m = fx * fx.transpose() + fy * fy.transpose();
        const double half_trace = 0.5 * m.trace();
        const double l1 =
            half_trace + std::sqrt(std::max(half_trace * half_trace - m.determinant(), 0.0));
        worst = std::max(worst, std::sqrt(l1));
      }
    }
  return 1.25 * worst / pitch_mm;
}

// Levels the shader can address (u_level_row's size): 2^15 texels across.
constexpr int kMaxShadingLevels = 16;

// The pyramid's levels 1.. of one channel in one texture, stacked downwards from the top-left
// corner (level l's row 0 at `rows[l]`), read with texelFetch at lod 0. Not a GL mip chain: a
// per-pixel level that differs within a 2 x 2 pixel quad is fetched at the quad's level on
// llvmpipe. Half floats but for the lobe (k is not bounded by the format); the other values are
// finite and far below half's range (pack.h's bounds). `rows` gets one entry per level (0 for 0).
GLuint MakeLevelAtlas(const ShadingPyramid& pyramid, int channel, std::vector<int>* rows) {
  const int width = pyramid.levels.size() > 1 ? pyramid.levels[1].width : 1;
  int height = 0;
  rows->assign(1, 0);
  for (size_t l = 1; l < pyramid.levels.size(); ++l) {
    rows->push_back(height);
    height += pyramid.levels[l].height;
  }
  height = std::max(height, 1);
  GLuint t = 0;
  glCreateTextures(GL_TEXTURE_2D, 1, &t);
  glTextureStorage2D(t, 1, channel == kLobe ? GL_RGBA32F : GL_RGBA16F, width, height);
  const std::vector<float> zeros(size_t(width) * height * 4, 0.0f);
  glTextureSubImage2D(t, 0, 0, 0, width, height, GL_RGBA, GL_FLOAT, zeros.data());
  for (size_t l = 1; l < pyramid.levels.size(); ++l) {
    const ShadingLevel& level = pyramid.levels[l];
    glTextureSubImage2D(t, 0, 0, (*rows)[l], level.width, level.height, GL_RGBA, GL_FLOAT,
                        level.rgba[channel].data());
  }
  glTextureParameteri(t, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTextureParameteri(t, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  glTextureParameteri(t, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTextureParameteri(t, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  return t;
}

struct Painting {
  std::string name;
  RigidTransform world_from_canvas;
  int texels_w = 0, texels_h = 0;
  double pitch_mm = 0, width_mm = 0, height_mm = 0;
  double delta0_mm = 0, max_height_mm = 0, min_height_mm = 0;
  std::vector<ReliefBox> boxes;
  std::vector<Vec3d> box_top;  // I per box, canvas frame
  GLuint textures[4] = {0, 0, 0, 0};
  GLuint filtered[kShadingChannels] = {};  // shading_pyramid.h's channels, levels 1.. (atlas)
  std::vector<int> level_rows;             // each level's first row in the atlases
  // Mesh, built on first use (decimation can take seconds).
  MeshOptions mesh_options;
  HeightField field;  // kept for the mesh only until it is built
  bool mesh_built = false;
  GLuint mesh_vao = 0, mesh_vbo = 0, mesh_ibo = 0;
  size_t mesh_triangles = 0;
  // A streamed painting (AddStreamedPainting): its resident tiles' textures instead of the above.
  struct Tile {
    GLuint textures[4] = {0, 0, 0, 0};
    int x0 = 0, y0 = 0, width = 0, height = 0;  // the textures (GpuTile)
    int own_x0 = 0, own_y0 = 0, own_width = 0, own_height = 0;
    double pitch_mm = 0;
    float min_height_mm = 0, max_height_mm = 0;
  };
  std::unique_ptr<PyramidStream> stream;
  std::map<TileKey, Tile> tiles;
};

void DeleteTiles(Painting& p) {
  for (auto& [key, tile] : p.tiles) glDeleteTextures(4, tile.textures);
  p.tiles.clear();
}

// This frame's evictions and uploads of a streamed painting.
void ApplyStreamFrame(Painting& p, StreamFrame& frame) {
  for (const TileKey& key : frame.evict) {
    auto it = p.tiles.find(key);
    if (it == p.tiles.end()) continue;
    glDeleteTextures(4, it->second.textures);
    p.tiles.erase(it);
  }
  for (GpuTile& g : frame.upload) {
    Painting::Tile t;
    t.x0 = g.x0;
    t.y0 = g.y0;
    t.width = g.width;
    t.height = g.height;
    t.own_x0 = g.own_x0;
    t.own_y0 = g.own_y0;
    t.own_width = g.own_width;
    t.own_height = g.own_height;
    t.pitch_mm = g.pitch_mm;
    t.min_height_mm = g.min_height_mm;
    t.max_height_mm = g.max_height_mm;
    // Half floats: a pack holds its values as half (or fewer bits), so nothing is lost.
    for (int k = 0; k < 4; ++k)
      t.textures[k] = MakeTexture(g.width, g.height, g.rgba[k], k == 0, GL_RGBA16F);
    p.tiles[g.key] = t;
  }
  frame.upload.clear();
}

}  // namespace

const char* ToString(Technique t) {
  switch (t) {
    case Technique::kMesh:
      return "mesh";
    case Technique::kReliefEverywhere:
      return "relief";
    case Technique::kBump:
      return "bump";
    case Technique::kHybrid:
      return "hybrid";
    case Technique::kHybridAdaptive:
      return "adaptive";
    case Technique::kScreenSpaceError:
      return "screen-error";
  }
  return "?";
}

Result<Technique> ParseTechnique(std::string_view name) {
  for (Technique t : kAllTechniques)
    if (name == ToString(t)) return t;
  return Error{"unknown technique '" + std::string(name) +
               "' (mesh, relief, bump, hybrid, adaptive, screen-error)"};
}

const char* ToString(ViewMode m) {
  switch (m) {
    case ViewMode::kRelit:
      return "relit";
    case ViewMode::kLight:
      return "light";
    case ViewMode::kSpecular:
      return "specular";
    case ViewMode::kNormals:
      return "normals";
    case ViewMode::kRaking:
      return "raking";
  }
  return "?";
}

Result<ViewMode> ParseViewMode(std::string_view name) {
  for (ViewMode m : kAllViewModes)
    if (name == ToString(m)) return m;
  return Error{"unknown view mode '" + std::string(name) +
               "' (relit, light, specular, normals, raking)"};
}

Vec3d LightDirectionFromAngles(double azimuth_deg, double elevation_deg) {
  const double a = azimuth_deg * kPi / 180, e = elevation_deg * kPi / 180;
  return Vec3d(std::cos(e) * std::cos(a), std::cos(e) * std::sin(a), std::sin(e));
}

Vec3d HemisphereLightDirection(double x, double y) {
  if (!std::isfinite(x) || !std::isfinite(y)) return Vec3d::UnitZ();
  const double r = std::hypot(x, y);
  const double rim = std::cos(kMinLightElevationDeg * kPi / 180);
  if (r > rim) return LightDirectionFromAngles(std::atan2(y, x) * 180 / kPi, kMinLightElevationDeg);
  return Vec3d(x, y, std::sqrt(std::max(0.0, 1 - r * r))).normalized();
}

Status RenderOptions::Validate() const {
  auto finite = [](double v) { return std::isfinite(v); };
  if (!light_direction.allFinite() || std::abs(light_direction.norm() - 1) > 1e-6 ||
      light_direction.z() <= 0)
    return Error{
        "light_direction must be a unit vector with z > 0 (towards the light, canvas "
        "frame)"};
  if (!finite(light_irradiance) || light_irradiance < 0)
    return Error{"light_irradiance must be >= 0, got " + FormatNumber(light_irradiance)};
  if (!finite(raking_elevation_deg) || raking_elevation_deg <= 0 || raking_elevation_deg > 90)
    return Error{"raking_elevation_deg must be in (0, 90], got " +
                 FormatNumber(raking_elevation_deg)};
  if (!finite(raking_azimuth_deg))
    return Error{"raking_azimuth_deg must be finite, got " + FormatNumber(raking_azimuth_deg)};
  if (!finite(specular_diffuse) || specular_diffuse < 0 || !finite(specular_gain) ||
      specular_gain < 0)
    return Error{"specular_diffuse and specular_gain must be >= 0, got " +
                 FormatNumber(specular_diffuse) + ", " + FormatNumber(specular_gain)};
  if (!finite(specular_sharpen) || specular_sharpen < 1)
    return Error{"specular_sharpen must be >= 1, got " + FormatNumber(specular_sharpen)};
  if (!finite(k) || k <= 0) return Error{"k must be finite and > 0, got " + FormatNumber(k)};
  if (!finite(eps_min) || !finite(eps_max) || eps_min < 0 || eps_max <= eps_min)
    return Error{"need 0 <= eps_min < eps_max, got " + FormatNumber(eps_min) + ", " +
                 FormatNumber(eps_max)};
  if (filter_max_samples < 1 || filter_max_samples > 64)
    return Error{"filter_max_samples must be in [1, 64], got " +
                 std::to_string(filter_max_samples)};
  if (!finite(max_error_px) || max_error_px <= 0)
    return Error{"max_error_px must be > 0, got " + FormatNumber(max_error_px)};
  if (!finite(linear_step_texels) || linear_step_texels <= 0)
    return Error{"linear_step_texels must be > 0, got " + FormatNumber(linear_step_texels)};
  if (min_linear_steps < 1 || max_linear_steps < min_linear_steps || max_linear_steps > 4096)
    return Error{"need 1 <= min_linear_steps <= max_linear_steps <= 4096, got " +
                 std::to_string(min_linear_steps) + ", " + std::to_string(max_linear_steps)};
  if (binary_steps < 0 || binary_steps > 32)
    return Error{"binary_steps must be in [0, 32], got " + std::to_string(binary_steps)};
  if (bump_parallax_iterations < 0 || bump_parallax_iterations > 32)
    return Error{"bump_parallax_iterations must be in [0, 32], got " +
                 std::to_string(bump_parallax_iterations)};
  if (bump_min_steps < 1 || bump_min_steps > max_linear_steps)
    return Error{"need 1 <= bump_min_steps <= max_linear_steps, got " +
                 std::to_string(bump_min_steps)};
  if (!finite(bump_search_min_texels) || bump_search_min_texels < 0)
    return Error{"bump_search_min_texels must be >= 0, got " +
                 FormatNumber(bump_search_min_texels)};
  if (bump_binary_steps < 0 || bump_binary_steps > 32)
    return Error{"bump_binary_steps must be in [0, 32], got " + std::to_string(bump_binary_steps)};
  if (!finite(exposure) || exposure <= 0 || !finite(style_tile_px) || style_tile_px <= 0 ||
      !finite(hatching_tile_px) || hatching_tile_px <= 0)
    return Error{"exposure, style_tile_px and hatching_tile_px must be > 0, got " +
                 FormatNumber(exposure) + ", " + FormatNumber(style_tile_px) + ", " +
                 FormatNumber(hatching_tile_px)};
  if (!finite(stroke_spacing_px) || stroke_spacing_px < 2 || stroke_spacing_px > 200 ||
      !finite(stroke_fidelity) || stroke_fidelity <= 0)
    return Error{"stroke_spacing_px must be in [2, 200] and stroke_fidelity > 0, got " +
                 FormatNumber(stroke_spacing_px) + ", " + FormatNumber(stroke_fidelity)};
  if (!finite(ambient) || ambient < 0)
    return Error{"ambient must be >= 0, got " + FormatNumber(ambient)};
  return Status::Ok();
}

struct Renderer::Impl {
  GLuint plane_program = 0, box_program = 0, mesh_program = 0, scene_program = 0;
  // The painting programs with the prefiltered reflectance compiled in (DIGITIZE_FILTER).
  GLuint plane_filtered = 0, box_filtered = 0, mesh_filtered = 0;
  GLuint style_program = 0, stroke_program = 0;
  GLuint stroke_vao = 0, stroke_vbo = 0;
  std::vector<StrokeFace> room_faces;  // the room's boxes, for the painterly strokes
  // The styles' inputs: the realistic render (colour + depth textures), made on first use, and
  // their textures (the noise cube, the tonal art map), built on first use.
  GLuint style_fbo = 0, style_colour = 0, style_depth = 0;
  int style_w = 0, style_h = 0;
  GLuint solid_texture = 0, tam_texture = 0;
  std::vector<float> tam_ink;
  GLuint empty_vao = 0;
  GLuint cube_vbo = 0, edge_vbo = 0;
  GLuint box_vao = 0, box_instances = 0;      // relief boxes
  GLuint scene_vao = 0, scene_instances = 0;  // room
  GLuint edge_vao = 0, edge_instances = 0;    // box outlines
  size_t scene_count = 0;
  std::vector<SpotCone> spots;
  double room_ambient = 0;
  std::vector<Painting> paintings;
  // Offscreen target.
  GLuint fbo = 0, colour = 0, depth = 0;
  int fbo_w = 0, fbo_h = 0;

  ~Impl() {
    for (Painting& p : paintings) {
      DeleteTiles(p);
      glDeleteTextures(4, p.textures);
      glDeleteTextures(kShadingChannels, p.filtered);
      if (p.mesh_built) {
        glDeleteVertexArrays(1, &p.mesh_vao);
        glDeleteBuffers(1, &p.mesh_vbo);
        glDeleteBuffers(1, &p.mesh_ibo);
      }
    }
    for (GLuint prog : {plane_program, box_program, mesh_program, scene_program, style_program,
                        stroke_program, plane_filtered, box_filtered, mesh_filtered})
      if (prog) glDeleteProgram(prog);
    if (stroke_vao) glDeleteVertexArrays(1, &stroke_vao);
    if (stroke_vbo) glDeleteBuffers(1, &stroke_vbo);
    const GLuint style_textures[] = {style_colour, style_depth, solid_texture, tam_texture};
    glDeleteTextures(4, style_textures);
    if (style_fbo) glDeleteFramebuffers(1, &style_fbo);
    const GLuint vaos[] = {empty_vao, box_vao, scene_vao, edge_vao};
    glDeleteVertexArrays(4, vaos);
    const GLuint bufs[] = {cube_vbo, edge_vbo, box_instances, scene_instances, edge_instances};
    glDeleteBuffers(5, bufs);
    DeleteTarget();
  }
  // A streamed painting: this frame's tiles (PyramidStream::Frame), uploaded and evicted first,
  // each drawn as the bump program's slab over its own rectangle, from its lowest to its highest
  // texel (the relief searched everywhere: a tile has no boxes), with its level's textures (the
  // pack's prefiltered levels). No shadows: a march would stop at the tile's edge.
  template <typename SetCommon>
  void DrawStreamed(Painting& p, const ViewCamera& camera, const RenderOptions& options,
                    const SetCommon& set_common, FrameStats& stats) {
    StreamFrame frame = p.stream->Frame(camera, p.world_from_canvas);
    stats.tiles_uploaded += int(frame.upload.size());
    ApplyStreamFrame(p, frame);
    stats.tiles_needed += frame.needed;
    stats.tiles_missing += frame.missing;
    stats.tiles_loading += frame.loading;
    stats.stream_bytes += frame.resident_bytes;
    for (std::string& e : frame.errors) stats.stream_errors.push_back(std::move(e));
    // With filter_reflectance, a pixel that covers more than a texel of the tile's level shades
    // several points of that level over its footprint (the filter over one level: u_levels 1).
    const GLuint prog = options.filter_reflectance ? plane_filtered : plane_program;
    set_common(prog);
    auto uniform = [&](const char* name) { return glGetUniformLocation(prog, name); };
    glProgramUniform1i(prog, uniform("u_levels"), 1);
    glProgramUniform1i(prog, uniform("u_shadows"), 0);
    glProgramUniform1i(prog, uniform("u_streamed"), 1);
    glProgramUniform1i(prog, uniform("u_parallax_iterations"), options.bump_parallax_iterations);
    glProgramUniform1i(prog, uniform("u_slab_search"), 1);
    glProgramUniform1f(prog, uniform("u_step_texels"), float(options.linear_step_texels));
    glProgramUniform1f(prog, uniform("u_search_min_texels"), float(options.bump_search_min_texels));
    glProgramUniform1i(prog, uniform("u_min_steps"), options.bump_min_steps);
    glProgramUniform1i(prog, uniform("u_max_steps"), options.max_linear_steps);
    glProgramUniform1i(prog, uniform("u_binary_steps"), options.bump_binary_steps);
    glBindVertexArray(box_vao);
    glEnable(GL_CULL_FACE);
    glCullFace(GL_BACK);
    for (const TileKey& key : frame.draw) {
      auto it = p.tiles.find(key);
      if (it == p.tiles.end()) continue;
      const Painting::Tile& t = it->second;
      for (int k = 0; k < 4; ++k) glBindTextureUnit(k, t.textures[k]);
      glProgramUniform2i(prog, uniform("u_texels"), t.width, t.height);
      glProgramUniform1f(prog, uniform("u_pitch_mm"), float(t.pitch_mm));
      glProgramUniform2f(prog, uniform("u_tile_origin"), float(t.x0), float(t.y0));
      const float x0 = float(t.own_x0 * t.pitch_mm);
      const float x1 = float(std::min((t.own_x0 + t.own_width) * t.pitch_mm, p.width_mm));
      const float y1 = float(p.height_mm - t.own_y0 * t.pitch_mm);
      const float y0 = float(std::max(0.0, p.height_mm - (t.own_y0 + t.own_height) * t.pitch_mm));
      const Vec3f lo(x0, y0, t.min_height_mm - 1e-3f), hi(x1, y1, t.max_height_mm + 1e-3f);
      glProgramUniform3fv(prog, uniform("u_slab_min"), 1, lo.data());
      glProgramUniform3fv(prog, uniform("u_slab_max"), 1, hi.data());
      glDrawArrays(GL_TRIANGLES, 0, 36);
      ++stats.tiles_drawn;
    }
    glDisable(GL_CULL_FACE);
    glProgramUniform1i(prog, uniform("u_streamed"), 0);
  }

  void DeleteTarget() {
    if (fbo) glDeleteFramebuffers(1, &fbo);
    if (colour) glDeleteTextures(1, &colour);
    if (depth) glDeleteRenderbuffers(1, &depth);
    fbo = colour = depth = 0;
  }
  void EnsureTarget(int w, int h) {
    if (fbo && fbo_w == w && fbo_h == h) return;
    DeleteTarget();
    glCreateFramebuffers(1, &fbo);
    glCreateTextures(GL_TEXTURE_2D, 1, &colour);
    glTextureStorage2D(colour, 1, GL_RGBA32F, w, h);
    glCreateRenderbuffers(1, &depth);
    glNamedRenderbufferStorage(depth, GL_DEPTH_COMPONENT32F, w, h);
    glNamedFramebufferTexture(fbo, GL_COLOR_ATTACHMENT0, colour, 0);
    glNamedFramebufferRenderbuffer(fbo, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, depth);
    DIGITIZE_CHECK(glCheckNamedFramebufferStatus(fbo, GL_FRAMEBUFFER) == GL_FRAMEBUFFER_COMPLETE,
                   "viewer: the float framebuffer is incomplete");
    fbo_w = w;
    fbo_h = h;
  }

  void EnsureStyleTarget(int w, int h) {
    if (style_fbo && style_w == w && style_h == h) return;
    if (style_fbo) {
      glDeleteFramebuffers(1, &style_fbo);
      const GLuint t[] = {style_colour, style_depth};
      glDeleteTextures(2, t);
    }
    glCreateFramebuffers(1, &style_fbo);
    glCreateTextures(GL_TEXTURE_2D, 1, &style_colour);
    glTextureStorage2D(style_colour, 1, GL_RGBA32F, w, h);
    glCreateTextures(GL_TEXTURE_2D, 1, &style_depth);
    glTextureStorage2D(style_depth, 1, GL_DEPTH_COMPONENT32F, w, h);
    for (GLuint t : {style_colour, style_depth}) {
      // Bilinear colour for the wobbled lookups; clamped so the edges repeat the border.
      glTextureParameteri(t, GL_TEXTURE_MIN_FILTER, t == style_colour ? GL_LINEAR : GL_NEAREST);
      glTextureParameteri(t, GL_TEXTURE_MAG_FILTER, t == style_colour ? GL_LINEAR : GL_NEAREST);
      glTextureParameteri(t, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
      glTextureParameteri(t, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    }
    glNamedFramebufferTexture(style_fbo, GL_COLOR_ATTACHMENT0, style_colour, 0);
    glNamedFramebufferTexture(style_fbo, GL_DEPTH_ATTACHMENT, style_depth, 0);
    DIGITIZE_CHECK(
        glCheckNamedFramebufferStatus(style_fbo, GL_FRAMEBUFFER) == GL_FRAMEBUFFER_COMPLETE,
        "viewer: the style pass's framebuffer is incomplete");
    style_w = w;
    style_h = h;
  }
  void EnsureStyleTextures(Style style) {
    if (style != Style::kHatching && !solid_texture) {
      const SolidTexture solid = BuildSolidTexture();
      glCreateTextures(GL_TEXTURE_3D, 1, &solid_texture);
      const int n = solid.size;
      glTextureStorage3D(solid_texture, 1 + int(std::log2(n)), GL_RGBA8, n, n, n);
      glTextureSubImage3D(solid_texture, 0, 0, 0, 0, n, n, n, GL_RGBA, GL_UNSIGNED_BYTE,
                          solid.texels.data());
      glGenerateTextureMipmap(solid_texture);
      glTextureParameteri(solid_texture, GL_TEXTURE_MIN_FILTER, GL_LINEAR_MIPMAP_LINEAR);
      glTextureParameteri(solid_texture, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
      for (GLenum wrap : {GL_TEXTURE_WRAP_S, GL_TEXTURE_WRAP_T, GL_TEXTURE_WRAP_R})
        glTextureParameteri(solid_texture, wrap, GL_REPEAT);
    }
    if (style == Style::kHatching && !tam_texture) {
      const TonalArtMap tam = BuildTonalArtMap();
      const int size = tam.At(0, 0).width;
      glCreateTextures(GL_TEXTURE_2D_ARRAY, 1, &tam_texture);
      glTextureStorage3D(tam_texture, tam.levels, GL_R32F, size, size, tam.tones);
      for (int tone = 0; tone < tam.tones; ++tone)
        for (int level = 0; level < tam.levels; ++level) {
          const Grid<float>& g = tam.At(tone, level);
          glTextureSubImage3D(tam_texture, level, 0, 0, tone, g.width, g.height, 1, GL_RED,
                              GL_FLOAT, g.data.data());
        }
      // The map's own levels as the mip chain (not generated): what keeps the stroke width.
      glTextureParameteri(tam_texture, GL_TEXTURE_MIN_FILTER, GL_LINEAR_MIPMAP_LINEAR);
      glTextureParameteri(tam_texture, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
      glTextureParameteri(tam_texture, GL_TEXTURE_WRAP_S, GL_REPEAT);
      glTextureParameteri(tam_texture, GL_TEXTURE_WRAP_T, GL_REPEAT);
      tam_ink.assign(tam.target.begin(), tam.target.end());
    }
  }

  // A VAO reading (corner, normal) per vertex from `vbo` and `instance_floats` floats per
  // instance from `instances`: locations 2, 3 (vec3 min, max) and 4 (alpha or albedo).
  static GLuint MakeInstancedVao(GLuint vbo, GLuint instances, int last_components) {
    GLuint vao = 0;
    glCreateVertexArrays(1, &vao);
    glVertexArrayVertexBuffer(vao, 0, vbo, 0, 6 * sizeof(float));
    glVertexArrayVertexBuffer(vao, 1, instances, 0, (6 + last_components) * sizeof(float));
    glVertexArrayBindingDivisor(vao, 1, 1);
    auto attrib = [&](GLuint loc, GLuint binding, int comps, int offset_floats) {
      glEnableVertexArrayAttrib(vao, loc);
      glVertexArrayAttribFormat(vao, loc, comps, GL_FLOAT, GL_FALSE, offset_floats * sizeof(float));
      glVertexArrayAttribBinding(vao, loc, binding);
    };
    attrib(0, 0, 3, 0);
    attrib(1, 0, 3, 3);
    attrib(2, 1, 3, 0);
    attrib(3, 1, 3, 3);
    attrib(4, 1, last_components, 6);
    return vao;
  }

  void BuildMesh(Painting& p) {
    const HeightMesh mesh = BuildHeightMesh(p.field, p.mesh_options.max_triangles);
    glCreateBuffers(1, &p.mesh_vbo);
    glNamedBufferStorage(p.mesh_vbo, mesh.positions.size() * sizeof(float), mesh.positions.data(),
                         0);
    glCreateBuffers(1, &p.mesh_ibo);
    glNamedBufferStorage(p.mesh_ibo, mesh.indices.size() * sizeof(uint32_t), mesh.indices.data(),
                         0);
    glCreateVertexArrays(1, &p.mesh_vao);
    glVertexArrayVertexBuffer(p.mesh_vao, 0, p.mesh_vbo, 0, 3 * sizeof(float));
    glVertexArrayElementBuffer(p.mesh_vao, p.mesh_ibo);
    glEnableVertexArrayAttrib(p.mesh_vao, 0);
    glVertexArrayAttribFormat(p.mesh_vao, 0, 3, GL_FLOAT, GL_FALSE, 0);
    glVertexArrayAttribBinding(p.mesh_vao, 0, 0);
    p.mesh_triangles = mesh.triangles();
    p.mesh_built = true;
    p.field = HeightField{};  // no longer needed
  }
};

Renderer::Renderer() : impl_(std::make_unique<Impl>()) {}
Renderer::~Renderer() = default;

Result<std::unique_ptr<Renderer>> Renderer::Create() {
  if (epoxy_gl_version() < 45)
    return Error{"viewer: OpenGL 4.5 is needed, the current context has " +
                 std::to_string(epoxy_gl_version() / 10) + "." +
                 std::to_string(epoxy_gl_version() % 10)};
  std::unique_ptr<Renderer> r(new Renderer());
  Impl& m = *r->impl_;
  auto plane = Link(shaders::kPlaneVertex, shaders::kPlaneFragment, "bump plane");
  if (!plane) return plane.error();
  m.plane_program = *plane;
  auto box = Link(shaders::kBoxVertex, shaders::kBoxFragment, "relief box");
  if (!box) return box.error();
  m.box_program = *box;
  auto mesh = Link(shaders::kMeshVertex, shaders::kMeshFragment, "mesh");
  if (!mesh) return mesh.error();
  m.mesh_program = *mesh;
  auto plane_f = Link(shaders::kPlaneVertex, shaders::kPlaneFragment, "bump plane (filtered)",
                      "DIGITIZE_FILTER");
  if (!plane_f) return plane_f.error();
  m.plane_filtered = *plane_f;
  auto box_f =
      Link(shaders::kBoxVertex, shaders::kBoxFragment, "relief box (filtered)", "DIGITIZE_FILTER");
  if (!box_f) return box_f.error();
  m.box_filtered = *box_f;
  auto mesh_f =
      Link(shaders::kMeshVertex, shaders::kMeshFragment, "mesh (filtered)", "DIGITIZE_FILTER");
  if (!mesh_f) return mesh_f.error();
  m.mesh_filtered = *mesh_f;
  auto scene = Link(shaders::kSceneVertex, shaders::kSceneFragment, "scene");
  if (!scene) return scene.error();
  m.scene_program = *scene;
  auto style = Link(shaders::kStyleVertex, shaders::kStyleFragment, "style pass");
  if (!style) return style.error();
  m.style_program = *style;
  auto stroke = Link(shaders::kStrokeVertex, shaders::kStrokeFragment, "painterly strokes");
  if (!stroke) return stroke.error();
  m.stroke_program = *stroke;
  glCreateBuffers(1, &m.stroke_vbo);
  glCreateVertexArrays(1, &m.stroke_vao);
  glVertexArrayVertexBuffer(m.stroke_vao, 0, m.stroke_vbo, 0, 5 * sizeof(float));
  glVertexArrayBindingDivisor(m.stroke_vao, 0, 1);
  glEnableVertexArrayAttrib(m.stroke_vao, 0);
  glVertexArrayAttribFormat(m.stroke_vao, 0, 4, GL_FLOAT, GL_FALSE, 0);
  glVertexArrayAttribBinding(m.stroke_vao, 0, 0);
  glEnableVertexArrayAttrib(m.stroke_vao, 1);
  glVertexArrayAttribFormat(m.stroke_vao, 1, 1, GL_FLOAT, GL_FALSE, 4 * sizeof(float));
  glVertexArrayAttribBinding(m.stroke_vao, 1, 0);

  glCreateVertexArrays(1, &m.empty_vao);
  const std::vector<float> cube = CubeTriangles(), edges = CubeEdges();
  glCreateBuffers(1, &m.cube_vbo);
  glNamedBufferStorage(m.cube_vbo, cube.size() * sizeof(float), cube.data(), 0);
  glCreateBuffers(1, &m.edge_vbo);
  glNamedBufferStorage(m.edge_vbo, edges.size() * sizeof(float), edges.data(), 0);
  glCreateBuffers(1, &m.box_instances);
  glCreateBuffers(1, &m.scene_instances);
  glCreateBuffers(1, &m.edge_instances);
  m.box_vao = Impl::MakeInstancedVao(m.cube_vbo, m.box_instances, 1);
  m.scene_vao = Impl::MakeInstancedVao(m.cube_vbo, m.scene_instances, 4);
  m.edge_vao = Impl::MakeInstancedVao(m.edge_vbo, m.edge_instances, 3);
  if (GLenum e = glGetError(); e != GL_NO_ERROR)
    return Error{"viewer: OpenGL error " + std::to_string(e) + " while setting up"};
  return r;
}

int Renderer::painting_count() const { return int(impl_->paintings.size()); }

Status Renderer::CheckImageSize(int width, int height) const {
  const std::string image = "a " + Size(width, height) + " image";
  if (width < 1 || height < 1) return Error{image + " has no pixels"};
  GLint renderbuffer = 0, texture = 0, viewport[2] = {0, 0};
  glGetIntegerv(GL_MAX_RENDERBUFFER_SIZE, &renderbuffer);
  glGetIntegerv(GL_MAX_TEXTURE_SIZE, &texture);
  glGetIntegerv(GL_MAX_VIEWPORT_DIMS, viewport);
  const int limit = std::min({renderbuffer, texture, viewport[0], viewport[1]});
  if (width > limit || height > limit)
    return Error{image + " is larger than this OpenGL's maximum render target size " +
                 std::to_string(limit) + " (GL_MAX_RENDERBUFFER_SIZE " +
                 std::to_string(renderbuffer) + ", GL_MAX_TEXTURE_SIZE " + std::to_string(texture) +
                 ", GL_MAX_VIEWPORT_DIMS " + std::to_string(viewport[0]) + "x" +
                 std::to_string(viewport[1]) + ")"};
  if (int64_t{width} * height > kMaxRenderPixels)
    return Error{image + " has more than the " + std::to_string(kMaxRenderPixels) +
                 " pixels (8192 x 8192) the viewer renders at once"};
  return Status::Ok();
}

Result<int> Renderer::AddPainting(const Pack& pack, const std::string& name,
                                  const RigidTransform& world_from_canvas,
                                  const MeshOptions& mesh) {
  auto setup = PreparePainting(pack, name);
  if (!setup) return setup.error();
  const int w = pack.width(), h = pack.height();
  auto fail = [&](const std::string& what) { return Error{name + ": " + what}; };
  GLint max_size = 0;
  glGetIntegerv(GL_MAX_TEXTURE_SIZE, &max_size);
  if (w > max_size || h > max_size)
    return fail(Size(w, h) + " texels exceed the GL texture limit " + std::to_string(max_size));

  Painting p;
  p.name = name;
  p.world_from_canvas = world_from_canvas;
  p.texels_w = w;
  p.texels_h = h;
  p.pitch_mm = setup->pitch_mm;
  p.width_mm = setup->width_mm;
  p.height_mm = setup->height_mm;
  p.delta0_mm = setup->delta0_mm;
  p.min_height_mm = setup->min_height_mm;
  p.max_height_mm = setup->max_height_mm;
  p.boxes = std::move(setup->boxes);
  p.box_top = std::move(setup->box_tops);
  const size_t n = size_t(w) * h;
  std::vector<float> surface(4 * n), rho_d(4 * n), rho_s(4 * n), lobe(4 * n);
  const std::vector<size_t> source = ShadingSource(pack);
  for (size_t i = 0; i < n; ++i) {
    const float hh = pack.field.height_mm.data[i];
    const Vec3f& nn = pack.normals.data[i];
    const bool shaded = source[i] != SIZE_MAX;
    const size_t from = shaded ? source[i] : i;
    const Vec3f& d = pack.maps.rho_d.data[from];
    const Vec3f& s = pack.maps.rho_s.data[from];
    const auto& c = pack.maps.lobe.data[from];
    for (int k = 0; k < 3; ++k) {
      surface[4 * i + k] = nn[k];
      rho_d[4 * i + k] = d[k];
      rho_s[4 * i + k] = s[k];
    }
    rho_s[4 * i + 3] = float(static_cast<int>(pack.maps.model.data[from]));  // Shade's model
    surface[4 * i + 3] = hh;
    rho_d[4 * i + 3] = shaded ? 1.0f : 0.0f;
    for (int k = 0; k < 4; ++k) lobe[4 * i + k] = c[k];
  }
  p.textures[0] = MakeTexture(w, h, surface, true);
  p.textures[1] = MakeTexture(w, h, rho_d, false);
  p.textures[2] = MakeTexture(w, h, rho_s, false);
  p.textures[3] = MakeTexture(w, h, lobe, false);
  const ShadingPyramid pyramid = BuildShadingPyramid(pack, source);
  for (int c = 0; c < kShadingChannels; ++c)
    p.filtered[c] = MakeLevelAtlas(pyramid, c, &p.level_rows);
  p.mesh_options = mesh;
  p.field = pack.field;
  if (GLenum e = glGetError(); e != GL_NO_ERROR) {
    glDeleteTextures(4, p.textures);
    glDeleteTextures(kShadingChannels, p.filtered);
    return fail("OpenGL error " + std::to_string(e) + " while uploading the textures");
  }
  impl_->paintings.push_back(std::move(p));
  return int(impl_->paintings.size()) - 1;
}

Result<int> Renderer::AddStreamedPainting(std::unique_ptr<PyramidStream> stream,
                                          const std::string& name,
                                          const RigidTransform& world_from_canvas) {
  if (!stream) return Error{name + ": no stream"};
  const PackSummary& s = stream->summary();
  Painting p;
  p.name = name;
  p.world_from_canvas = world_from_canvas;
  p.texels_w = s.width;
  p.texels_h = s.height;
  p.pitch_mm = s.pitch_mm;
  p.width_mm = stream->width_mm();
  p.height_mm = stream->height_mm();
  p.delta0_mm = s.delta0_mm;
  p.max_height_mm = s.max_height_mm;
  p.stream = std::move(stream);
  impl_->paintings.push_back(std::move(p));
  return int(impl_->paintings.size()) - 1;
}

bool Renderer::SettleStreams(const ViewCamera& camera, double seconds) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  for (;;) {
    bool complete = true;
    for (Painting& p : impl_->paintings) {
      if (!p.stream) continue;
      StreamFrame frame = p.stream->Frame(camera, p.world_from_canvas);
      ApplyStreamFrame(p, frame);
      // Settled: every tile the view needs is resident, or what is still missing cannot come
      // (a tile that failed, a budget the drawn tiles fill).
      complete &= frame.missing == 0 || frame.loading == 0;
    }
    if (complete || std::chrono::steady_clock::now() > deadline) return complete;
    for (Painting& p : impl_->paintings)
      if (p.stream) p.stream->WaitForLoads(0.05);
  }
}

void Renderer::SetRoom(const Room& room) {
  std::vector<float> data;
  for (const SceneBox& b : room.boxes)
    data.insert(data.end(), {float(b.min_mm.x()), float(b.min_mm.y()), float(b.min_mm.z()),
                             float(b.max_mm.x()), float(b.max_mm.y()), float(b.max_mm.z()),
                             b.albedo.x(), b.albedo.y(), b.albedo.z(), float(int(b.surface))});
  glNamedBufferData(impl_->scene_instances, data.size() * sizeof(float), data.data(),
                    GL_STATIC_DRAW);
  impl_->scene_count = room.boxes.size();
  impl_->spots = room.spots;
  impl_->room_faces = BoxFaces(room.boxes);
  impl_->room_ambient = room.ambient;
}

std::vector<float> Renderer::BoxAlphas(int index, const ViewCamera& camera,
                                       const RenderOptions& options) const {
  const Painting& p = impl_->paintings.at(index);
  std::vector<float> alpha(p.boxes.size(), 0.0f);
  const Technique t = options.technique;
  if (t == Technique::kHybrid) std::fill(alpha.begin(), alpha.end(), 1.0f);
  if (t != Technique::kHybridAdaptive && t != Technique::kScreenSpaceError) return alpha;
  const RigidTransform canvas_from_world = p.world_from_canvas.Inverse();
  const Vec3d eye = canvas_from_world.Apply(camera.eye_mm);
  const Camera cam = ToCamera(camera);
  for (size_t i = 0; i < p.boxes.size(); ++i) {
    const Vec3d& top = p.box_top[i];
    double a = 1.0;
    if (t == Technique::kHybridAdaptive) {
      // r = |IB| / |CI| with B on the plane z = delta0 along C -> I: r = (h - delta0) / (Cz - h).
      if (eye.z() > top.z() + 1e-9) {
        const double r = (top.z() - p.delta0_mm) / (eye.z() - top.z());
        const double kr = options.k * r;
        a = kr < options.eps_min   ? 0.0
            : kr > options.eps_max ? 1.0
                                   : (kr - options.eps_min) / (options.eps_max - options.eps_min);
      }
    } else {
      // On-screen length of I's drop to the bump plane: how far the bump plane moves its texel.
      const Vec3d i_world = p.world_from_canvas.Apply(top);
      const Vec3d b_world =
          p.world_from_canvas.Apply(Vec3d(top.x(), top.y(), std::min(top.z(), p.delta0_mm)));
      if (!cam.InFront(i_world) && !cam.InFront(b_world)) {
        a = 0.0;
      } else if (cam.InFront(i_world) && cam.InFront(b_world)) {
        const double e = (cam.Project(i_world) - cam.Project(b_world)).norm();
        const double lo = 0.5 * options.max_error_px, hi = options.max_error_px;
        a = std::clamp((e - lo) / (hi - lo), 0.0, 1.0);
      }
    }
    alpha[i] = float(a);
  }
  return alpha;
}

FrameStats Renderer::Draw(const ViewCamera& camera, const std::vector<Light>& lights,
                          const RenderOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  Impl& m = *impl_;
  FrameStats stats;
  // A style draws the realistic frame into its own target first, then into the caller's.
  const bool styled = options.style != Style::kRealistic || options.display_output;
  GLint caller_fbo = 0;
  if (styled) {
    glGetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &caller_fbo);
    m.EnsureStyleTarget(camera.width, camera.height);
    m.EnsureStyleTextures(options.style);
    glBindFramebuffer(GL_FRAMEBUFFER, m.style_fbo);
  }
  glViewport(0, 0, camera.width, camera.height);
  glClearColor(0, 0, 0, 1);
  glClearDepth(1.0);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glDepthMask(GL_TRUE);
  glDisable(GL_BLEND);
  glDisable(GL_CULL_FACE);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  const Mat4d clip_from_world = ClipFromWorld(camera);
  const Mat3d world_from_camera = ToCamera(camera).camera_from_scan.rotation.transpose();

  std::vector<Light> scene_lights;
  for (const Light& l : lights)
    if (int(scene_lights.size()) < kMaxLights) scene_lights.push_back(l);
  // The mode's light replaces the scene's on the paintings; it is given in their canvas frame.
  std::vector<Light> mode_lights;
  if (options.mode != ViewMode::kRelit && options.mode != ViewMode::kNormals) {
    Light l;
    l.type = LightType::kDirectional;
    l.direction =
        options.mode == ViewMode::kRaking
            ? LightDirectionFromAngles(options.raking_azimuth_deg, options.raking_elevation_deg)
            : options.light_direction;
    l.irradiance = Vec3f::Constant(float(options.light_irradiance));
    mode_lights.push_back(l);
  }
  // Lights given in `frame_from_light` coordinates, moved into the program's frame: a point's
  // position (u_light_pos) and intensity, or a direction towards the light and its irradiance.
  auto set_lights = [&](GLuint prog, const std::vector<Light>& ls,
                        const RigidTransform& frame_from_light, bool points_only) {
    int n = 0;
    for (const Light& l : ls) {
      const bool directional = l.type == LightType::kDirectional;
      if (points_only && directional) continue;
      const Vec3f pos = (directional ? frame_from_light.ApplyToDirection(l.direction)
                                     : frame_from_light.Apply(l.position_mm))
                            .cast<float>();
      const Vec3f& power = directional ? l.irradiance : l.intensity;
      const std::string idx = "[" + std::to_string(n++) + "]";
      glProgramUniform3fv(prog, glGetUniformLocation(prog, ("u_light_pos" + idx).c_str()), 1,
                          pos.data());
      glProgramUniform3fv(prog, glGetUniformLocation(prog, ("u_light_int" + idx).c_str()), 1,
                          power.data());
      glProgramUniform1i(prog, glGetUniformLocation(prog, ("u_light_directional" + idx).c_str()),
                         directional ? 1 : 0);
    }
    glProgramUniform1i(prog, glGetUniformLocation(prog, "u_num_lights"), n);
  };
  auto set_mat = [](GLuint prog, const char* name, const Mat4d& mat) {
    const Mat4f f = mat.cast<float>();  // column-major, as GL expects
    glProgramUniformMatrix4fv(prog, glGetUniformLocation(prog, name), 1, GL_FALSE, f.data());
  };

  // The room.
  if (m.scene_count > 0) {
    const GLuint prog = m.scene_program;
    glUseProgram(prog);
    set_mat(prog, "u_clip_from_model", clip_from_world);
    const Vec3f eye = camera.eye_mm.cast<float>();
    glProgramUniform3fv(prog, glGetUniformLocation(prog, "u_eye"), 1, eye.data());
    glProgramUniform1f(prog, glGetUniformLocation(prog, "u_ambient"), float(m.room_ambient));
    glProgramUniform1i(prog, glGetUniformLocation(prog, "u_flat"), 0);
    set_lights(prog, scene_lights, RigidTransform{}, /*points_only=*/true);
    // Each point light's cone (SpotCone), in the order set_lights kept them.
    int n = 0;
    for (size_t i = 0; i < scene_lights.size(); ++i) {
      if (scene_lights[i].type == LightType::kDirectional) continue;
      SpotCone cone;
      if (i < m.spots.size()) cone = m.spots[i];
      const Vec3f axis = cone.axis.normalized().cast<float>();
      const std::string idx = "[" + std::to_string(n++) + "]";
      glProgramUniform4f(prog, glGetUniformLocation(prog, ("u_spot" + idx).c_str()), axis.x(),
                         axis.y(), axis.z(), 0.0f);
      glProgramUniform2f(prog, glGetUniformLocation(prog, ("u_spot_cos" + idx).c_str()),
                         float(std::cos(std::min(cone.inner_deg, 180.0) * kPi / 180)),
                         float(std::cos(std::min(cone.outer_deg, 180.0) * kPi / 180)));
    }
    glBindVertexArray(m.scene_vao);
    glDrawArraysInstanced(GL_TRIANGLES, 0, 36, GLsizei(m.scene_count));
  }

  const Technique t = options.technique;
  for (int pi = 0; pi < int(m.paintings.size()); ++pi) {
    Painting& p = m.paintings[pi];
    const RigidTransform canvas_from_world = p.world_from_canvas.Inverse();
    const Mat4d clip_from_canvas = clip_from_world * Homogeneous(p.world_from_canvas);
    const Vec3f eye = canvas_from_world.Apply(camera.eye_mm).cast<float>();
    for (int k = 0; k < 4; ++k) glBindTextureUnit(k, p.textures[k]);
    for (int k = 0; k < kShadingChannels; ++k) glBindTextureUnit(4 + k, p.filtered[k]);
    const Mat3d canvas_from_camera = canvas_from_world.rotation * world_from_camera;
    const Vec3f cam_right = canvas_from_camera.col(0).cast<float>();
    const Vec3f cam_down = canvas_from_camera.col(1).cast<float>();
    const Vec3f cam_forward = canvas_from_camera.col(2).cast<float>();
    auto set_common = [&](GLuint prog) {
      glUseProgram(prog);
      set_mat(prog, "u_clip_from_canvas", clip_from_canvas);
      glProgramUniform2f(prog, glGetUniformLocation(prog, "u_size_mm"), float(p.width_mm),
                         float(p.height_mm));
      glProgramUniform2i(prog, glGetUniformLocation(prog, "u_texels"), p.texels_w, p.texels_h);
      glProgramUniform1f(prog, glGetUniformLocation(prog, "u_pitch_mm"), float(p.pitch_mm));
      glProgramUniform3fv(prog, glGetUniformLocation(prog, "u_eye"), 1, eye.data());
      glProgramUniform1f(prog, glGetUniformLocation(prog, "u_ambient"), float(options.ambient));
      glProgramUniform1f(prog, glGetUniformLocation(prog, "u_delta0"), float(p.delta0_mm));
      glProgramUniform1i(prog, glGetUniformLocation(prog, "u_heatmap"),
                         options.alpha_heatmap ? 1 : 0);
      glProgramUniform1i(prog, glGetUniformLocation(prog, "u_shadows"), options.shadows ? 1 : 0);
      glProgramUniform1f(prog, glGetUniformLocation(prog, "u_max_height"),
                         float(p.max_height_mm) + 1e-3f);
      glProgramUniform1f(prog, glGetUniformLocation(prog, "u_shadow_step_texels"),
                         float(options.linear_step_texels));
      glProgramUniform1i(prog, glGetUniformLocation(prog, "u_shadow_max_steps"),
                         options.max_linear_steps);
      if (options.mode == ViewMode::kRelit)
        set_lights(prog, scene_lights, canvas_from_world, false);
      else
        set_lights(prog, mode_lights, RigidTransform{}, false);
      glProgramUniform1i(prog, glGetUniformLocation(prog, "u_mode"),
                         options.mode == ViewMode::kNormals    ? 2
                         : options.mode == ViewMode::kSpecular ? 1
                                                               : 0);
      glProgramUniform3f(prog, glGetUniformLocation(prog, "u_specular"),
                         float(options.specular_diffuse), float(options.specular_gain),
                         float(options.specular_sharpen));
      // ggx.h's clamps, so that the shader's GGX is its formula with its constants.
      glProgramUniform3f(prog, glGetUniformLocation(prog, "u_ggx_limits"), kGgxMinAlpha,
                         kGgxMaxAlpha, kGgxMinCos);
      glProgramUniform1f(prog, glGetUniformLocation(prog, "u_max_brdf"), kMaxBrdf);
      glProgramUniform1i(prog, glGetUniformLocation(prog, "u_filter_max_samples"),
                         options.filter_max_samples);
      glProgramUniform1f(
          prog, glGetUniformLocation(prog, "u_pixel_scale"),
          float(2 * std::tan(camera.fov_y_deg * kPi / 360) / std::max(camera.height, 1)));
      glProgramUniform3fv(prog, glGetUniformLocation(prog, "u_cam_right"), 1, cam_right.data());
      glProgramUniform3fv(prog, glGetUniformLocation(prog, "u_cam_down"), 1, cam_down.data());
      glProgramUniform3fv(prog, glGetUniformLocation(prog, "u_cam_forward"), 1, cam_forward.data());
      const int levels = std::min(int(p.level_rows.size()), kMaxShadingLevels);
      glProgramUniform1i(prog, glGetUniformLocation(prog, "u_levels"), levels);
      glProgramUniform1iv(prog, glGetUniformLocation(prog, "u_level_row"), levels,
                          p.level_rows.data());
    };
    // The filtered programs only where some pixel may cover more than a texel.
    const bool filter = !p.stream && options.filter_reflectance &&
                        MaxFootprintTexels(p.width_mm, p.height_mm, p.pitch_mm, p.max_height_mm,
                                           eye.cast<double>(), canvas_from_camera, camera) > 1.0;
    if (p.stream) {
      m.DrawStreamed(p, camera, options, set_common, stats);
      continue;
    }
    const GLuint plane_prog = filter ? m.plane_filtered : m.plane_program;
    const GLuint box_prog = filter ? m.box_filtered : m.box_program;
    const GLuint mesh_prog = filter ? m.mesh_filtered : m.mesh_program;
    stats.filtered_paintings += filter ? 1 : 0;
    stats.boxes_total += int(p.boxes.size());

    if (t == Technique::kMesh) {
      if (!p.mesh_built) m.BuildMesh(p);
      set_common(mesh_prog);
      glBindVertexArray(p.mesh_vao);
      glDrawElements(GL_TRIANGLES, GLsizei(p.mesh_triangles * 3), GL_UNSIGNED_INT, nullptr);
      stats.mesh_triangles += p.mesh_triangles;
      continue;
    }
    if (t != Technique::kReliefEverywhere) {
      set_common(plane_prog);
      glProgramUniform1i(plane_prog, glGetUniformLocation(plane_prog, "u_parallax_iterations"),
                         options.bump_parallax_iterations);
      const GLuint pp = plane_prog;
      glProgramUniform1i(pp, glGetUniformLocation(pp, "u_slab_search"),
                         options.bump_slab_search ? 1 : 0);
      glProgramUniform1f(pp, glGetUniformLocation(pp, "u_step_texels"),
                         float(options.linear_step_texels));
      glProgramUniform1f(pp, glGetUniformLocation(pp, "u_search_min_texels"),
                         float(options.bump_search_min_texels));
      glProgramUniform1i(pp, glGetUniformLocation(pp, "u_min_steps"), options.bump_min_steps);
      glProgramUniform1i(pp, glGetUniformLocation(pp, "u_max_steps"), options.max_linear_steps);
      glProgramUniform1i(pp, glGetUniformLocation(pp, "u_binary_steps"), options.bump_binary_steps);
      const Vec3f slab_min(0.0f, 0.0f, float(std::min(p.min_height_mm, p.delta0_mm)) - 1e-3f);
      const Vec3f slab_max(float(p.width_mm), float(p.height_mm), float(p.delta0_mm));
      glProgramUniform3fv(plane_prog, glGetUniformLocation(plane_prog, "u_slab_min"), 1,
                          slab_min.data());
      glProgramUniform3fv(plane_prog, glGetUniformLocation(plane_prog, "u_slab_max"), 1,
                          slab_max.data());
      glBindVertexArray(m.box_vao);  // the cube's corners; no instance attribute is read
      glEnable(GL_CULL_FACE);
      glCullFace(GL_BACK);
      glDrawArrays(GL_TRIANGLES, 0, 36);
      glDisable(GL_CULL_FACE);
    }
    // Relief boxes: (min, max, alpha) per drawn box.
    std::vector<float> inst;
    std::vector<float> outline;
    if (t == Technique::kReliefEverywhere) {
      // One box over the whole canvas, from its lowest to its highest point.
      inst = {0.0f,
              0.0f,
              float(p.min_height_mm) - 1e-3f,
              float(p.width_mm),
              float(p.height_mm),
              float(p.max_height_mm) + 1e-3f,
              1.0f};
      stats.boxes_drawn = 1;
    } else {
      const std::vector<float> alpha = BoxAlphas(pi, camera, options);
      for (size_t i = 0; i < p.boxes.size(); ++i) {
        if (alpha[i] <= 0.0f) continue;
        const ReliefBox& b = p.boxes[i];
        const float x0 = float(b.x0 * p.pitch_mm), x1 = float((b.x0 + b.width) * p.pitch_mm);
        const float y1 = float(p.height_mm - b.y0 * p.pitch_mm);
        const float y0 = float(p.height_mm - (b.y0 + b.height) * p.pitch_mm);
        // A hair above H so the top texel is inside, not on the lid.
        const float z0 = float(p.delta0_mm), z1 = float(p.max_height_mm) + 1e-3f;
        inst.insert(inst.end(), {x0, y0, z0, x1, y1, z1, alpha[i]});
        if (options.show_boxes) outline.insert(outline.end(), {x0, y0, z0, x1, y1, z1, 1, 1, 0});
        ++stats.boxes_drawn;
        if (alpha[i] < 1.0f) ++stats.boxes_blended;
      }
    }
    if (!inst.empty()) {
      set_common(box_prog);
      glProgramUniform1f(box_prog, glGetUniformLocation(box_prog, "u_step_texels"),
                         float(options.linear_step_texels));
      glProgramUniform1i(box_prog, glGetUniformLocation(box_prog, "u_min_steps"),
                         options.min_linear_steps);
      glProgramUniform1i(box_prog, glGetUniformLocation(box_prog, "u_max_steps"),
                         options.max_linear_steps);
      glProgramUniform1i(box_prog, glGetUniformLocation(box_prog, "u_binary_steps"),
                         options.binary_steps);
      glNamedBufferData(m.box_instances, inst.size() * sizeof(float), inst.data(), GL_STREAM_DRAW);
      glBindVertexArray(m.box_vao);
      glEnable(GL_CULL_FACE);
      glCullFace(GL_FRONT);  // back faces give the exit point
      glEnable(GL_BLEND);
      glBlendFunc(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA);
      glDrawArraysInstanced(GL_TRIANGLES, 0, 36, GLsizei(inst.size() / 7));
      glDisable(GL_BLEND);
      glDisable(GL_CULL_FACE);
    }
    if (!outline.empty()) {
      const GLuint prog = m.scene_program;
      glUseProgram(prog);
      set_mat(prog, "u_clip_from_model", clip_from_canvas);
      glProgramUniform1i(prog, glGetUniformLocation(prog, "u_flat"), 1);
      glNamedBufferData(m.edge_instances, outline.size() * sizeof(float), outline.data(),
                        GL_STREAM_DRAW);
      glBindVertexArray(m.edge_vao);
      glDrawArraysInstanced(GL_LINES, 0, 24, GLsizei(outline.size() / 9));
    }
  }
  if (styled) {
    glBindFramebuffer(GL_FRAMEBUFFER, GLuint(caller_fbo));
    glDisable(GL_DEPTH_TEST);
    glDisable(GL_BLEND);
    glDisable(GL_CULL_FACE);
    const GLuint prog = m.style_program;
    glUseProgram(prog);
    set_mat(prog, "u_world_from_clip", clip_from_world.inverse());
    const Vec3f eye = camera.eye_mm.cast<float>();
    const Vec3f fwd = (camera.target_mm - camera.eye_mm).normalized().cast<float>();
    glProgramUniform3fv(prog, glGetUniformLocation(prog, "u_eye"), 1, eye.data());
    glProgramUniform3fv(prog, glGetUniformLocation(prog, "u_forward"), 1, fwd.data());
    glProgramUniform1f(prog, glGetUniformLocation(prog, "u_exposure"), float(options.exposure));
    glProgramUniform1f(prog, glGetUniformLocation(prog, "u_knee"), float(kToneKnee));
    // Octave 1's cube spans style_tile_px on screen at z = 2^floor(log2 z): f_px u_tile = tile.
    const double f_px = 0.5 * camera.height / std::tan(0.5 * camera.fov_y_deg * kPi / 180);
    glProgramUniform1f(prog, glGetUniformLocation(prog, "u_tile"),
                       float(options.style_tile_px / f_px));
    glProgramUniform1f(prog, glGetUniformLocation(prog, "u_tam_tile"),
                       float(options.hatching_tile_px / f_px));
    if (!m.tam_ink.empty())
      glProgramUniform1fv(prog, glGetUniformLocation(prog, "u_tam_ink"), GLsizei(m.tam_ink.size()),
                          m.tam_ink.data());
    glProgramUniform1i(prog, glGetUniformLocation(prog, "u_style"), int(options.style));
    glProgramUniform1i(prog, glGetUniformLocation(prog, "u_display_out"),
                       options.display_output ? 1 : 0);
    glProgramUniform1i(prog, glGetUniformLocation(prog, "u_debug"),
                       options.style_debug_texture ? 1 : 0);
    glBindTextureUnit(0, m.style_colour);
    glBindTextureUnit(1, m.style_depth);
    glBindTextureUnit(2, m.solid_texture);
    glBindTextureUnit(3, m.tam_texture);
    glBindVertexArray(m.empty_vao);
    glDrawArrays(GL_TRIANGLES, 0, 3);
    if (options.style == Style::kPainterly) {
      // The strokes over it: the room's faces and each canvas (its bump plane), farthest first.
      std::vector<StrokeFace> faces = m.room_faces;
      for (const Painting& p : m.paintings) {
        StrokeFace f;
        f.origin = p.world_from_canvas.Apply(Vec3d(0, 0, p.delta0_mm));
        f.u = p.world_from_canvas.ApplyToDirection(Vec3d::UnitX());
        f.v = p.world_from_canvas.ApplyToDirection(Vec3d::UnitY());
        f.u_len = p.width_mm;
        f.v_len = p.height_mm;
        f.id = uint32_t(faces.size()) + 7919u;
        faces.push_back(f);
      }
      StrokeSelectOptions so;
      so.spacing_px = options.stroke_spacing_px;
      const std::vector<StrokeAnchor> anchors = SelectStrokeAnchors(faces, camera, so);
      std::vector<float> data;
      data.reserve(anchors.size() * 5);
      for (const StrokeAnchor& a : anchors)
        data.insert(data.end(), {a.position.x(), a.position.y(), a.position.z(), a.weight,
                                 float(a.id & 0xffffffu)});
      stats.strokes = anchors.size();
      if (!anchors.empty()) {
        glNamedBufferData(m.stroke_vbo, data.size() * sizeof(float), data.data(), GL_STREAM_DRAW);
        const GLuint sp = m.stroke_program;
        glUseProgram(sp);
        set_mat(sp, "u_clip_from_world", clip_from_world);
        glProgramUniform2f(sp, glGetUniformLocation(sp, "u_near_far"), float(camera.near_mm),
                           float(camera.far_mm));
        glProgramUniform1f(sp, glGetUniformLocation(sp, "u_spacing_px"),
                           float(options.stroke_spacing_px));
        glProgramUniform1f(sp, glGetUniformLocation(sp, "u_fidelity"),
                           float(options.stroke_fidelity));
        glProgramUniform1f(sp, glGetUniformLocation(sp, "u_exposure"), float(options.exposure));
        glProgramUniform1f(sp, glGetUniformLocation(sp, "u_knee"), float(kToneKnee));
        glProgramUniform1i(sp, glGetUniformLocation(sp, "u_display_out"),
                           options.display_output ? 1 : 0);
        glEnable(GL_BLEND);
        glBlendFunc(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA);
        glBindVertexArray(m.stroke_vao);
        glDrawArraysInstanced(GL_TRIANGLE_STRIP, 0, 4, GLsizei(anchors.size()));
        glDisable(GL_BLEND);
      }
    }
    glEnable(GL_DEPTH_TEST);
  }
  glBindVertexArray(0);
  stats.cpu_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return stats;
}

RenderedImage Renderer::Render(const ViewCamera& camera, const std::vector<Light>& lights,
                               const RenderOptions& options) {
  const Status valid_camera = camera.Validate();
  DIGITIZE_CHECK(valid_camera.ok(), "Renderer::Render: " + valid_camera.message());
  const Status valid = options.Validate();
  DIGITIZE_CHECK(valid.ok(), "Renderer::Render: " + valid.message());
  const Status fits = CheckImageSize(camera.width, camera.height);
  DIGITIZE_CHECK(fits.ok(), "Renderer::Render: " + fits.message());
  Impl& m = *impl_;
  m.EnsureTarget(camera.width, camera.height);
  glBindFramebuffer(GL_FRAMEBUFFER, m.fbo);
  const auto start = std::chrono::steady_clock::now();
  RenderedImage out;
  out.stats = Draw(camera, lights, options);
  glFinish();
  out.ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  std::vector<float> rgba(size_t(camera.width) * camera.height * 4);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, camera.width, camera.height, GL_RGBA, GL_FLOAT, rgba.data());
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  out.rgb = Grid<Vec3f>(camera.width, camera.height);
  for (int y = 0; y < camera.height; ++y) {
    const float* row =
        rgba.data() + size_t(camera.height - 1 - y) * camera.width * 4;  // GL: bottom first
    for (int x = 0; x < camera.width; ++x) {
      Vec3f c(row[4 * x], row[4 * x + 1], row[4 * x + 2]);
      DIGITIZE_CHECK(c.allFinite(), "Renderer::Render: non-finite radiance about to leave");
      out.rgb(x, y) = c;
    }
  }
  return out;
}

Vec3f DisplayColour(const Vec3f& linear, double exposure) {
  Vec3d c = linear.cast<double>() * exposure;
  for (int k = 0; k < 3; ++k)
    if (!std::isfinite(c[k]) || c[k] < 0) c[k] = 0;
  const double top = c.maxCoeff(), knee = kToneKnee;
  if (top > knee) {
    const double x = (top - knee) / (1 - knee);
    c *= (knee + (1 - knee) * x / (1 + x)) / top;
  }
  return c.cwiseMax(0.0).cwiseMin(1.0).cast<float>();
}

Grid<std::array<uint8_t, 3>> ToneMap(const Grid<Vec3f>& rgb, double exposure) {
  Grid<std::array<uint8_t, 3>> out(rgb.width, rgb.height);
  for (size_t i = 0; i < rgb.data.size(); ++i) {
    const Vec3f d = DisplayColour(rgb.data[i], exposure);
    for (int c = 0; c < 3; ++c) {
      const double v = d[c] <= 0.0031308 ? 12.92 * d[c] : 1.055 * std::pow(d[c], 1 / 2.4) - 0.055;
      out.data[i][c] = uint8_t(std::lround(std::clamp(v, 0.0, 1.0) * 255));
    }
  }
  return out;
}

}  // namespace digitize::viewer
