// Included by every painting program (plane.frag, box.frag, mesh.frag): texture layout, lookups
// and the shading (Lafortune or GGX per texel, and the view modes). renderer.h states what the
// programs compute.
layout(binding = 0) uniform sampler2D u_surface;  // nx, ny, nz, height (mm); bilinear, clamped
layout(binding = 1) uniform sampler2D u_rho_d;    // rgb, a = 1 inside the canvas; per texel
layout(binding = 2) uniform sampler2D u_rho_s;    // rgb (GGX: F0), a = model (0 Lafortune,
                                                  // 1 GGX; reflectance_maps.h); per texel
layout(binding = 3) uniform sampler2D u_lobe;     // cx, cy, cz, k (GGX: 0, 0, 1, alpha)
uniform vec2 u_size_mm;
uniform ivec2 u_texels;
uniform float u_pitch_mm;
uniform vec3 u_eye;            // canvas frame, mm
uniform int u_num_lights;
uniform vec3 u_light_pos[8];   // canvas frame, mm; directional: unit direction towards it
uniform vec3 u_light_int[8];   // RGB intensity: E = I / d^2; directional: irradiance E
uniform int u_light_directional[8];
uniform float u_ambient;
uniform mat4 u_clip_from_canvas;
uniform float u_delta0;
uniform int u_heatmap;
uniform int u_shadows;           // 1: relief self-shadowing
uniform float u_max_height;      // H, mm: above it nothing casts a shadow
uniform float u_shadow_step_texels;
uniform int u_shadow_max_steps;
uniform int u_mode;             // 0 shaded, 1 specular enhancement, 2 normals (renderer.h)
uniform vec3 u_specular;        // specular enhancement: diffuse scale, gain, sharpening
uniform vec3 u_ggx_limits;      // ggx.h: kGgxMinAlpha, kGgxMaxAlpha, kGgxMinCos
uniform float u_max_brdf;       // lafortune.h: kMaxBrdf
const float kPi = 3.14159265358979323846;

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

// ggx.h's GgxSpecular, term for term, for three channels' F0: F(v.h) D(n.h) G1(n.v) G1(n.l) /
// (4 n.v n.l) with n.v, n.l clamped at kGgxMinCos. v, l: tangent frame, z > 0.
vec3 GgxSpecular(vec3 f0, float alpha, vec3 v, vec3 l) {
  vec3 hv = v + l;
  float h_len2 = dot(hv, hv);
  if (!(h_len2 > 1e-12)) return vec3(0.0);
  float inv_h = 1.0 / sqrt(h_len2);
  float nh = hv.z * inv_h;
  float vh = max(0.0, v.x * hv.x * inv_h + v.y * hv.y * inv_h + v.z * hv.z * inv_h);
  float nv = max(u_ggx_limits.z, v.z);
  float nl = max(u_ggx_limits.z, l.z);
  float a2 = alpha * alpha;
  float d_den = (a2 - 1.0) * nh * nh + 1.0;
  float d = a2 / (kPi * d_den * d_den);
  float m = 1.0 - vh;
  float m2 = m * m;
  vec3 fresnel = f0 + (1.0 - f0) * (m2 * m2 * m);
  float g1v = 2.0 * nv / (nv + sqrt(a2 + (1.0 - a2) * nv * nv));
  float g1l = 2.0 * nl / (nl + sqrt(a2 + (1.0 - a2) * nl * nl));
  return fresnel * (d * g1v * g1l / (4.0 * nv * nl));
}

// Radiance leaving canvas point p (mm) towards the eye: relight.h's shading, per light; or the
// view mode's look of it (u_mode).
vec3 Shade(vec3 p) {
  vec2 uv = UvOf(p.xy);
  ivec2 t = clamp(ivec2(floor(uv * vec2(u_texels))), ivec2(0), u_texels - 1);
  vec4 rd = texelFetch(u_rho_d, t, 0);
  if (rd.a < 0.5) return vec3(0.0);
  vec3 n = textureLod(u_surface, uv, 0.0).xyz;
  float len = length(n);
  n = len > 1e-12 ? n / len : vec3(0.0, 0.0, 1.0);
  if (u_mode == 2) return n * 0.5 + 0.5;
  // Tangent frame as tangent_frame.h: x = canvas X made perpendicular to n.
  vec3 axis = vec3(1.0, 0.0, 0.0);
  vec3 nc = cross(n, axis);
  if (dot(nc, nc) < 1e-6) axis = vec3(0.0, 1.0, 0.0);
  vec3 tx = normalize(axis - n * dot(n, axis));
  vec3 ty = cross(n, tx);
  vec3 vw = normalize(u_eye - p);
  vec3 v = vec3(dot(tx, vw), dot(ty, vw), dot(n, vw));
  vec4 rs = texelFetch(u_rho_s, t, 0);
  vec4 c = texelFetch(u_lobe, t, 0);
  bool ggx = rs.a > 0.5;
  vec3 diffuse = rd.rgb;
  vec3 spec = rs.rgb;
  float lobe_k = c.w;
  if (u_mode == 1) {
    // Specular enhancement: grey, dimmed diffuse; the specular term brightened and sharpened.
    diffuse = vec3(dot(rd.rgb, vec3(0.2126, 0.7152, 0.0722)) * u_specular.x);
    if (ggx) {
      lobe_k = max(c.w / u_specular.z, u_ggx_limits.x);
      spec = rs.rgb * u_specular.y;
    } else {
      lobe_k = c.w * u_specular.z;
      spec = rs.rgb * (u_specular.y * (lobe_k + 2.0) / (c.w + 2.0));
    }
  }
  vec3 sum = u_ambient * diffuse;
  if (v.z <= 0.0) return sum;
  float alpha = clamp(lobe_k, u_ggx_limits.x, u_ggx_limits.y);
  for (int i = 0; i < u_num_lights; ++i) {
    vec3 lw;
    vec3 e;
    float dist;
    if (u_light_directional[i] != 0) {
      lw = u_light_pos[i];
      e = u_light_int[i];
      dist = 1e30;
    } else {
      vec3 d = u_light_pos[i] - p;
      float d2 = dot(d, d);
      lw = d * inversesqrt(d2);
      e = u_light_int[i] / d2;
      dist = sqrt(d2);
    }
    vec3 l = vec3(dot(tx, lw), dot(ty, lw), dot(n, lw));
    if (l.z <= 0.0) continue;
    if (u_shadows != 0 && Shadowed(p, lw, dist)) continue;
    vec3 f;
    if (ggx) {
      f = min(diffuse + GgxSpecular(spec, alpha, v, l), vec3(u_max_brdf));
    } else {
      float base = c.x * v.x * l.x + c.y * v.y * l.y + c.z * v.z * l.z;
      float lobe = base > 1e-20 ? exp(min(lobe_k * log(base), 80.0)) : 0.0;
      f = min(diffuse + spec * lobe, vec3(u_max_brdf));
    }
    sum += f * l.z * e;
  }
  return sum;
}
