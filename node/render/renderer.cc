#include "node/render/renderer.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>

#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>
#include <glm/gtc/type_ptr.hpp>

#include "node/devices/gl_util.h"
#include "node/render/glm_convert.h"
#include "node/render/renderer_internal.h"
#include "node/render/shaders.h"

// The renderer's passes are split over files: this one (set-up, views, frames, shader variants),
// renderer_geometry.cc (the model's upload), renderer_masks.cc, renderer_passes.cc (the forward
// passes and patterns) and renderer_deferred.cc (the surface cache and the light pass).

namespace sandtable::node {

using render_internal::Clock;
using render_internal::FlippedContinuous;
using render_internal::MakeTexture2D;
using render_internal::Matrix;
using render_internal::MsSince;

namespace render_internal {

GlTexture MakeTexture2D(int internal_format, int w, int h, unsigned int format, unsigned int type,
                        const void* data, int filter) {
  GlTexture texture = GlTexture::Generate();
  glBindTexture(GL_TEXTURE_2D, texture.get());
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, filter);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, filter);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAX_LEVEL, 0);
  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
  glTexImage2D(GL_TEXTURE_2D, 0, internal_format, w, h, 0, format, type, data);
  return texture;
}

cv::Mat FlippedContinuous(const cv::Mat& image) {
  cv::Mat flipped;
  cv::flip(image, flipped, 0);
  return flipped.isContinuous() ? flipped : flipped.clone();
}

bool OutsideFrustum(const Eigen::Matrix4d& clip_from_table, const Eigen::AlignedBox3d& box) {
  if (box.isEmpty()) return true;
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

Eigen::Matrix4d Matrix(const Rigid3d& transform) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topLeftCorner<3, 3>() = transform.rotation.toRotationMatrix();
  m.topRightCorner<3, 1>() = transform.translation;
  return m;
}

}  // namespace render_internal

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

Renderer::Renderer(GlContext* context, const RendererOptions& options)
    : context_(context), options_(options), gl_(std::make_unique<GlResources>()) {}

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
  Expected<unsigned int> program =
      LinkProgram("shadow", shaders::kShadowVertex, shaders::kShadowFragment);
  if (!program.ok()) return program.status();
  gl_->shadow_program.Reset(*program);
  program = LinkProgram("blit", kFullScreenQuadVertexShader, kTexelBlitFragmentShader);
  if (!program.ok()) return program.status();
  gl_->blit_program.Reset(*program);

  gl_->scene_vao = GlVertexArray::Generate();
  gl_->scene_vbo = GlBuffer::Generate();
  gl_->shadow_vao = GlVertexArray::Generate();
  gl_->shadow_vbo = GlBuffer::Generate();
  ST_RETURN_IF_ERROR(UploadGeometry(gl_->shadow_vao.get(), gl_->shadow_vbo.get(), /*edge_px=*/0.0,
                                    &shadow_groups_));
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
  ST_RETURN_IF_ERROR(UploadGeometry(gl_->scene_vao.get(), gl_->scene_vbo.get(), /*edge_px=*/0.0,
                                    &groups_, &normals));
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
    gl_->face_normals = MakeTexture2D(GL_RGB32F, face_table_size_.width, face_table_size_.height,
                                      GL_RGB, GL_FLOAT, normals.data(), GL_NEAREST);
    gl_->face_light = MakeTexture2D(GL_R32F, face_table_size_.width, face_table_size_.height,
                                    GL_RED, GL_FLOAT, nullptr, GL_NEAREST);
    gl_->face_light_fbo = GlFramebuffer::Generate();
    glBindFramebuffer(GL_FRAMEBUFFER, gl_->face_light_fbo.get());
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D,
                           gl_->face_light.get(), 0);
    if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE) {
      return InternalError("OpenGL: the face light's framebuffer is incomplete");
    }
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
  }

  gl_->overlay_vao = GlVertexArray::Generate();
  glBindVertexArray(gl_->overlay_vao.get());
  gl_->overlay_vbo = GlBuffer::Generate();
  glBindBuffer(GL_ARRAY_BUFFER, gl_->overlay_vbo.get());
  glEnableVertexAttribArray(0);
  glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, sizeof(OverlayVertex),
                        reinterpret_cast<void*>(offsetof(OverlayVertex, position_in_table_m)));
  glEnableVertexAttribArray(1);
  glVertexAttribPointer(1, 4, GL_FLOAT, GL_FALSE, sizeof(OverlayVertex),
                        reinterpret_cast<void*>(offsetof(OverlayVertex, colour)));
  gl_->empty_vao = GlVertexArray::Generate();
  glBindVertexArray(0);

  InitMaterials(scene);

  // The sun's depth map, compared in the lookup (sampler2DShadow).
  gl_->shadow_texture = GlTexture::Generate();
  glBindTexture(GL_TEXTURE_2D, gl_->shadow_texture.get());
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
  gl_->shadow_fbo = GlFramebuffer::Generate();
  glBindFramebuffer(GL_FRAMEBUFFER, gl_->shadow_fbo.get());
  glFramebufferTexture2D(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_TEXTURE_2D,
                         gl_->shadow_texture.get(), 0);
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
      gl_->output_depth = GlRenderbuffer::Generate();
      glBindRenderbuffer(GL_RENDERBUFFER, gl_->output_depth.get());
      glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT24, size_.width, size_.height);
      glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER,
                                gl_->output_depth.get());
    }
  }
  // The floor's texture: a full-screen image to sample.
  cv::Mat grey(size_, CV_8UC3, cv::Scalar::all(128));
  gl_->floor_texture = MakeTexture2D(GL_RGB8, size_.width, size_.height, GL_RGB, GL_UNSIGNED_BYTE,
                                     grey.data, GL_NEAREST);
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  glDisable(GL_DITHER);
  glDisable(GL_BLEND);
  glDisable(GL_FRAMEBUFFER_SRGB);
  return CheckGl("creating the renderer");
}

// Materials and their textures (encoded texels, filtered as they are; mipmapped).
void Renderer::InitMaterials(const Scene& scene) {
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
    GlTexture id = GlTexture::Generate();
    glBindTexture(GL_TEXTURE_2D, id.get());
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
    gl_->textures.push_back(std::move(id));
  }
}

Renderer::~Renderer() {
  // The GL objects go with gl_, in the context that made them. Without it they are given up, not
  // deleted: OpenGL is not to be called with no context current.
  if (gl_ && !context_->MakeCurrent().ok()) (void)gl_.release();
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
    ST_RETURN_IF_ERROR(
        UploadGeometry(gl_->scene_vao.get(), gl_->scene_vbo.get(), tessellation_px_, &groups_));
    geometry_tessellated_ = true;
  } else if (geometry_tessellated_) {
    ST_RETURN_IF_ERROR(UploadGeometry(gl_->scene_vao.get(), gl_->scene_vbo.get(), 0.0, &groups_));
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
    UploadTexels(&gl_->warp_texture, warp_texels_);
  } else if (has_mask_) {
    UploadTexels(&gl_->mask_texture, mask_rows_);
  }
  packed_warp_ = packed;
  return CheckGl("setting the projector view");
}

float Renderer::LiftGamma() const {
  // Encoded output: the lift is added in linear light; a float target is linear already.
  return context_->float_output() ? 1.0f : static_cast<float>(options_.display_gamma);
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
    const GLuint target = warp ? gl_->ideal_fbo.get() : output;
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
      ST_RETURN_IF_ERROR(timed(
          Pass::kWarp, [&] { return DrawWarp(gl_->ideal_colour.get(), view_.needs_prewarp()); }));
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
    ST_RETURN_IF_ERROR(DrawWarp(gl_->lit_texture.get(), /*distort=*/false));
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
  ST_RETURN_IF_ERROR(DrawWarp(gl_->ideal_colour.get(), view_.needs_prewarp()));
  glFinish();
  ST_RETURN_IF_ERROR(CheckGl("warping the last frame again"));
  stats.ran[static_cast<int>(Pass::kWarp)] = true;
  stats.frame_ms = stats.pass_ms[static_cast<int>(Pass::kWarp)] = MsSince(start);
  return stats;
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
  if (auto it = gl_->variants.find(key); it != gl_->variants.end()) return it->second.get();
  const std::string defines = "#version 330 core\n#define MODE " + std::to_string(mode) +
                              "\n#define TEXTURED " + std::to_string(textured) + "\n#define SUN " +
                              std::to_string(sun) + "\n#define MASKED " + std::to_string(masked) +
                              "\n#define DISTORT " + std::to_string(distort) + "\n#define LIFTED " +
                              std::to_string(lifted) + "\n#define PACKED " +
                              std::to_string(packed) + "\n";
  // Each kind's shaders (a null vertex shader: the full-screen quad's; `project`: the vertex
  // shader calls Project, shaders/project.glsl) and name, in ProgramKind's order.
  struct Source {
    const char* vertex;
    bool project;
    const char* fragment;
    const char* name;
  };
  static constexpr Source kSources[7] = {
      {shaders::kSceneVertex, true, shaders::kSceneFragment, "scene"},
      {shaders::kOverlayVertex, true, shaders::kOverlayFragment, "overlay"},
      {nullptr, false, shaders::kWarpFragment, "warp"},
      {shaders::kSurfaceVertex, false, shaders::kSurfaceFragment, "surface"},
      {nullptr, false, shaders::kSurfaceWarpFragment, "surface warp"},
      {nullptr, false, shaders::kLightFragment, "light"},
      {nullptr, false, shaders::kFaceLightFragment, "face light"},
  };
  const Source& source = kSources[static_cast<int>(kind)];
  const std::string vertex =
      !source.vertex ? std::string(kFullScreenQuadVertexShader)
                     : defines + (source.project ? shaders::kProject : "") + source.vertex;
  const std::string fragment = defines + shaders::kFragmentCommon + source.fragment;
  const char* name = source.name;
  Expected<unsigned int> program =
      LinkProgram("variant " + std::to_string(key) + " of the " + name + " program", vertex.c_str(),
                  fragment.c_str());
  if (!program.ok()) return program.status();
  gl_->variants[key].Reset(*program);
  return *program;
}

std::pair<Eigen::Vector4d, int> Renderer::GroupMaterial(const Group& g) const {
  if (g.material < 0 || g.material >= static_cast<int>(material_colours_.size())) {
    return {Eigen::Vector4d(1, 1, 1, 1), -1};
  }
  const int texture = material_textures_[g.material];
  return {material_colours_[g.material],
          texture >= 0 && texture < static_cast<int>(gl_->textures.size()) ? texture : -1};
}

}  // namespace sandtable::node
