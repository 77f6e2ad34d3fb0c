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
// Prefiltered reflectance: shading_pyramid.h's channels, its levels 1.. stacked in one texture
// each (level l's row 0 at u_level_row[l]; renderer.cpp's MakeLevelAtlas).
layout(binding = 4) uniform sampler2D u_f_diffuse;    // (w rho_d, w)
layout(binding = 5) uniform sampler2D u_f_lafortune;  // (w_l rho_s, w_l)
layout(binding = 6) uniform sampler2D u_f_lobe;       // w_l (cx, cy, cz, k)
layout(binding = 7) uniform sampler2D u_f_ggx;        // (w_g F0, w_g)
layout(binding = 8) uniform sampler2D u_f_normal;     // (w n, w_g alpha^2)
uniform int u_levels;              // the pyramid's levels, level 0 included
uniform int u_level_row[16];
uniform int u_filter_max_samples;  // shading samples per pixel, at most
uniform float u_pixel_scale;       // a pixel's size at unit depth: 2 tan(fov / 2) / height
uniform vec3 u_cam_right;          // the camera's axes, canvas frame (x right, y down, z ahead)
uniform vec3 u_cam_down;
uniform vec3 u_cam_forward;
const float kPi = 3.14159265358979323846;

// A streamed tile (pyramid_stream.h): the textures hold u_texels texels of a pyramid level from
// texel u_tile_origin of that level's grid, u_pitch_mm the level's texel; u_size_mm stays the
// canvas's.
uniform int u_streamed;
uniform vec2 u_tile_origin;

// Canvas XY (mm) -> texture coordinates: texel (x, y) centre at X = (x + 0.5) pitch,
// Y = (h - y - 0.5) pitch (height_field.h), row 0 uploaded first.
vec2 UvOf(vec2 xy) {
  if (u_streamed != 0)
    return (vec2(xy.x, u_size_mm.y - xy.y) / u_pitch_mm - u_tile_origin) / vec2(u_texels);
  return vec2(xy.x / u_size_mm.x, 1.0 - xy.y / u_size_mm.y);
}
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

// What the shading reads at a surface point: one texel's reflectance (the reference's), or the
// mean over a pixel's footprint, each model weighed by its share of the texels.
struct Surface {
  float coverage;   // shaded share (0: relit black)
  vec3 n;           // unit shading normal
  float cos_scale;  // the diffuse cosine's factor: |mean normal| (1 for one texel)
  vec3 rho_d;
  float w_laf;      // Lafortune share: rho_s, c = (cx, cy, cz, k)
  vec3 rho_s;
  vec4 c;
  float w_ggx;      // GGX share: F0, alpha
  vec3 f0;
  float alpha;
};

Surface PointSurface(vec2 xy) {
  Surface s;
  vec2 uv = UvOf(xy);
  ivec2 t = clamp(ivec2(floor(uv * vec2(u_texels))), ivec2(0), u_texels - 1);
  vec4 rd = texelFetch(u_rho_d, t, 0);
  s.coverage = rd.a < 0.5 ? 0.0 : 1.0;
  vec3 n = textureLod(u_surface, uv, 0.0).xyz;
  float len = length(n);
  s.n = len > 1e-12 ? n / len : vec3(0.0, 0.0, 1.0);
  s.cos_scale = 1.0;
  s.rho_d = rd.rgb;
  vec4 rs = texelFetch(u_rho_s, t, 0);
  vec4 c = texelFetch(u_lobe, t, 0);
  bool ggx = rs.a > 0.5;
  s.w_laf = ggx ? 0.0 : 1.0;
  s.w_ggx = ggx ? 1.0 : 0.0;
  s.rho_s = rs.rgb;
  s.c = c;
  s.f0 = rs.rgb;
  s.alpha = c.w;
  return s;
}

// Level `level` >= 1's texel under xy as a surface: the exact mean of the 2^level x 2^level
// texels it covers (the reference's reflectance is constant over a texel), each model's
// parameters averaged over its own texels; the normals' spread (1 - |mean n|) widens the lobes
// (Toksvig).
Surface LevelSurface(vec2 xy, int level) {
  Surface s;
  ivec2 size = max(u_texels >> level, ivec2(1));
  ivec2 t = clamp(ivec2(floor(UvOf(xy) * vec2(size))), ivec2(0), size - 1) +
            ivec2(0, u_level_row[level]);
  vec4 fd = texelFetch(u_f_diffuse, t, 0);
  s.coverage = clamp(fd.a, 0.0, 1.0);
  if (fd.a < 1e-4) {
    s.coverage = 0.0;
    return s;
  }
  vec4 fn = texelFetch(u_f_normal, t, 0);
  vec4 fl = texelFetch(u_f_lafortune, t, 0);
  vec4 fc = texelFetch(u_f_lobe, t, 0);
  vec4 fg = texelFetch(u_f_ggx, t, 0);
  vec3 mean_n = fn.xyz / fd.a;
  float len = length(mean_n);
  s.n = len > 1e-6 ? mean_n / len : vec3(0.0, 0.0, 1.0);
  len = clamp(len, 1e-3, 1.0);
  s.cos_scale = len;
  float spread = (1.0 - len) / len;
  s.rho_d = fd.rgb / fd.a;
  s.w_laf = clamp(fl.a / fd.a, 0.0, 1.0);
  s.w_ggx = clamp(fg.a / fd.a, 0.0, 1.0);
  s.rho_s = vec3(0.0);
  s.c = vec4(0.0, 0.0, 1.0, 0.0);
  if (fl.a > 1e-6) {
    vec4 c = fc / fl.a;
    float k = max(c.w, 0.0);
    float k_wide = k / (1.0 + k * spread);
    s.c = vec4(c.xyz, k_wide);
    s.rho_s = fl.rgb / fl.a * ((k_wide + 2.0) / (k + 2.0));
  }
  s.f0 = fg.a > 1e-6 ? fg.rgb / fg.a : vec3(0.0);
  s.alpha = fg.a > 1e-6 ? sqrt(max(fn.w / fg.a, 0.0) + spread) : 1.0;
  return s;
}

// Radiance leaving canvas point p (mm) towards the eye for the surface `s` there: relight.h's
// shading, per light; or the view mode's look of it (u_mode).
vec3 ShadeSurface(vec3 p, Surface s) {
  if (s.coverage <= 0.0) return vec3(0.0);
  vec3 n = s.n;
  if (u_mode == 2) return n * 0.5 + 0.5;
  // Tangent frame as tangent_frame.h: x = canvas X made perpendicular to n.
  vec3 axis = vec3(1.0, 0.0, 0.0);
  vec3 nc = cross(n, axis);
  if (dot(nc, nc) < 1e-6) axis = vec3(0.0, 1.0, 0.0);
  vec3 tx = normalize(axis - n * dot(n, axis));
  vec3 ty = cross(n, tx);
  vec3 vw = normalize(u_eye - p);
  vec3 v = vec3(dot(tx, vw), dot(ty, vw), dot(n, vw));
  vec3 diffuse = s.rho_d;
  vec3 spec = s.rho_s;
  vec3 f0 = s.f0;
  float lobe_k = s.c.w;
  float alpha_in = s.alpha;
  if (u_mode == 1) {
    // Specular enhancement: grey, dimmed diffuse; the specular term brightened and sharpened.
    diffuse = vec3(dot(s.rho_d, vec3(0.2126, 0.7152, 0.0722)) * u_specular.x);
    alpha_in = max(s.alpha / u_specular.z, u_ggx_limits.x);
    f0 = s.f0 * u_specular.y;
    lobe_k = s.c.w * u_specular.z;
    spec = s.rho_s * (u_specular.y * (lobe_k + 2.0) / (s.c.w + 2.0));
  }
  vec3 sum = u_ambient * diffuse;
  if (v.z <= 0.0) return sum * s.coverage;
  float alpha = clamp(alpha_in, u_ggx_limits.x, u_ggx_limits.y);
  vec3 diffuse_cos = diffuse * s.cos_scale;
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
    vec3 f = diffuse_cos;
    if (s.w_ggx > 0.0) f += s.w_ggx * GgxSpecular(f0, alpha, v, l);
    if (s.w_laf > 0.0) {
      float base = s.c.x * v.x * l.x + s.c.y * v.y * l.y + s.c.z * v.z * l.z;
      float lobe = base > 1e-20 ? exp(min(lobe_k * log(base), 80.0)) : 0.0;
      f += s.w_laf * spec * lobe;
    }
    sum += min(f, vec3(u_max_brdf)) * l.z * e;
  }
  return sum * s.coverage;
}

// The pixel's footprint through p on the plane z = p.z: the ellipse (axes a >= b, mm, major
// direction e1) of the pixel's square, from the camera's axes. false where the view ray runs
// along the plane (no bounded footprint).
bool Footprint(vec3 p, out float a, out float b, out vec2 e1) {
  vec3 dp = p - u_eye;
  float z = dot(dp, u_cam_forward);
  if (!(z > 1e-6)) return false;
  vec3 dir = dp / z;  // the ray at unit depth
  if (abs(dir.z) < 1e-6) return false;
  float size = u_pixel_scale * z;
  // Moving the pixel by one along an image axis moves the ray's point on the plane by:
  vec2 fx = size * (u_cam_right - dir * (u_cam_right.z / dir.z)).xy;
  vec2 fy = size * (u_cam_down - dir * (u_cam_down.z / dir.z)).xy;
  float m00 = fx.x * fx.x + fy.x * fy.x;
  float m01 = fx.x * fx.y + fy.x * fy.y;
  float m11 = fx.y * fx.y + fy.y * fy.y;
  float half_tr = 0.5 * (m00 + m11);
  float disc = sqrt(max(half_tr * half_tr - (m00 * m11 - m01 * m01), 0.0));
  float l1 = half_tr + disc;
  a = sqrt(l1);
  b = sqrt(max(half_tr - disc, 0.0));
  e1 = abs(m01) > 1e-12 * l1 ? normalize(vec2(m01, l1 - m00))
                             : (m00 >= m11 ? vec2(1.0, 0.0) : vec2(0.0, 1.0));
  return a == a && b == b;
}

// Radiance leaving canvas point p towards the eye: the texel's shading where a pixel covers at
// most a texel (the reference's), the footprint's mean where it covers more (renderer.h). The
// filter is compiled in (DIGITIZE_FILTER) only in the programs drawn where some pixel may cover
// more than a texel: present but unused, it slows llvmpipe's other frames by ~30 %.
vec3 Shade(vec3 p) {
  float blend = 0.0;
  vec3 filtered = vec3(0.0);
#ifdef DIGITIZE_FILTER
  float a, b;
  vec2 e1;
  if (Footprint(p, a, b, e1) && a > u_pitch_mm) {
    // Shading samples on an n_major x n_minor grid over the footprint, at most
    // u_filter_max_samples, each the surface of the level whose texel is about the sample's share
    // of the footprint (level 0: the texel itself, as the reference).
    int max_n = max(u_filter_max_samples, 1);
    float share_texels = sqrt(a * b / float(max_n)) / u_pitch_mm;
    int level = clamp(int(floor(log2(max(share_texels, 1.0)))), 0, u_levels - 1);
    float texel_mm = u_pitch_mm * exp2(float(level));
    int n_major = clamp(int(ceil(a / texel_mm)), 1, max_n);
    int n_minor = clamp(int(ceil(b / texel_mm)), 1, max(1, max_n / n_major));
    vec2 e2 = vec2(-e1.y, e1.x);
    vec3 sum = vec3(0.0);
    float total = 0.0;
    for (int i = 0; i < n_major; ++i) {
      for (int j = 0; j < n_minor; ++j) {
        vec2 q = p.xy + e1 * (a * ((float(i) + 0.5) / float(n_major) - 0.5)) +
                 e2 * (b * ((float(j) + 0.5) / float(n_minor) - 0.5));
        if (any(lessThan(q, vec2(0.0))) || any(greaterThan(q, u_size_mm))) continue;
        vec3 qs = vec3(q, p.z);
        Surface s = level == 0 ? PointSurface(q) : LevelSurface(q, level);
        // A sample stands for a patch of the plane; the pixel sees that patch of the relief
        // by its projected area, (n . v) / n_z of the plane's: at grazing views a slope
        // facing the eye fills more of the pixel than one facing away.
        float weight = max(dot(s.n, normalize(u_eye - qs)), 0.0) / max(s.n.z, 0.05);
        sum += weight * ShadeSurface(qs, s);
        total += weight;
      }
    }
    if (total > 0.0) {
      filtered = sum / total;
      // From 1 to 2 texels across, blended into the point-sampled radiance: no seam where it
      // starts; beyond, the point sample is not shaded at all.
      blend = clamp(a / u_pitch_mm - 1.0, 0.0, 1.0);
    }
  }
  if (blend >= 1.0) return filtered;
#endif
  vec3 point_radiance = ShadeSurface(p, PointSurface(p.xy));
  return blend > 0.0 ? mix(point_radiance, filtered, blend) : point_radiance;
}
