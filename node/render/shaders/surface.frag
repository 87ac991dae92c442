// The deferred path (renderer.h). The surface cache is one RGBA32UI texel per output pixel
// (one lookup a pixel in the light pass: on llvmpipe each full-screen lookup costs 2-5 ms at
// 1280x800, more than its bytes): x the camera-space depth of the surface (float bits), y its
// ideal pixel (u | v << 16, OpenCV), z its encoded base colour x texture (8 bits a channel), w its
// face (index + 1; 0: no surface). The scene pass draws the ideal cache (the geometry as such,
// the colour in a filterable RGBA8); depth is interpolated perspective-correctly: exact at the
// pixel's centre.
uniform vec4 u_base_colour;
uniform sampler2D u_texture;
uniform int u_first_face;
uniform float u_height_px;
in float v_depth;
in vec2 v_uv;
layout(location = 0) out uvec4 o_geometry;
layout(location = 1) out vec4 o_colour;
void main() {
  vec3 c = u_base_colour.rgb;
#if TEXTURED
  c *= texture(u_texture, v_uv).rgb;
#endif
  uvec2 ideal = uvec2(gl_FragCoord.x, u_height_px - gl_FragCoord.y);  // OpenCV row
  o_geometry = uvec4(floatBitsToUint(v_depth), ideal.x | (ideal.y << 16), 0u,
                     uint(u_first_face + gl_PrimitiveID + 1));
  o_colour = vec4(c, 1.0);
}
