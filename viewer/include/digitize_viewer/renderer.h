// The real-time painting renderer (paper 001 section 5): the canvas as a plane at the bump level
// delta0 with bump mapping (5.1), the significant relief as the pack's boxes, each relief-mapped
// (5.2, after Policarpo et al. 2005: linear search, then binary refinement, along the view ray
// between the box's entry and exit points), blended per box by the paper's adaptive alpha (5.3)
// -- plus the comparison techniques of the paper's Table 1 and a screen-space-error rule.
//
// Layer: viewer (libdigitize only). GL types stay in renderer.cpp; an OpenGL 4.5 core context
// must be current on the calling thread for every call (HeadlessContext or a GLFW window).
//
// SHADING (shared by every technique, so transitions do not pop, and identical to RenderRelit so
// every image has a measurable error against the Embree reference):
//   - the shading point P is the technique's surface point in the canvas frame (mm);
//   - texel = nearest texel of P's continuous texel coordinates (per-texel reflectance and model:
//     Lafortune or GGX, evaluated as lafortune.h / ggx.h with the same clamps; texels
//     kOutside are black), normal = bilinear interpolation of the pack's normals at P,
//     renormalised, tangent frame as tangent_frame.h (cz = 1 gauge of the pack's lobes);
//   - v = towards the eye from P, l = towards each point light from P, E = I / |light - P|^2
//     (a directional light: l its direction, E its irradiance),
//     radiance = sum over lights of f_r(v, l) max(0, n.l) E  (0 where n.v <= 0), plus
//     `ambient` x rho_d (0 by default: the reference has no ambient term);
//   - with `shadows`, a light whose ray from P is blocked by the height field contributes 0;
//   - output: linear radiance (RGBA32F target), no tone mapping.
//   - with filter_reflectance (default), where a pixel's footprint on the canvas spans more than
//     a texel (far and grazing views: one texel per pixel aliases, and the image flickers as the
//     eye moves) the pixel shades the surface under it instead of one point: the footprint is
//     the pixel's square projected through P onto the plane z = P.z, an ellipse of axes a >= b;
//     a grid of at most filter_max_samples samples over it, each the reflectance of one level
//     of shading_pyramid.h's pyramid whose texel is about the sample's share of the footprint
//     (level 0: the texel itself, as above; a coarser level: the exact mean of the texels it
//     covers, each model's parameters averaged over its own texels, the normals' spread
//     widening the lobes -- Toksvig: s = (1 - |mean n|) / |mean n|, Lafortune k' = k / (1 + k s)
//     with rho_s x (k' + 2) / (k + 2) to keep its energy, GGX alpha'^2 = alpha^2 + s -- and the
//     diffuse cosine scaled by |mean n|), shaded as above and weighted by its projected area
//     (n.v) / n_z. From 1 to 2 texels across the result is blended into the point-sampled
//     radiance (no seam); below 1 texel the shading is the reference's exactly. The samples lie
//     on the plane through P, not where the pixel's other rays meet the relief: at grazing views
//     over tall relief a sample can see a glint those rays do not (tests/viewer_test.cpp).
// Techniques differ only in P:
//   kBump: P = (xy, h(xy)) where xy is where the view ray meets the plane z = delta0 (the view and
//     light vectors are "corrected by the height", paper 5.4), corrected along the ray: with
//     bump_slab_search (default) by the first intersection of the ray with the height field
//     inside the slab [lowest texel, delta0] (linear search + bisections, as a relief box) where
//     the ray crosses more than bump_search_min_texels of the slab, else (face views, or relief
//     above the plane at the entry point) by bump_parallax_iterations fixed-point steps
//     (parallax mapping; 0 without the search = the paper's bump). The plane is the top of that
//     slab, drawn with its sides, so the canvas outline stays where the true surface's is at
//     grazing views; a ray whose corrected point falls outside the canvas draws nothing (as the
//     reference);
//   relief (inside a box): P = the first intersection of the view ray with the bilinearly
//     interpolated height field between the box's entry and exit points (linear search with
//     steps of linear_step_texels texels along the ray's footprint, at most max_linear_steps,
//     then binary_steps bisections); a ray that leaves the box without a hit draws nothing (the
//     bump plane or another box shows there);
//   kMesh: P = the rasterised triangle mesh of the height field (one vertex per texel centre,
//     extended to the canvas outline like the tracer), optionally simplified (MeshOptions).
// Per box alpha (kHybridAdaptive): I = (u_max, v_max, h_max), B = the projection of I on the
// bump plane along the view ray, C = the eye, r = |IB| / |CI|; alpha = 0 if K r < eps_min, 1 if
// K r > eps_max, else (K r - eps_min) / (eps_max - eps_min) (a camera at or below h_max: alpha 1).
// kScreenSpaceError: e = the on-screen length (px) of the segment from I down to the bump plane
// (how far the bump plane displaces I's texel); alpha ramps from 0 at max_error_px / 2 to 1 at
// max_error_px. alpha 0: box not drawn; 1: opaque; between: blended over the bump plane.
#pragma once

#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "digitize/core.h"
#include "digitize/pack.h"
#include "digitize/photo_set.h"
#include "digitize_viewer/pyramid_stream.h"
#include "digitize_viewer/stylise.h"
#include "digitize_viewer/view.h"

namespace digitize::viewer {

enum class Technique {
  kMesh,              // the height field's triangle mesh (OpenMesh; full or simplified)
  kReliefEverywhere,  // one box over the whole canvas, from its lowest to its highest point
  kBump,              // the plane at delta0 only
  kHybrid,            // bump plane + every box relief-mapped, opaque
  kHybridAdaptive,    // bump plane + boxes by the paper's K / eps rule
  kScreenSpaceError,  // bump plane + boxes whose parallax error exceeds max_error_px
};
inline constexpr Technique kAllTechniques[] = {
    Technique::kMesh,   Technique::kReliefEverywhere, Technique::kBump,
    Technique::kHybrid, Technique::kHybridAdaptive,   Technique::kScreenSpaceError};
// "mesh", "relief", "bump", "hybrid", "adaptive", "screen-error"
const char* ToString(Technique t);
Result<Technique> ParseTechnique(std::string_view name);

// What a fragment shows of its surface point (a "look", the same for every technique). The RTI
// tools' views; each but kRelit lights the painting with one directional light given in the
// painting's canvas frame (x right, y up, z out of the canvas), so it is the same on every wall.
enum class ViewMode {
  kRelit,     // the scene's lights (point or directional), shaded as RenderRelit
  kLight,     // one directional light from light_direction (the window drags it with the mouse)
  kSpecular,  // specular enhancement under the kLight light: rho_d to grey x specular_diffuse,
              // the specular term brightened (specular_gain) and sharpened (specular_sharpen)
  kNormals,   // the interpolated unit normal as colour: rgb = n * 0.5 + 0.5 (canvas frame), unlit
  kRaking,    // one directional light raking_elevation_deg above the canvas plane from
              // raking_azimuth_deg (0 = from +x, 90 = from +y)
};
inline constexpr ViewMode kAllViewModes[] = {
    ViewMode::kRelit, ViewMode::kLight, ViewMode::kSpecular, ViewMode::kNormals, ViewMode::kRaking};
// "relit", "light", "specular", "normals", "raking"
const char* ToString(ViewMode m);
Result<ViewMode> ParseViewMode(std::string_view name);

// The kLight direction for a cursor at (x, y) in [-1, 1]^2 over the view (x right, y up): the
// point of the unit disc under the cursor lifted onto the upper hemisphere, (x, y, sqrt(1 - x^2 -
// y^2)); a cursor outside the disc gives the rim's direction at kMinLightElevationDeg. Unit, z > 0.
inline constexpr double kMinLightElevationDeg = 2.0;
Vec3d HemisphereLightDirection(double x, double y);
// Unit direction towards a light elevation_deg above the canvas plane from azimuth_deg (0 = +x).
Vec3d LightDirectionFromAngles(double azimuth_deg, double elevation_deg);

struct RenderOptions {
  Technique technique = Technique::kHybridAdaptive;
  ViewMode mode = ViewMode::kRelit;
  // kLight / kSpecular: unit direction towards the light, canvas frame, z > 0. Irradiance pi: a
  // white Lambertian texel facing the light reads radiance 1 (paper white, as StandardLight).
  Vec3d light_direction = Vec3d(-0.5, 0.5, 1.0).normalized();
  double light_irradiance = 3.14159265358979323846;
  // kRaking (degrees): 10 deg is the conservators' raking light; azimuth 180 = from the left.
  double raking_elevation_deg = 10.0;
  double raking_azimuth_deg = 180.0;
  // kSpecular: diffuse = grey(rho_d) x specular_diffuse (grey: Rec. 709 luminance); the specular
  // term x specular_gain, its lobe sharpened by specular_sharpen (Lafortune: k x s, rho_s scaled
  // by (s k + 2) / (k + 2) so the lobe keeps its energy before the gain; GGX: alpha / s, at least
  // kGgxMinAlpha, F0 x gain).
  double specular_diffuse = 0.3;
  double specular_gain = 2.0;
  double specular_sharpen = 2.0;
  // Adaptive rule (paper eq. 2). r is dimensionless (a ratio of lengths); with K = 1, eps_min =
  // 0.004 and eps_max = 0.008 a 1.75 mm-high impasto appears (alpha > 0) once the camera is
  // closer than ~44 cm above the bump plane and is fully relief-mapped below ~22 cm.
  double k = 1.0;
  double eps_min = 0.004, eps_max = 0.008;
  double max_error_px = 1.0;  // kScreenSpaceError: parallax error (px) at which a box is opaque
  // Relief mapping.
  double linear_step_texels = 1.0;  // linear-search step along the ray's footprint, texels
  int max_linear_steps = 256;       // cap per ray (a grazing ray over a whole canvas)
  int min_linear_steps = 16;        // floor per ray (a ray almost along the normal: with 4, steps
                                    // of H / 4 skipped the tips of glossy blobs, 15 dB at far-face)
  int binary_steps = 6;             // bisections after the linear search
  // The bump plane's texture lookup: fixed-point steps moving the plane point along the view
  // ray to where it meets the height field (parallax mapping). 0 = the paper's plain bump mapping
  // (texel under the plane point); 4 removes most of the plane's offset from the true canvas
  // (delta0 above it): framed face view 27 -> 52 dB against the reference (point-sampled,
  // docs/benchmarks.md).
  int bump_parallax_iterations = 4;
  // The bump plane's surface point by a search instead (default): the first intersection of the
  // view ray with the height field inside the slab [lowest texel, delta0] below the plane (steep
  // parallax / parallax occlusion mapping limited to that slab): steps of linear_step_texels
  // along the ray's footprint across the slab (so ~ tan of the view angle: few at face views), at
  // least bump_min_steps, at most max_linear_steps, then bump_binary_steps bisections. With the
  // paper's delta0 = 30 % of H the relief under the plane is what fixed-point steps cannot follow
  // at grazing views (docs/benchmarks.md). false: bump_parallax_iterations fixed-point steps.
  bool bump_slab_search = true;
  // Where the ray's footprint across the slab is at most this many texels (face views), the
  // fixed-point steps are exact enough and cheaper: the search is skipped there.
  double bump_search_min_texels = 1.0;
  int bump_min_steps = 2;
  int bump_binary_steps = 6;
  double ambient = 0;  // ambient radiance factor x rho_d (gallery look; 0 = none)
  // Prefiltered reflectance where a pixel covers more than a texel (see SHADING above); false:
  // one texel per pixel everywhere, as RenderRelit (aliases at far and grazing views).
  bool filter_reflectance = true;
  int filter_max_samples = 16;  // shading samples per pixel where it covers several texels, >= 1
  // Relief self-shadowing: per shading point and light, a march through the height field towards
  // the light (steps of linear_step_texels, at most max_linear_steps) until the ray rises above H.
  // Off by default, as in the paper; RenderRelit with shadows on is its reference.
  bool shadows = false;
  // Stylised looks (stylise.h): the realistic render redrawn by a screen pass.
  Style style = Style::kRealistic;
  // The output: false (default) linear radiance, which screenshots tone-map (ToneMap); true the
  // display value DisplayColour(radiance, exposure), for a framebuffer that encodes linear values
  // to sRGB on write (the window) -- so the window shows what a screenshot does.
  bool display_output = false;
  double exposure = 1.0;             // the display value the styles take their tone from
                                     // (DisplayColour); screenshots tone-map with the same
  double style_tile_px = 256;        // watercolor, binary, collage: the on-screen size of the solid
                                     // texture's first octave at the start of a zoom cycle
  double hatching_tile_px = 192;     // hatching: a tonal art map tile's on-screen size at the
                                     // start of a zoom cycle (half of it at the end)
  double stroke_spacing_px = 9;      // painterly: the strokes' spacing on screen
  double stroke_fidelity = 0.25;     // painterly: colour distance (display RGB) that ends a stroke
  bool style_debug_texture = false;  // the dynamic solid texture's pigment channel, grey
                                     // (what the infinite-zoom tests measure)
  // Debug views (the gallery's panel).
  bool alpha_heatmap = false;  // colour relief fragments by their box's alpha (blue 0 .. red 1),
                               // the bump plane dark grey
  bool show_boxes = false;     // draw the drawn boxes' edges (yellow)

  // Finite, k > 0, 0 <= eps_min < eps_max, max_error_px > 0, steps in range; light_direction
  // unit with z > 0, light_irradiance >= 0, raking elevation in (0, 90], specular_diffuse and
  // specular_gain >= 0, specular_sharpen >= 1, exposure, style_tile_px, hatching_tile_px,
  // stroke_spacing_px and stroke_fidelity > 0.
  Status Validate() const;
};

// Simplification of the height-field mesh (kMesh).
struct MeshOptions {
  size_t max_triangles = 0;  // 0 = full resolution (2 (w + 1) (h + 1) triangles); else the
                             // OpenMesh quadric decimater reduces the mesh to at most this many
};

struct FrameStats {
  int boxes_total = 0;        // boxes of the drawn paintings
  int boxes_drawn = 0;        // alpha > 0
  int boxes_blended = 0;      // 0 < alpha < 1
  size_t mesh_triangles = 0;  // kMesh: triangles drawn
  size_t strokes = 0;         // painterly: anchors selected (drawn unless hidden)
  int filtered_paintings =
      0;              // drawn with the prefiltered reflectance (a pixel may cover > 1 texel)
  double cpu_ms = 0;  // CPU time to issue the frame (GL is asynchronous: see the bench)
  // Streamed paintings (AddStreamedPainting), summed over them.
  int tiles_drawn = 0;
  int tiles_needed = 0;      // at the level the view needs
  int tiles_missing = 0;     // of them not resident yet: a coarser ancestor drawn instead
  int tiles_loading = 0;     // queued or being read
  int tiles_uploaded = 0;    // this frame
  int64_t stream_bytes = 0;  // resident tiles' texture memory
  std::vector<std::string> stream_errors;  // tiles that failed to read (each reported once)
};

struct RenderedImage {
  Grid<Vec3f> rgb;  // linear radiance, row 0 = top (as RenderRelit), never NaN/Inf (checked)
  FrameStats stats;
  double ms = 0;  // Draw + glFinish, steady clock
};

// How a room box shades (scene.frag): Lambertian with a plain albedo, the albedo patterned as
// floorboards (boards along world Y, each its own tint, with grain), or a lamp's lens that emits
// its albedo as radiance.
enum class SceneSurface { kPlain = 0, kFloorboards = 1, kEmissive = 2 };

// A wall, floor or frame of the gallery: an axis-aligned box in the world frame.
struct SceneBox {
  Vec3d min_mm = Vec3d::Zero(), max_mm = Vec3d::Zero();
  Vec3f albedo = Vec3f::Constant(0.5f);
  SceneSurface surface = SceneSurface::kPlain;
};

// A point light's cone on the room (walls, floor, frames): full strength within inner_deg of
// `axis`, none beyond outer_deg, smooth between. The paintings see the light without the cone:
// the gallery aims it so that the whole frame is within inner_deg.
struct SpotCone {
  Vec3d axis = -Vec3d::UnitZ();  // unit, from the light
  double inner_deg = 180, outer_deg = 180;
};

// What the room is made of and how it is lit besides Draw's lights.
struct Room {
  std::vector<SceneBox> boxes;
  std::vector<SpotCone> spots;  // spots[i] shapes Draw's lights[i]; a light without one is bare
  // Light bounced round the room, radiance = albedo x ambient x (0.75 + 0.25 n.z): surfaces
  // facing up (floor) a little brighter than walls, the ceiling's underside a little darker.
  double ambient = 0;
};

class Renderer {
 public:
  // Compiles the shaders. Errors: no OpenGL 4.5 context current, a shader that does not compile
  // (the GL log in the message).
  static Result<std::unique_ptr<Renderer>> Create();
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  // Uploads a pack (textures, boxes) placed in the world by world_from_canvas. Errors (`name`
  // says which pack): what PreparePainting refuses (painting_setup.h: fewer than 2 x 2 texels, a
  // pack that does not Validate), textures over the GL limit. Returns the painting's index.
  Result<int> AddPainting(const Pack& pack, const std::string& name,
                          const RigidTransform& world_from_canvas = {},
                          const MeshOptions& mesh = {});
  // Hangs a tiled pack streamed (pyramid_stream.h): no texel is uploaded now; each Draw uploads
  // the tiles the view needs (at most StreamOptions::max_uploads_per_frame a frame, within its
  // budget) and draws the resident ones, coarser ancestors where those are still loading. Tiles
  // are drawn with the bump program's slab over each tile (relief searched from the tile's lowest
  // to its highest texel; no relief boxes, no shadows, the levels' own prefiltering instead of
  // filter_reflectance), in every technique. Returns the painting's index.
  Result<int> AddStreamedPainting(std::unique_ptr<PyramidStream> stream, const std::string& name,
                                  const RigidTransform& world_from_canvas = {});
  // Loads and uploads (without drawing) until every streamed painting has the tiles `camera`
  // needs, or nothing more can come, at most `seconds`: for screenshots and tests. Whether it got
  // there.
  bool SettleStreams(const ViewCamera& camera, double seconds);
  int painting_count() const;
  void SetRoom(const Room& room);  // the room; empty = none

  // Draws everything into the currently bound framebuffer (viewport = camera size), clearing it
  // to black. Point and directional lights (world frame), at most kMaxLights; options.mode may
  // replace them on the paintings (ViewMode). The room is lit by the point lights.
  FrameStats Draw(const ViewCamera& camera, const std::vector<Light>& lights,
                  const RenderOptions& options);
  // Whether Render can produce a width x height image here: both sides at least 1 and within
  // this GL's limits (GL_MAX_RENDERBUFFER_SIZE, GL_MAX_TEXTURE_SIZE, GL_MAX_VIEWPORT_DIMS), and
  // at most kMaxRenderPixels (the float target, its read-back and the image take ~50 bytes a
  // pixel). The error says which limit, e.g. "a 100000x100000 image is larger than this
  // OpenGL's maximum render target size 16384".
  Status CheckImageSize(int width, int height) const;
  static constexpr int64_t kMaxRenderPixels = int64_t{1} << 26;  // 8192 x 8192: ~3.4 GB

  // Draws into an internal float framebuffer and reads it back. Throws InvariantError on invalid
  // options or camera, or an image size CheckImageSize refuses (the caller's code).
  RenderedImage Render(const ViewCamera& camera, const std::vector<Light>& lights,
                       const RenderOptions& options);

  // Per-box alpha of painting `index` for this camera and options (what Draw uses).
  std::vector<float> BoxAlphas(int index, const ViewCamera& camera,
                               const RenderOptions& options) const;

  static constexpr int kMaxLights = 8;

 private:
  Renderer();
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Linear radiance -> display value in [0, 1] (before the sRGB encoding). Exposure multiplies
// first; then a highlight shoulder on the largest channel M: up to kToneKnee it passes unchanged
// (the paintings' midtones stay as photographed), above it M' = k + (1 - k) x / (1 + x), x = (M -
// k) / (1 - k) (continuous with slope 1 at the knee, below 1 for every M, gentle enough to keep
// highlights apart: paper white reads 0.875, 2x paper white 0.95, 10x 0.99),
// the colour scaled by M' / M so it keeps its hue and saturation. Gold leaf under a picture light
// stays gold instead of clipping to white (a shoulder on luminance cannot: the only colour of
// luminance 1 is white). Non-finite or negative input reads 0.
inline constexpr double kToneKnee = 0.75;
Vec3f DisplayColour(const Vec3f& linear, double exposure = 1.0);
// DisplayColour -> 8-bit sRGB. For screenshots.
Grid<std::array<uint8_t, 3>> ToneMap(const Grid<Vec3f>& rgb, double exposure = 1.0);

}  // namespace digitize::viewer
