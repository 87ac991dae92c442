// The sun's light on each face, encoded (ambient + Lambert, as the scene pass lights a vertex):
// one texel a face, drawn when the sun moves.
uniform sampler2D u_normals;
uniform vec3 u_sun_direction;
uniform float u_ambient;
uniform float u_inverse_gamma;
out vec4 o_light;
void main() {
  vec3 n = texelFetch(u_normals, ivec2(gl_FragCoord.xy), 0).xyz;
  float lambert = max(dot(n, u_sun_direction), 0.0);
  o_light = vec4(pow(u_ambient + (1.0 - u_ambient) * lambert, u_inverse_gamma));
}
