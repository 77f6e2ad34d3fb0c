// Room, frames and box outlines: instanced unit cubes (or edges) in the world frame.
#version 450 core
layout(location = 0) in vec3 a_corner;
layout(location = 1) in vec3 a_normal;
layout(location = 2) in vec3 a_min;
layout(location = 3) in vec3 a_max;
layout(location = 4) in vec4 a_albedo;  // rgb, SceneSurface in w (outlines: w unused)
uniform mat4 u_clip_from_model;
out vec3 v_pos;
out vec3 v_normal;
flat out vec3 v_albedo;
flat out int v_surface;
void main() {
  v_pos = mix(a_min, a_max, a_corner);
  v_normal = a_normal;
  v_albedo = a_albedo.rgb;
  v_surface = int(a_albedo.w + 0.5);
  gl_Position = u_clip_from_model * vec4(v_pos, 1.0);
}
