// Room, frames and box outlines (scene.vert): Lambertian, or a flat colour for lines.
#version 450 core
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
