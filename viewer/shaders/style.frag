// The style pass (stylise.h): the realistic render's colour and depth in, the stylised colour
// out (linear radiance, so that ToneMap with the same exposure shows the styled display value).
#version 450 core
#include "style_common.glsl"
layout(binding = 0) uniform sampler2D u_colour;    // linear radiance
layout(binding = 1) uniform sampler2D u_depth;     // window depth, 1 = nothing drawn
layout(binding = 2) uniform sampler3D u_solid;     // SolidTexture: r pigment, g grain, b strokes,
                                                   // a wobble; tiling, equalised to uniform
layout(binding = 3) uniform sampler2DArray u_tam;  // tonal art map: layer = tone, mips = levels
uniform mat4 u_world_from_clip;
uniform vec3 u_eye;
uniform vec3 u_forward;      // the camera's viewing direction (unit)
uniform float u_tile;        // solid texture: octave 1 spans u_tile x 2^floor(log2 z) mm
uniform float u_tam_tile;    // hatching: a tonal art map tile spans u_tam_tile x 2^floor(log2 z)
                             // mm (and twice that, blended over the zoom cycle)
uniform float u_tam_ink[6];  // mean ink of each tone
uniform int u_style;         // stylise.h Style: 1 watercolor, 2 binary, 3 collage, 4 hatching,
                             // 5 painterly (this pass: the canvas under the strokes)
uniform int u_debug;         // 1: the contrast-restored pigment texture itself, grey
out vec4 o_color;

const vec3 kPaper = vec3(0.97, 0.95, 0.90);  // display value of the paper the styles draw on

vec3 WorldAt(vec2 frag, float depth) {
  vec4 ndc = vec4(frag / vec2(textureSize(u_colour, 0)) * 2.0 - 1.0, depth * 2.0 - 1.0, 1.0);
  vec4 w = u_world_from_clip * ndc;
  return w.xyz / w.w;
}

// Seed 003's dynamic solid texture at world point p (stylise.h InfiniteZoom), every channel,
// with the blend's contrast restored round the mean 0.5.
vec4 DynamicSolid(vec3 p) {
  float z = max(dot(p - u_eye, u_forward), 1.0);
  float lz = log2(z);
  float s = lz - floor(lz);
  vec3 x = p / (exp2(floor(lz)) * u_tile);
  vec4 a = vec4(s / 2.0, 0.5 - s / 6.0, 1.0 / 3.0 - s / 6.0, 1.0 / 6.0 - s / 6.0);
  vec4 t = a.x * texture(u_solid, x) + a.y * texture(u_solid, 2.0 * x) +
           a.z * texture(u_solid, 4.0 * x) + a.w * texture(u_solid, 8.0 * x);
  return clamp(0.5 + (t - 0.5) * inversesqrt(dot(a, a)), 0.0, 1.0);
}

vec3 DisplayAt(vec2 frag) { return Display(texture(u_colour, frag / vec2(textureSize(u_colour, 0))).rgb); }

float DepthEdge(vec2 frag) {  // relative depth jump round the pixel (outlines)
  vec2 inv = 1.0 / vec2(textureSize(u_depth, 0));
  float c = texture(u_depth, frag * inv).r;
  vec3 pc = WorldAt(frag, c);
  float zc = max(dot(pc - u_eye, u_forward), 1.0);
  float e = 0.0;
  for (int k = 0; k < 4; ++k) {
    vec2 o = vec2(k == 0 ? 1.0 : k == 1 ? -1.0 : 0.0, k == 2 ? 1.0 : k == 3 ? -1.0 : 0.0);
    float d = texture(u_depth, (frag + o) * inv).r;
    float zn = d >= 1.0 ? 1e9 : max(dot(WorldAt(frag + o, d) - u_eye, u_forward), 1.0);
    e = max(e, abs(zn - zc) / zc);
  }
  return e;
}

// The tone an ink drawing renders: lifted (gamma 0.6) so that a dim gallery wall is drawn with
// open strokes rather than near-solid ink, as an illustrator would; monotone, 0 and 1 kept.
float Drawn(float y) { return pow(clamp(y, 0.0, 1.0), 0.6); }

// Ink of the tonal art map at uv for the ink a pixel needs: the two nearest tones blended
// (below the lightest tone: towards bare paper; beyond the darkest: towards solid ink).
float Hatch(vec2 uv, float need) {
  if (need <= u_tam_ink[0]) return need / u_tam_ink[0] * texture(u_tam, vec3(uv, 0.0)).r;
  if (need >= u_tam_ink[5]) {
    float t5 = texture(u_tam, vec3(uv, 5.0)).r;
    return t5 + (need - u_tam_ink[5]) / (1.0 - u_tam_ink[5]) * (1.0 - t5);
  }
  int j = 0;
  for (int k = 0; k < 5; ++k)
    if (need >= u_tam_ink[k]) j = k;
  float w = (need - u_tam_ink[j]) / (u_tam_ink[j + 1] - u_tam_ink[j]);
  return mix(texture(u_tam, vec3(uv, float(j))).r, texture(u_tam, vec3(uv, float(j + 1))).r, w);
}

int Band(float y) { return int(clamp(floor(y * 4.0), 0.0, 3.0)); }

void main() {
  vec2 frag = gl_FragCoord.xy;
  vec2 inv = 1.0 / vec2(textureSize(u_colour, 0));
  float depth = texture(u_depth, frag * inv).r;
  vec3 lin = texture(u_colour, frag * inv).rgb;
  if (depth >= 1.0) { o_color = vec4(u_display_out != 0 ? Display(lin) : lin, 1.0); return; }
  vec3 c = Display(lin);
  if (u_style == 0) { o_color = vec4(Output(c), 1.0); return; }  // realistic: the tone curve only
  vec3 p = WorldAt(frag, depth);
  float y = dot(c, kLuma);
  // The noise cube only where it is used (four trilinear 3D lookups: most of this pass's cost).
  vec4 t = u_style <= 3 || u_debug != 0 ? DynamicSolid(p) : vec4(0.5);
  if (u_debug != 0) { o_color = vec4(Output(vec3(t.r)), 1.0); return; }
  vec3 outc = c;
  if (u_style == 1) {  // watercolor
    vec2 wobble = (t.ab - 0.5) * 5.0;  // px
    vec3 w = DisplayAt(frag + wobble);
    vec3 gx = DisplayAt(frag + wobble + vec2(1.5, 0.0)) - DisplayAt(frag + wobble - vec2(1.5, 0.0));
    vec3 gy = DisplayAt(frag + wobble + vec2(0.0, 1.5)) - DisplayAt(frag + wobble - vec2(0.0, 1.5));
    float edge = clamp(length(gx) + length(gy), 0.0, 1.0);
    float d = 1.0 + 1.1 * (t.r - 0.5) + 0.5 * (t.g - 0.5) + 0.8 * edge;
    w = mix(w, kPaper, 0.12);  // pigment on paper: never quite the render's black or white
    outc = clamp(w - (w - w * w) * (d - 1.0), 0.0, 1.0);
  } else if (u_style == 2) {  // binary: threshold structure vs the tone, plus outlines
    float ink = 1.0 - Drawn(y);
    bool dark = t.b < ink * 1.05 - 0.02 || DepthEdge(frag) > 0.03;
    outc = dark ? vec3(0.02) : kPaper;
  } else if (u_style == 3) {  // collage: 4 tone bands, each its own paper strip
    float yw = y + 0.08 * (t.a - 0.5);
    int b = Band(yw);
    bool border = false;
    for (int k = 0; k < 8 && !border; ++k) {
      vec2 o = 2.5 * vec2(cos(0.785 * float(k)), sin(0.785 * float(k)));
      border = Band(dot(DisplayAt(frag + o), kLuma) + 0.08 * (t.a - 0.5)) != b;
    }
    float tex = b == 0 ? t.r : b == 1 ? t.b : b == 2 ? t.g : t.r;
    vec3 hue = c / max(max(c.r, max(c.g, c.b)), 1e-3);
    float level = (float(b) + 0.6) / 4.0;
    vec3 strip = mix(vec3(1.0), hue, 0.75) * level * (0.8 + 0.4 * tex);
    outc = border ? kPaper : clamp(strip, 0.0, 1.0);
  } else if (u_style == 4) {  // hatching: tonal art maps
    // The tile follows the distance as the solid textures' octaves do (a two-octave zoom cycle:
    // the map at 2^k and 2^(k+1) blended by s), so strokes keep their on-screen size instead of
    // swelling in close-ups; the map's mip levels do the rest.
    vec3 n = abs(normalize(cross(dFdx(p), dFdy(p))));
    vec2 plane = n.x > n.y && n.x > n.z ? p.yz : n.y > n.z ? p.xz : p.xy;
    float z = max(dot(p - u_eye, u_forward), 1.0);
    float lz = log2(z);
    float s = lz - floor(lz);
    vec2 uv = plane / (exp2(floor(lz)) * u_tam_tile);
    float need = clamp(1.0 - Drawn(y), 0.0, 1.0);
    outc = kPaper * (1.0 - clamp(mix(Hatch(uv, need), Hatch(0.5 * uv, need), s), 0.0, 1.0));
  }
  o_color = vec4(Output(outc), 1.0);
}
