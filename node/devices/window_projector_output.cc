#include "node/devices/window_projector_output.h"

#include <cstdlib>
#include <mutex>

#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>

#include "common/base/log.h"

namespace sandtable::node {
namespace {

// GLFW is process-wide: initialised by the first window, terminated with the last.
std::mutex glfw_mutex;
int glfw_users = 0;
// GLFW reports errors through a callback on the thread that made the failing call.
thread_local std::string glfw_last_error;

void OnGlfwError(int code, const char* description) {
  glfw_last_error =
      std::string(description ? description : "") + " (GLFW error " + std::to_string(code) + ")";
}

std::string TakeGlfwError() {
  std::string text = glfw_last_error.empty() ? "no detail" : glfw_last_error;
  glfw_last_error.clear();
  return text;
}

bool HasEnv(const char* name) {
  const char* value = std::getenv(name);
  return value != nullptr && value[0] != '\0';
}

Status AcquireGlfw(const std::string& who) {
  std::lock_guard<std::mutex> lock(glfw_mutex);
  if (glfw_users == 0) {
    glfwSetErrorCallback(OnGlfwError);
    const std::string no_display = who + ": no display: set DISPLAY or run under xvfb-run";
    if (!HasEnv("DISPLAY") && !HasEnv("WAYLAND_DISPLAY")) return UnavailableError(no_display);
    glfw_last_error.clear();
    if (glfwInit() != GLFW_TRUE) return UnavailableError(no_display + " (" + TakeGlfwError() + ")");
  }
  ++glfw_users;
  return OkStatus();
}

void ReleaseGlfw() {
  std::lock_guard<std::mutex> lock(glfw_mutex);
  if (--glfw_users == 0) glfwTerminate();
}

std::string SizeText(int w, int h) { return std::to_string(w) + "x" + std::to_string(h); }

std::string MonitorList(GLFWmonitor** monitors, int count) {
  std::string text;
  for (int i = 0; i < count; ++i) {
    const GLFWvidmode* mode = glfwGetVideoMode(monitors[i]);
    const char* name = glfwGetMonitorName(monitors[i]);
    if (i) text += ", ";
    text += std::to_string(i) + " '" + (name ? name : "?") + "'";
    if (mode) text += " " + SizeText(mode->width, mode->height);
  }
  return text;
}

}  // namespace

Status WindowOptions::Check() const {
  if (monitor_index < 0) {
    return InvalidArgumentError("window: monitor index " + std::to_string(monitor_index) +
                                " must be >= 0");
  }
  if (windowed && (windowed_size_px.width <= 0 || windowed_size_px.height <= 0)) {
    return InvalidArgumentError("window: windowed size " +
                                SizeText(windowed_size_px.width, windowed_size_px.height) +
                                " must be positive");
  }
  return OkStatus();
}

Expected<std::unique_ptr<WindowProjectorOutput>> WindowProjectorOutput::Open(
    const WindowOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  std::unique_ptr<WindowProjectorOutput> output(new WindowProjectorOutput());
  output->description_ =
      "window:" + std::to_string(options.monitor_index) + (options.windowed ? ":windowed" : "");
  output->keep_read_back_ = options.keep_read_back;
  const std::string& who = output->description_;
  ST_RETURN_IF_ERROR(AcquireGlfw(who));
  output->glfw_acquired_ = true;  // released by the destructor from here on

  int count = 0;
  GLFWmonitor** monitors = glfwGetMonitors(&count);
  if (monitors == nullptr || options.monitor_index >= count) {
    return UnavailableError(who + ": no monitor " + std::to_string(options.monitor_index) + " (" +
                            std::to_string(count) + " connected" +
                            (count ? ": " + MonitorList(monitors, count) : std::string()) + ")");
  }
  GLFWmonitor* monitor = monitors[options.monitor_index];
  const GLFWvidmode* mode = glfwGetVideoMode(monitor);
  if (mode == nullptr) return UnavailableError(who + ": the monitor has no video mode");

  glfwDefaultWindowHints();
  glfwWindowHint(GLFW_CLIENT_API, GLFW_OPENGL_API);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
  glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
  glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
  glfwWindowHint(GLFW_RED_BITS, 8);
  glfwWindowHint(GLFW_GREEN_BITS, 8);
  glfwWindowHint(GLFW_BLUE_BITS, 8);
  glfwWindowHint(GLFW_DOUBLEBUFFER, GLFW_TRUE);
  glfwWindowHint(GLFW_SAMPLES, 0);
  glfwWindowHint(GLFW_RESIZABLE, GLFW_FALSE);
  glfwWindowHint(GLFW_AUTO_ICONIFY, GLFW_FALSE);  // a projector stays lit without focus
  glfw_last_error.clear();
  if (options.windowed) {
    glfwWindowHint(GLFW_DECORATED, GLFW_FALSE);
    output->window_ =
        glfwCreateWindow(options.windowed_size_px.width, options.windowed_size_px.height,
                         options.title.c_str(), nullptr, nullptr);
    if (output->window_) {
      int x = 0, y = 0;
      glfwGetMonitorPos(monitor, &x, &y);
      glfwSetWindowPos(output->window_, x, y);
    }
  } else {
    glfwWindowHint(GLFW_REFRESH_RATE, mode->refreshRate);
    output->window_ =
        glfwCreateWindow(mode->width, mode->height, options.title.c_str(), monitor, nullptr);
  }
  if (output->window_ == nullptr) {
    return UnavailableError(who + ": cannot open an OpenGL 3.3 core window (" + TakeGlfwError() +
                            ")");
  }
  glfwSetInputMode(output->window_, GLFW_CURSOR, GLFW_CURSOR_HIDDEN);
  output->MakeCurrent();
  glfwSwapInterval(options.vsync ? 1 : 0);
  int width = 0, height = 0;
  glfwGetFramebufferSize(output->window_, &width, &height);
  output->size_px_ = cv::Size(width, height);
  if (width <= 0 || height <= 0) {
    return UnavailableError(who + ": the window has an empty framebuffer");
  }
  GLint bits[3] = {0, 0, 0};
  const GLenum channels[3] = {GL_FRAMEBUFFER_ATTACHMENT_RED_SIZE,
                              GL_FRAMEBUFFER_ATTACHMENT_GREEN_SIZE,
                              GL_FRAMEBUFFER_ATTACHMENT_BLUE_SIZE};
  for (int c = 0; c < 3; ++c) {
    glGetFramebufferAttachmentParameteriv(GL_FRAMEBUFFER, GL_BACK_LEFT, channels[c], &bits[c]);
  }
  if (bits[0] < 8 || bits[1] < 8 || bits[2] < 8) {
    return UnavailableError(who + ": the display gives " + std::to_string(bits[0]) + "/" +
                            std::to_string(bits[1]) + "/" + std::to_string(bits[2]) +
                            " bits per channel, frames need 8 (Xvfb: -screen 0 WxHx24)");
  }
  Expected<std::unique_ptr<GlFrameBlitter>> blitter = GlFrameBlitter::Create(output->size_px_);
  if (!blitter.ok()) return blitter.status().WithContext(who);
  output->blitter_ = std::move(*blitter);
  // Black until the first frame.
  ST_RETURN_IF_ERROR(output->blitter_->Redraw().WithContext(who));
  glfwSwapBuffers(output->window_);
  ST_LOG(kInfo) << who << ": " << SizeText(width, height) << " OpenGL "
                << reinterpret_cast<const char*>(glGetString(GL_VERSION)) << " on '"
                << reinterpret_cast<const char*>(glGetString(GL_RENDERER)) << "'";
  // Current on no thread between calls: the next may come from any thread.
  glfwMakeContextCurrent(nullptr);
  return output;
}

WindowProjectorOutput::~WindowProjectorOutput() {
  if (window_) {
    {
      ContextHold hold(this);
      blitter_.reset();  // GL objects go while their context is current
    }
    glfwDestroyWindow(window_);
  }
  if (glfw_acquired_) ReleaseGlfw();
}

WindowProjectorOutput::ContextHold::ContextHold(WindowProjectorOutput* window) : window_(window) {
  window_->context_mutex_.lock();
  if (window_->hold_depth_++ == 0) glfwMakeContextCurrent(window_->window_);
}

WindowProjectorOutput::ContextHold::~ContextHold() {
  if (--window_->hold_depth_ == 0) glfwMakeContextCurrent(nullptr);
  window_->context_mutex_.unlock();
}

void WindowProjectorOutput::MakeCurrent() {
  if (glfwGetCurrentContext() != window_) glfwMakeContextCurrent(window_);
}

Expected<ShownFrame> WindowProjectorOutput::Show(const cv::Mat& frame) {
  ST_RETURN_IF_ERROR(CheckProjectorFrame(frame, size_px_, description_));
  ContextHold hold(this);
  glfwPollEvents();  // keeps the window responsive to its window system
  ST_RETURN_IF_ERROR(blitter_->Draw(frame).WithContext(description_));
  if (keep_read_back_) {
    Expected<cv::Mat> drawn = blitter_->ReadBackBuffer();
    if (!drawn.ok()) return drawn.status().WithContext(description_);
    last_read_back_ = std::move(*drawn);
  }
  return PresentBackBuffer();
}

Expected<ShownFrame> WindowProjectorOutput::PresentBackBuffer() {
  ContextHold hold(this);
  glfwSwapBuffers(window_);
  glFinish();  // the swap has happened (with vsync: at the vertical blank)
  glfwPollEvents();
  ShownFrame shown;
  shown.shown_time = DeviceClock::now();
  shown.frame_index = ++frames_shown_;
  ST_LOG(kDebug) << description_ << ": frame " << shown.frame_index << " swapped";
  return shown;
}

}  // namespace sandtable::node
