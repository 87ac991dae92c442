// What the renderer's source files (renderer*.cc) share and nothing else includes: the GL objects
// a Renderer owns, and small helpers. Needs a current context like the Renderer itself.
#pragma once

#include <chrono>
#include <cstdint>
#include <map>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "common/geometry/rigid3.h"
#include "node/render/gl_objects.h"
#include "node/render/renderer.h"

namespace sandtable::node {

// A surface cache (the layout is in shaders/surface.frag): the ideal one (geometry RGBA32UI,
// colour RGBA8, depth) drawn by the scene pass, the output one (geometry: the packed texel) by
// the warp pass.
struct Renderer::SurfaceTarget {
  GlFramebuffer fbo;
  GlTexture geometry, colour;
  GlRenderbuffer depth;
};

struct Renderer::PreparedMask {
  GlTexture texture;  // packed (with the warp's source) when packed, else the mask alone
  bool packed = false;
  bool has_lift = false;
  cv::Mat rows;  // the mask's texels (factor, lift), GL row order, as mask_rows_ holds them
};

// Every OpenGL object of a Renderer, freed together (~Renderer makes the context current first).
struct Renderer::GlResources {
  GlProgram shadow_program, blit_program;
  std::map<int, GlProgram> variants;  // Variant's programs by key
  GlVertexArray scene_vao, shadow_vao, overlay_vao;
  GlBuffer scene_vbo, shadow_vbo, overlay_vbo;
  GlVertexArray empty_vao;          // full-screen passes (the quad comes from gl_VertexID)
  std::vector<GlTexture> textures;  // the scene's, by index
  GlFramebuffer shadow_fbo;
  GlTexture shadow_texture;  // the sun's depth map
  GlFramebuffer ideal_fbo;   // the ideal image (the warp pass's input)
  GlTexture ideal_colour;
  GlRenderbuffer ideal_depth;
  GlRenderbuffer output_depth;  // for an offscreen output without a depth buffer
  SurfaceTarget surface, ideal_surface;
  // The sun's light on each face (R32F, kFaceRowTexels a row; face f at (f % ..., f / ...)),
  // drawn from the faces' normals (RGB32F, same layout) when the sun moves.
  GlTexture face_normals, face_light;
  GlFramebuffer face_light_fbo;
  // The last deferred frame before the mask (RGBA8, output pixels), written by the light pass and
  // the overlay as a second target while lit_attached_: Rewarp masks it again in one pass.
  GlTexture lit_texture;
  // The warp pass's inputs (warp_texels_, mask_rows_ in renderer.h), the test pattern last
  // uploaded, and the floor's full-screen image (RenderFloor).
  GlTexture warp_texture, mask_texture, pattern_texture, floor_texture;
  std::map<uint64_t, PreparedMask> prepared;
  std::vector<GlTexture> retired_textures;  // replaced by UseMask; deleted off its path
};

namespace render_internal {

using Clock = std::chrono::steady_clock;

inline double MsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// A new 2D texture, clamped at its edges, one level, `filter` both ways; `data` may be null.
GlTexture MakeTexture2D(int internal_format, int w, int h, unsigned int format, unsigned int type,
                        const void* data, int filter);

// Rows of an OpenCV-ordered image (row 0 at the top) in GL order (row 0 at the bottom).
cv::Mat FlippedContinuous(const cv::Mat& image);

// Every corner of `box` beyond the same clip plane (an empty box: outside).
bool OutsideFrustum(const Eigen::Matrix4d& clip_from_table, const Eigen::AlignedBox3d& box);

// The projector's rigid transform as a 4x4 matrix (camera <- table, metres).
Eigen::Matrix4d Matrix(const Rigid3d& transform);

}  // namespace render_internal
}  // namespace sandtable::node
