// The renderer's deferred path (renderer.h): the surface cache drawn once per view, the faces'
// light when the sun moves, and the light pass every frame.
#include <cmath>

#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>
#include <glm/gtc/type_ptr.hpp>

#include "node/devices/gl_util.h"
#include "node/render/glm_convert.h"
#include "node/render/renderer.h"
#include "node/render/renderer_internal.h"

namespace sandtable::node {

using render_internal::MakeTexture2D;
using render_internal::Matrix;
using render_internal::OutsideFrustum;

Status Renderer::EnsureSurfaceTargets() {
  if (gl_->surface.fbo.get()) return OkStatus();
  auto attach = [&](SurfaceTarget* t, GLuint colour) -> Status {
    t->fbo = GlFramebuffer::Generate();
    glBindFramebuffer(GL_FRAMEBUFFER, t->fbo.get());
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, t->geometry.get(),
                           0);
    if (colour) {
      glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT1, GL_TEXTURE_2D, colour, 0);
      t->depth = GlRenderbuffer::Generate();
      glBindRenderbuffer(GL_RENDERBUFFER, t->depth.get());
      glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT24, size_.width, size_.height);
      glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER,
                                t->depth.get());
    }
    const GLenum buffers[2] = {GL_COLOR_ATTACHMENT0, GL_COLOR_ATTACHMENT1};
    glDrawBuffers(colour ? 2 : 1, buffers);
    if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE) {
      return InternalError("OpenGL: the surface cache's framebuffer is incomplete");
    }
    return OkStatus();
  };
  // The ideal cache: geometry, filterable colour, depth. The output cache: the packed texel.
  gl_->ideal_surface.geometry =
      MakeTexture2D(GL_RGBA32UI, size_.width, size_.height, GL_RGBA_INTEGER, GL_UNSIGNED_INT,
                    nullptr, GL_NEAREST);
  gl_->ideal_surface.colour = MakeTexture2D(GL_RGBA8, size_.width, size_.height, GL_RGBA,
                                            GL_UNSIGNED_BYTE, nullptr, GL_LINEAR);
  ST_RETURN_IF_ERROR(attach(&gl_->ideal_surface, gl_->ideal_surface.colour.get()));
  gl_->surface.geometry = MakeTexture2D(GL_RGBA32UI, size_.width, size_.height, GL_RGBA_INTEGER,
                                        GL_UNSIGNED_INT, nullptr, GL_NEAREST);
  ST_RETURN_IF_ERROR(attach(&gl_->surface, 0));
  return CheckGl("creating the surface cache");
}

// The model into the ideal surface cache (DrawSurfaceWarp packs it into output pixels). Groups
// culled and drawn nearest first as in DrawScene.
Status Renderer::DrawSurfaceScene() {
  ST_RETURN_IF_ERROR(EnsureSurfaceTargets());
  glBindFramebuffer(GL_FRAMEBUFFER, gl_->ideal_surface.fbo.get());
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
  glBindVertexArray(gl_->scene_vao.get());
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
    if (textured) glBindTexture(GL_TEXTURE_2D, gl_->textures[texture].get());
    glDrawArrays(GL_TRIANGLES, g.first_vertex, g.vertex_count);
    surface_triangles_ += g.vertex_count / 3;
  }
  return CheckGl("drawing the surface cache");
}

Status Renderer::DrawSurfaceWarp() {
  glBindFramebuffer(GL_FRAMEBUFFER, gl_->surface.fbo.get());
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
  glBindTexture(GL_TEXTURE_2D, gl_->warp_texture.get());
  glActiveTexture(GL_TEXTURE3);
  glBindTexture(GL_TEXTURE_2D, gl_->ideal_surface.geometry.get());
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D, gl_->ideal_surface.colour.get());
  glBindVertexArray(gl_->empty_vao.get());
  glDrawArrays(GL_TRIANGLE_STRIP, 0, 4);
  surface_valid_ = true;
  return CheckGl("packing the surface cache");
}

// The sun's light on each face (kFaceLightFragment), for a unit direction above the horizon.
Status Renderer::DrawFaceLight(const Eigen::Vector3d& sun) {
  glBindFramebuffer(GL_FRAMEBUFFER, gl_->face_light_fbo.get());
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
  glBindTexture(GL_TEXTURE_2D, gl_->face_normals.get());
  glBindVertexArray(gl_->empty_vao.get());
  glDrawArrays(GL_TRIANGLE_STRIP, 0, 4);
  face_light_sun_ = sun;
  return CheckGl("drawing the faces' light");
}

Status Renderer::AttachLitTarget(bool attach) {
  if (attach == lit_attached_) return OkStatus();
  if (attach && !gl_->lit_texture.get()) {
    gl_->lit_texture = MakeTexture2D(GL_RGBA8, size_.width, size_.height, GL_RGBA, GL_UNSIGNED_BYTE,
                                     nullptr, GL_NEAREST);
  }
  glBindFramebuffer(GL_FRAMEBUFFER, context_->output_framebuffer());
  glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT1, GL_TEXTURE_2D,
                         attach ? gl_->lit_texture.get() : 0, 0);
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
  glBindTexture(GL_TEXTURE_2D, gl_->shadow_texture.get());
  glActiveTexture(GL_TEXTURE2);
  glBindTexture(GL_TEXTURE_2D, packed_warp_ ? gl_->warp_texture.get() : gl_->mask_texture.get());
  glActiveTexture(GL_TEXTURE3);
  glBindTexture(GL_TEXTURE_2D, gl_->surface.geometry.get());
  glActiveTexture(GL_TEXTURE4);
  glBindTexture(GL_TEXTURE_2D, gl_->face_light.get());
  glActiveTexture(GL_TEXTURE0);
  glBindVertexArray(gl_->empty_vao.get());
  glDrawArrays(GL_TRIANGLE_STRIP, 0, 4);
  return CheckGl("drawing the light pass");
}

}  // namespace sandtable::node
