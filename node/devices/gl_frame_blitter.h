// GlFrameBlitter: the OpenGL part of a window projector. It uploads a GRAY8 or RGB8 frame into
// a texture of the window's size and draws it with a full-screen textured quad whose fragment
// shader fetches exactly one texel per pixel (texelFetch, no filtering, no scaling), so the
// framebuffer holds the frame's values unchanged. Gray frames use an R8 texture swizzled to
// (R, R, R). Frame row 0 is the top of the window (GL's row 0 is the bottom: flipped here).
//
// Needs an OpenGL 3.3 core context with an 8-bit-per-channel default framebuffer, current on
// the calling thread for every call (including the destructor). Errors (shader compilation,
// GL errors) are INTERNAL with the GL message; nothing aborts.
#pragma once

#include <memory>

#include <opencv2/core.hpp>

#include "common/base/status.h"

namespace sandtable::node {

class GlFrameBlitter {
 public:
  // Compiles the program and allocates the textures for frames of `size_px`.
  static Expected<std::unique_ptr<GlFrameBlitter>> Create(cv::Size size_px);
  ~GlFrameBlitter();
  GlFrameBlitter(const GlFrameBlitter&) = delete;
  GlFrameBlitter& operator=(const GlFrameBlitter&) = delete;

  // Uploads `frame` (GRAY8 or RGB8 of size_px, checked by the caller) and draws it into the
  // back buffer of the default framebuffer.
  Status Draw(const cv::Mat& frame);
  // Draws the last uploaded frame again (black before the first Draw).
  Status Redraw();
  // The back buffer (what the last Draw/Redraw drew, before the swap) as RGB8 (CV_8UC3, R
  // first), row 0 at the top: glReadPixels of the whole window.
  Expected<cv::Mat> ReadBackBuffer();

 private:
  explicit GlFrameBlitter(cv::Size size_px) : size_px_(size_px) {}
  Status Init();

  cv::Size size_px_;
  unsigned int program_ = 0;
  unsigned int vertex_array_ = 0;
  unsigned int gray_texture_ = 0;
  unsigned int rgb_texture_ = 0;
  unsigned int current_texture_ = 0;
};

}  // namespace sandtable::node
