#include "node/render/renderer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>
#include <glm/gtc/type_ptr.hpp>

#include "node/devices/gl_util.h"
#include "node/render/glm_convert.h"
#include "node/render/test_patterns.h"

namespace sandtable::node {
namespace {

using Clock = std::chrono::steady_clock;

double MsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// Shaders are specialised by #define (a variant per feature set, compiled on first use):
// llvmpipe runs both sides of a branch on a uniform, so one shader with every feature behind
// uniforms costs as much as all of them together.

// The pre-warp in a vertex shader: the pinhole clip position, with x and y replaced by those
// of the Brown-distorted pixel (CameraModel::Project) when DISTORT; w and z stay, so clipping,
// depth and perspective-correct interpolation are the pinhole's. Past the monotonic domain of
// the lens model (far outside the image) the pinhole position is kept.
constexpr const char* kProject = R"(
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
)";

const std::string kSceneVertex = std::string(R"(
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
out vec2 v_light;  // encoded light in shadow, in the sun (flat faces: per vertex is exact)
)") + kProject + R"(
void main() {
  v_position = a_position;
  v_uv = a_uv;
  v_sun = (u_sun_clip_from_table * vec4(a_position, 1.0)).xyz * 0.5 + 0.5;
  float lambert = max(dot(a_normal, u_sun_direction), 0.0);
  v_light = vec2(pow(u_ambient, u_inverse_gamma),
                 pow(u_ambient + (1.0 - u_ambient) * lambert, u_inverse_gamma));
  gl_Position = Project(a_position, u_clip_from_table);
}
)";

// Every fragment shader of a variant starts with this (after its #defines): the mask (factor,
// lift) applied to an encoded colour, the lift added in linear light (LiftGamma).
constexpr const char* kFragmentCommon = R"(
uniform float u_lift_gamma;
vec3 ApplyMask(vec3 c, vec2 m) {
  c *= m.r;
#if LIFTED
  c = pow(pow(c, vec3(u_lift_gamma)) + m.g, vec3(1.0 / u_lift_gamma));
#endif
  return c;
}
)";

// MODE: 0 the show, 1 white, 2 the table grid, 3 table positions (float targets), 4 black.
// Colours are display-encoded; u_base_colour is encoded, the light is raised to 1 / gamma in the
// vertex shader (in shadow and in the sun; the shadow lookup mixes the two) and the mask on
// upload. The shadow map is looked up with one nearest compare (four cost 2 ms more a frame).
constexpr const char* kSceneFragment = R"(
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
)";

constexpr const char* kShadowVertex = R"(#version 330 core
// The sun's depth map: positions only.
layout(location = 0) in vec3 a_position;
uniform mat4 u_sun_clip_from_table;
void main() { gl_Position = u_sun_clip_from_table * vec4(a_position, 1.0); }
)";
constexpr const char* kShadowFragment = R"(#version 330 core
void main() {}
)";

// MODE 1 (a deferred frame): depth-tested against the surface cache in the fragment shader (no
// depth buffer is written by the light pass): hidden where the surface is nearer the projector.
// MODE 2: the same, the colour before the mask also kept (second target, Renderer::Rewarp).
const std::string kOverlayVertex = std::string(R"(
layout(location = 0) in vec3 a_position;
layout(location = 1) in vec4 a_colour;
uniform mat4 u_clip_from_table;
out vec4 v_colour;
#if MODE >= 1
uniform mat4 u_view_from_table;
out float v_depth;
#endif
)") + kProject + R"(
void main() {
  v_colour = a_colour;
#if MODE >= 1
  v_depth = (u_view_from_table * vec4(a_position, 1.0)).z;
#endif
  gl_Position = Project(a_position, u_clip_from_table);
}
)";
constexpr const char* kOverlayFragment = R"(
uniform sampler2D u_mask;
in vec4 v_colour;
layout(location = 0) out vec4 o_colour;
#if MODE >= 1
uniform usampler2D u_cache;
uniform float u_depth_tolerance_m;
in float v_depth;
#endif
#if MODE == 2
layout(location = 1) out vec4 o_lit;  // the colour before the mask (Renderer::Rewarp)
#endif
void main() {
#if MODE >= 1
  uvec4 q = texelFetch(u_cache, ivec2(gl_FragCoord.xy), 0);
  if (q.w != 0u && v_depth > uintBitsToFloat(q.x) + u_depth_tolerance_m) discard;
#endif
  o_colour = v_colour;
#if MODE == 2
  o_lit = v_colour;
#endif
#if MASKED
#if PACKED
  vec2 m = texelFetch(u_mask, ivec2(gl_FragCoord.xy), 0).ba;
#else
  vec2 m = texelFetch(u_mask, ivec2(gl_FragCoord.xy), 0).rg;
#endif
  o_colour.rgb = ApplyMask(o_colour.rgb, m);
#endif
}
)";

// Output pixel p shows the ideal image at u_warp[p].xy (GL texture coordinates, negative: none),
// times the mask u_warp[p].zw (encoded on upload, or linear for float targets); without a
// pre-warp the mask alone, u_mask[p].xy.
constexpr const char* kWarpFragment = R"(
uniform sampler2D u_image;
uniform sampler2D u_warp;
uniform sampler2D u_mask;
out vec4 o_colour;
void main() {
  ivec2 p = ivec2(gl_FragCoord.xy);
#if DISTORT
  vec4 w = texelFetch(u_warp, p, 0);
  vec2 t = w.xy;
  vec3 c = (t.x <= 0.0 || t.y <= 0.0 || t.x >= 1.0 || t.y >= 1.0) ? vec3(0.0)
                                                                  : texture(u_image, t).rgb;
#else
  vec3 c = texelFetch(u_image, p, 0).rgb;
#endif
#if MASKED
#if DISTORT
  vec2 m = w.zw;
#elif PACKED
  vec2 m = texelFetch(u_mask, p, 0).ba;
#else
  vec2 m = texelFetch(u_mask, p, 0).rg;
#endif
  c = ApplyMask(c, m);
#endif
  o_colour = vec4(c, 1.0);
}
)";

// The deferred path (renderer.h). The surface cache is one RGBA32UI texel per output pixel
// (one lookup a pixel in the light pass: on llvmpipe each full-screen lookup costs 2-5 ms at
// 1280x800, more than its bytes): x the camera-space depth of the surface (float bits), y its
// ideal pixel (u | v << 16, OpenCV), z its encoded base colour x texture (8 bits a channel), w its
// face (index + 1; 0: no surface). The scene pass draws the ideal cache (the geometry as such,
// the colour in a filterable RGBA8); depth is interpolated perspective-correctly: exact at the
// pixel's centre.
constexpr const char* kSurfaceVertex = R"(
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
)";
constexpr const char* kSurfaceFragment = R"(
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
)";
// The ideal cache into output pixels (DISTORT: through the pre-warp, else pixel for pixel),
// packed: the geometry of the nearest ideal pixel (depths are not to be blended across an
// outline; the light pass rebuilds the point on that pixel's ray), the colour filtered as the
// warp pass filters the ideal image; none where the nearest pixel has no surface.
constexpr const char* kSurfaceWarpFragment = R"(
uniform sampler2D u_warp;
uniform usampler2D u_geometry;
uniform sampler2D u_colour;
out uvec4 o_cache;
void main() {
  o_cache = uvec4(0u);
#if DISTORT
  vec2 t = texelFetch(u_warp, ivec2(gl_FragCoord.xy), 0).xy;
  if (t.x <= 0.0 || t.y <= 0.0 || t.x >= 1.0 || t.y >= 1.0) return;
  ivec2 size = textureSize(u_geometry, 0);
  uvec4 g = texelFetch(u_geometry, clamp(ivec2(t * vec2(size)), ivec2(0), size - 1), 0);
  vec3 c = texture(u_colour, t).rgb;
#else
  uvec4 g = texelFetch(u_geometry, ivec2(gl_FragCoord.xy), 0);
  vec3 c = texelFetch(u_colour, ivec2(gl_FragCoord.xy), 0).rgb;
#endif
  if (g.w == 0u) return;
  uvec3 q = uvec3(round(clamp(c, 0.0, 1.0) * 255.0));
  o_cache = uvec4(g.x, g.y, q.r | (q.g << 8) | (q.b << 16), g.w);
}
)";
// The sun's light on each face, encoded (ambient + Lambert, as the scene pass lights a vertex):
// one texel a face, drawn when the sun moves.
constexpr const char* kFaceLightFragment = R"(
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
)";
// A deferred frame, per output pixel: the cached colour lit by the sun (its face's light x the
// shadow lookup at the surface's point, rebuilt on its ideal pixel's ray, as the scene pass lights
// it; times u_light without a sun), times the mask, plus the lift. No branch on the surface:
// where there is none the colour is black. PACKED: the mask is in the warp's texture (zw). MODE 1:
// the colour before the mask also goes to a second target (lit_texture_): a new mask is then one
// full-screen pass over it (Renderer::Rewarp), not the light pass again.
constexpr const char* kLightFragment = R"(
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
)";

struct SceneVertex {
  float position[3];
  float normal[3];
  float uv[2];
};

GLuint MakeTexture2D(GLint internal_format, int w, int h, GLenum format, GLenum type,
                     const void* data, GLint filter) {
  GLuint texture = 0;
  glGenTextures(1, &texture);
  glBindTexture(GL_TEXTURE_2D, texture);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, filter);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, filter);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAX_LEVEL, 0);
  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
  glTexImage2D(GL_TEXTURE_2D, 0, internal_format, w, h, 0, format, type, data);
  return texture;
}

// Rows of an OpenCV-ordered image (row 0 at the top) in GL order (row 0 at the bottom).
cv::Mat FlippedContinuous(const cv::Mat& image) {
  cv::Mat flipped;
  cv::flip(image, flipped, 0);
  return flipped.isContinuous() ? flipped : flipped.clone();
}

bool OutsideFrustum(const Eigen::Matrix4d& clip_from_table, const Eigen::AlignedBox3d& box) {
  if (box.isEmpty()) return true;
  // Outside when every corner is beyond the same clip plane.
  int outside[6] = {0, 0, 0, 0, 0, 0};
  for (int i = 0; i < 8; ++i) {
    const Eigen::Vector4d c =
        clip_from_table * box.corner(static_cast<Eigen::AlignedBox3d::CornerType>(i)).homogeneous();
    outside[0] += c.x() < -c.w();
    outside[1] += c.x() > c.w();
    outside[2] += c.y() < -c.w();
    outside[3] += c.y() > c.w();
    outside[4] += c.z() < -c.w();
    outside[5] += c.z() > c.w();
  }
  return std::any_of(std::begin(outside), std::end(outside), [](int n) { return n == 8; });
}

// The projector's rigid transform as a 4x4 matrix (camera <- table, metres).
Eigen::Matrix4d Matrix(const Rigid3d& transform) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topLeftCorner<3, 3>() = transform.rotation.toRotationMatrix();
  m.topRightCorner<3, 1>() = transform.translation;
  return m;
}

}  // namespace

const char* PassName(Pass pass) {
  switch (pass) {
    case Pass::kShadow:
      return "shadow";
    case Pass::kScene:
      return "scene";
    case Pass::kOverlay:
      return "overlay";
    case Pass::kWarp:
      return "warp";
    case Pass::kPattern:
      return "pattern";
    case Pass::kLight:
      return "light";
  }
  return "?";
}

Status RendererOptions::Check() const {
  ST_RETURN_IF_ERROR(overlay.Check());
  if (shadow_map_px < 16 || shadow_map_px > 16384) {
    return InvalidArgumentError("renderer: shadow_map_px must be in 16..16384");
  }
  if (!(ambient >= 0.0 && ambient <= 1.0)) {
    return InvalidArgumentError("renderer: ambient must be in [0, 1]");
  }
  if (!(grid_spacing_m > 0.0) || !(grid_line_width_m > 0.0) ||
      grid_line_width_m >= grid_spacing_m) {
    return InvalidArgumentError(
        "renderer: grid spacing and line width must be > 0, the line narrower than the spacing");
  }
  if (!(overlay.lift_m >= 0.0) || overlay.round_segments < 3) {
    return InvalidArgumentError("renderer: overlay lift_m >= 0 and round_segments >= 3");
  }
  return OkStatus();
}

Expected<std::unique_ptr<Renderer>> Renderer::Create(GlContext* context, const Scene& scene,
                                                     const RendererOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  std::unique_ptr<Renderer> renderer(new Renderer(context, options));
  ST_RETURN_IF_ERROR(renderer->Init(scene));
  return renderer;
}

Status Renderer::Init(const Scene& scene) {
  ST_RETURN_IF_ERROR(context_->MakeCurrent());
  size_ = context_->size();
  scene_bounds_ = scene.Bounds();
  scene_ = scene;
  Expected<unsigned int> program = LinkProgram("shadow", kShadowVertex, kShadowFragment);
  if (!program.ok()) return program.status();
  shadow_program_ = *program;
  program = LinkProgram("blit", kFullScreenQuadVertexShader, kTexelBlitFragmentShader);
  if (!program.ok()) return program.status();
  blit_program_ = *program;

  glGenVertexArrays(1, &scene_vao_);
  glGenBuffers(1, &scene_vbo_);
  glGenVertexArrays(1, &shadow_vao_);
  glGenBuffers(1, &shadow_vbo_);
  ST_RETURN_IF_ERROR(UploadGeometry(shadow_vao_, shadow_vbo_, /*edge_px=*/0.0, &shadow_groups_));
  // A group flat at the bottom of the scene (a table, a ground plane) shadows nothing under a sun
  // above the horizon (the only sun the shadow pass draws for): everything else is at or above
  // it. Left out of the sun's depth map, its texels keep the cleared far depth and the table is
  // lit there as it would be; on llvmpipe it was most of the pass's fill.
  constexpr double kFlatM = 1e-6;
  std::erase_if(shadow_groups_, [&](const Group& g) {
    return !g.bounds.isEmpty() && g.bounds.sizes().z() < kFlatM &&
           g.bounds.min().z() < scene_bounds_.min().z() + kFlatM;
  });
  std::vector<float> normals;
  ST_RETURN_IF_ERROR(UploadGeometry(scene_vao_, scene_vbo_, /*edge_px=*/0.0, &groups_, &normals));
  // The deferred path's face tables (renderer.h): the normals, and the light drawn from them. A
  // model with more faces than a table can hold (4096 x the largest texture's rows) is drawn
  // with the forward passes.
  const int faces = std::max<int>(1, static_cast<int>(normals.size() / 3));
  face_table_size_ =
      cv::Size(std::min(faces, kFaceRowTexels), (faces + kFaceRowTexels - 1) / kFaceRowTexels);
  GLint max_texture_px = 0;
  glGetIntegerv(GL_MAX_TEXTURE_SIZE, &max_texture_px);
  deferred_ = options_.deferred && face_table_size_.height <= max_texture_px;
  if (deferred_) {
    normals.resize(static_cast<size_t>(face_table_size_.area()) * 3, 0.0f);
    face_normals_ = MakeTexture2D(GL_RGB32F, face_table_size_.width, face_table_size_.height,
                                  GL_RGB, GL_FLOAT, normals.data(), GL_NEAREST);
    face_light_ = MakeTexture2D(GL_R32F, face_table_size_.width, face_table_size_.height, GL_RED,
                                GL_FLOAT, nullptr, GL_NEAREST);
    glGenFramebuffers(1, &face_light_fbo_);
    glBindFramebuffer(GL_FRAMEBUFFER, face_light_fbo_);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, face_light_, 0);
    if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE) {
      return InternalError("OpenGL: the face light's framebuffer is incomplete");
    }
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
  }

  glGenVertexArrays(1, &overlay_vao_);
  glBindVertexArray(overlay_vao_);
  glGenBuffers(1, &overlay_vbo_);
  glBindBuffer(GL_ARRAY_BUFFER, overlay_vbo_);
  glEnableVertexAttribArray(0);
  glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, sizeof(OverlayVertex),
                        reinterpret_cast<void*>(offsetof(OverlayVertex, position_in_table_m)));
  glEnableVertexAttribArray(1);
  glVertexAttribPointer(1, 4, GL_FLOAT, GL_FALSE, sizeof(OverlayVertex),
                        reinterpret_cast<void*>(offsetof(OverlayVertex, colour)));
  glGenVertexArrays(1, &empty_vao_);
  glBindVertexArray(0);

  // Materials and their textures (encoded texels, filtered as they are; mipmapped).
  // Base colour factors are linear (glTF): encoded here once (see the colour note in renderer.h).
  for (const Material& material : scene.materials) {
    Eigen::Vector4d encoded = material.base_color_factor;
    for (int i = 0; i < 3; ++i) {
      encoded[i] = std::pow(std::clamp(encoded[i], 0.0, 1.0), 1.0 / options_.display_gamma);
    }
    material_colours_.push_back(encoded);
    material_textures_.push_back(material.base_color_texture);
  }
  for (const Texture& texture : scene.textures) {
    GLuint id = 0;
    glGenTextures(1, &id);
    glBindTexture(GL_TEXTURE_2D, id);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, texture.width_px, texture.height_px, 0, GL_RGBA,
                 GL_UNSIGNED_BYTE, texture.rgba.data());
    glGenerateMipmap(GL_TEXTURE_2D);
    // Mipmaps (the nearest level, filtered bilinearly: trilinear costs twice on llvmpipe) only
    // for a texture larger than the output, which a projector can see minified; a smaller one
    // is magnified or near 1:1 and sampled bilinearly (mip selection costs ~2 ms a frame on
    // llvmpipe at 1280x800).
    const bool mipmapped =
        std::max(texture.width_px, texture.height_px) > std::max(size_.width, size_.height);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER,
                    mipmapped ? GL_LINEAR_MIPMAP_NEAREST : GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S,
                    texture.repeat_s ? GL_REPEAT : GL_CLAMP_TO_EDGE);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T,
                    texture.repeat_t ? GL_REPEAT : GL_CLAMP_TO_EDGE);
    textures_.push_back(id);
  }

  // The sun's depth map, compared in the lookup (sampler2DShadow).
  glGenTextures(1, &shadow_texture_);
  glBindTexture(GL_TEXTURE_2D, shadow_texture_);
  glTexImage2D(GL_TEXTURE_2D, 0, GL_DEPTH_COMPONENT24, options_.shadow_map_px,
               options_.shadow_map_px, 0, GL_DEPTH_COMPONENT, GL_FLOAT, nullptr);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_BORDER);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_BORDER);
  const float border[4] = {1, 1, 1, 1};
  glTexParameterfv(GL_TEXTURE_2D, GL_TEXTURE_BORDER_COLOR, border);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_COMPARE_MODE, GL_COMPARE_REF_TO_TEXTURE);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_COMPARE_FUNC, GL_LEQUAL);
  glGenFramebuffers(1, &shadow_fbo_);
  glBindFramebuffer(GL_FRAMEBUFFER, shadow_fbo_);
  glFramebufferTexture2D(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_TEXTURE_2D, shadow_texture_, 0);
  glDrawBuffer(GL_NONE);
  glReadBuffer(GL_NONE);
  if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE) {
    return InternalError("OpenGL: the shadow map framebuffer is incomplete");
  }

  // A depth buffer for the output when it is an offscreen framebuffer without one.
  if (context_->output_framebuffer() != 0) {
    glBindFramebuffer(GL_FRAMEBUFFER, context_->output_framebuffer());
    GLint type = GL_NONE;
    glGetFramebufferAttachmentParameteriv(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT,
                                          GL_FRAMEBUFFER_ATTACHMENT_OBJECT_TYPE, &type);
    if (type == GL_NONE) {
      glGenRenderbuffers(1, &output_depth_);
      glBindRenderbuffer(GL_RENDERBUFFER, output_depth_);
      glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT24, size_.width, size_.height);
      glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER,
                                output_depth_);
    }
  }
  // The floor's texture: a full-screen image to sample.
  cv::Mat grey(size_, CV_8UC3, cv::Scalar::all(128));
  floor_texture_ = MakeTexture2D(GL_RGB8, size_.width, size_.height, GL_RGB, GL_UNSIGNED_BYTE,
                                 grey.data, GL_NEAREST);
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  glDisable(GL_DITHER);
  glDisable(GL_BLEND);
  glDisable(GL_FRAMEBUFFER_SRGB);
  return CheckGl("creating the renderer");
}

// The model into the vertex buffer, grouped by material (one draw call each), flat normals.
// With edge_px > 0, every triangle in front of the projector is split at the midpoint of its
// longest edge until no edge spans more than edge_px on the projector's (pinhole) image: the
// folded pre-warp bends edges only at vertices.
Status Renderer::UploadGeometry(unsigned int vao, unsigned int vbo, double edge_px,
                                std::vector<Group>* groups, std::vector<float>* face_normals) {
  const bool tessellate = edge_px > 0.0;
  const Scene& scene = scene_;
  std::vector<std::vector<int>> by_material(std::max<size_t>(scene.materials.size(), 1));
  for (int t = 0; t < scene.NumTriangles(); ++t) {
    int m = t < static_cast<int>(scene.triangle_material.size()) ? scene.triangle_material[t] : 0;
    if (m < 0 || m >= static_cast<int>(by_material.size())) m = 0;
    by_material[m].push_back(t);
  }
  const bool has_uv = scene.texcoords.size() == scene.positions_in_table_m.size();
  const double max_edge2 = edge_px * edge_px;
  const Eigen::Matrix3d rotation = view_.projector_from_table.rotation.toRotationMatrix();
  const Eigen::Vector3d translation = view_.projector_from_table.translation;
  const double fx = view_.projector.fx_px, fy = view_.projector.fy_px;
  // The pinhole pixel of a vertex; nullopt at or behind the near plane.
  auto pixel = [&](const SceneVertex& v) -> std::optional<Eigen::Vector2d> {
    const Eigen::Vector3d c =
        rotation * Eigen::Vector3d(v.position[0], v.position[1], v.position[2]) + translation;
    if (c.z() <= view_.near_m) return std::nullopt;
    return Eigen::Vector2d(fx * c.x() / c.z() + view_.projector.cx_px,
                           fy * c.y() / c.z() + view_.projector.cy_px);
  };
  // Bounds the work a degenerate request could cause: at most this many triangles.
  constexpr size_t kMaxTessellatedTriangles = 4'000'000;
  std::vector<SceneVertex> vertices;
  vertices.reserve(static_cast<size_t>(scene.NumTriangles()) * 3);
  groups->clear();
  std::vector<std::array<SceneVertex, 3>> stack;
  for (size_t m = 0; m < by_material.size(); ++m) {
    if (by_material[m].empty()) continue;
    Group group;
    group.first_vertex = static_cast<int>(vertices.size());
    group.material = static_cast<int>(m);
    for (int t : by_material[m]) {
      const Eigen::Vector3d n = scene.FaceNormal(t);
      std::array<SceneVertex, 3> tri{};
      for (int k = 0; k < 3; ++k) {
        const int v = scene.triangles[t][k];
        const Eigen::Vector3f& p = scene.positions_in_table_m[v];
        for (int i = 0; i < 3; ++i) {
          tri[k].position[i] = p[i];
          tri[k].normal[i] = static_cast<float>(n[i]);
        }
        if (has_uv) {
          tri[k].uv[0] = scene.texcoords[v].x();
          tri[k].uv[1] = scene.texcoords[v].y();
        }
        group.bounds.extend(p.cast<double>());
      }
      stack.push_back(tri);
      while (!stack.empty()) {
        const std::array<SceneVertex, 3> a = stack.back();
        stack.pop_back();
        int longest = -1;
        double longest2 = max_edge2;
        if (tessellate && vertices.size() / 3 + stack.size() < kMaxTessellatedTriangles) {
          const std::optional<Eigen::Vector2d> px[3] = {pixel(a[0]), pixel(a[1]), pixel(a[2])};
          // Off the image (all three corners beyond one of its sides, with a margin of one
          // edge): nothing of it is seen, it is left whole.
          bool off_image = !(px[0] && px[1] && px[2]);
          for (int axis = 0; axis < 2 && !off_image; ++axis) {
            const double size = axis == 0 ? size_.width : size_.height;
            const double lo = -edge_px, hi = size + edge_px;
            off_image = ((*px[0])[axis] < lo && (*px[1])[axis] < lo && (*px[2])[axis] < lo) ||
                        ((*px[0])[axis] > hi && (*px[1])[axis] > hi && (*px[2])[axis] > hi);
          }
          for (int e = 0; e < 3 && !off_image; ++e) {
            const double d2 = (*px[e] - *px[(e + 1) % 3]).squaredNorm();
            if (d2 > longest2) {
              longest2 = d2;
              longest = e;
            }
          }
        }
        if (longest < 0) {
          vertices.insert(vertices.end(), a.begin(), a.end());
          continue;
        }
        // Split edge (longest, longest + 1) at its midpoint.
        const int i0 = longest, i1 = (longest + 1) % 3, i2 = (longest + 2) % 3;
        SceneVertex mid = a[i0];
        for (int i = 0; i < 3; ++i)
          mid.position[i] = 0.5f * (a[i0].position[i] + a[i1].position[i]);
        for (int i = 0; i < 2; ++i) mid.uv[i] = 0.5f * (a[i0].uv[i] + a[i1].uv[i]);
        stack.push_back({a[i0], mid, a[i2]});
        stack.push_back({mid, a[i1], a[i2]});
      }
    }
    group.vertex_count = static_cast<int>(vertices.size()) - group.first_vertex;
    groups->push_back(group);
  }
  if (face_normals) {
    face_normals->clear();
    for (size_t v = 0; v + 2 < vertices.size(); v += 3) {
      face_normals->insert(face_normals->end(), vertices[v].normal, vertices[v].normal + 3);
    }
  }
  glBindVertexArray(vao);
  glBindBuffer(GL_ARRAY_BUFFER, vbo);
  glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(vertices.size() * sizeof(SceneVertex)),
               vertices.data(), GL_STATIC_DRAW);
  glEnableVertexAttribArray(0);
  glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, sizeof(SceneVertex),
                        reinterpret_cast<void*>(offsetof(SceneVertex, position)));
  glEnableVertexAttribArray(1);
  glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, sizeof(SceneVertex),
                        reinterpret_cast<void*>(offsetof(SceneVertex, normal)));
  glEnableVertexAttribArray(2);
  glVertexAttribPointer(2, 2, GL_FLOAT, GL_FALSE, sizeof(SceneVertex),
                        reinterpret_cast<void*>(offsetof(SceneVertex, uv)));
  glBindVertexArray(0);
  return CheckGl("uploading the model");
}

Renderer::~Renderer() {
  if (!context_->MakeCurrent().ok()) return;
  for (GLuint p : {shadow_program_, blit_program_}) {
    if (p) glDeleteProgram(p);
  }
  for (const auto& [key, p] : variants_) glDeleteProgram(p);
  std::vector<GLuint> textures = textures_;
  for (const auto& [key, slot] : prepared_) {
    if (slot.texture) textures.push_back(slot.texture);
  }
  textures.insert(textures.end(), retired_textures_.begin(), retired_textures_.end());
  for (GLuint t : {shadow_texture_, ideal_colour_, warp_texture_, mask_texture_, pattern_texture_,
                   floor_texture_, face_normals_, face_light_, lit_texture_}) {
    if (t) textures.push_back(t);
  }
  for (const SurfaceTarget* t : {&surface_, &ideal_surface_}) {
    for (GLuint id : {t->geometry, t->colour}) {
      if (id) textures.push_back(id);
    }
    if (t->depth) glDeleteRenderbuffers(1, &t->depth);
    if (t->fbo) glDeleteFramebuffers(1, &t->fbo);
  }
  if (!textures.empty()) glDeleteTextures(static_cast<GLsizei>(textures.size()), textures.data());
  for (GLuint rb : {ideal_depth_, output_depth_}) {
    if (rb) glDeleteRenderbuffers(1, &rb);
  }
  for (GLuint fb : {shadow_fbo_, ideal_fbo_, face_light_fbo_}) {
    if (fb) glDeleteFramebuffers(1, &fb);
  }
  for (GLuint b : {scene_vbo_, shadow_vbo_, overlay_vbo_}) {
    if (b) glDeleteBuffers(1, &b);
  }
  for (GLuint a : {scene_vao_, shadow_vao_, overlay_vao_, empty_vao_}) {
    if (a) glDeleteVertexArrays(1, &a);
  }
}

Status Renderer::SetView(const ProjectorView& view) {
  if (view.projector.width_px != size_.width || view.projector.height_px != size_.height) {
    return InvalidArgumentError("renderer: the projector is " +
                                std::to_string(view.projector.width_px) + "x" +
                                std::to_string(view.projector.height_px) + " px, the output " +
                                std::to_string(size_.width) + "x" + std::to_string(size_.height));
  }
  ST_RETURN_IF_ERROR(context_->MakeCurrent());
  SyncUsedMaskRows();
  ClearPreparedMasks();  // made with the old view's pre-warp
  view_ = view;
  has_view_ = true;
  last_warped_ = false;
  surface_valid_ = false;
  overlay_view_dirty_ = true;
  const bool packed = view.needs_prewarp() && !options_.fold_prewarp;
  if (!packed && mask_in_warp_texels_) {
    // The mask goes back to a texture of its own.
    mask_rows_.create(size_, CV_MAKETYPE(warp_texels_.depth(), 2));
    const int from_warp[] = {2, 0, 3, 1};
    cv::mixChannels(&warp_texels_, 1, &mask_rows_, 1, from_warp, 2);
    mask_in_warp_texels_ = false;
  }
  const bool fold = options_.fold_prewarp && view.needs_prewarp();
  if (fold) {
    // Edges short enough that the lens model's curvature bends them by at most
    // prewarp_tolerance_px between vertices: a chord of L px deviates by L^2 / 8 x curvature.
    tessellation_px_ = std::clamp(
        std::sqrt(8.0 * options_.prewarp_tolerance_px / std::max(view.max_curvature_per_px, 1e-12)),
        options_.min_tessellation_px, options_.max_tessellation_px);
    ST_RETURN_IF_ERROR(UploadGeometry(scene_vao_, scene_vbo_, tessellation_px_, &groups_));
    geometry_tessellated_ = true;
  } else if (geometry_tessellated_) {
    ST_RETURN_IF_ERROR(UploadGeometry(scene_vao_, scene_vbo_, 0.0, &groups_));
    geometry_tessellated_ = false;
    tessellation_px_ = 0.0;
  }
  // Nearest groups first (by their bounds' centres along the projector's axis): what a building
  // hides of the table then fails the depth test before it is shaded.
  std::vector<std::pair<double, int>> order;
  for (int i = 0; i < static_cast<int>(groups_.size()); ++i) {
    const Eigen::Vector3d centre = view.projector_from_table.rotation * groups_[i].bounds.center() +
                                   view.projector_from_table.translation;
    order.emplace_back(groups_[i].bounds.isEmpty() ? 0.0 : centre.z(), i);
  }
  std::stable_sort(order.begin(), order.end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });
  draw_order_.clear();
  for (const auto& [depth, index] : order) draw_order_.push_back(index);
  if (packed) {
    // OpenCV ideal pixel -> GL texture coordinates of the ideal image; rows in GL order.
    cv::Mat coords(view.source_px.size(), CV_32FC2);
    for (int v = 0; v < coords.rows; ++v) {
      const auto* in = view.source_px.ptr<cv::Vec2f>(v);
      auto* out = coords.ptr<cv::Vec2f>(v);
      for (int u = 0; u < coords.cols; ++u) {
        const cv::Vec2f src = in[u];
        if (!std::isfinite(src[0]) || !std::isfinite(src[1])) {
          out[u] = cv::Vec2f(-1.0f, -1.0f);
        } else {
          out[u] = cv::Vec2f((src[0] + 0.5f) / size_.width, 1.0f - (src[1] + 0.5f) / size_.height);
        }
      }
    }
    // 16-bit normalized for an 8-bit target (0.02 px steps at 1280 px; -1 clamps to 0, and 0
    // and 1 mean "no source"), floats for a float target. Source and mask go in one texture
    // (warp_texels_): one fetch a pixel in the warp instead of two 16-bit fetches, 3-4 ms a
    // frame less on llvmpipe at 1280x800 (docs/render.md).
    const bool is_float = context_->float_output();
    if (!is_float) coords.convertTo(coords, CV_16UC2, 65535.0);
    const cv::Mat source = FlippedContinuous(coords);
    warp_texels_.create(size_, CV_MAKETYPE(source.depth(), 4));
    const int to_source[] = {0, 0, 1, 1};
    cv::mixChannels(&source, 1, &warp_texels_, 1, to_source, 2);
    if (has_mask_ && !mask_in_warp_texels_) {
      const int to_mask[] = {0, 2, 1, 3};
      cv::mixChannels(&mask_rows_, 1, &warp_texels_, 1, to_mask, 2);
    } else if (!has_mask_) {
      // (factor 1, lift 0): what the warp reads when it runs without a mask is unused, but kept
      // defined.
      const int to_mask[] = {0, 2, 1, 3};
      const cv::Mat none(size_, CV_MAKETYPE(source.depth(), 2),
                         cv::Scalar(is_float ? 1.0 : 65535.0, 0.0));
      cv::mixChannels(&none, 1, &warp_texels_, 1, to_mask, 2);
    }
    mask_in_warp_texels_ = has_mask_;
    ST_RETURN_IF_ERROR(EnsureIdealTarget());
    UploadTexels(&warp_texture_, warp_texels_);
  } else if (has_mask_) {
    UploadTexels(&mask_texture_, mask_rows_);
  }
  packed_warp_ = packed;
  return CheckGl("setting the projector view");
}

Status Renderer::CheckMask(const cv::Mat& mask) const {
  if (mask.size() != size_ ||
      (mask.type() != CV_32FC1 && mask.type() != CV_8UC1 && mask.type() != CV_32FC2)) {
    return InvalidArgumentError(
        "renderer: a mask must be CV_32FC1, CV_8UC1 or CV_32FC2 (factor, lift) of the output's "
        "size " +
        std::to_string(size_.width) + "x" + std::to_string(size_.height));
  }
  return OkStatus();
}

bool Renderer::EncodeMask(const cv::Mat& mask, cv::Mat* texels, int stride, int offset) const {
  // One pass over the rows: clamped to [0, 1] (NaN: 0), the factor encoded once (the colour note
  // in renderer.h), the lift linear (added in linear light in the shader); a float target holds
  // linear values. 16-bit normalized for an 8-bit target, converted here: a float upload into a
  // 16-bit texture goes through the driver's per-texel conversion, 2-3x slower on llvmpipe.
  const bool is_float = context_->float_output();
  const int cols = size_.width;
  std::vector<float> factor(cols), lift(cols, 0.0f);
  cv::Mat factor_row(1, cols, CV_32F, factor.data());
  auto unit = [](float x) { return x > 0.0f ? (x < 1.0f ? x : 1.0f) : 0.0f; };
  float lift_max = 0.0f;
  for (int v = 0; v < size_.height; ++v) {
    if (mask.type() == CV_8UC1) {
      const uint8_t* in = mask.ptr<uint8_t>(v);
      for (int u = 0; u < cols; ++u) factor[u] = in[u] * (1.0f / 255.0f);
    } else if (mask.type() == CV_32FC1) {
      const float* in = mask.ptr<float>(v);
      for (int u = 0; u < cols; ++u) factor[u] = unit(in[u]);
    } else {
      const float* in = mask.ptr<float>(v);
      for (int u = 0; u < cols; ++u) {
        factor[u] = unit(in[2 * u]);
        lift[u] = unit(in[2 * u + 1]);
        lift_max = std::max(lift_max, lift[u]);
      }
    }
    if (!is_float) cv::pow(factor_row, 1.0 / options_.display_gamma, factor_row);
    const int gl_row = size_.height - 1 - v;
    if (is_float) {
      float* out = texels->ptr<float>(gl_row) + offset;
      for (int u = 0; u < cols; ++u) {
        out[stride * u] = factor[u];
        out[stride * u + 1] = lift[u];
      }
    } else {
      uint16_t* out = texels->ptr<uint16_t>(gl_row) + offset;
      for (int u = 0; u < cols; ++u) {
        out[stride * u] = static_cast<uint16_t>(factor[u] * 65535.0f + 0.5f);
        out[stride * u + 1] = static_cast<uint16_t>(lift[u] * 65535.0f + 0.5f);
      }
    }
  }
  return lift_max > 0.0f;
}

Status Renderer::SetMask(const cv::Mat& mask) {
  ST_RETURN_IF_ERROR(context_->MakeCurrent());
  ClearPreparedMasks();  // made for the blend before
  used_mask_rows_.release();
  if (mask.empty()) {
    has_mask_ = has_lift_ = false;
    return OkStatus();
  }
  ST_RETURN_IF_ERROR(CheckMask(mask));
  // Into a buffer kept between masks (a re-blend's first frame waits for this swap; the buffers
  // made anew each time cost as much again in page faults; set_mask_ms of
  // sandtable_render_bench): straight into the warp's packed texels (channels 2, 3) when there
  // is a pre-warp, into the mask's own texels otherwise.
  cv::Mat* texels = &mask_rows_;
  int stride = 2, offset = 0;
  if (packed_warp_) {
    texels = &warp_texels_;
    stride = 4;
    offset = 2;
  } else {
    mask_rows_.create(size_, context_->float_output() ? CV_32FC2 : CV_16UC2);
  }
  has_lift_ = EncodeMask(mask, texels, stride, offset);
  has_mask_ = true;
  mask_in_warp_texels_ = packed_warp_;
  if (!options_.fold_prewarp) ST_RETURN_IF_ERROR(EnsureIdealTarget());
  UploadTexels(packed_warp_ ? &warp_texture_ : &mask_texture_, *texels);
  return CheckGl("setting the mask");
}

Status Renderer::PrepareMask(uint64_t key, const cv::Mat& mask) {
  if (mask.empty()) return InvalidArgumentError("renderer: a prepared mask cannot be empty");
  ST_RETURN_IF_ERROR(CheckMask(mask));
  ST_RETURN_IF_ERROR(context_->MakeCurrent());
  for (unsigned int t : retired_textures_) glDeleteTextures(1, &t);
  retired_textures_.clear();
  PreparedMask& slot = prepared_[key];
  slot.rows.create(size_, context_->float_output() ? CV_32FC2 : CV_16UC2);
  slot.has_lift = EncodeMask(mask, &slot.rows, 2, 0);
  slot.packed = packed_warp_;
  if (!options_.fold_prewarp) ST_RETURN_IF_ERROR(EnsureIdealTarget());
  if (packed_warp_) {
    // The warp's source with this mask, in a packed texture of its own.
    warp_texels_.copyTo(prepared_scratch_);
    const int to_mask[] = {0, 2, 1, 3};
    cv::mixChannels(&slot.rows, 1, &prepared_scratch_, 1, to_mask, 2);
    UploadTexels(&slot.texture, prepared_scratch_);
  } else {
    UploadTexels(&slot.texture, slot.rows);
  }
  return CheckGl("preparing a mask");
}

Status Renderer::UseMask(uint64_t key) {
  auto it = prepared_.find(key);
  if (it == prepared_.end() || it->second.packed != packed_warp_) {
    return NotFoundError("renderer: no mask prepared under " + std::to_string(key));
  }
  // The prepared texture becomes the current one; the current one and the other prepared
  // masks (made for the blend before this one) are deleted later, off a re-blend's path.
  unsigned int& current = packed_warp_ ? warp_texture_ : mask_texture_;
  if (current) retired_textures_.push_back(current);
  current = it->second.texture;
  it->second.texture = 0;
  used_mask_rows_ = std::move(it->second.rows);
  has_mask_ = true;
  has_lift_ = it->second.has_lift;
  mask_in_warp_texels_ = packed_warp_;
  for (auto& [k, slot] : prepared_) {
    if (slot.texture) retired_textures_.push_back(slot.texture);
  }
  prepared_.clear();
  return OkStatus();
}

void Renderer::ClearPreparedMasks() {
  if (prepared_.empty() && retired_textures_.empty()) return;
  if (!context_->MakeCurrent().ok()) return;
  for (auto& [k, slot] : prepared_) {
    if (slot.texture) retired_textures_.push_back(slot.texture);
  }
  prepared_.clear();
  for (unsigned int t : retired_textures_) glDeleteTextures(1, &t);
  retired_textures_.clear();
}

void Renderer::SyncUsedMaskRows() {
  if (used_mask_rows_.empty()) return;
  if (mask_in_warp_texels_) {
    const int to_mask[] = {0, 2, 1, 3};
    cv::mixChannels(&used_mask_rows_, 1, &warp_texels_, 1, to_mask, 2);
  } else {
    mask_rows_ = used_mask_rows_;
  }
  used_mask_rows_.release();
}

void Renderer::UploadTexels(unsigned int* texture, const cv::Mat& texels) {
  const bool is_float = texels.depth() == CV_32F;
  const GLenum format = texels.channels() == 4 ? GL_RGBA : GL_RG;
  const GLint internal = texels.channels() == 4 ? (is_float ? GL_RGBA32F : GL_RGBA16)
                                                : (is_float ? GL_RG32F : GL_RG16);
  const GLenum type = is_float ? GL_FLOAT : GL_UNSIGNED_SHORT;
  if (!*texture) {
    *texture =
        MakeTexture2D(internal, size_.width, size_.height, format, type, texels.data, GL_NEAREST);
  } else {
    glBindTexture(GL_TEXTURE_2D, *texture);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, size_.width, size_.height, format, type, texels.data);
  }
}

float Renderer::LiftGamma() const {
  // Encoded output: the lift is added in linear light; a float target is linear already.
  return context_->float_output() ? 1.0f : static_cast<float>(options_.display_gamma);
}

Status Renderer::EnsureIdealTarget() {
  if (ideal_fbo_) return OkStatus();
  const bool is_float = context_->float_output();
  ideal_colour_ =
      MakeTexture2D(is_float ? GL_RGBA32F : GL_RGBA8, size_.width, size_.height, GL_RGBA,
                    is_float ? GL_FLOAT : GL_UNSIGNED_BYTE, nullptr, GL_LINEAR);
  glGenRenderbuffers(1, &ideal_depth_);
  glBindRenderbuffer(GL_RENDERBUFFER, ideal_depth_);
  glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT24, size_.width, size_.height);
  glGenFramebuffers(1, &ideal_fbo_);
  glBindFramebuffer(GL_FRAMEBUFFER, ideal_fbo_);
  glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, ideal_colour_, 0);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, ideal_depth_);
  if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE) {
    return InternalError("OpenGL: the ideal-image framebuffer is incomplete");
  }
  return CheckGl("creating the ideal-image target");
}

Expected<FrameStats> Renderer::Render(const RenderContent& content) {
  const Clock::time_point start = Clock::now();
  ST_RETURN_IF_ERROR(context_->MakeCurrent());
  FrameStats stats;
  auto timed = [&](Pass pass, auto&& draw) -> Status {
    const Clock::time_point t0 = Clock::now();
    Status s = draw();
    if (options_.time_passes) {
      glFinish();
      stats.pass_ms[static_cast<int>(pass)] += MsSince(t0);
    }
    stats.ran[static_cast<int>(pass)] = true;
    return s;
  };
  const GLuint output = context_->output_framebuffer();
  last_deferred_ = last_lit_kept_ = false;
  const bool raw = content.pattern == TestPattern::kProjectorId ||
                   content.pattern == TestPattern::kColourBars ||
                   content.pattern == TestPattern::kRawWhite;
  last_warped_ = false;
  if (raw || !has_view_) {
    // Raw patterns need no calibration; without one, anything else is black.
    ST_RETURN_IF_ERROR(timed(Pass::kPattern, [&] {
      if (!raw) {
        glBindFramebuffer(GL_FRAMEBUFFER, output);
        glViewport(0, 0, size_.width, size_.height);
        glClearColor(0, 0, 0, 1);
        glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
        return OkStatus();
      }
      return DrawPattern(content);
    }));
  } else {
    const bool show = content.pattern == TestPattern::kNone && !content.debug_positions;
    const bool sun = show && content.sun_direction_in_table.has_value() &&
                     content.sun_direction_in_table->z() > 0.0;
    if (sun && (!shadow_sun_ || !shadow_sun_->isApprox(*content.sun_direction_in_table, 1e-9))) {
      ST_RETURN_IF_ERROR(
          timed(Pass::kShadow, [&] { return DrawShadow(*content.sun_direction_in_table); }));
    }
    const bool fold = options_.fold_prewarp;
    const bool deferred = deferred_ && !fold && show && !context_->float_output();
    const Eigen::Vector3d sun_unit =
        sun ? content.sun_direction_in_table->normalized() : Eigen::Vector3d::UnitZ();
    if (deferred && sun && (!face_light_sun_ || !face_light_sun_->isApprox(sun_unit, 1e-12))) {
      // Counted with the shadow pass: both are drawn when the sun moves.
      ST_RETURN_IF_ERROR(timed(Pass::kShadow, [&] { return DrawFaceLight(sun_unit); }));
    }
    if (deferred) {
      // Deferred (renderer.h): the surface cache once per view, then light and overlay.
      if (!surface_valid_) {
        ST_RETURN_IF_ERROR(timed(Pass::kScene, [&] { return DrawSurfaceScene(); }));
        // Packed into output pixels: through the pre-warp (the warp pass), or pixel for pixel
        // (counted with the scene pass).
        const bool prewarp = view_.needs_prewarp();
        ST_RETURN_IF_ERROR(
            timed(prewarp ? Pass::kWarp : Pass::kScene, [&] { return DrawSurfaceWarp(); }));
        stats.ran[static_cast<int>(Pass::kScene)] = surface_groups_drawn_ > 0;
        stats.ran[static_cast<int>(Pass::kWarp)] = prewarp;
      }
      stats.groups_drawn = surface_groups_drawn_;
      stats.groups_culled = surface_groups_culled_;
      stats.scene_triangles = surface_triangles_;
      stats.prewarp = view_.needs_prewarp();
      stats.masked = has_mask_;
      // A sun below the horizon lights with the sky alone (as DrawScene); no sun: unlit.
      const float light =
          !content.sun_direction_in_table
              ? 1.0f
              : static_cast<float>(std::pow(options_.ambient, 1.0 / options_.display_gamma));
      const bool overlay = content.has_overlay();
      // The frame before the mask is kept for Rewarp in a second target of the output
      // framebuffer, where the context's output is a framebuffer object (headless); a window's
      // default framebuffer takes no second target (Rewarp re-lights there).
      ST_RETURN_IF_ERROR(AttachLitTarget(output != 0));
      if (surface_groups_drawn_ == 0 && !has_mask_) {
        // Nothing of the model in the frustum, nothing to lift: black.
        glBindFramebuffer(GL_FRAMEBUFFER, output);
        glViewport(0, 0, size_.width, size_.height);
        glClearColor(0, 0, 0, 1);
        glClear(GL_COLOR_BUFFER_BIT);
      } else {
        ST_RETURN_IF_ERROR(timed(Pass::kLight, [&] { return DrawLight(sun, light); }));
      }
      if (overlay) {
        ST_RETURN_IF_ERROR(timed(Pass::kOverlay, [&] {
          return DrawOverlay(content, /*fold=*/true, &stats, /*against_cache=*/true);
        }));
      }
      last_lit_kept_ = lit_attached_;
      ST_RETURN_IF_ERROR(AttachLitTarget(false));
      last_deferred_ = last_warped_ = true;
      last_sun_ = sun;
      last_light_ = light;
      last_overlay_ = overlay;
      glFinish();
      ST_RETURN_IF_ERROR(CheckGl("rendering a frame"));
      stats.frame_ms = MsSince(start);
      return stats;
    }
    const bool warp = !fold && (view_.needs_prewarp() || has_mask_);
    const GLuint target = warp ? ideal_fbo_ : output;
    ST_RETURN_IF_ERROR(
        timed(Pass::kScene, [&] { return DrawScene(content, target, fold, &stats); }));
    stats.ran[static_cast<int>(Pass::kScene)] = stats.groups_drawn > 0;
    stats.prewarp = view_.needs_prewarp();
    stats.tessellation_px = tessellation_px_;
    stats.masked = has_mask_ && !content.debug_positions;
    if (show && content.has_overlay()) {
      ST_RETURN_IF_ERROR(timed(Pass::kOverlay, [&] { return DrawOverlay(content, fold, &stats); }));
    }
    if (warp) {
      ST_RETURN_IF_ERROR(
          timed(Pass::kWarp, [&] { return DrawWarp(ideal_colour_, view_.needs_prewarp()); }));
      last_warped_ = true;
    }
  }
  glFinish();
  ST_RETURN_IF_ERROR(CheckGl("rendering a frame"));
  stats.frame_ms = MsSince(start);
  return stats;
}

Expected<FrameStats> Renderer::Rewarp() {
  if (!CanRewarp()) {
    return UnavailableError(
        "renderer: no frame to warp again (the last one did not go through the warp pass, or "
        "the view changed since)");
  }
  const Clock::time_point start = Clock::now();
  ST_RETURN_IF_ERROR(context_->MakeCurrent());
  FrameStats stats;
  stats.prewarp = view_.needs_prewarp();
  stats.masked = has_mask_;
  if (last_lit_kept_) {
    // The frame before the mask was kept: the new mask over it, one full-screen pass.
    ST_RETURN_IF_ERROR(DrawWarp(lit_texture_, /*distort=*/false));
    glFinish();
    ST_RETURN_IF_ERROR(CheckGl("masking the last frame again"));
    stats.ran[static_cast<int>(Pass::kWarp)] = true;
    stats.frame_ms = stats.pass_ms[static_cast<int>(Pass::kWarp)] = MsSince(start);
    return stats;
  }
  if (last_deferred_) {
    ST_RETURN_IF_ERROR(DrawLight(last_sun_, last_light_));
    stats.ran[static_cast<int>(Pass::kLight)] = true;
    if (last_overlay_) {
      ST_RETURN_IF_ERROR(DrawOverlayBuffer(/*fold=*/true, /*against_cache=*/true));
      stats.ran[static_cast<int>(Pass::kOverlay)] = true;
      stats.overlay_triangles = overlay_vertices_ / 3;
    }
    glFinish();
    ST_RETURN_IF_ERROR(CheckGl("lighting the last frame again"));
    stats.frame_ms = stats.pass_ms[static_cast<int>(Pass::kLight)] = MsSince(start);
    return stats;
  }
  ST_RETURN_IF_ERROR(DrawWarp(ideal_colour_, view_.needs_prewarp()));
  glFinish();
  ST_RETURN_IF_ERROR(CheckGl("warping the last frame again"));
  stats.ran[static_cast<int>(Pass::kWarp)] = true;
  stats.frame_ms = stats.pass_ms[static_cast<int>(Pass::kWarp)] = MsSince(start);
  return stats;
}

Status Renderer::DrawShadow(const Eigen::Vector3d& sun) {
  // Orthographic from the sun: a frame whose -z looks along the light, fitted to the scene.
  const Eigen::Vector3d z = sun.normalized();
  Eigen::Vector3d x = Eigen::Vector3d::UnitZ().cross(z);
  if (x.norm() < 1e-6) x = Eigen::Vector3d::UnitX();
  x.normalize();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d light_from_table_r;
  light_from_table_r.row(0) = x;
  light_from_table_r.row(1) = y;
  light_from_table_r.row(2) = z;
  Eigen::AlignedBox3d box;
  for (int i = 0; i < 8; ++i) {
    box.extend(light_from_table_r *
               scene_bounds_.corner(static_cast<Eigen::AlignedBox3d::CornerType>(i)));
  }
  const Eigen::Vector3d lo = box.min(), hi = box.max();
  // GL ortho: x, y to [-1, 1]; the eye looks down -z, so depth = -z_light, near = -hi.z.
  const double n = -hi.z() - 0.01, f = -lo.z() + 0.01;
  Eigen::Matrix4d ortho = Eigen::Matrix4d::Identity();
  ortho(0, 0) = 2.0 / (hi.x() - lo.x());
  ortho(0, 3) = -(hi.x() + lo.x()) / (hi.x() - lo.x());
  ortho(1, 1) = 2.0 / (hi.y() - lo.y());
  ortho(1, 3) = -(hi.y() + lo.y()) / (hi.y() - lo.y());
  ortho(2, 2) = -2.0 / (f - n);
  ortho(2, 3) = -(f + n) / (f - n);
  Eigen::Matrix4d light_from_table = Eigen::Matrix4d::Identity();
  light_from_table.topLeftCorner<3, 3>() = light_from_table_r;
  sun_clip_from_table_ = ortho * light_from_table;
  shadow_sun_ = sun;

  glBindFramebuffer(GL_FRAMEBUFFER, shadow_fbo_);
  glViewport(0, 0, options_.shadow_map_px, options_.shadow_map_px);
  glEnable(GL_DEPTH_TEST);
  glDepthMask(GL_TRUE);
  glDepthFunc(GL_LESS);
  glClear(GL_DEPTH_BUFFER_BIT);
  glEnable(GL_POLYGON_OFFSET_FILL);
  glPolygonOffset(2.0f, 4.0f);
  glUseProgram(shadow_program_);
  const glm::mat4 m = ToGlm(sun_clip_from_table_);
  glUniformMatrix4fv(glGetUniformLocation(shadow_program_, "u_sun_clip_from_table"), 1, GL_FALSE,
                     glm::value_ptr(m));
  glBindVertexArray(shadow_vao_);
  for (const Group& g : shadow_groups_) glDrawArrays(GL_TRIANGLES, g.first_vertex, g.vertex_count);
  glDisable(GL_POLYGON_OFFSET_FILL);
  return CheckGl("drawing the shadow map");
}

void Renderer::SetDistortionUniforms(unsigned int program, bool distort) {
  auto loc = [&](const char* name) { return glGetUniformLocation(program, name); };
  if (!distort) return;
  const CameraModel& p = view_.projector;
  const glm::mat4 m = ToGlm(Matrix(view_.projector_from_table));
  glUniformMatrix4fv(loc("u_camera_from_table"), 1, GL_FALSE, glm::value_ptr(m));
  glUniform4f(loc("u_intrinsics"), static_cast<float>(p.fx_px), static_cast<float>(p.fy_px),
              static_cast<float>(p.cx_px), static_cast<float>(p.cy_px));
  glUniform2f(loc("u_size_px"), static_cast<float>(size_.width), static_cast<float>(size_.height));
  glUniform3f(loc("u_radial"), static_cast<float>(p.distortion.k1),
              static_cast<float>(p.distortion.k2), static_cast<float>(p.distortion.k3));
  glUniform2f(loc("u_tangential"), static_cast<float>(p.distortion.p1),
              static_cast<float>(p.distortion.p2));
  glUniform1f(loc("u_domain_r2"), static_cast<float>(view_.distortion_domain_r2));
}

Expected<unsigned int> Renderer::Variant(ProgramKind kind, int mode, bool textured, bool sun,
                                         bool masked, bool distort, bool packed) {
  const bool lifted = masked && has_lift_;
  const int key = static_cast<int>(kind) | mode << 3 | textured << 6 | sun << 7 | masked << 8 |
                  distort << 9 | lifted << 10 | packed << 11;
  if (auto it = variants_.find(key); it != variants_.end()) return it->second;
  const std::string defines = "#version 330 core\n#define MODE " + std::to_string(mode) +
                              "\n#define TEXTURED " + std::to_string(textured) + "\n#define SUN " +
                              std::to_string(sun) + "\n#define MASKED " + std::to_string(masked) +
                              "\n#define DISTORT " + std::to_string(distort) + "\n#define LIFTED " +
                              std::to_string(lifted) + "\n#define PACKED " +
                              std::to_string(packed) + "\n";
  // Each kind's shaders (a null vertex shader: the full-screen quad's) and name, in ProgramKind's
  // order.
  struct Source {
    const char* vertex;
    const char* fragment;
    const char* name;
  };
  static const Source kSources[7] = {
      {kSceneVertex.c_str(), kSceneFragment, "scene"},
      {kOverlayVertex.c_str(), kOverlayFragment, "overlay"},
      {nullptr, kWarpFragment, "warp"},
      {kSurfaceVertex, kSurfaceFragment, "surface"},
      {nullptr, kSurfaceWarpFragment, "surface warp"},
      {nullptr, kLightFragment, "light"},
      {nullptr, kFaceLightFragment, "face light"},
  };
  const Source& source = kSources[static_cast<int>(kind)];
  const std::string vertex =
      source.vertex ? defines + source.vertex : std::string(kFullScreenQuadVertexShader);
  const std::string fragment = defines + kFragmentCommon + source.fragment;
  const char* name = source.name;
  Expected<unsigned int> program =
      LinkProgram("variant " + std::to_string(key) + " of the " + name + " program", vertex.c_str(),
                  fragment.c_str());
  if (!program.ok()) return program.status();
  variants_[key] = *program;
  return *program;
}

std::pair<Eigen::Vector4d, int> Renderer::GroupMaterial(const Group& g) const {
  if (g.material < 0 || g.material >= static_cast<int>(material_colours_.size())) {
    return {Eigen::Vector4d(1, 1, 1, 1), -1};
  }
  const int texture = material_textures_[g.material];
  return {material_colours_[g.material],
          texture >= 0 && texture < static_cast<int>(textures_.size()) ? texture : -1};
}

Status Renderer::DrawScene(const RenderContent& content, unsigned int target, bool fold,
                           FrameStats* stats) {
  glBindFramebuffer(GL_FRAMEBUFFER, target);
  glViewport(0, 0, size_.width, size_.height);
  glClearColor(0, 0, 0, 1);
  glClearDepth(1.0);
  glDepthMask(GL_TRUE);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glDisable(GL_CULL_FACE);  // thin walls and open meshes are seen from either side
  const int mode = content.debug_positions                      ? 3
                   : content.pattern == TestPattern::kWhite     ? 1
                   : content.pattern == TestPattern::kTableGrid ? 2
                   : content.pattern == TestPattern::kBlack     ? 4
                                                                : 0;
  const bool sun = mode == 0 && content.sun_direction_in_table.has_value();
  // The sun below the horizon lights nothing: ambient only.
  const Eigen::Vector3d sun_direction = sun && content.sun_direction_in_table->z() > 0.0
                                            ? content.sun_direction_in_table->normalized()
                                            : Eigen::Vector3d::Zero();
  const bool masked = fold && has_mask_ && mode != 3;
  const bool distort = fold && view_.needs_prewarp();
  const glm::mat4 clip = ToGlm(view_.clip_from_table);
  const glm::mat4 sun_clip = ToGlm(sun_clip_from_table_);
  glActiveTexture(GL_TEXTURE2);
  glBindTexture(GL_TEXTURE_2D, mask_texture_);
  glActiveTexture(GL_TEXTURE1);
  glBindTexture(GL_TEXTURE_2D, shadow_texture_);
  glActiveTexture(GL_TEXTURE0);
  glBindVertexArray(scene_vao_);
  GLuint current = 0;
  for (int index : draw_order_) {
    const Group& g = groups_[index];
    if (OutsideFrustum(view_.clip_from_table, g.bounds)) {
      ++stats->groups_culled;
      continue;
    }
    ++stats->groups_drawn;
    const auto [colour, texture] = GroupMaterial(g);
    const bool textured = mode == 0 && texture >= 0;
    Expected<unsigned int> program =
        Variant(ProgramKind::kScene, mode, textured, sun, masked, distort);
    if (!program.ok()) return program.status();
    auto loc = [&](const char* name) { return glGetUniformLocation(*program, name); };
    if (*program != current) {
      current = *program;
      glUseProgram(current);
      glUniformMatrix4fv(loc("u_clip_from_table"), 1, GL_FALSE, glm::value_ptr(clip));
      glUniformMatrix4fv(loc("u_sun_clip_from_table"), 1, GL_FALSE, glm::value_ptr(sun_clip));
      const glm::vec3 d = ToGlm(sun_direction);
      glUniform3f(loc("u_sun_direction"), d.x, d.y, d.z);
      glUniform1f(loc("u_ambient"), static_cast<float>(options_.ambient));
      glUniform1f(loc("u_inverse_gamma"), static_cast<float>(1.0 / options_.display_gamma));
      SetDistortionUniforms(current, distort);
      glUniform1i(loc("u_mask"), 2);
      glUniform1f(loc("u_lift_gamma"), LiftGamma());
      glUniform1f(loc("u_grid_spacing_m"), static_cast<float>(options_.grid_spacing_m));
      glUniform1f(loc("u_grid_half_line_m"), static_cast<float>(0.5 * options_.grid_line_width_m));
      glUniform1i(loc("u_texture"), 0);
      glUniform1i(loc("u_shadow"), 1);
    }
    glUniform4f(loc("u_base_colour"), static_cast<float>(colour[0]), static_cast<float>(colour[1]),
                static_cast<float>(colour[2]), static_cast<float>(colour[3]));
    if (textured) glBindTexture(GL_TEXTURE_2D, textures_[texture]);
    glDrawArrays(GL_TRIANGLES, g.first_vertex, g.vertex_count);
    stats->scene_triangles += g.vertex_count / 3;
  }
  return CheckGl("drawing the scene");
}

Status Renderer::DrawOverlay(const RenderContent& content, bool fold, FrameStats* stats,
                             bool against_cache) {
  if (content.overlay_version != overlay_version_ || overlay_view_dirty_) {
    const std::vector<OverlayVertex> vertices =
        BuildOverlay(content, view_.centre_in_table_m, options_.overlay);
    glBindBuffer(GL_ARRAY_BUFFER, overlay_vbo_);
    glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(vertices.size() * sizeof(OverlayVertex)),
                 vertices.data(), GL_DYNAMIC_DRAW);
    overlay_vertices_ = static_cast<int>(vertices.size());
    overlay_version_ = content.overlay_version;
    overlay_view_dirty_ = false;
    stats->overlay_rebuilt = true;
  }
  stats->overlay_triangles = overlay_vertices_ / 3;
  return DrawOverlayBuffer(fold, against_cache);
}

Status Renderer::DrawOverlayBuffer(bool fold, bool against_cache) {
  if (against_cache) {
    glDisable(GL_DEPTH_TEST);  // tested against the surface cache in the shader
  } else {
    // Same target as the scene (its depth buffer is still bound): tested, not written.
    glEnable(GL_DEPTH_TEST);
    glDepthFunc(GL_LEQUAL);
    glDepthMask(GL_FALSE);
  }
  const bool distort = fold && view_.needs_prewarp();
  // Folded with a pre-warp pass in use (a deferred frame): the mask is in the warp's texture.
  const bool packed = fold && packed_warp_;
  const int mode = !against_cache ? 0 : lit_attached_ ? 2 : 1;
  Expected<unsigned int> program =
      Variant(ProgramKind::kOverlay, mode, false, false, fold && has_mask_, distort, packed);
  if (!program.ok()) return program.status();
  glUseProgram(*program);
  if (against_cache) {
    const glm::mat4 m = ToGlm(Matrix(view_.projector_from_table));
    glUniformMatrix4fv(glGetUniformLocation(*program, "u_view_from_table"), 1, GL_FALSE,
                       glm::value_ptr(m));
    // A stroke is lifted towards the projector (OverlayOptions::lift_m); what is behind a surface
    // by more than a tenth of a millimetre is hidden.
    glUniform1f(glGetUniformLocation(*program, "u_depth_tolerance_m"), 1e-4f);
    glUniform1i(glGetUniformLocation(*program, "u_cache"), 3);
    glActiveTexture(GL_TEXTURE3);
    glBindTexture(GL_TEXTURE_2D, surface_.geometry);
  }
  const glm::mat4 clip = ToGlm(view_.clip_from_table);
  glUniformMatrix4fv(glGetUniformLocation(*program, "u_clip_from_table"), 1, GL_FALSE,
                     glm::value_ptr(clip));
  SetDistortionUniforms(*program, distort);
  glUniform1i(glGetUniformLocation(*program, "u_mask"), 2);
  glUniform1f(glGetUniformLocation(*program, "u_lift_gamma"), LiftGamma());
  glActiveTexture(GL_TEXTURE2);
  glBindTexture(GL_TEXTURE_2D, packed ? warp_texture_ : mask_texture_);
  glActiveTexture(GL_TEXTURE0);
  glBindVertexArray(overlay_vao_);
  glDrawArrays(GL_TRIANGLES, 0, overlay_vertices_);
  glDepthMask(GL_TRUE);
  return CheckGl("drawing the overlay");
}

Status Renderer::EnsureSurfaceTargets() {
  if (surface_.fbo) return OkStatus();
  auto attach = [&](SurfaceTarget* t, GLuint colour) -> Status {
    glGenFramebuffers(1, &t->fbo);
    glBindFramebuffer(GL_FRAMEBUFFER, t->fbo);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, t->geometry, 0);
    if (colour) {
      glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT1, GL_TEXTURE_2D, colour, 0);
      glGenRenderbuffers(1, &t->depth);
      glBindRenderbuffer(GL_RENDERBUFFER, t->depth);
      glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT24, size_.width, size_.height);
      glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, t->depth);
    }
    const GLenum buffers[2] = {GL_COLOR_ATTACHMENT0, GL_COLOR_ATTACHMENT1};
    glDrawBuffers(colour ? 2 : 1, buffers);
    if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE) {
      return InternalError("OpenGL: the surface cache's framebuffer is incomplete");
    }
    return OkStatus();
  };
  // The ideal cache: geometry, filterable colour, depth. The output cache: the packed texel.
  ideal_surface_.geometry = MakeTexture2D(GL_RGBA32UI, size_.width, size_.height, GL_RGBA_INTEGER,
                                          GL_UNSIGNED_INT, nullptr, GL_NEAREST);
  ideal_surface_.colour = MakeTexture2D(GL_RGBA8, size_.width, size_.height, GL_RGBA,
                                        GL_UNSIGNED_BYTE, nullptr, GL_LINEAR);
  ST_RETURN_IF_ERROR(attach(&ideal_surface_, ideal_surface_.colour));
  surface_.geometry = MakeTexture2D(GL_RGBA32UI, size_.width, size_.height, GL_RGBA_INTEGER,
                                    GL_UNSIGNED_INT, nullptr, GL_NEAREST);
  ST_RETURN_IF_ERROR(attach(&surface_, 0));
  return CheckGl("creating the surface cache");
}

// The model into the ideal surface cache (DrawSurfaceWarp packs it into output pixels). Groups
// culled and drawn nearest first as in DrawScene.
Status Renderer::DrawSurfaceScene() {
  ST_RETURN_IF_ERROR(EnsureSurfaceTargets());
  glBindFramebuffer(GL_FRAMEBUFFER, ideal_surface_.fbo);
  glViewport(0, 0, size_.width, size_.height);
  const GLuint no_surface[4] = {0, 0, 0, 0};  // face 0: no surface
  const GLfloat black[4] = {0, 0, 0, 0};
  glClearBufferuiv(GL_COLOR, 0, no_surface);
  glClearBufferfv(GL_COLOR, 1, black);
  glClearDepth(1.0);
  glDepthMask(GL_TRUE);
  glClear(GL_DEPTH_BUFFER_BIT);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glDisable(GL_CULL_FACE);
  const glm::mat4 clip = ToGlm(view_.clip_from_table);
  const glm::mat4 camera = ToGlm(Matrix(view_.projector_from_table));
  glActiveTexture(GL_TEXTURE0);
  glBindVertexArray(scene_vao_);
  surface_groups_drawn_ = surface_groups_culled_ = surface_triangles_ = 0;
  GLuint current = 0;
  for (int index : draw_order_) {
    const Group& g = groups_[index];
    if (OutsideFrustum(view_.clip_from_table, g.bounds)) {
      ++surface_groups_culled_;
      continue;
    }
    ++surface_groups_drawn_;
    const auto [colour, texture] = GroupMaterial(g);
    const bool textured = texture >= 0;
    Expected<unsigned int> program =
        Variant(ProgramKind::kSurface, 0, textured, false, false, false);
    if (!program.ok()) return program.status();
    auto loc = [&](const char* name) { return glGetUniformLocation(*program, name); };
    if (*program != current) {
      current = *program;
      glUseProgram(current);
      glUniformMatrix4fv(loc("u_clip_from_table"), 1, GL_FALSE, glm::value_ptr(clip));
      glUniformMatrix4fv(loc("u_camera_from_table"), 1, GL_FALSE, glm::value_ptr(camera));
      glUniform1f(loc("u_height_px"), static_cast<float>(size_.height));
      glUniform1i(loc("u_texture"), 0);
    }
    glUniform1i(loc("u_first_face"), g.first_vertex / 3);
    glUniform4f(loc("u_base_colour"), static_cast<float>(colour[0]), static_cast<float>(colour[1]),
                static_cast<float>(colour[2]), static_cast<float>(colour[3]));
    if (textured) glBindTexture(GL_TEXTURE_2D, textures_[texture]);
    glDrawArrays(GL_TRIANGLES, g.first_vertex, g.vertex_count);
    surface_triangles_ += g.vertex_count / 3;
  }
  return CheckGl("drawing the surface cache");
}

Status Renderer::DrawSurfaceWarp() {
  glBindFramebuffer(GL_FRAMEBUFFER, surface_.fbo);
  glViewport(0, 0, size_.width, size_.height);
  glDisable(GL_DEPTH_TEST);
  Expected<unsigned int> program =
      Variant(ProgramKind::kSurfaceWarp, 0, false, false, false, view_.needs_prewarp());
  if (!program.ok()) return program.status();
  glUseProgram(*program);
  glUniform1i(glGetUniformLocation(*program, "u_colour"), 0);
  glUniform1i(glGetUniformLocation(*program, "u_warp"), 1);
  glUniform1i(glGetUniformLocation(*program, "u_geometry"), 3);
  glActiveTexture(GL_TEXTURE1);
  glBindTexture(GL_TEXTURE_2D, warp_texture_);
  glActiveTexture(GL_TEXTURE3);
  glBindTexture(GL_TEXTURE_2D, ideal_surface_.geometry);
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D, ideal_surface_.colour);
  glBindVertexArray(empty_vao_);
  glDrawArrays(GL_TRIANGLE_STRIP, 0, 4);
  surface_valid_ = true;
  return CheckGl("packing the surface cache");
}

// The sun's light on each face (kFaceLightFragment), for a unit direction above the horizon.
Status Renderer::DrawFaceLight(const Eigen::Vector3d& sun) {
  glBindFramebuffer(GL_FRAMEBUFFER, face_light_fbo_);
  glViewport(0, 0, face_table_size_.width, face_table_size_.height);
  glDisable(GL_DEPTH_TEST);
  Expected<unsigned int> program = Variant(ProgramKind::kFaceLight, 0, false, false, false, false);
  if (!program.ok()) return program.status();
  glUseProgram(*program);
  auto loc = [&](const char* name) { return glGetUniformLocation(*program, name); };
  const glm::vec3 d = ToGlm(sun);
  glUniform3f(loc("u_sun_direction"), d.x, d.y, d.z);
  glUniform1f(loc("u_ambient"), static_cast<float>(options_.ambient));
  glUniform1f(loc("u_inverse_gamma"), static_cast<float>(1.0 / options_.display_gamma));
  glUniform1i(loc("u_normals"), 0);
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D, face_normals_);
  glBindVertexArray(empty_vao_);
  glDrawArrays(GL_TRIANGLE_STRIP, 0, 4);
  face_light_sun_ = sun;
  return CheckGl("drawing the faces' light");
}

Status Renderer::AttachLitTarget(bool attach) {
  if (attach == lit_attached_) return OkStatus();
  if (attach && !lit_texture_) {
    lit_texture_ = MakeTexture2D(GL_RGBA8, size_.width, size_.height, GL_RGBA, GL_UNSIGNED_BYTE,
                                 nullptr, GL_NEAREST);
  }
  glBindFramebuffer(GL_FRAMEBUFFER, context_->output_framebuffer());
  glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT1, GL_TEXTURE_2D,
                         attach ? lit_texture_ : 0, 0);
  const GLenum buffers[2] = {GL_COLOR_ATTACHMENT0, GL_COLOR_ATTACHMENT1};
  glDrawBuffers(attach ? 2 : 1, buffers);
  lit_attached_ = attach;
  if (attach && glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE) {
    (void)AttachLitTarget(false);
    return InternalError("OpenGL: the output framebuffer takes no second target");
  }
  return CheckGl(attach ? "attaching the lit frame's target" : "detaching the lit frame's target");
}

// One full-screen pass into the output. `sun`: lit by the sun (face light x shadow; both drawn
// for the current sun), otherwise times `light`.
Status Renderer::DrawLight(bool sun, float light) {
  glBindFramebuffer(GL_FRAMEBUFFER, context_->output_framebuffer());
  glViewport(0, 0, size_.width, size_.height);
  glDisable(GL_DEPTH_TEST);
  Expected<unsigned int> program = Variant(ProgramKind::kLight, lit_attached_ ? 1 : 0, false, sun,
                                           has_mask_, false, packed_warp_);
  if (!program.ok()) return program.status();
  glUseProgram(*program);
  auto loc = [&](const char* name) { return glGetUniformLocation(*program, name); };
  const Eigen::Matrix4d table_from_camera = Matrix(view_.projector_from_table.Inverse());
  const glm::mat4 sun_clip = ToGlm(Eigen::Matrix4d(sun_clip_from_table_ * table_from_camera));
  glUniformMatrix4fv(loc("u_sun_clip_from_camera"), 1, GL_FALSE, glm::value_ptr(sun_clip));
  const CameraModel& p = view_.projector;
  glUniform4f(loc("u_inverse_intrinsics"), static_cast<float>(1.0 / p.fx_px),
              static_cast<float>(1.0 / p.fy_px), static_cast<float>(p.cx_px),
              static_cast<float>(p.cy_px));
  glUniform1f(loc("u_ambient_encoded"),
              static_cast<float>(std::pow(options_.ambient, 1.0 / options_.display_gamma)));
  glUniform1f(loc("u_light"), light);
  glUniform1f(loc("u_lift_gamma"), LiftGamma());
  glUniform1i(loc("u_shadow"), 1);
  glUniform1i(loc("u_mask"), 2);
  glUniform1i(loc("u_cache"), 3);
  glUniform1i(loc("u_face_light"), 4);
  glActiveTexture(GL_TEXTURE1);
  glBindTexture(GL_TEXTURE_2D, shadow_texture_);
  glActiveTexture(GL_TEXTURE2);
  glBindTexture(GL_TEXTURE_2D, packed_warp_ ? warp_texture_ : mask_texture_);
  glActiveTexture(GL_TEXTURE3);
  glBindTexture(GL_TEXTURE_2D, surface_.geometry);
  glActiveTexture(GL_TEXTURE4);
  glBindTexture(GL_TEXTURE_2D, face_light_);
  glActiveTexture(GL_TEXTURE0);
  glBindVertexArray(empty_vao_);
  glDrawArrays(GL_TRIANGLE_STRIP, 0, 4);
  return CheckGl("drawing the light pass");
}

// The warp pass: output pixel p shows `image` (the ideal image through the pre-warp when
// `distort`, else pixel for pixel) times the mask.
Status Renderer::DrawWarp(unsigned int image, bool distort) {
  glBindFramebuffer(GL_FRAMEBUFFER, context_->output_framebuffer());
  glViewport(0, 0, size_.width, size_.height);
  glDisable(GL_DEPTH_TEST);
  Expected<unsigned int> program =
      Variant(ProgramKind::kWarp, 0, false, false, has_mask_, distort, packed_warp_);
  if (!program.ok()) return program.status();
  glUseProgram(*program);
  auto loc = [&](const char* name) { return glGetUniformLocation(*program, name); };
  glUniform1i(loc("u_image"), 0);
  glUniform1i(loc("u_warp"), 1);
  glUniform1i(loc("u_mask"), 2);
  glUniform1f(loc("u_lift_gamma"), LiftGamma());
  glActiveTexture(GL_TEXTURE1);
  glBindTexture(GL_TEXTURE_2D, warp_texture_);
  glActiveTexture(GL_TEXTURE2);
  glBindTexture(GL_TEXTURE_2D, packed_warp_ ? warp_texture_ : mask_texture_);
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D, image);
  glBindVertexArray(empty_vao_);
  glDrawArrays(GL_TRIANGLE_STRIP, 0, 4);
  return CheckGl("drawing the warp pass");
}

Status Renderer::DrawPattern(const RenderContent& content) {
  glBindFramebuffer(GL_FRAMEBUFFER, context_->output_framebuffer());
  glViewport(0, 0, size_.width, size_.height);
  glDisable(GL_DEPTH_TEST);
  if (content.pattern == TestPattern::kRawWhite) {
    glClearColor(1, 1, 1, 1);
    glClear(GL_COLOR_BUFFER_BIT);
    glClearColor(0, 0, 0, 1);
    return CheckGl("drawing raw white");
  }
  if (pattern_uploaded_ != content.pattern || (content.pattern == TestPattern::kProjectorId &&
                                               pattern_id_uploaded_ != content.projector_id)) {
    const cv::Mat image = content.pattern == TestPattern::kProjectorId
                              ? ProjectorIdPattern(size_, content.projector_id)
                              : ColourBarsPattern(size_);
    if (pattern_texture_) glDeleteTextures(1, &pattern_texture_);
    pattern_texture_ = MakeTexture2D(GL_RGB8, size_.width, size_.height, GL_RGB, GL_UNSIGNED_BYTE,
                                     image.data, GL_NEAREST);
    pattern_uploaded_ = content.pattern;
    pattern_id_uploaded_ = content.projector_id;
  }
  glUseProgram(blit_program_);
  glUniform1i(glGetUniformLocation(blit_program_, "u_image"), 0);
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D, pattern_texture_);
  glBindVertexArray(empty_vao_);
  glDrawArrays(GL_TRIANGLE_STRIP, 0, 4);
  return CheckGl("drawing a test pattern");
}

Expected<double> Renderer::RenderFloor() {
  ST_RETURN_IF_ERROR(context_->MakeCurrent());
  glFinish();
  const Clock::time_point start = Clock::now();
  glBindFramebuffer(GL_FRAMEBUFFER, context_->output_framebuffer());
  glViewport(0, 0, size_.width, size_.height);
  glDisable(GL_DEPTH_TEST);
  glUseProgram(blit_program_);
  glUniform1i(glGetUniformLocation(blit_program_, "u_image"), 0);
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D, floor_texture_);
  glBindVertexArray(empty_vao_);
  glDrawArrays(GL_TRIANGLE_STRIP, 0, 4);
  glFinish();
  const double ms = MsSince(start);
  ST_RETURN_IF_ERROR(CheckGl("drawing the floor"));
  return ms;
}

}  // namespace sandtable::node
