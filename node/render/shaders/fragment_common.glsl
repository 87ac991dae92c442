// Every fragment shader of a variant starts with this (after its #defines): the mask (factor,
// lift) applied to an encoded colour, the lift added in linear light (Renderer::LiftGamma).
uniform float u_lift_gamma;
vec3 ApplyMask(vec3 c, vec2 m) {
  c *= m.r;
#if LIFTED
  c = pow(pow(c, vec3(u_lift_gamma)) + m.g, vec3(1.0 / u_lift_gamma));
#endif
  return c;
}
