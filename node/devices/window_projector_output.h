// WindowProjectorOutput: a real projector driven by a GLFW window on one monitor, fullscreen
// at the monitor's current video mode (the projector's native mode), or, for tests and desks,
// an undecorated window of a chosen size placed on that monitor. OpenGL 3.3 core profile, an
// 8-bit RGB double-buffered framebuffer, vsync (swap interval 1). Show() uploads the frame to a
// texture, draws it with a full-screen quad (gl_frame_blitter.h: texel-exact), swaps and waits
// for the swap to complete (glFinish); shown_time is taken then. The window's pixels then equal
// the frame exactly (the tests read them back from the GL back buffer and from the X server).
//
// size(): the framebuffer's size in px (fullscreen: the monitor's mode).
// Failure behaviour, one line each, never a crash:
//   no display (DISPLAY unset or the X server not there): UNAVAILABLE
//     "window:0: no display: set DISPLAY or run under xvfb-run ..."
//   no monitor N: UNAVAILABLE naming the monitors there are;
//   no OpenGL 3.3 core context, or a framebuffer under 8 bits per channel (frames could not be
//   shown exactly): UNAVAILABLE saying so.
// Threading: GLFW wants windows created and destroyed on the process's main thread. Show() may
// be called from any thread (a node's render thread, its calibration's workers): each call holds
// the window's GL context current on the calling thread and releases it when it returns (a GLX
// context current on one thread cannot be made current on another), so calls from different
// threads take turns. A renderer drawing into the window holds it the same way (ContextHold).
// Several windows may be open at once (GLFW is initialised with the first and terminated with
// the last).
#pragma once

#include <memory>
#include <mutex>
#include <string>

#include "node/devices/gl_frame_blitter.h"
#include "node/devices/projector_output.h"

struct GLFWwindow;

namespace sandtable::node {

struct WindowOptions {
  int monitor_index = 0;                 // glfwGetMonitors() order; 0 is the primary monitor
  bool windowed = false;                 // false: fullscreen on the monitor
  cv::Size windowed_size_px{1280, 800};  // windowed mode only
  bool vsync = true;
  std::string title = "sandtable";
  // Reads every frame back after drawing it (last_read_back()): tests and diagnostics; costs
  // a glReadPixels of the whole window per frame.
  bool keep_read_back = false;

  Status Check() const;
};

class WindowProjectorOutput : public ProjectorOutput {
 public:
  static Expected<std::unique_ptr<WindowProjectorOutput>> Open(const WindowOptions& options);
  ~WindowProjectorOutput() override;
  WindowProjectorOutput(const WindowProjectorOutput&) = delete;
  WindowProjectorOutput& operator=(const WindowProjectorOutput&) = delete;

  cv::Size size() const override { return size_px_; }
  std::string description() const override { return description_; }
  Expected<ShownFrame> Show(const cv::Mat& frame) override;

  // With WindowOptions::keep_read_back: the last frame as drawn, read back from the back buffer
  // with glReadPixels after drawing and before the swap, as RGB8 (CV_8UC3, R first, row 0 at
  // the top; a GRAY8 frame reads back with R = G = B). Empty before the first Show() or when
  // the option is off. (The front buffer is not read: Mesa's software rasteriser, e.g. under
  // Xvfb, keeps no client-side copy of it.)
  const cv::Mat& last_read_back() const { return last_read_back_; }

  // The window's GL context current on the calling thread from construction to destruction;
  // other threads' Show() and holds wait meanwhile. Holds nest on one thread; the outermost
  // releases the context.
  class ContextHold {
   public:
    explicit ContextHold(WindowProjectorOutput* window);
    ~ContextHold();
    ContextHold(const ContextHold&) = delete;
    ContextHold& operator=(const ContextHold&) = delete;

   private:
    WindowProjectorOutput* window_;
  };

  // For a renderer that draws into the window itself (node/render/gl_context.h), within a
  // ContextHold: makes the window's context current on the calling thread (framebuffer 0 is the
  // window's back buffer), and swaps what was drawn there like Show() does (poll, swap, wait for
  // the swap).
  void MakeCurrent();
  Expected<ShownFrame> PresentBackBuffer();

 private:
  WindowProjectorOutput() = default;

  GLFWwindow* window_ = nullptr;
  // ContextHold: who holds the context, and how deep (guarded by the mutex itself).
  std::recursive_mutex context_mutex_;
  int hold_depth_ = 0;
  bool glfw_acquired_ = false;
  std::unique_ptr<GlFrameBlitter> blitter_;
  cv::Size size_px_;
  std::string description_;
  bool keep_read_back_ = false;
  cv::Mat last_read_back_;
  uint64_t frames_shown_ = 0;
};

}  // namespace sandtable::node
