// GlContext: where the renderer draws. Two back-ends under the same renderer code:
//   EglContext    headless: EGL on Mesa's surfaceless platform (EGL_PLATFORM_SURFACELESS_MESA),
//                 an OpenGL 3.3+ core context with no display; the output is an offscreen
//                 framebuffer (RGBA8 colour) of the projector's size, read back for the world
//                 or a PNG. Mesa's llvmpipe in CI and tests; a GPU's driver where there is one.
//   WindowContext a GLFW window (node/devices/window_projector_output.h: fullscreen on a chosen
//                 monitor, vsync); the output is the window's back buffer, presented by a swap.
// The renderer draws its last pass into output_framebuffer() (size() px) and calls Present().
// Threading: a context is current on one thread at a time; MakeCurrent() on the thread that
// renders before any GL call (the EGL context may be created on one thread and used on another).
// An EGL context cannot be made current on a thread that holds a window's (GLX) context: glvnd
// answers EGL_BAD_ACCESS (MakeCurrent returns UNAVAILABLE); the render loop has its own thread.
#pragma once

#include <memory>
#include <string>

#include <opencv2/core.hpp>

#include "common/base/status.h"
#include "node/devices/projector_output.h"

namespace sandtable::node {

class WindowProjectorOutput;

class GlContext {
 public:
  virtual ~GlContext() = default;
  virtual Status MakeCurrent() = 0;
  virtual cv::Size size() const = 0;
  // The framebuffer object the last pass draws into (0: the window's back buffer).
  virtual unsigned int output_framebuffer() const = 0;
  // Makes the drawn frame visible: a window swaps (and waits for the swap); an offscreen
  // context only finishes the GL work. shown_time is taken then.
  virtual Expected<ShownFrame> Present() = 0;
  // "EGL surfaceless, OpenGL 4.5 (Core Profile) Mesa 22.3.6, llvmpipe (LLVM 15.0.6, 256 bits)".
  virtual std::string description() const = 0;

  // True for a float output (tests: RenderContent::debug_positions needs one).
  virtual bool float_output() const { return false; }

  // The output framebuffer as RGB8 (CV_8UC3, R first, row 0 at the top, OpenCV order), or
  // for a float output as CV_32FC3.
  Expected<cv::Mat> ReadOutput();
};

enum class OutputFormat { kRgba8, kRgba32f };

// A headless context with an offscreen output of `size_px` (8-bit, or float for tests that
// read positions back), on Mesa's surfaceless platform, or where that offers no display (NVIDIA's
// driver with no display server) on the first EGL device (EGL_EXT_platform_device);
// SANDTABLE_EGL_PLATFORM=device in the environment goes to the devices straight away.
// UNAVAILABLE naming the step when EGL, both platforms or a 3.3 core context are not there;
// INVALID_ARGUMENT for a size outside 1..16384.
Expected<std::unique_ptr<GlContext>> CreateEglContext(cv::Size size_px,
                                                      OutputFormat format = OutputFormat::kRgba8);

// The renderer draws into `window`'s back buffer (the window outlives the context).
std::unique_ptr<GlContext> CreateWindowContext(WindowProjectorOutput* window);

}  // namespace sandtable::node
