// Output pixel p shows the ideal image at u_warp[p].xy (GL texture coordinates, negative: none),
// times the mask u_warp[p].zw (encoded on upload, or linear for float targets); without a
// pre-warp the mask alone, u_mask[p].xy.
uniform sampler2D u_image;
uniform sampler2D u_warp;
uniform sampler2D u_mask;
out vec4 o_colour;
void main() {
  ivec2 p = ivec2(gl_FragCoord.xy);
#if DISTORT
  vec4 w = texelFetch(u_warp, p, 0);
  vec2 t = w.xy;
  vec3 c = (t.x <= 0.0 || t.y <= 0.0 || t.x >= 1.0 || t.y >= 1.0) ? vec3(0.0)
                                                                  : texture(u_image, t).rgb;
#else
  vec3 c = texelFetch(u_image, p, 0).rgb;
#endif
#if MASKED
#if DISTORT
  vec2 m = w.zw;
#elif PACKED
  vec2 m = texelFetch(u_mask, p, 0).ba;
#else
  vec2 m = texelFetch(u_mask, p, 0).rg;
#endif
  c = ApplyMask(c, m);
#endif
  o_colour = vec4(c, 1.0);
}
