// The show's model (after project.glsl): flat faces, so the light per vertex is exact.
layout(location = 0) in vec3 a_position;
layout(location = 1) in vec3 a_normal;
layout(location = 2) in vec2 a_uv;
uniform mat4 u_clip_from_table;
uniform mat4 u_sun_clip_from_table;
uniform vec3 u_sun_direction;
uniform float u_ambient;
uniform float u_inverse_gamma;
out vec3 v_position;
out vec2 v_uv;
out vec3 v_sun;
out vec2 v_light;  // encoded light in shadow, in the sun
void main() {
  v_position = a_position;
  v_uv = a_uv;
  v_sun = (u_sun_clip_from_table * vec4(a_position, 1.0)).xyz * 0.5 + 0.5;
  float lambert = max(dot(a_normal, u_sun_direction), 0.0);
  v_light = vec2(pow(u_ambient, u_inverse_gamma),
                 pow(u_ambient + (1.0 - u_ambient) * lambert, u_inverse_gamma));
  gl_Position = Project(a_position, u_clip_from_table);
}
