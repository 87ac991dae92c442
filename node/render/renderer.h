// Renderer: what a projector shows, drawn with OpenGL 3.3 core into a GlContext
// (docs/render.md). Passes, in TR09-017's order (its Figure 7):
//   shadow   the virtual sun's depth map (orthographic from the sun); only when the sun moved
//            or was never drawn
//   scene    the glTF model from the calibrated projector: base colour x base-colour texture,
//            lit by the sun (ambient + Lambert x shadow) when there is one; or white, or the
//            table grid, for those test patterns. Material groups outside the frustum are culled
//   overlay  strokes, traces and markers (overlay_geometry.h), depth-tested against the scene
//   warp     the lens-distortion pre-warp and the mask (blend x intensity correction)
//   pattern  a 2D test pattern (id, colour bars) or raw white, instead of all of the above
// Folding (RendererOptions::fold_prewarp; off by default: on llvmpipe the tessellation it needs
// costs more than the warp pass it saves, docs/render.md): the pre-warp runs in the vertex shader
// (each vertex goes through the Brown model, exactly CameraModel::Project, on a model tessellated
// finely enough that the lens bends no edge by more than prewarp_tolerance_px between vertices) and
// the mask multiplies in the scene's and overlay's fragment shaders: no warp pass, no intermediate
// image. Unfolded, the scene is drawn with the pinhole matrix into an ideal image and a full-screen
// warp pass looks each output pixel up in it. A pass a frame does not need is skipped and counted
// in FrameStats.
// Deferred (RendererOptions::deferred, on by default; the show only, 8-bit targets, unfolded): the
// projector does not move between calibrations and the model is static, so what the scene pass
// and the pre-warp compute of the model at every output pixel (the surface's depth along its
// ideal pixel's ray, its face, its base colour x texture) is drawn once per view into a surface
// cache, one RGBA32UI texel a pixel (the scene pass into an ideal cache, the warp pass resampling
// and packing it into output pixels: nearest for the geometry, bilinear for the colour), and
// kept. Every frame then runs only what changes with time: when the sun moved, the shadow map and
// the sun's light on each face (one texel a face); one full-screen light pass (the face's light x
// the shadow lookup at the point rebuilt from the cache, the mask, the lift); the overlay, drawn
// straight into output pixels through the lens model in its vertex shader and depth-tested
// against the cache. FrameStats counts the cached passes as skipped (docs/render.md).
//
// Colour: every value is display-encoded (what the projector is sent). Products of linear
// quantities (albedo x light x mask) are taken on encoded values with the display's power law
// (display_gamma, 2.2): encode(a b) = encode(a) encode(b), exact for a power-law projector
// such as the world's; texture filtering runs on encoded texels.
//
// Calibration and masks swap in between frames (SetView, SetMask); the distortion map is
// computed beforehand off the render thread (PrepareProjectorView). Every call needs the
// context current on the calling thread; errors are Status (INTERNAL with the GL error),
// nothing aborts.
#pragma once

#include <array>
#include <map>
#include <memory>
#include <optional>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "common/base/status.h"
#include "common/scene/scene.h"
#include "node/render/gl_context.h"
#include "node/render/gl_objects.h"
#include "node/render/overlay_geometry.h"
#include "node/render/projector_view.h"
#include "node/render/render_content.h"

namespace sandtable::node {

struct RendererOptions {
  int shadow_map_px = 1024;            // 1.5 mm per texel over a 1.5 m table
  bool fold_prewarp = false;           // see above
  bool deferred = true;                // the show lit from a surface cache (see above)
  double prewarp_tolerance_px = 0.02;  // folded pre-warp: chord error of a triangle edge
  double min_tessellation_px = 8.0;    // ... edges never shorter than this
  double max_tessellation_px = 256.0;  // ... nor left longer
  double display_gamma = 2.2;
  double ambient = 0.35;        // share of light that is not the sun's (sky), in [0, 1]
  double grid_spacing_m = 0.1;  // the table grid's line spacing
  double grid_line_width_m = 0.003;
  OverlayOptions overlay;
  bool time_passes = false;  // glFinish after each pass to time it (benchmarks)
  Status Check() const;
};

enum class Pass { kShadow = 0, kScene, kOverlay, kWarp, kPattern, kLight };
inline constexpr int kPassCount = 6;
const char* PassName(Pass pass);

struct FrameStats {
  double frame_ms = 0.0;                     // CPU wall time of Render, GL work finished
  std::array<bool, kPassCount> ran{};        // which passes ran
  std::array<double, kPassCount> pass_ms{};  // with RendererOptions::time_passes
  int groups_drawn = 0, groups_culled = 0;   // material groups of the model
  int overlay_triangles = 0;
  bool overlay_rebuilt = false;
  int scene_triangles = 0;       // drawn (after tessellation)
  bool prewarp = false;          // the frame went through the pre-warp (folded or as a pass)
  double tessellation_px = 0.0;  // folded pre-warp: the longest edge of the scene's triangles
  bool masked = false;
};

class Renderer {
 public:
  // `context` stays current-able and outlives the renderer; `scene` in the table frame (the
  // model as placed, table included).
  static Expected<std::unique_ptr<Renderer>> Create(GlContext* context, const Scene& scene,
                                                    const RendererOptions& options = {});
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  // The calibrated projector (size must be the context's). Cheap: uploads the distortion map.
  Status SetView(const ProjectorView& view);
  bool has_view() const { return has_view_; }
  // Per output pixel factor in [0, 1] (CV_32FC1 or CV_8UC1 / 255 of the context's size, row 0
  // at the top), applied in linear light: the blend mask times the intensity correction times
  // a join's blanking. Empty: identity (the warp pass may be skipped). CV_32FC2: (factor,
  // lift): the lift, linear, is added after the factor (black-level matching, docs/blend.md:
  // out = encode(decode(c) factor + lift)).
  Status SetMask(const cv::Mat& mask);
  // Prepared masks: a mask encoded and uploaded ahead of time under `key` (what SetMask does,
  // into a texture of its own), so that UseMask(key) later makes it current without either: a
  // re-blend after a neighbour left swaps the mask prepared for it in (docs/blend.md, "Prepared
  // masks"). A new view, a new SetMask or a UseMask drops every prepared mask (they were made
  // for the old view, or for the blend before). Memory: one texture of the output's size each
  // (8 MB at 1280x800 with a pre-warp, 4 MB without).
  Status PrepareMask(uint64_t key, const cv::Mat& mask);
  bool HasPreparedMask(uint64_t key) const;
  // NOT_FOUND when no mask is prepared under `key`.
  Status UseMask(uint64_t key);
  void ClearPreparedMasks();

  // Draws one frame into the context's output framebuffer (not presented: GlContext::Present).
  Expected<FrameStats> Render(const RenderContent& content);
  // The last frame again under the current mask: the warp pass alone over the ideal image the
  // last Render left; for a deferred frame the mask alone over the frame before the mask, which
  // the light pass and the overlay keep in a second target (headless contexts), or in a window
  // the light pass and the overlay again over the surface cache with the last frame's sun (a
  // mask swap, a re-blend, needs nothing else).
  // UNAVAILABLE unless CanRewarp().
  Expected<FrameStats> Rewarp();
  // The last Render went through the warp pass (unfolded) or was deferred, and no view was set
  // since.
  bool CanRewarp() const { return last_warped_; }
  // The floor: one full-screen textured pass at the output size, GL work finished; ms.
  Expected<double> RenderFloor();

 private:
  Renderer(GlContext* context, const RendererOptions& options);
  Status Init(const Scene& scene);
  void InitMaterials(const Scene& scene);
  Status DrawScene(const RenderContent& content, unsigned int target, bool fold, FrameStats* stats);
  // Adds lit_texture_ to the output framebuffer as a second draw buffer, or takes it away.
  Status AttachLitTarget(bool attach);
  struct Group;
  // `face_normals`: each triangle's normal in the buffer's order (3 floats a triangle), if given.
  Status UploadGeometry(unsigned int vao, unsigned int vbo, double edge_px,
                        std::vector<Group>* groups, std::vector<float>* face_normals = nullptr);
  void SetDistortionUniforms(unsigned int program, bool distort);
  enum class ProgramKind {
    kScene = 0,
    kOverlay = 1,
    kWarp = 2,
    kSurface = 3,      // the model into the surface cache
    kSurfaceWarp = 4,  // the ideal surface cache resampled into output pixels
    kLight = 5,        // the deferred frame's full-screen pass
    kFaceLight = 6,    // the sun's light on each face (Variant's table has one row a kind)
  };
  // The program specialised for these features (compiled on first use, then cached). `packed`:
  // the mask is read from the warp's packed texture (its zw).
  float LiftGamma() const;  // the exponent the shaders add the lift under
  Expected<unsigned int> Variant(ProgramKind kind, int mode, bool textured, bool sun, bool masked,
                                 bool distort, bool packed = false);
  // A group's encoded base colour and texture (an index into the scene's textures, -1: none); white
  // without a material.
  std::pair<Eigen::Vector4d, int> GroupMaterial(const Group& g) const;
  Status DrawShadow(const Eigen::Vector3d& sun);
  // The overlay: rebuilt when the content's changed, then drawn. `fold`: into output pixels
  // (through the lens model, masked) rather than into the ideal image.
  // `against_cache`: depth-tested against the surface cache (a deferred frame) rather than the
  // bound depth buffer.
  Status DrawOverlay(const RenderContent& content, bool fold, FrameStats* stats,
                     bool against_cache = false);
  Status DrawOverlayBuffer(bool fold, bool against_cache);
  // The deferred path (see above).
  Status EnsureSurfaceTargets();
  Status DrawSurfaceScene();  // counts into surface_groups_*_, which every frame reports
  Status DrawSurfaceWarp();
  Status DrawFaceLight(const Eigen::Vector3d& sun);
  Status DrawLight(bool sun, float light);
  // The warp pass over `image` (the ideal image; distort: through the pre-warp) into the output.
  Status DrawWarp(unsigned int image, bool distort);
  Status DrawPattern(const RenderContent& content);
  Status EnsureIdealTarget();
  struct GlResources;  // every GL object the renderer owns (renderer_internal.h)
  struct SurfaceTarget;
  struct PreparedMask;
  // `texels` into `*texture`, made when there is none yet.
  void UploadTexels(GlTexture* texture, const cv::Mat& texels);

  struct Group {
    int first_vertex = 0, vertex_count = 0;
    int material = -1;
    Eigen::AlignedBox3d bounds;
  };

  GlContext* context_;
  RendererOptions options_;
  Scene scene_;
  bool geometry_tessellated_ = false;
  cv::Size size_;
  Eigen::AlignedBox3d scene_bounds_;
  std::vector<Group> groups_;         // the scene pass's (tessellated for a folded pre-warp)
  std::vector<Group> shadow_groups_;  // the model as given, less a flat bottom (Create)
  std::vector<int> draw_order_;       // groups_ nearest first for the current view (SetView)
  double tessellation_px_ = 0.0;
  std::vector<Eigen::Vector4d> material_colours_;
  std::vector<int> material_textures_;
  std::unique_ptr<GlResources> gl_;
  bool surface_valid_ = false;  // the surface cache holds the model for view_
  int surface_groups_drawn_ = 0, surface_groups_culled_ = 0, surface_triangles_ = 0;
  // The faces' tables (GlResources::face_normals, face_light): this many faces a row.
  static constexpr int kFaceRowTexels = 4096;
  bool deferred_ = false;  // options_.deferred, and the model's faces fit the tables
  cv::Size face_table_size_;
  std::optional<Eigen::Vector3d> face_light_sun_;  // the sun the faces' light was drawn for
  bool last_deferred_ = false;  // the last frame was deferred (Rewarp re-lights it)
  bool last_sun_ = false;       // ... lit by the sun (face light x shadow)
  float last_light_ = 1.0f;     // ... or by this factor
  bool last_overlay_ = false;   // ... with an overlay
  bool lit_attached_ = false;   // the lit texture is the output's second target
  bool last_lit_kept_ = false;  // the lit texture holds the last frame
  // The warp pass's inputs: with an unfolded pre-warp (packed_warp_) one RGBA texture of
  // (source x, y, mask factor, lift) per output pixel, one fetch a pixel; otherwise the mask alone
  // (RG). Texels are 16-bit normalized (32-bit floats for a float target) in GL row order, kept
  // between masks: a new mask is written into them in place and uploaded.
  cv::Mat warp_texels_;  // source (GL texture coordinates of the ideal image; 0 or -1: none), mask
  cv::Mat mask_rows_;    // factor (encoded; linear for a float target), lift (linear)
  bool packed_warp_ = false;
  bool mask_in_warp_texels_ = false;  // the current mask lives in warp_texels_, not mask_rows_
  cv::Mat prepared_scratch_;          // the packed texels of the mask being prepared
  // After UseMask: the current mask's texels, not yet copied back into warp_texels_ or
  // mask_rows_ (only SetView reads them; SetMask rewrites them whole).
  cv::Mat used_mask_rows_;
  Status CheckMask(const cv::Mat& mask) const;
  // `mask` into `texels` (channels offset, offset + 1 of stride a texel): clamped, the factor
  // encoded, GL row order. Returns whether it carries a lift.
  bool EncodeMask(const cv::Mat& mask, cv::Mat* texels, int stride, int offset) const;
  void SyncUsedMaskRows();
  bool has_view_ = false, has_mask_ = false;
  bool last_warped_ = false;  // the ideal image holds the last frame (see CanRewarp)
  bool has_lift_ = false;     // the mask carries a black-level lift (SetMask, CV_32FC2)
  ProjectorView view_;
  std::optional<Eigen::Vector3d> shadow_sun_;  // the sun of the current shadow map
  Eigen::Matrix4d sun_clip_from_table_ = Eigen::Matrix4d::Identity();
  uint64_t overlay_version_ = ~uint64_t{0};
  bool overlay_view_dirty_ = true;
  int overlay_vertices_ = 0;
  TestPattern pattern_uploaded_ = TestPattern::kNone;
  uint32_t pattern_id_uploaded_ = ~0u;
};

}  // namespace sandtable::node
