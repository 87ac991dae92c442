#include "node/devices/gl_frame_blitter.h"

#include <algorithm>
#include <string>
#include <vector>

#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>

#include "node/devices/gl_util.h"

namespace sandtable::node {
namespace {

GLuint MakeTexture(GLint internal_format, GLenum format, cv::Size size, bool gray) {
  GLuint texture = 0;
  glGenTextures(1, &texture);
  glBindTexture(GL_TEXTURE_2D, texture);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAX_LEVEL, 0);
  if (gray) {
    const GLint swizzle[4] = {GL_RED, GL_RED, GL_RED, GL_ONE};
    glTexParameteriv(GL_TEXTURE_2D, GL_TEXTURE_SWIZZLE_RGBA, swizzle);
  }
  // Black until the first frame.
  const std::vector<unsigned char> black(
      static_cast<size_t>(size.width) * size.height * (gray ? 1 : 3), 0);
  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
  glTexImage2D(GL_TEXTURE_2D, 0, internal_format, size.width, size.height, 0, format,
               GL_UNSIGNED_BYTE, black.data());
  return texture;
}

}  // namespace

Expected<std::unique_ptr<GlFrameBlitter>> GlFrameBlitter::Create(cv::Size size_px) {
  std::unique_ptr<GlFrameBlitter> blitter(new GlFrameBlitter(size_px));
  ST_RETURN_IF_ERROR(blitter->Init());
  return blitter;
}

Status GlFrameBlitter::Init() {
  Expected<unsigned int> program =
      LinkProgram("frame blitter", kFullScreenQuadVertexShader, kTexelBlitFragmentShader);
  if (!program.ok()) return program.status();
  program_ = *program;
  glUseProgram(program_);
  glUniform1i(glGetUniformLocation(program_, "u_image"), 0);
  glGenVertexArrays(1, &vertex_array_);
  gray_texture_ = MakeTexture(GL_R8, GL_RED, size_px_, /*gray=*/true);
  rgb_texture_ = MakeTexture(GL_RGB8, GL_RGB, size_px_, /*gray=*/false);
  current_texture_ = gray_texture_;
  // Exact values: no dithering, blending or multisampling between texel and framebuffer.
  glDisable(GL_DITHER);
  glDisable(GL_BLEND);
  glDisable(GL_MULTISAMPLE);
  glDisable(GL_FRAMEBUFFER_SRGB);
  return CheckGl("creating the frame program and textures");
}

GlFrameBlitter::~GlFrameBlitter() {
  if (gray_texture_) glDeleteTextures(1, &gray_texture_);
  if (rgb_texture_) glDeleteTextures(1, &rgb_texture_);
  if (vertex_array_) glDeleteVertexArrays(1, &vertex_array_);
  if (program_) glDeleteProgram(program_);
}

Status GlFrameBlitter::Draw(const cv::Mat& frame) {
  const bool gray = frame.channels() == 1;
  current_texture_ = gray ? gray_texture_ : rgb_texture_;
  glBindTexture(GL_TEXTURE_2D, current_texture_);
  cv::Mat packed = frame;
  if (frame.step[0] % frame.elemSize() != 0) packed = frame.clone();  // odd stride: repack
  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
  glPixelStorei(GL_UNPACK_ROW_LENGTH, static_cast<GLint>(packed.step[0] / packed.elemSize()));
  glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, packed.cols, packed.rows, gray ? GL_RED : GL_RGB,
                  GL_UNSIGNED_BYTE, packed.data);
  glPixelStorei(GL_UNPACK_ROW_LENGTH, 0);
  ST_RETURN_IF_ERROR(CheckGl("uploading the frame"));
  return Redraw();
}

Status GlFrameBlitter::Redraw() {
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  glDrawBuffer(GL_BACK);
  glViewport(0, 0, size_px_.width, size_px_.height);
  glUseProgram(program_);
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D, current_texture_);
  glBindVertexArray(vertex_array_);
  glDrawArrays(GL_TRIANGLE_STRIP, 0, 4);
  return CheckGl("drawing the frame");
}

Expected<cv::Mat> GlFrameBlitter::ReadBackBuffer() {
  cv::Mat bottom_up(size_px_, CV_8UC3);
  glBindFramebuffer(GL_READ_FRAMEBUFFER, 0);
  glReadBuffer(GL_BACK);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, size_px_.width, size_px_.height, GL_RGB, GL_UNSIGNED_BYTE, bottom_up.data);
  ST_RETURN_IF_ERROR(CheckGl("reading the framebuffer back"));
  cv::Mat top_down;
  cv::flip(bottom_up, top_down, 0);
  return top_down;
}

}  // namespace sandtable::node
