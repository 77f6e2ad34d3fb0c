// A relief box (box.vert): the view ray from the box's entry point to this fragment (its exit
// point) searched for the height field; the hit is shaded and writes its depth.
#version 450 core
#include "painting_common.glsl"
#include "relief_march.glsl"
in vec3 v_pos;
flat in vec3 v_min;
flat in vec3 v_max;
flat in float v_alpha;
out vec4 o_color;
void main() {
  vec3 d = normalize(v_pos - u_eye);
  vec3 t_min, t_max;
  SlabCrossings(d, v_min, v_max, t_min, t_max);
  float tnear = max(max(t_min.x, t_min.y), max(t_min.z, 0.0));
  float tfar = dot(v_pos - u_eye, d);
  if (tfar <= tnear) discard;
  vec3 a = u_eye + d * tnear;
  vec3 p = a;
  bool hit = a.z <= HeightAt(a.xy) || MarchRelief(a, v_pos, FootprintTexels(a, v_pos), p);
  if (!hit) discard;
  vec4 c = u_clip_from_canvas * vec4(p, 1.0);
  gl_FragDepth = clamp(0.5 * c.z / c.w + 0.5, 0.0, 1.0);
  o_color = vec4(u_heatmap != 0 ? Heat(v_alpha) : Shade(p), v_alpha);
}
