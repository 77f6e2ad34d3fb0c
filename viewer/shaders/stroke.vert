// Painterly strokes (seed 002, sections 5.3-5.4): one instanced quad per anchor
// (painterly_strokes.h). Its colour is the realistic render's at the anchor, its direction
// along the render's iso-luminance lines (across the gradient; a fixed slant where the render
// is flat), its size the spacing times the anchor's weight (so strokes grow in and shrink out
// as the hierarchy refines), each stroke's own perturbation from its id; fidelity: each half of
// the stroke stops where the render's colour along it strays more than u_fidelity from the
// stroke's. Hidden anchors (behind what the depth buffer holds) draw nothing.
#version 450 core
#include "style_common.glsl"
layout(location = 0) in vec4 a_anchor;  // world xyz, weight
layout(location = 1) in float a_id;     // the anchor's id (as a float: 24 bits used)
layout(binding = 0) uniform sampler2D u_colour;
layout(binding = 1) uniform sampler2D u_depth;
uniform mat4 u_clip_from_world;
uniform vec2 u_near_far;
uniform float u_spacing_px;
uniform float u_fidelity;
out vec2 v_local;  // along (-1 .. 1 over the drawn length), across (-1 .. 1)
flat out vec3 v_colour;
flat out float v_seed;

float Hash(float x) { return fract(sin(x * 12.9898 + 78.233) * 43758.5453); }
float ViewZ(float depth) {  // window depth -> distance along the view (mm)
  float n = u_near_far.x, f = u_near_far.y, z = depth * 2.0 - 1.0;
  return 2.0 * n * f / (f + n - z * (f - n));
}
vec3 DisplayAt(vec2 px) { return Display(texture(u_colour, px / vec2(textureSize(u_colour, 0))).rgb); }

void main() {
  vec4 c = u_clip_from_world * vec4(a_anchor.xyz, 1.0);
  gl_Position = vec4(2.0, 2.0, 2.0, 1.0);  // culled unless drawn below
  v_local = vec2(0.0);
  v_colour = vec3(0.0);
  v_seed = 0.0;
  if (c.w <= 0.0) return;
  vec2 size = vec2(textureSize(u_colour, 0));
  vec2 px = (c.xy / c.w * 0.5 + 0.5) * size;
  ivec2 ipx = ivec2(clamp(px, vec2(0.0), size - 1.0));
  float z_own = c.w;  // clip w is the view depth
  float z_buf = ViewZ(texelFetch(u_depth, ipx, 0).r);
  if (z_own > z_buf * 1.01 + 2.0) return;  // hidden
  float w = a_anchor.w;
  float seed = Hash(a_id);
  vec3 col = DisplayAt(px);
  // Direction: along the iso-luminance line through the anchor.
  float lx = dot(DisplayAt(px + vec2(2.0, 0.0)) - DisplayAt(px - vec2(2.0, 0.0)), kLuma);
  float ly = dot(DisplayAt(px + vec2(0.0, 2.0)) - DisplayAt(px - vec2(0.0, 2.0)), kLuma);
  float theta = length(vec2(lx, ly)) > 0.02 ? atan(ly, lx) + 1.5707963 : 0.9;
  theta += (Hash(seed + 1.0) - 0.5) * 0.5;
  vec2 dir = vec2(cos(theta), sin(theta)), across = vec2(-dir.y, dir.x);
  float half_len = 1.3 * u_spacing_px * w * (0.8 + 0.4 * Hash(seed + 2.0));
  float half_wid = 0.5 * u_spacing_px * w * (0.8 + 0.4 * Hash(seed + 3.0));
  // Fidelity: march each half out from the anchor, stop before the colour strays.
  float ext[2];
  for (int side = 0; side < 2; ++side) {
    float sgn = side == 0 ? -1.0 : 1.0, t = 0.0;
    for (int k = 1; k <= 6; ++k) {
      float tk = half_len * float(k) / 6.0;
      if (length(DisplayAt(px + sgn * tk * dir) - col) > u_fidelity) break;
      t = tk;
    }
    ext[side] = max(t, half_wid);  // at least a dab
  }
  int corner = gl_VertexID;
  float along = (corner & 1) != 0 ? ext[1] : -ext[0];
  float side = (corner & 2) != 0 ? 1.0 : -1.0;
  vec2 q = px + along * dir + side * half_wid * across;
  gl_Position = vec4((q / size * 2.0 - 1.0), 0.0, 1.0);
  v_local = vec2((corner & 1) != 0 ? 1.0 : -1.0, side);
  v_colour = col * (0.93 + 0.14 * Hash(seed + 4.0));
  v_seed = seed;
}
