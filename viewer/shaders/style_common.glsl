// Included by the style programs (style.frag, stroke.vert, stroke.frag): renderer.h's
// DisplayColour and its inverse, so a style's display value leaves as the linear radiance that
// ToneMap with the same exposure shows as that value.
uniform float u_exposure;
uniform float u_knee;  // renderer.h kToneKnee
const vec3 kLuma = vec3(0.2126, 0.7152, 0.0722);

// renderer.h DisplayColour, and back.
vec3 Display(vec3 c) {
  c = max(c * u_exposure, vec3(0.0));
  float top = max(c.r, max(c.g, c.b));
  if (top > u_knee) {
    float x = (top - u_knee) / (1.0 - u_knee);
    c *= (u_knee + (1.0 - u_knee) * x / (1.0 + x)) / top;
  }
  return clamp(c, 0.0, 1.0);
}
uniform int u_display_out;  // 1: write display values (the window's sRGB framebuffer encodes them)
// Inverse of Display: the linear radiance whose display value is d.
vec3 Linear(vec3 d) {
  d = clamp(d, 0.0, 1.0);
  float m = min(max(d.r, max(d.g, d.b)), 0.995);
  vec3 c = d;
  if (m > u_knee) {
    float y = (m - u_knee) / (1.0 - u_knee);
    c *= (u_knee + (1.0 - u_knee) * y / (1.0 - y)) / m;
  }
  return c / u_exposure;
}


// What a pass writes for display value d: d itself for the window, else its linear radiance (the
// caller tone-maps it again: ToneMap).
vec3 Output(vec3 d) { return u_display_out != 0 ? d : Linear(d); }
