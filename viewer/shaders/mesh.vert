// The height field's triangle mesh (height_mesh.h), in the canvas frame.
#version 450 core
layout(location = 0) in vec3 a_pos;
uniform mat4 u_clip_from_canvas;
out vec3 v_pos;
void main() {
  v_pos = a_pos;
  gl_Position = u_clip_from_canvas * vec4(a_pos, 1.0);
}
