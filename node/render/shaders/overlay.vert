// Strokes, traces and markers (after project.glsl). MODE >= 1 (a deferred frame): the depth
// along the projector's axis goes to the fragment shader, which tests it against the surface
// cache.
layout(location = 0) in vec3 a_position;
layout(location = 1) in vec4 a_colour;
uniform mat4 u_clip_from_table;
out vec4 v_colour;
#if MODE >= 1
uniform mat4 u_view_from_table;
out float v_depth;
#endif
void main() {
  v_colour = a_colour;
#if MODE >= 1
  v_depth = (u_view_from_table * vec4(a_position, 1.0)).z;
#endif
  gl_Position = Project(a_position, u_clip_from_table);
}
