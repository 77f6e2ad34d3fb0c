// A painterly stroke (stroke.vert): soft-edged, with bristle streaks along it and a tapered end.
#version 450 core
#include "style_common.glsl"
in vec2 v_local;
flat in vec3 v_colour;
flat in float v_seed;
out vec4 o_color;
void main() {
  float across = abs(v_local.y), along = abs(v_local.x);
  float edge = 1.0 - smoothstep(0.55, 1.0, across);
  float taper = 1.0 - smoothstep(0.7, 1.0, along) * smoothstep(0.2, 1.0, across);
  float bristle = 0.85 + 0.15 * sin(v_local.y * 9.0 + v_seed * 40.0);
  float a = edge * taper;
  if (a <= 0.01) discard;
  o_color = vec4(Output(clamp(v_colour * bristle, 0.0, 1.0)), a);
}
