// The renderer's masks (renderer.h): encoded into the warp's texels or a texture of their own,
// and prepared ahead of time.
#include <algorithm>
#include <string>
#include <utility>
#include <vector>

#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>

#include "node/devices/gl_util.h"
#include "node/render/renderer.h"
#include "node/render/renderer_internal.h"

namespace sandtable::node {

using render_internal::MakeTexture2D;

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
  UploadTexels(packed_warp_ ? &gl_->warp_texture : &gl_->mask_texture, *texels);
  return CheckGl("setting the mask");
}

bool Renderer::HasPreparedMask(uint64_t key) const { return gl_->prepared.count(key) > 0; }

Status Renderer::PrepareMask(uint64_t key, const cv::Mat& mask) {
  if (mask.empty()) return InvalidArgumentError("renderer: a prepared mask cannot be empty");
  ST_RETURN_IF_ERROR(CheckMask(mask));
  ST_RETURN_IF_ERROR(context_->MakeCurrent());
  gl_->retired_textures.clear();
  PreparedMask& slot = gl_->prepared[key];
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
  auto it = gl_->prepared.find(key);
  if (it == gl_->prepared.end() || it->second.packed != packed_warp_) {
    return NotFoundError("renderer: no mask prepared under " + std::to_string(key));
  }
  // The prepared texture becomes the current one; the current one and the other prepared
  // masks (made for the blend before this one) are deleted later, off a re-blend's path.
  GlTexture& current = packed_warp_ ? gl_->warp_texture : gl_->mask_texture;
  if (current) gl_->retired_textures.push_back(std::move(current));
  current = std::move(it->second.texture);
  used_mask_rows_ = std::move(it->second.rows);
  has_mask_ = true;
  has_lift_ = it->second.has_lift;
  mask_in_warp_texels_ = packed_warp_;
  for (auto& [k, slot] : gl_->prepared) {
    if (slot.texture) gl_->retired_textures.push_back(std::move(slot.texture));
  }
  gl_->prepared.clear();
  return OkStatus();
}

void Renderer::ClearPreparedMasks() {
  if (gl_->prepared.empty() && gl_->retired_textures.empty()) return;
  if (!context_->MakeCurrent().ok()) return;
  for (auto& [k, slot] : gl_->prepared) {
    if (slot.texture) gl_->retired_textures.push_back(std::move(slot.texture));
  }
  gl_->prepared.clear();
  gl_->retired_textures.clear();
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

void Renderer::UploadTexels(GlTexture* texture, const cv::Mat& texels) {
  const bool is_float = texels.depth() == CV_32F;
  const GLenum format = texels.channels() == 4 ? GL_RGBA : GL_RG;
  const GLint internal = texels.channels() == 4 ? (is_float ? GL_RGBA32F : GL_RGBA16)
                                                : (is_float ? GL_RG32F : GL_RG16);
  const GLenum type = is_float ? GL_FLOAT : GL_UNSIGNED_SHORT;
  if (!*texture) {
    *texture =
        MakeTexture2D(internal, size_.width, size_.height, format, type, texels.data, GL_NEAREST);
  } else {
    glBindTexture(GL_TEXTURE_2D, texture->get());
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, size_.width, size_.height, format, type, texels.data);
  }
}

Status Renderer::EnsureIdealTarget() {
  if (gl_->ideal_fbo.get()) return OkStatus();
  const bool is_float = context_->float_output();
  gl_->ideal_colour =
      MakeTexture2D(is_float ? GL_RGBA32F : GL_RGBA8, size_.width, size_.height, GL_RGBA,
                    is_float ? GL_FLOAT : GL_UNSIGNED_BYTE, nullptr, GL_LINEAR);
  gl_->ideal_depth = GlRenderbuffer::Generate();
  glBindRenderbuffer(GL_RENDERBUFFER, gl_->ideal_depth.get());
  glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT24, size_.width, size_.height);
  gl_->ideal_fbo = GlFramebuffer::Generate();
  glBindFramebuffer(GL_FRAMEBUFFER, gl_->ideal_fbo.get());
  glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D,
                         gl_->ideal_colour.get(), 0);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER,
                            gl_->ideal_depth.get());
  if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE) {
    return InternalError("OpenGL: the ideal-image framebuffer is incomplete");
  }
  return CheckGl("creating the ideal-image target");
}

}  // namespace sandtable::node
