// The model into the ideal surface cache (surface.frag): the camera-space depth and the uv.
layout(location = 0) in vec3 a_position;
layout(location = 2) in vec2 a_uv;
uniform mat4 u_clip_from_table;
uniform mat4 u_camera_from_table;
out float v_depth;
out vec2 v_uv;
void main() {
  v_depth = (u_camera_from_table * vec4(a_position, 1.0)).z;
  v_uv = a_uv;
  gl_Position = u_clip_from_table * vec4(a_position, 1.0);
}
