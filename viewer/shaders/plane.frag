// The bump plane (plane.vert): the canvas shaded at the surface point the view ray finds below
// each fragment of the slab.
#version 450 core
#include "painting_common.glsl"
#include "relief_march.glsl"
in vec3 v_pos;
out vec4 o_color;
uniform vec3 u_slab_min;
uniform vec3 u_slab_max;
uniform int u_slab_search;          // 1: linear + binary search through the slab
uniform int u_parallax_iterations;  // fixed-point steps (0 = plain bump); with the search: where
                                    // the relief rises above the plane
uniform float u_search_min_texels;

// Parallax mapping: slide along the view ray d to where it meets the height there.
vec3 Parallax(vec3 d) {
  vec3 p = v_pos;
  for (int i = 0; i < u_parallax_iterations && d.z < -1e-6; ++i)
    p = v_pos + d * ((HeightAt(p.xy) - v_pos.z) / d.z);
  return p;
}

void main() {
  vec3 d = normalize(v_pos - u_eye);
  vec3 p;
  if (u_slab_search != 0) {
    // Parallax occlusion mapping limited to the slab [lowest texel, delta0]: the first
    // intersection of the view ray with the height field between the slab's entry point (this
    // fragment) and its exit point, searched like a relief box. The number of steps follows the
    // ray's footprint across the slab (~ tan of the view angle): a few at face views, more at
    // grazing ones.
    vec3 t_min, t_max;
    SlabCrossings(d, u_slab_min, u_slab_max, t_min, t_max);
    float tfar = min(min(t_max.x, t_max.y), t_max.z);
    float tnear = dot(v_pos - u_eye, d);
    vec3 a = v_pos;
    vec3 b = u_eye + d * max(tfar, tnear);
    float footprint = FootprintTexels(a, b);
    // A streamed tile's slab is the tile's own, from its lowest to its highest texel: a ray that
    // crosses it within a texel leaves through a side into the next tile, which goes on from
    // there, so it is searched like any other (fixed-point steps from the slab's top would land
    // beyond the tile).
    if (a.z <= HeightAt(a.xy) || (footprint <= u_search_min_texels && u_streamed == 0)) {
      // Relief above the plane here (a box's, not drawn), or a ray so steep that it crosses the
      // slab within a texel or so (face views): the fixed-point steps, as without the search
      // (they also move the point back towards the eye where the relief is above the plane).
      p = Parallax(d);
    } else if (!MarchRelief(a, b, footprint, p)) {
      // Out through a side without meeting the surface: the ray sees no canvas (as the reference).
      discard;
    }
  } else {
    p = Parallax(d);  // optional: 0 iterations is the paper's plain bump
  }
  // A ray that meets the surface beyond the canvas outline sees no canvas (as the reference).
  if (any(lessThan(p.xy, vec2(-1e-3))) || any(greaterThan(p.xy, u_size_mm + 1e-3))) discard;
  p.z = HeightAt(p.xy);  // view and light vectors corrected by the height (paper 5.4)
  vec3 col = Shade(p);
  if (u_heatmap != 0) col = vec3(0.15) * clamp(dot(col, vec3(0.3, 0.6, 0.1)) * 4.0, 0.0, 1.0);
  o_color = vec4(col, 1.0);
}
