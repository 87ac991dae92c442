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

// sRGB transfer functions, shared by the scene and warp programs.
constexpr const char* kTransfer = R"(
float Encode(float l) { return l <= 0.0031308 ? 12.92 * l : 1.055 * pow(l, 1.0 / 2.4) - 0.055; }
float Decode(float e) { return e <= 0.04045 ? e / 12.92 : pow((e + 0.055) / 1.055, 2.4); }
vec3 Encode(vec3 c) { return vec3(Encode(c.r), Encode(c.g), Encode(c.b)); }
vec3 Decode(vec3 c) { return vec3(Decode(c.r), Decode(c.g), Decode(c.b)); }
)";

constexpr const char* kSceneVertex = R"(#version 330 core
layout(location = 0) in vec3 a_position;
layout(location = 1) in vec3 a_normal;
layout(location = 2) in vec2 a_uv;
uniform mat4 u_clip_from_table;
uniform mat4 u_sun_clip_from_table;
out vec3 v_position;
out vec3 v_normal;
out vec2 v_uv;
out vec3 v_sun;
void main() {
  v_position = a_position;
  v_normal = a_normal;
  v_uv = a_uv;
  v_sun = (u_sun_clip_from_table * vec4(a_position, 1.0)).xyz * 0.5 + 0.5;
  gl_Position = u_clip_from_table * vec4(a_position, 1.0);
}
)";

// u_mode: 0 the show, 1 white, 2 the table grid, 3 table positions (float targets).
const std::string kSceneFragment = std::string(R"(#version 330 core
uniform int u_mode;
uniform vec4 u_base_colour;
uniform bool u_textured;
uniform sampler2D u_texture;
uniform bool u_sun;
uniform vec3 u_sun_direction;
uniform float u_ambient;
uniform sampler2DShadow u_shadow;
uniform float u_grid_spacing_m;
uniform float u_grid_half_line_m;
in vec3 v_position;
in vec3 v_normal;
in vec2 v_uv;
in vec3 v_sun;
out vec4 o_colour;
)") + kTransfer + R"(
void main() {
  if (u_mode == 1) { o_colour = vec4(1.0); return; }
  if (u_mode == 3) { o_colour = vec4(v_position, 1.0); return; }
  if (u_mode == 2) {
    vec2 cells = v_position.xy / u_grid_spacing_m;
    vec2 off_m = abs(cells - round(cells)) * u_grid_spacing_m;
    vec2 half_m = max(vec2(u_grid_half_line_m), 0.75 * fwidth(v_position.xy));
    float on = (off_m.x < half_m.x || off_m.y < half_m.y) ? 1.0 : 0.0;
    o_colour = vec4(vec3(on), 1.0);
    return;
  }
  vec4 albedo = u_base_colour;
  if (u_textured) albedo *= texture(u_texture, v_uv);
  float light = 1.0;
  if (u_sun) {
    float lambert = max(dot(normalize(v_normal), u_sun_direction), 0.0);
    float lit = lambert > 0.0 ? texture(u_shadow, v_sun) : 0.0;
    light = u_ambient + (1.0 - u_ambient) * lambert * lit;
  }
  o_colour = vec4(Encode(clamp(albedo.rgb * light, 0.0, 1.0)), 1.0);
}
)";

constexpr const char* kShadowVertex = R"(#version 330 core
layout(location = 0) in vec3 a_position;
uniform mat4 u_sun_clip_from_table;
void main() { gl_Position = u_sun_clip_from_table * vec4(a_position, 1.0); }
)";
constexpr const char* kShadowFragment = R"(#version 330 core
void main() {}
)";

constexpr const char* kOverlayVertex = R"(#version 330 core
layout(location = 0) in vec3 a_position;
layout(location = 1) in vec4 a_colour;
uniform mat4 u_clip_from_table;
out vec4 v_colour;
void main() {
  v_colour = a_colour;
  gl_Position = u_clip_from_table * vec4(a_position, 1.0);
}
)";
constexpr const char* kOverlayFragment = R"(#version 330 core
in vec4 v_colour;
out vec4 o_colour;
void main() { o_colour = v_colour; }
)";

// Full-screen triangle strip from gl_VertexID.
constexpr const char* kQuadVertex = R"(#version 330 core
void main() {
  vec2 corner = vec2(float(gl_VertexID & 1), float(gl_VertexID >> 1));
  gl_Position = vec4(corner * 2.0 - 1.0, 0.0, 1.0);
}
)";

// Output pixel p shows the ideal image at u_source[p] (GL texture coordinates, negative: none),
// times the mask in linear light.
const std::string kWarpFragment = std::string(R"(#version 330 core
uniform sampler2D u_image;
uniform bool u_warp;
uniform sampler2D u_source;
uniform bool u_masked;
uniform sampler2D u_mask;
uniform bool u_linear;
out vec4 o_colour;
)") + kTransfer + R"(
void main() {
  ivec2 p = ivec2(gl_FragCoord.xy);
  vec3 c;
  if (u_warp) {
    vec2 t = texelFetch(u_source, p, 0).rg;
    c = (t.x < 0.0 || t.y < 0.0 || t.x > 1.0 || t.y > 1.0) ? vec3(0.0) : texture(u_image, t).rgb;
  } else {
    c = texelFetch(u_image, p, 0).rgb;
  }
  if (u_masked) c = u_linear ? c * texelFetch(u_mask, p, 0).r
                             : Encode(Decode(c) * texelFetch(u_mask, p, 0).r);
  o_colour = vec4(c, 1.0);
}
)";

// One texel per pixel, the texture's row 0 at the top of the output.
constexpr const char* kBlitFragment = R"(#version 330 core
uniform sampler2D u_image;
out vec4 o_colour;
void main() {
  ivec2 size = textureSize(u_image, 0);
  ivec2 texel = ivec2(int(gl_FragCoord.x), size.y - 1 - int(gl_FragCoord.y));
  o_colour = vec4(texelFetch(u_image, texel, 0).rgb, 1.0);
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
  }
  return "?";
}

Status RendererOptions::Check() const {
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
  Expected<unsigned int> program = LinkProgram("scene", kSceneVertex, kSceneFragment.c_str());
  if (!program.ok()) return program.status();
  scene_program_ = *program;
  program = LinkProgram("shadow", kShadowVertex, kShadowFragment);
  if (!program.ok()) return program.status();
  shadow_program_ = *program;
  program = LinkProgram("overlay", kOverlayVertex, kOverlayFragment);
  if (!program.ok()) return program.status();
  overlay_program_ = *program;
  program = LinkProgram("warp", kQuadVertex, kWarpFragment.c_str());
  if (!program.ok()) return program.status();
  warp_program_ = *program;
  program = LinkProgram("blit", kQuadVertex, kBlitFragment);
  if (!program.ok()) return program.status();
  blit_program_ = *program;

  // The model, grouped by material (one draw call each), flat normals.
  std::vector<std::vector<int>> by_material(std::max<size_t>(scene.materials.size(), 1));
  for (int t = 0; t < scene.NumTriangles(); ++t) {
    int m = t < static_cast<int>(scene.triangle_material.size()) ? scene.triangle_material[t] : 0;
    if (m < 0 || m >= static_cast<int>(by_material.size())) m = 0;
    by_material[m].push_back(t);
  }
  std::vector<SceneVertex> vertices;
  vertices.reserve(static_cast<size_t>(scene.NumTriangles()) * 3);
  const bool has_uv = scene.texcoords.size() == scene.positions_in_table_m.size();
  for (size_t m = 0; m < by_material.size(); ++m) {
    if (by_material[m].empty()) continue;
    Group group;
    group.first_vertex = static_cast<int>(vertices.size());
    group.material = static_cast<int>(m);
    for (int t : by_material[m]) {
      const Eigen::Vector3d n = scene.FaceNormal(t);
      for (int k = 0; k < 3; ++k) {
        const int v = scene.triangles[t][k];
        SceneVertex sv{};
        const Eigen::Vector3f& p = scene.positions_in_table_m[v];
        for (int i = 0; i < 3; ++i) {
          sv.position[i] = p[i];
          sv.normal[i] = static_cast<float>(n[i]);
        }
        if (has_uv) {
          sv.uv[0] = scene.texcoords[v].x();
          sv.uv[1] = scene.texcoords[v].y();
        }
        group.bounds.extend(p.cast<double>());
        vertices.push_back(sv);
      }
    }
    group.vertex_count = static_cast<int>(vertices.size()) - group.first_vertex;
    groups_.push_back(group);
  }
  glGenVertexArrays(1, &scene_vao_);
  glBindVertexArray(scene_vao_);
  glGenBuffers(1, &scene_vbo_);
  glBindBuffer(GL_ARRAY_BUFFER, scene_vbo_);
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

  // Materials and their textures (sRGB: the sampler returns linear values, mipmapped).
  for (const Material& material : scene.materials) {
    material_colours_.push_back(material.base_color_factor);
    material_textures_.push_back(material.base_color_texture);
  }
  for (const Texture& texture : scene.textures) {
    GLuint id = 0;
    glGenTextures(1, &id);
    glBindTexture(GL_TEXTURE_2D, id);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    glTexImage2D(GL_TEXTURE_2D, 0, GL_SRGB8_ALPHA8, texture.width_px, texture.height_px, 0, GL_RGBA,
                 GL_UNSIGNED_BYTE, texture.rgba.data());
    glGenerateMipmap(GL_TEXTURE_2D);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR_MIPMAP_LINEAR);
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
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
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

Renderer::~Renderer() {
  if (!context_->MakeCurrent().ok()) return;
  const GLuint programs[] = {scene_program_, shadow_program_, overlay_program_, warp_program_,
                             blit_program_};
  for (GLuint p : programs) {
    if (p) glDeleteProgram(p);
  }
  std::vector<GLuint> textures = textures_;
  for (GLuint t : {shadow_texture_, ideal_colour_, source_texture_, mask_texture_, pattern_texture_,
                   floor_texture_}) {
    if (t) textures.push_back(t);
  }
  if (!textures.empty()) glDeleteTextures(static_cast<GLsizei>(textures.size()), textures.data());
  for (GLuint rb : {ideal_depth_, output_depth_}) {
    if (rb) glDeleteRenderbuffers(1, &rb);
  }
  for (GLuint fb : {shadow_fbo_, ideal_fbo_}) {
    if (fb) glDeleteFramebuffers(1, &fb);
  }
  for (GLuint b : {scene_vbo_, overlay_vbo_}) {
    if (b) glDeleteBuffers(1, &b);
  }
  for (GLuint a : {scene_vao_, overlay_vao_, empty_vao_}) {
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
  view_ = view;
  has_view_ = true;
  overlay_view_dirty_ = true;
  if (source_texture_) {
    glDeleteTextures(1, &source_texture_);
    source_texture_ = 0;
  }
  if (view.needs_prewarp()) {
    // OpenCV ideal pixel -> GL texture coordinates of the ideal image; rows in GL order.
    cv::Mat coords(view.source_px.size(), CV_32FC2);
    for (int v = 0; v < coords.rows; ++v) {
      const auto* in = view.source_px.ptr<cv::Vec2f>(v);
      auto* out = coords.ptr<cv::Vec2f>(v);
      for (int u = 0; u < coords.cols; ++u) {
        const cv::Vec2f s = in[u];
        if (!std::isfinite(s[0]) || !std::isfinite(s[1])) {
          out[u] = cv::Vec2f(-1.0f, -1.0f);
        } else {
          out[u] = cv::Vec2f((s[0] + 0.5f) / size_.width, 1.0f - (s[1] + 0.5f) / size_.height);
        }
      }
    }
    const cv::Mat gl_rows = FlippedContinuous(coords);
    source_texture_ = MakeTexture2D(GL_RG32F, size_.width, size_.height, GL_RG, GL_FLOAT,
                                    gl_rows.data, GL_NEAREST);
    ST_RETURN_IF_ERROR(EnsureIdealTarget());
  }
  return CheckGl("setting the projector view");
}

Status Renderer::SetMask(const cv::Mat& mask) {
  ST_RETURN_IF_ERROR(context_->MakeCurrent());
  if (mask.empty()) {
    has_mask_ = false;
    return OkStatus();
  }
  if (mask.size() != size_ || (mask.type() != CV_32FC1 && mask.type() != CV_8UC1)) {
    return InvalidArgumentError(
        "renderer: a mask must be CV_32FC1 or CV_8UC1 of the output's "
        "size " +
        std::to_string(size_.width) + "x" + std::to_string(size_.height));
  }
  cv::Mat factor;
  if (mask.type() == CV_8UC1) {
    mask.convertTo(factor, CV_32F, 1.0 / 255.0);
  } else {
    factor = mask;
  }
  const cv::Mat gl_rows = FlippedContinuous(factor);
  if (!mask_texture_) {
    mask_texture_ = MakeTexture2D(GL_R32F, size_.width, size_.height, GL_RED, GL_FLOAT,
                                  gl_rows.data, GL_NEAREST);
  } else {
    glBindTexture(GL_TEXTURE_2D, mask_texture_);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, size_.width, size_.height, GL_RED, GL_FLOAT,
                    gl_rows.data);
  }
  has_mask_ = true;
  ST_RETURN_IF_ERROR(EnsureIdealTarget());
  return CheckGl("setting the mask");
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
      stats.pass_ms[static_cast<int>(pass)] = MsSince(t0);
    }
    stats.ran[static_cast<int>(pass)] = true;
    return s;
  };
  const GLuint output = context_->output_framebuffer();
  const bool raw = content.pattern == TestPattern::kProjectorId ||
                   content.pattern == TestPattern::kColourBars ||
                   content.pattern == TestPattern::kRawWhite;
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
    const bool warp = view_.needs_prewarp() || has_mask_;
    const GLuint target = warp ? ideal_fbo_ : output;
    ST_RETURN_IF_ERROR(timed(Pass::kScene, [&] { return DrawScene(content, target, &stats); }));
    stats.ran[static_cast<int>(Pass::kScene)] = stats.groups_drawn > 0;
    if (show && content.has_overlay()) {
      ST_RETURN_IF_ERROR(timed(Pass::kOverlay, [&] { return DrawOverlay(content, &stats); }));
    }
    if (warp) {
      ST_RETURN_IF_ERROR(timed(Pass::kWarp, [&] { return DrawWarp(); }));
    }
  }
  glFinish();
  ST_RETURN_IF_ERROR(CheckGl("rendering a frame"));
  stats.frame_ms = MsSince(start);
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
  glBindVertexArray(scene_vao_);
  for (const Group& g : groups_) glDrawArrays(GL_TRIANGLES, g.first_vertex, g.vertex_count);
  glDisable(GL_POLYGON_OFFSET_FILL);
  return CheckGl("drawing the shadow map");
}

Status Renderer::DrawScene(const RenderContent& content, unsigned int target, FrameStats* stats) {
  glBindFramebuffer(GL_FRAMEBUFFER, target);
  glViewport(0, 0, size_.width, size_.height);
  glClearColor(0, 0, 0, 1);
  glClearDepth(1.0);
  glDepthMask(GL_TRUE);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glDisable(GL_CULL_FACE);  // thin walls and open meshes are seen from either side
  glUseProgram(scene_program_);
  const int mode = content.debug_positions                      ? 3
                   : content.pattern == TestPattern::kWhite     ? 1
                   : content.pattern == TestPattern::kTableGrid ? 2
                                                                : 0;
  const bool sun = mode == 0 && content.sun_direction_in_table.has_value();
  const glm::mat4 clip = ToGlm(view_.clip_from_table);
  const glm::mat4 sun_clip = ToGlm(sun_clip_from_table_);
  auto loc = [&](const char* name) { return glGetUniformLocation(scene_program_, name); };
  glUniformMatrix4fv(loc("u_clip_from_table"), 1, GL_FALSE, glm::value_ptr(clip));
  glUniformMatrix4fv(loc("u_sun_clip_from_table"), 1, GL_FALSE, glm::value_ptr(sun_clip));
  glUniform1i(loc("u_mode"), mode);
  glUniform1i(loc("u_sun"), sun ? 1 : 0);
  if (sun) {
    const glm::vec3 d = ToGlm(content.sun_direction_in_table->normalized());
    glUniform3f(loc("u_sun_direction"), d.x, d.y, d.z);
    // Night (the sun below the horizon): ambient only, no shadow lookup.
    glUniform1f(loc("u_ambient"), static_cast<float>(options_.ambient));
  }
  glUniform1f(loc("u_grid_spacing_m"), static_cast<float>(options_.grid_spacing_m));
  glUniform1f(loc("u_grid_half_line_m"), static_cast<float>(0.5 * options_.grid_line_width_m));
  glUniform1i(loc("u_texture"), 0);
  glUniform1i(loc("u_shadow"), 1);
  glActiveTexture(GL_TEXTURE1);
  glBindTexture(GL_TEXTURE_2D, shadow_texture_);
  glActiveTexture(GL_TEXTURE0);
  glBindVertexArray(scene_vao_);
  for (const Group& g : groups_) {
    if (OutsideFrustum(view_.clip_from_table, g.bounds)) {
      ++stats->groups_culled;
      continue;
    }
    ++stats->groups_drawn;
    const bool has_material = g.material < static_cast<int>(material_colours_.size());
    const Eigen::Vector4d colour =
        has_material ? material_colours_[g.material] : Eigen::Vector4d(1, 1, 1, 1);
    const int texture = has_material ? material_textures_[g.material] : -1;
    glUniform4f(loc("u_base_colour"), static_cast<float>(colour[0]), static_cast<float>(colour[1]),
                static_cast<float>(colour[2]), static_cast<float>(colour[3]));
    const bool textured = texture >= 0 && texture < static_cast<int>(textures_.size());
    glUniform1i(loc("u_textured"), textured ? 1 : 0);
    if (textured) glBindTexture(GL_TEXTURE_2D, textures_[texture]);
    glDrawArrays(GL_TRIANGLES, g.first_vertex, g.vertex_count);
  }
  return CheckGl("drawing the scene");
}

Status Renderer::DrawOverlay(const RenderContent& content, FrameStats* stats) {
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
  // Same target as the scene (its depth buffer is still bound): tested, not written.
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LEQUAL);
  glDepthMask(GL_FALSE);
  glUseProgram(overlay_program_);
  const glm::mat4 clip = ToGlm(view_.clip_from_table);
  glUniformMatrix4fv(glGetUniformLocation(overlay_program_, "u_clip_from_table"), 1, GL_FALSE,
                     glm::value_ptr(clip));
  glBindVertexArray(overlay_vao_);
  glDrawArrays(GL_TRIANGLES, 0, overlay_vertices_);
  glDepthMask(GL_TRUE);
  return CheckGl("drawing the overlay");
}

Status Renderer::DrawWarp() {
  glBindFramebuffer(GL_FRAMEBUFFER, context_->output_framebuffer());
  glViewport(0, 0, size_.width, size_.height);
  glDisable(GL_DEPTH_TEST);
  glUseProgram(warp_program_);
  auto loc = [&](const char* name) { return glGetUniformLocation(warp_program_, name); };
  glUniform1i(loc("u_image"), 0);
  glUniform1i(loc("u_source"), 1);
  glUniform1i(loc("u_mask"), 2);
  glUniform1i(loc("u_warp"), view_.needs_prewarp() ? 1 : 0);
  glUniform1i(loc("u_masked"), has_mask_ ? 1 : 0);
  glUniform1i(loc("u_linear"), context_->float_output() ? 1 : 0);
  glActiveTexture(GL_TEXTURE1);
  glBindTexture(GL_TEXTURE_2D, source_texture_);
  glActiveTexture(GL_TEXTURE2);
  glBindTexture(GL_TEXTURE_2D, mask_texture_);
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D, ideal_colour_);
  glBindVertexArray(empty_vao_);
  glDrawArrays(GL_TRIANGLE_STRIP, 0, 4);
  return CheckGl("drawing the pre-warp");
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
