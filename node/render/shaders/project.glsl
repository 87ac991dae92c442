// Project(): the pre-warp in a vertex shader, put before the vertex shaders of the scene and
// overlay variants. The pinhole clip position, with x and y replaced by those of the
// Brown-distorted pixel (CameraModel::Project) when DISTORT; w and z stay, so clipping, depth and
// perspective-correct interpolation are the pinhole's. Past the monotonic domain of the lens model
// (far outside the image) the pinhole position is kept.
#if DISTORT
uniform mat4 u_camera_from_table;
uniform vec4 u_intrinsics;   // fx, fy, cx, cy (px)
uniform vec2 u_size_px;
uniform vec3 u_radial;       // k1, k2, k3
uniform vec2 u_tangential;   // p1, p2
uniform float u_domain_r2;
vec4 Project(vec3 x_in_table, mat4 clip_from_table) {
  vec4 clip = clip_from_table * vec4(x_in_table, 1.0);
  vec3 c = (u_camera_from_table * vec4(x_in_table, 1.0)).xyz;
  if (c.z <= 0.0) return clip;
  vec2 n = c.xy / c.z;
  float r2 = dot(n, n);
  if (r2 > u_domain_r2) return clip;
  float radial = 1.0 + r2 * (u_radial.x + r2 * (u_radial.y + r2 * u_radial.z));
  vec2 d = n * radial +
           vec2(2.0 * u_tangential.x * n.x * n.y + u_tangential.y * (r2 + 2.0 * n.x * n.x),
                u_tangential.x * (r2 + 2.0 * n.y * n.y) + 2.0 * u_tangential.y * n.x * n.y);
  vec2 px = u_intrinsics.xy * d + u_intrinsics.zw;
  vec2 ndc = vec2(2.0 * (px.x + 0.5) / u_size_px.x - 1.0, 1.0 - 2.0 * (px.y + 0.5) / u_size_px.y);
  return vec4(ndc * clip.w, clip.z, clip.w);
}
#else
vec4 Project(vec3 x_in_table, mat4 clip_from_table) {
  return clip_from_table * vec4(x_in_table, 1.0);
}
#endif
