// A deferred frame, per output pixel: the cached colour lit by the sun (its face's light x the
// shadow lookup at the surface's point, rebuilt on its ideal pixel's ray, as the scene pass lights
// it; times u_light without a sun), times the mask, plus the lift. No branch on the surface:
// where there is none the colour is black. PACKED: the mask is in the warp's texture (zw). MODE 1:
// the colour before the mask also goes to a second target (the lit texture): a new mask is then
// one full-screen pass over it (Renderer::Rewarp), not the light pass again.
uniform usampler2D u_cache;
uniform sampler2D u_face_light;
uniform sampler2DShadow u_shadow;
uniform sampler2D u_mask;
uniform mat4 u_sun_clip_from_camera;
uniform vec4 u_inverse_intrinsics;  // 1 / fx, 1 / fy, cx, cy (px)
uniform float u_ambient_encoded;
uniform float u_light;
layout(location = 0) out vec4 o_colour;
#if MODE == 1
layout(location = 1) out vec4 o_lit;  // the colour before the mask (Renderer::Rewarp)
#endif
void main() {
  ivec2 p = ivec2(gl_FragCoord.xy);
  uvec4 q = texelFetch(u_cache, p, 0);
  vec3 c = vec3(uvec3(q.z, q.z >> 8, q.z >> 16) & 255u) * (1.0 / 255.0);
#if SUN
  float depth = uintBitsToFloat(q.x);
  vec2 ideal = vec2(uvec2(q.y, q.y >> 16) & 65535u);
  vec4 x = vec4(depth * (ideal - u_inverse_intrinsics.zw) * u_inverse_intrinsics.xy, depth, 1.0);
  int face = max(int(q.w) - 1, 0);
  float lit = texelFetch(u_face_light, ivec2(face & 4095, face >> 12), 0).r;
  vec3 s = (u_sun_clip_from_camera * x).xyz * 0.5 + 0.5;
  c *= mix(u_ambient_encoded, lit, texture(u_shadow, s));
#else
  c *= u_light;
#endif
#if MODE == 1
  o_lit = vec4(c, 1.0);
#endif
#if MASKED
#if PACKED
  vec2 m = texelFetch(u_mask, p, 0).ba;
#else
  vec2 m = texelFetch(u_mask, p, 0).rg;
#endif
  c = ApplyMask(c, m);
#endif
  o_colour = vec4(c, 1.0);
}
