// The bump plane: the top of the canvas slab [0, W] x [0, H] x [lowest point, delta0], drawn
// with its sides (front faces only) so that at grazing views the canvas outline is where the true
// surface's is, not where the raised plane's edge would put it.
#version 450 core
layout(location = 0) in vec3 a_corner;
uniform mat4 u_clip_from_canvas;
uniform vec3 u_slab_min;
uniform vec3 u_slab_max;
out vec3 v_pos;
void main() {
  v_pos = mix(u_slab_min, u_slab_max, a_corner);
  gl_Position = u_clip_from_canvas * vec4(v_pos, 1.0);
}
