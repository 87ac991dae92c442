#include "node/render/gl_context.h"

#include <cstdlib>
#include <string>

#include <EGL/egl.h>
#include <EGL/eglext.h>
#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>
#include <opencv2/core.hpp>

#include "node/devices/gl_util.h"
#include "node/devices/window_projector_output.h"

namespace sandtable::node {
namespace {

std::string EglErrorText() { return "EGL error 0x" + cv::format("%04x", eglGetError()); }

std::string GlDescription(const std::string& back_end) {
  const char* version = reinterpret_cast<const char*>(glGetString(GL_VERSION));
  const char* renderer = reinterpret_cast<const char*>(glGetString(GL_RENDERER));
  return back_end + ", OpenGL " + (version ? version : "?") + ", " + (renderer ? renderer : "?");
}

class EglContext : public GlContext {
 public:
  ~EglContext() override {
    if (display_ == EGL_NO_DISPLAY) return;
    if (context_ != EGL_NO_CONTEXT) {
      eglMakeCurrent(display_, EGL_NO_SURFACE, EGL_NO_SURFACE, context_);
      if (framebuffer_) glDeleteFramebuffers(1, &framebuffer_);
      if (colour_) glDeleteRenderbuffers(1, &colour_);
      eglMakeCurrent(display_, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
      eglDestroyContext(display_, context_);
    }
    // The display is shared by every context of the process (EGL returns the same one);
    // eglTerminate would pull it from under the others, so it is left initialised.
  }

  Status Init(cv::Size size_px, OutputFormat format) {
    size_ = size_px;
    float_ = format == OutputFormat::kRgba32f;
    if (size_px.width <= 0 || size_px.height <= 0 || size_px.width > 16384 ||
        size_px.height > 16384) {
      return InvalidArgumentError("EGL context: size " + std::to_string(size_px.width) + "x" +
                                  std::to_string(size_px.height) + " px is outside 1..16384");
    }
    ST_RETURN_IF_ERROR(OpenDisplay());
    if (eglBindAPI(EGL_OPENGL_API) != EGL_TRUE) {
      return UnavailableError("EGL: no desktop OpenGL API: " + EglErrorText());
    }
    // Surfaceless configs offer pbuffers only (the default EGL_SURFACE_TYPE asks for windows).
    const EGLint config_attributes[] = {EGL_SURFACE_TYPE, EGL_PBUFFER_BIT, EGL_RENDERABLE_TYPE,
                                        EGL_OPENGL_BIT, EGL_NONE};
    EGLConfig config = nullptr;
    EGLint configs = 0;
    if (eglChooseConfig(display_, config_attributes, &config, 1, &configs) != EGL_TRUE ||
        configs < 1) {
      return UnavailableError("EGL: no OpenGL config: " + EglErrorText());
    }
    const EGLint context_attributes[] = {EGL_CONTEXT_MAJOR_VERSION,
                                         3,
                                         EGL_CONTEXT_MINOR_VERSION,
                                         3,
                                         EGL_CONTEXT_OPENGL_PROFILE_MASK,
                                         EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT,
                                         EGL_NONE};
    context_ = eglCreateContext(display_, config, EGL_NO_CONTEXT, context_attributes);
    if (context_ == EGL_NO_CONTEXT) {
      return UnavailableError("EGL: no OpenGL 3.3 core context: " + EglErrorText());
    }
    ST_RETURN_IF_ERROR(MakeCurrent());
    glGenRenderbuffers(1, &colour_);
    glBindRenderbuffer(GL_RENDERBUFFER, colour_);
    glRenderbufferStorage(GL_RENDERBUFFER, float_ ? GL_RGBA32F : GL_RGBA8, size_.width,
                          size_.height);
    glGenFramebuffers(1, &framebuffer_);
    glBindFramebuffer(GL_FRAMEBUFFER, framebuffer_);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, colour_);
    if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE) {
      return UnavailableError("EGL: the offscreen output framebuffer is incomplete");
    }
    glClearColor(0, 0, 0, 1);
    glClear(GL_COLOR_BUFFER_BIT);
    ST_RETURN_IF_ERROR(CheckGl("creating the offscreen output"));
    description_ = GlDescription(back_end_);
    return OkStatus();
  }

  // Mesa's surfaceless platform first (llvmpipe in CI, any Mesa driver); where it offers no
  // display, as under NVIDIA's driver without a display server, the first EGL device
  // (EGL_EXT_platform_device) that initialises. SANDTABLE_EGL_PLATFORM=device skips the first.
  Status OpenDisplay() {
    const char* platform = std::getenv("SANDTABLE_EGL_PLATFORM");
    const bool device_only = platform != nullptr && std::string(platform) == "device";
    auto get_platform_display = reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(
        eglGetProcAddress("eglGetPlatformDisplayEXT"));
    if (!get_platform_display) {
      return UnavailableError("EGL: no eglGetPlatformDisplayEXT (install libegl-mesa0)");
    }
    EGLint major = 0, minor = 0;
    std::string surfaceless_error = "skipped: SANDTABLE_EGL_PLATFORM=device";
    if (!device_only) {
      display_ = get_platform_display(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
      if (display_ != EGL_NO_DISPLAY && eglInitialize(display_, &major, &minor) == EGL_TRUE) {
        back_end_ = "EGL surfaceless";
        return OkStatus();
      }
      surfaceless_error = EglErrorText();
    }
    display_ = EGL_NO_DISPLAY;
    auto query_devices =
        reinterpret_cast<PFNEGLQUERYDEVICESEXTPROC>(eglGetProcAddress("eglQueryDevicesEXT"));
    EGLDeviceEXT devices[8];
    EGLint device_count = 0;
    if (query_devices && query_devices(8, devices, &device_count) == EGL_TRUE) {
      for (EGLint i = 0; i < device_count; ++i) {
        EGLDisplay display = get_platform_display(EGL_PLATFORM_DEVICE_EXT, devices[i], nullptr);
        if (display != EGL_NO_DISPLAY && eglInitialize(display, &major, &minor) == EGL_TRUE) {
          display_ = display;
          back_end_ = "EGL device " + std::to_string(i);
          return OkStatus();
        }
      }
    }
    return UnavailableError(
        "EGL: no surfaceless display (Mesa's EGL_MESA_platform_surfaceless; install "
        "libegl-mesa0 libgl1-mesa-dri: " +
        surfaceless_error + ") and no EGL device that initialises (" +
        std::to_string(device_count) + " found)");
  }

  Status MakeCurrent() override {
    if (eglGetCurrentContext() == context_) return OkStatus();
    if (eglMakeCurrent(display_, EGL_NO_SURFACE, EGL_NO_SURFACE, context_) != EGL_TRUE) {
      return UnavailableError("EGL: eglMakeCurrent failed: " + EglErrorText());
    }
    return OkStatus();
  }
  cv::Size size() const override { return size_; }
  unsigned int output_framebuffer() const override { return framebuffer_; }
  Expected<ShownFrame> Present() override {
    glFinish();
    ShownFrame shown;
    shown.frame_index = ++frames_;
    shown.shown_time = DeviceClock::now();
    return shown;
  }
  std::string description() const override { return description_; }
  bool float_output() const override { return float_; }

 private:
  bool float_ = false;
  EGLDisplay display_ = EGL_NO_DISPLAY;
  EGLContext context_ = EGL_NO_CONTEXT;
  std::string back_end_;
  GLuint framebuffer_ = 0, colour_ = 0;
  cv::Size size_;
  uint64_t frames_ = 0;
  std::string description_;
};

class WindowContext : public GlContext {
 public:
  explicit WindowContext(WindowProjectorOutput* window) : window_(window) {
    window_->MakeCurrent();
    description_ = GlDescription("GLFW window " + window_->description());
  }
  Status MakeCurrent() override {
    window_->MakeCurrent();
    return OkStatus();
  }
  cv::Size size() const override { return window_->size(); }
  unsigned int output_framebuffer() const override { return 0; }
  Expected<ShownFrame> Present() override { return window_->PresentBackBuffer(); }
  std::string description() const override { return description_; }

 private:
  WindowProjectorOutput* window_;
  std::string description_;
};

}  // namespace

Expected<cv::Mat> GlContext::ReadOutput() {
  ST_RETURN_IF_ERROR(MakeCurrent());
  const cv::Size s = size();
  const bool is_float = float_output();
  cv::Mat bottom_up(s, is_float ? CV_32FC3 : CV_8UC3);
  glBindFramebuffer(GL_READ_FRAMEBUFFER, output_framebuffer());
  if (output_framebuffer() == 0) {
    glReadBuffer(GL_BACK);
  } else {
    glReadBuffer(GL_COLOR_ATTACHMENT0);
  }
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, s.width, s.height, GL_RGB, is_float ? GL_FLOAT : GL_UNSIGNED_BYTE,
               bottom_up.data);
  ST_RETURN_IF_ERROR(CheckGl("reading the output back"));
  cv::Mat top_down;
  cv::flip(bottom_up, top_down, 0);
  return top_down;
}

Expected<std::unique_ptr<GlContext>> CreateEglContext(cv::Size size_px, OutputFormat format) {
  auto context = std::make_unique<EglContext>();
  ST_RETURN_IF_ERROR(context->Init(size_px, format));
  return std::unique_ptr<GlContext>(std::move(context));
}

std::unique_ptr<GlContext> CreateWindowContext(WindowProjectorOutput* window) {
  return std::make_unique<WindowContext>(window);
}

}  // namespace sandtable::node
