#version 330 core
// The sun's depth map: positions only.
layout(location = 0) in vec3 a_position;
uniform mat4 u_sun_clip_from_table;
void main() { gl_Position = u_sun_clip_from_table * vec4(a_position, 1.0); }
