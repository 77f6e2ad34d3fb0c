// Included by every painting program (plane.frag, box.frag, mesh.frag): texture layout, lookups
// and the Lafortune shading. renderer.h states what the programs compute.
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
