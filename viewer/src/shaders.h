// GLSL 4.50 sources of the renderer (renderer.h states what they compute). Kept as strings so the
// library has no file to find at run time.
#pragma once

namespace digitize::viewer::shaders {

// Shared by every painting program: texture layout, lookups and the Lafortune shading.
inline constexpr const char* kCommon = R"(#version 450 core
layout(binding = 0) uniform sampler2D u_surface;  // nx, ny, nz, height (mm); bilinear, clamped
layout(binding = 1) uniform sampler2D u_rho_d;    // rgb, a = 1 inside the canvas; per texel
layout(binding = 2) uniform sampler2D u_rho_s;    // rgb; per texel
layout(binding = 3) uniform sampler2D u_lobe;     // cx, cy, cz, k; per texel
uniform vec2 u_size_mm;
uniform ivec2 u_texels;
uniform float u_pitch_mm;
uniform vec3 u_eye;            // canvas frame, mm
uniform int u_num_lights;
uniform vec3 u_light_pos[8];   // canvas frame, mm
uniform vec3 u_light_int[8];   // RGB intensity: E = I / d^2
uniform float u_ambient;
uniform mat4 u_clip_from_canvas;
uniform float u_delta0;
uniform int u_heatmap;
uniform int u_shadows;           // 1: relief self-shadowing
uniform float u_max_height;      // H, mm: above it nothing casts a shadow
uniform float u_shadow_step_texels;
uniform int u_shadow_max_steps;

// Canvas XY (mm) -> texture coordinates: texel (x, y) centre at X = (x + 0.5) pitch,
// Y = (h - y - 0.5) pitch (height_field.h), row 0 uploaded first.
vec2 UvOf(vec2 xy) { return vec2(xy.x / u_size_mm.x, 1.0 - xy.y / u_size_mm.y); }
float HeightAt(vec2 xy) { return textureLod(u_surface, UvOf(xy), 0.0).w; }

// Whether the relief blocks the light seen from surface point p along unit direction lw (canvas
// frame): a linear march through the height field until the ray rises above H or leaves the
// canvas (what RenderRelit's shadow rays find, up to the step).
bool Shadowed(vec3 p, vec3 lw, float light_dist) {
  if (lw.z <= 1e-4) return false;  // along or below the plane: such lights fail n.l anyway
  float t_top = min((u_max_height - p.z) / lw.z, light_dist);
  if (t_top <= 0.0) return false;
  float footprint = t_top * length(lw.xy) / u_pitch_mm;
  int n = clamp(int(ceil(footprint / u_shadow_step_texels)), 2, u_shadow_max_steps);
  float dt = t_top / float(n);
  for (int i = 1; i <= n; ++i) {
    vec3 q = p + lw * (dt * float(i));
    if (any(lessThan(q.xy, vec2(0.0))) || any(greaterThan(q.xy, u_size_mm))) return false;
    if (HeightAt(q.xy) > q.z + 1e-3) return true;
  }
  return false;
}

vec3 Heat(float a) { return clamp(vec3(2.0 * a, 2.0 - abs(4.0 * a - 2.0), 2.0 - 2.0 * a), 0.0, 1.0); }

// Radiance leaving canvas point p (mm) towards the eye: relight.h's shading, per light.
vec3 Shade(vec3 p) {
  vec2 uv = UvOf(p.xy);
  ivec2 t = clamp(ivec2(floor(uv * vec2(u_texels))), ivec2(0), u_texels - 1);
  vec4 rd = texelFetch(u_rho_d, t, 0);
  if (rd.a < 0.5) return vec3(0.0);
  vec3 n = textureLod(u_surface, uv, 0.0).xyz;
  float len = length(n);
  n = len > 1e-12 ? n / len : vec3(0.0, 0.0, 1.0);
  // Tangent frame as tangent_frame.h: x = canvas X made perpendicular to n.
  vec3 axis = vec3(1.0, 0.0, 0.0);
  vec3 nc = cross(n, axis);
  if (dot(nc, nc) < 1e-6) axis = vec3(0.0, 1.0, 0.0);
  vec3 tx = normalize(axis - n * dot(n, axis));
  vec3 ty = cross(n, tx);
  vec3 vw = normalize(u_eye - p);
  vec3 v = vec3(dot(tx, vw), dot(ty, vw), dot(n, vw));
  vec3 sum = u_ambient * rd.rgb;
  if (v.z <= 0.0) return sum;
  vec3 rs = texelFetch(u_rho_s, t, 0).rgb;
  vec4 c = texelFetch(u_lobe, t, 0);
  for (int i = 0; i < u_num_lights; ++i) {
    vec3 d = u_light_pos[i] - p;
    float d2 = dot(d, d);
    vec3 lw = d * inversesqrt(d2);
    vec3 l = vec3(dot(tx, lw), dot(ty, lw), dot(n, lw));
    if (l.z <= 0.0) continue;
    if (u_shadows != 0 && Shadowed(p, lw, sqrt(d2))) continue;
    float base = c.x * v.x * l.x + c.y * v.y * l.y + c.z * v.z * l.z;
    float lobe = base > 1e-20 ? exp(min(c.w * log(base), 80.0)) : 0.0;
    vec3 f = min(rd.rgb + rs * lobe, vec3(1e30));
    sum += f * l.z * u_light_int[i] / d2;
  }
  return sum;
}
)";

// The bump plane: the top of the canvas slab [0, W] x [0, H] x [lowest point, delta0], drawn
// with its sides (front faces only) so that at grazing views the canvas outline is where the true
// surface's is, not where the raised plane's edge would put it.
inline constexpr const char* kPlaneVertex = R"(#version 450 core
layout(location = 0) in vec3 a_corner;
uniform mat4 u_clip_from_canvas;
uniform vec3 u_slab_min;
uniform vec3 u_slab_max;
out vec3 v_pos;
void main() {
  v_pos = mix(u_slab_min, u_slab_max, a_corner);
  gl_Position = u_clip_from_canvas * vec4(v_pos, 1.0);
}
)";

inline constexpr const char* kPlaneFragment = R"(
in vec3 v_pos;
out vec4 o_color;
uniform vec3 u_slab_min;
uniform vec3 u_slab_max;
uniform int u_slab_search;          // 1: linear + binary search through the slab
uniform int u_parallax_iterations;  // fixed-point steps (0 = plain bump); with the search: where
                                    // the relief rises above the plane
uniform float u_step_texels;
uniform float u_search_min_texels;
uniform int u_min_steps;
uniform int u_max_steps;
uniform int u_binary_steps;
void main() {
  vec3 d = normalize(v_pos - u_eye);
  vec3 p = v_pos;
  if (u_slab_search != 0) {
    // Parallax occlusion mapping limited to the slab [lowest texel, delta0]: the first
    // intersection of the view ray with the height field between the slab's entry point (this
    // fragment) and its exit point, searched like a relief box. The number of steps follows the
    // ray's footprint across the slab (~ tan of the view angle): a few at face views, more at
    // grazing ones.
    vec3 safe = vec3(abs(d.x) > 1e-9 ? d.x : 1e-9, abs(d.y) > 1e-9 ? d.y : 1e-9,
                     abs(d.z) > 1e-9 ? d.z : 1e-9);
    vec3 t0 = (u_slab_min - u_eye) / safe, t1 = (u_slab_max - u_eye) / safe;
    vec3 tmax = max(t0, t1);
    float tfar = min(min(tmax.x, tmax.y), tmax.z);
    float tnear = dot(v_pos - u_eye, d);
    vec3 a = v_pos;
    vec3 b = u_eye + d * max(tfar, tnear);
    float footprint = length(b.xy - a.xy) / u_pitch_mm;
    int n = clamp(int(ceil(footprint / u_step_texels)), u_min_steps, u_max_steps);
    vec3 step = (b - a) / float(n);
    bool hit = a.z <= HeightAt(a.xy);
    int i = 0;
    if (hit || footprint <= u_search_min_texels) {
      // Relief above the plane here (a box's, not drawn), or a ray so steep that it crosses the
      // slab within a texel or so (face views): the fixed-point steps, as without the search
      // (they also move the point back towards the eye where the relief is above the plane).
      hit = true;
      for (int k = 0; k < u_parallax_iterations && d.z < -1e-6; ++k)
        p = v_pos + d * ((HeightAt(p.xy) - v_pos.z) / d.z);
    } else {
      for (i = 1; i <= n; ++i) {
        p = a + step * float(i);
        if (p.z <= HeightAt(p.xy)) { hit = true; break; }
      }
    }
    // Out through a side without meeting the surface: the ray sees no canvas (as the reference).
    if (!hit) discard;
    if (i > 0) {
      vec3 lo = p - step, hi = p;
      for (int j = 0; j < u_binary_steps; ++j) {
        vec3 mid = 0.5 * (lo + hi);
        if (mid.z <= HeightAt(mid.xy)) hi = mid; else lo = mid;
      }
      p = 0.5 * (lo + hi);
    }
  } else {
    // Parallax mapping (optional): slide along the view ray to where it meets the height there.
    for (int i = 0; i < u_parallax_iterations && d.z < -1e-6; ++i)
      p = v_pos + d * ((HeightAt(p.xy) - v_pos.z) / d.z);
  }
  // A ray that meets the surface beyond the canvas outline sees no canvas (as the reference).
  if (any(lessThan(p.xy, vec2(-1e-3))) || any(greaterThan(p.xy, u_size_mm + 1e-3))) discard;
  p.z = HeightAt(p.xy);  // view and light vectors corrected by the height (paper 5.4)
  vec3 col = Shade(p);
  if (u_heatmap != 0) col = vec3(0.15) * clamp(dot(col, vec3(0.3, 0.6, 0.1)) * 4.0, 0.0, 1.0);
  o_color = vec4(col, 1.0);
}
)";

// Relief boxes: instanced unit cube, back faces only (the exit point); the entry point comes
// from the box bounds (slab test), which also covers an eye inside the box.
inline constexpr const char* kBoxVertex = R"(#version 450 core
layout(location = 0) in vec3 a_corner;
layout(location = 2) in vec3 a_min;
layout(location = 3) in vec3 a_max;
layout(location = 4) in float a_alpha;
uniform mat4 u_clip_from_canvas;
out vec3 v_pos;
flat out vec3 v_min;
flat out vec3 v_max;
flat out float v_alpha;
void main() {
  v_pos = mix(a_min, a_max, a_corner);
  v_min = a_min;
  v_max = a_max;
  v_alpha = a_alpha;
  gl_Position = u_clip_from_canvas * vec4(v_pos, 1.0);
}
)";

inline constexpr const char* kBoxFragment = R"(
in vec3 v_pos;
flat in vec3 v_min;
flat in vec3 v_max;
flat in float v_alpha;
out vec4 o_color;
uniform float u_step_texels;
uniform int u_min_steps;
uniform int u_max_steps;
uniform int u_binary_steps;
void main() {
  vec3 d = normalize(v_pos - u_eye);
  vec3 safe = vec3(abs(d.x) > 1e-9 ? d.x : 1e-9, abs(d.y) > 1e-9 ? d.y : 1e-9,
                   abs(d.z) > 1e-9 ? d.z : 1e-9);
  vec3 t0 = (v_min - u_eye) / safe, t1 = (v_max - u_eye) / safe;
  vec3 tmin = min(t0, t1);
  float tnear = max(max(tmin.x, tmin.y), max(tmin.z, 0.0));
  float tfar = dot(v_pos - u_eye, d);
  if (tfar <= tnear) discard;
  vec3 a = u_eye + d * tnear;
  vec3 b = v_pos;
  float footprint = length(b.xy - a.xy) / u_pitch_mm;
  int n = clamp(int(ceil(footprint / u_step_texels)), u_min_steps, u_max_steps);
  vec3 step = (b - a) / float(n);
  vec3 p = a;
  bool hit = a.z <= HeightAt(a.xy);
  int i = 0;
  if (!hit) {
    for (i = 1; i <= n; ++i) {
      p = a + step * float(i);
      if (p.z <= HeightAt(p.xy)) { hit = true; break; }
    }
  }
  if (!hit) discard;
  if (i > 0) {
    vec3 lo = p - step, hi = p;
    for (int j = 0; j < u_binary_steps; ++j) {
      vec3 mid = 0.5 * (lo + hi);
      if (mid.z <= HeightAt(mid.xy)) hi = mid; else lo = mid;
    }
    p = 0.5 * (lo + hi);
  }
  vec4 c = u_clip_from_canvas * vec4(p, 1.0);
  gl_FragDepth = clamp(0.5 * c.z / c.w + 0.5, 0.0, 1.0);
  o_color = vec4(u_heatmap != 0 ? Heat(v_alpha) : Shade(p), v_alpha);
}
)";

inline constexpr const char* kMeshVertex = R"(#version 450 core
layout(location = 0) in vec3 a_pos;
uniform mat4 u_clip_from_canvas;
out vec3 v_pos;
void main() {
  v_pos = a_pos;
  gl_Position = u_clip_from_canvas * vec4(a_pos, 1.0);
}
)";

inline constexpr const char* kMeshFragment = R"(
in vec3 v_pos;
out vec4 o_color;
void main() { o_color = vec4(Shade(v_pos), 1.0); }
)";

// Room, frames and box outlines: world frame, Lambertian (or a flat colour for lines).
inline constexpr const char* kSceneVertex = R"(#version 450 core
layout(location = 0) in vec3 a_corner;
layout(location = 1) in vec3 a_normal;
layout(location = 2) in vec3 a_min;
layout(location = 3) in vec3 a_max;
layout(location = 4) in vec3 a_albedo;
uniform mat4 u_clip_from_model;
out vec3 v_pos;
out vec3 v_normal;
flat out vec3 v_albedo;
void main() {
  v_pos = mix(a_min, a_max, a_corner);
  v_normal = a_normal;
  v_albedo = a_albedo;
  gl_Position = u_clip_from_model * vec4(v_pos, 1.0);
}
)";

inline constexpr const char* kSceneFragment = R"(#version 450 core
in vec3 v_pos;
in vec3 v_normal;
flat in vec3 v_albedo;
out vec4 o_color;
uniform vec3 u_eye;
uniform int u_num_lights;
uniform vec3 u_light_pos[8];
uniform vec3 u_light_int[8];
uniform float u_ambient;
uniform int u_flat;  // 1: lines, plain albedo
void main() {
  if (u_flat != 0) { o_color = vec4(v_albedo, 1.0); return; }
  vec3 n = normalize(v_normal);
  if (dot(n, u_eye - v_pos) < 0.0) n = -n;  // walls are seen from inside
  vec3 sum = vec3(u_ambient);
  for (int i = 0; i < u_num_lights; ++i) {
    vec3 d = u_light_pos[i] - v_pos;
    float d2 = dot(d, d);
    sum += max(dot(n, d * inversesqrt(d2)), 0.0) * u_light_int[i] / d2;
  }
  o_color = vec4(v_albedo / 3.14159265 * sum, 1.0);
}
)";

}  // namespace digitize::viewer::shaders
