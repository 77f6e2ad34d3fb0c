// Relief boxes: instanced unit cube, back faces only (the exit point); the entry point comes
// from the box bounds (slab test in box.frag), which also covers an eye inside the box.
#version 450 core
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
