// The renderer's forward passes (renderer.h): the sun's shadow map, the scene, the overlay, the
// warp, test patterns and the floor.
#include <vector>

#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>
#include <glm/gtc/type_ptr.hpp>

#include "node/devices/gl_util.h"
#include "node/render/glm_convert.h"
#include "node/render/renderer.h"
#include "node/render/renderer_internal.h"
#include "node/render/test_patterns.h"

namespace sandtable::node {

using render_internal::Clock;
using render_internal::MakeTexture2D;
using render_internal::Matrix;
using render_internal::MsSince;
using render_internal::OutsideFrustum;

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

  glBindFramebuffer(GL_FRAMEBUFFER, gl_->shadow_fbo.get());
  glViewport(0, 0, options_.shadow_map_px, options_.shadow_map_px);
  glEnable(GL_DEPTH_TEST);
  glDepthMask(GL_TRUE);
  glDepthFunc(GL_LESS);
  glClear(GL_DEPTH_BUFFER_BIT);
  glEnable(GL_POLYGON_OFFSET_FILL);
  glPolygonOffset(2.0f, 4.0f);
  glUseProgram(gl_->shadow_program.get());
  const glm::mat4 m = ToGlm(sun_clip_from_table_);
  glUniformMatrix4fv(glGetUniformLocation(gl_->shadow_program.get(), "u_sun_clip_from_table"), 1,
                     GL_FALSE, glm::value_ptr(m));
  glBindVertexArray(gl_->shadow_vao.get());
  for (const Group& g : shadow_groups_) glDrawArrays(GL_TRIANGLES, g.first_vertex, g.vertex_count);
  glDisable(GL_POLYGON_OFFSET_FILL);
  return CheckGl("drawing the shadow map");
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
  glBindTexture(GL_TEXTURE_2D, gl_->mask_texture.get());
  glActiveTexture(GL_TEXTURE1);
  glBindTexture(GL_TEXTURE_2D, gl_->shadow_texture.get());
  glActiveTexture(GL_TEXTURE0);
  glBindVertexArray(gl_->scene_vao.get());
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
    if (textured) glBindTexture(GL_TEXTURE_2D, gl_->textures[texture].get());
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
    glBindBuffer(GL_ARRAY_BUFFER, gl_->overlay_vbo.get());
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
    glBindTexture(GL_TEXTURE_2D, gl_->surface.geometry.get());
  }
  const glm::mat4 clip = ToGlm(view_.clip_from_table);
  glUniformMatrix4fv(glGetUniformLocation(*program, "u_clip_from_table"), 1, GL_FALSE,
                     glm::value_ptr(clip));
  SetDistortionUniforms(*program, distort);
  glUniform1i(glGetUniformLocation(*program, "u_mask"), 2);
  glUniform1f(glGetUniformLocation(*program, "u_lift_gamma"), LiftGamma());
  glActiveTexture(GL_TEXTURE2);
  glBindTexture(GL_TEXTURE_2D, packed ? gl_->warp_texture.get() : gl_->mask_texture.get());
  glActiveTexture(GL_TEXTURE0);
  glBindVertexArray(gl_->overlay_vao.get());
  glDrawArrays(GL_TRIANGLES, 0, overlay_vertices_);
  glDepthMask(GL_TRUE);
  return CheckGl("drawing the overlay");
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
  glBindTexture(GL_TEXTURE_2D, gl_->warp_texture.get());
  glActiveTexture(GL_TEXTURE2);
  glBindTexture(GL_TEXTURE_2D, packed_warp_ ? gl_->warp_texture.get() : gl_->mask_texture.get());
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D, image);
  glBindVertexArray(gl_->empty_vao.get());
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
    gl_->pattern_texture = MakeTexture2D(GL_RGB8, size_.width, size_.height, GL_RGB,
                                         GL_UNSIGNED_BYTE, image.data, GL_NEAREST);
    pattern_uploaded_ = content.pattern;
    pattern_id_uploaded_ = content.projector_id;
  }
  glUseProgram(gl_->blit_program.get());
  glUniform1i(glGetUniformLocation(gl_->blit_program.get(), "u_image"), 0);
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D, gl_->pattern_texture.get());
  glBindVertexArray(gl_->empty_vao.get());
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
  glUseProgram(gl_->blit_program.get());
  glUniform1i(glGetUniformLocation(gl_->blit_program.get(), "u_image"), 0);
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D, gl_->floor_texture.get());
  glBindVertexArray(gl_->empty_vao.get());
  glDrawArrays(GL_TRIANGLE_STRIP, 0, 4);
  glFinish();
  const double ms = MsSince(start);
  ST_RETURN_IF_ERROR(CheckGl("drawing the floor"));
  return ms;
}

}  // namespace sandtable::node
