// MODE 1 (a deferred frame): depth-tested against the surface cache here (no depth buffer is
// written by the light pass): hidden where the surface is nearer the projector.
// MODE 2: the same, the colour before the mask also kept (second target, Renderer::Rewarp).
uniform sampler2D u_mask;
in vec4 v_colour;
layout(location = 0) out vec4 o_colour;
#if MODE >= 1
uniform usampler2D u_cache;
uniform float u_depth_tolerance_m;
in float v_depth;
#endif
#if MODE == 2
layout(location = 1) out vec4 o_lit;  // the colour before the mask (Renderer::Rewarp)
#endif
void main() {
#if MODE >= 1
  uvec4 q = texelFetch(u_cache, ivec2(gl_FragCoord.xy), 0);
  if (q.w != 0u && v_depth > uintBitsToFloat(q.x) + u_depth_tolerance_m) discard;
#endif
  o_colour = v_colour;
#if MODE == 2
  o_lit = v_colour;
#endif
#if MASKED
#if PACKED
  vec2 m = texelFetch(u_mask, ivec2(gl_FragCoord.xy), 0).ba;
#else
  vec2 m = texelFetch(u_mask, ivec2(gl_FragCoord.xy), 0).rg;
#endif
  o_colour.rgb = ApplyMask(o_colour.rgb, m);
#endif
}
