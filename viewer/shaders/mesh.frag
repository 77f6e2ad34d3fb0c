// The mesh (mesh.vert) shaded with the painting's textures.
#version 450 core
#include "painting_common.glsl"
in vec3 v_pos;
out vec4 o_color;
void main() { o_color = vec4(Shade(v_pos), 1.0); }
