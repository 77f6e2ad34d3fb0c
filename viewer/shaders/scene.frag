// Room, frames and box outlines (scene.vert): Lambertian under the picture lights (each shaped
// by its cone) plus the room's bounced ambient, floorboards patterned here, lamp lenses emitting;
// a flat colour for lines.
#version 450 core
in vec3 v_pos;
in vec3 v_normal;
flat in vec3 v_albedo;
flat in int v_surface;  // SceneSurface: 0 plain, 1 floorboards, 2 emissive
out vec4 o_color;
uniform vec3 u_eye;
uniform int u_num_lights;
uniform vec3 u_light_pos[8];
uniform vec3 u_light_int[8];
uniform vec4 u_spot[8];      // xyz: the cone's axis from the light
uniform vec2 u_spot_cos[8];  // cos of the inner and outer half-angles (-1, -1: no cone)
uniform float u_ambient;
uniform int u_flat;  // 1: lines, plain albedo

float Hash(vec2 p) { return fract(sin(dot(p, vec2(127.1, 311.7))) * 43758.5453); }

// Oak boards 140 mm wide running along world Y, in staggered lengths of 1.6 m, each with its own
// tint, a darker seam and fine grain along the board.
vec3 Floorboards(vec3 base, vec2 xy) {
  float col = floor(xy.x / 140.0);
  float along = xy.y / 1600.0 + Hash(vec2(col, 7.0));
  float row = floor(along);
  float tint = 0.78 + 0.4 * Hash(vec2(col, row));
  float u = fract(xy.x / 140.0), v = fract(along);
  float seam = smoothstep(0.0, 0.02, u) * smoothstep(1.0, 0.98, u) *
               smoothstep(0.0, 0.004, v) * smoothstep(1.0, 0.996, v);
  float grain = 0.93 + 0.07 * sin(xy.x * 0.9 + 3.0 * sin(xy.y * 0.004 + col));
  return base * tint * grain * mix(0.45, 1.0, seam);
}

void main() {
  if (u_flat != 0) { o_color = vec4(v_albedo, 1.0); return; }
  if (v_surface == 2) { o_color = vec4(v_albedo, 1.0); return; }
  vec3 n = normalize(v_normal);
  if (dot(n, u_eye - v_pos) < 0.0) n = -n;  // walls are seen from inside
  vec3 albedo = v_surface == 1 ? Floorboards(v_albedo, v_pos.xy) : v_albedo;
  vec3 sum = vec3(0.0);
  for (int i = 0; i < u_num_lights; ++i) {
    vec3 d = u_light_pos[i] - v_pos;
    float d2 = dot(d, d);
    vec3 l = d * inversesqrt(d2);
    float cone = 1.0;
    if (u_spot_cos[i].y > -0.9999)
      cone = smoothstep(u_spot_cos[i].y, u_spot_cos[i].x, dot(-l, u_spot[i].xyz));
    sum += cone * max(dot(n, l), 0.0) * u_light_int[i] / d2;
  }
  vec3 c = albedo / 3.14159265 * sum + albedo * u_ambient * (0.75 + 0.25 * n.z);
  o_color = vec4(c, 1.0);
}
