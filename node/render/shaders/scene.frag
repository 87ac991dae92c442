// MODE: 0 the show, 1 white, 2 the table grid, 3 table positions (float targets), 4 black.
// Colours are display-encoded; u_base_colour is encoded, the light is raised to 1 / gamma in the
// vertex shader (in shadow and in the sun; the shadow lookup mixes the two) and the mask on
// upload. The shadow map is looked up with one nearest compare (four cost 2 ms more a frame).
uniform vec4 u_base_colour;
uniform sampler2D u_texture;
uniform sampler2DShadow u_shadow;
uniform float u_grid_spacing_m;
uniform float u_grid_half_line_m;
uniform sampler2D u_mask;
in vec3 v_position;
in vec2 v_uv;
in vec3 v_sun;
in vec2 v_light;
out vec4 o_colour;
void main() {
#if MODE == 3
  o_colour = vec4(v_position, 1.0);
  return;
#endif
#if MODE == 1
  vec3 c = vec3(1.0);
#elif MODE == 4
  vec3 c = vec3(0.0);
#elif MODE == 2
  vec2 cells = v_position.xy / u_grid_spacing_m;
  vec2 off_m = abs(cells - round(cells)) * u_grid_spacing_m;
  vec2 half_m = max(vec2(u_grid_half_line_m), 0.75 * fwidth(v_position.xy));
  vec3 c = vec3((off_m.x < half_m.x || off_m.y < half_m.y) ? 1.0 : 0.0);
#else
  vec3 c = u_base_colour.rgb;
#if TEXTURED
  c *= texture(u_texture, v_uv).rgb;
#endif
#if SUN
  c *= mix(v_light.x, v_light.y, texture(u_shadow, v_sun));
#endif
#endif
#if MASKED
  vec2 m = texelFetch(u_mask, ivec2(gl_FragCoord.xy), 0).rg;
  c = ApplyMask(c, m);
#endif
  o_colour = vec4(c, 1.0);
}
