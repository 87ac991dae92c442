// The ideal cache into output pixels (DISTORT: through the pre-warp, else pixel for pixel),
// packed: the geometry of the nearest ideal pixel (depths are not to be blended across an
// outline; the light pass rebuilds the point on that pixel's ray), the colour filtered as the
// warp pass filters the ideal image; none where the nearest pixel has no surface.
uniform sampler2D u_warp;
uniform usampler2D u_geometry;
uniform sampler2D u_colour;
out uvec4 o_cache;
void main() {
  o_cache = uvec4(0u);
#if DISTORT
  vec2 t = texelFetch(u_warp, ivec2(gl_FragCoord.xy), 0).xy;
  if (t.x <= 0.0 || t.y <= 0.0 || t.x >= 1.0 || t.y >= 1.0) return;
  ivec2 size = textureSize(u_geometry, 0);
  uvec4 g = texelFetch(u_geometry, clamp(ivec2(t * vec2(size)), ivec2(0), size - 1), 0);
  vec3 c = texture(u_colour, t).rgb;
#else
  uvec4 g = texelFetch(u_geometry, ivec2(gl_FragCoord.xy), 0);
  vec3 c = texelFetch(u_colour, ivec2(gl_FragCoord.xy), 0).rgb;
#endif
  if (g.w == 0u) return;
  uvec3 q = uvec3(round(clamp(c, 0.0, 1.0) * 255.0));
  o_cache = uvec4(g.x, g.y, q.r | (q.g << 8) | (q.b << 16), g.w);
}
