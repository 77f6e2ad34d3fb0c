// Included after painting_common.glsl by the programs that search the height field along a view
// ray: plane.frag (the slab search) and box.frag (the relief boxes). Relief mapping as paper 001
// section 5.2 (after Policarpo et al. 2005): linear steps along the ray, then bisection of the
// step that crosses the surface.
uniform float u_step_texels;
uniform int u_min_steps;
uniform int u_max_steps;
uniform int u_binary_steps;

// Where the line u_eye + t d crosses the planes of box [lo, hi]: t per axis at the nearer and the
// farther plane. A direction component within 1e-9 of 0 counts as 1e-9, so t stays finite.
void SlabCrossings(vec3 d, vec3 lo, vec3 hi, out vec3 t_min, out vec3 t_max) {
  vec3 safe = vec3(abs(d.x) > 1e-9 ? d.x : 1e-9, abs(d.y) > 1e-9 ? d.y : 1e-9,
                   abs(d.z) > 1e-9 ? d.z : 1e-9);
  vec3 t0 = (lo - u_eye) / safe, t1 = (hi - u_eye) / safe;
  t_min = min(t0, t1);
  t_max = max(t0, t1);
}

// Texels the segment a -> b spans on the canvas.
float FootprintTexels(vec3 a, vec3 b) { return length(b.xy - a.xy) / u_pitch_mm; }

// The first intersection of segment a -> b (a above the relief) with the height field, in p:
// linear steps of u_step_texels along its footprint (u_min_steps to u_max_steps of them), then
// u_binary_steps bisections of the step that crosses. False when the segment stays above it.
bool MarchRelief(vec3 a, vec3 b, float footprint, out vec3 p) {
  int n = clamp(int(ceil(footprint / u_step_texels)), u_min_steps, u_max_steps);
  vec3 step = (b - a) / float(n);
  for (int i = 1; i <= n; ++i) {
    p = a + step * float(i);
    if (p.z <= HeightAt(p.xy)) {
      vec3 lo = p - step, hi = p;
      for (int j = 0; j < u_binary_steps; ++j) {
        vec3 mid = 0.5 * (lo + hi);
        if (mid.z <= HeightAt(mid.xy)) hi = mid; else lo = mid;
      }
      p = 0.5 * (lo + hi);
      return true;
    }
  }
  return false;
}
