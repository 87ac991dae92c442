#include "tests/node/devices/x_screen.h"

#include <X11/Xlib.h>
#include <X11/Xutil.h>

namespace sandtable::node::testing {

namespace {

// One connection for the whole test binary: opening one per read in a polling loop exhausts
// the X server's client slots (later XOpenDisplay calls, GLFW's included, then fail).
Display* Connection() {
  static Display* display = XOpenDisplay(nullptr);
  return display;
}

}  // namespace

cv::Mat ReadXScreen(cv::Rect area) {
  Display* display = Connection();
  if (display == nullptr) return {};
  XSync(display, False);
  XImage* image = XGetImage(display, DefaultRootWindow(display), area.x, area.y,
                            static_cast<unsigned>(area.width), static_cast<unsigned>(area.height),
                            AllPlanes, ZPixmap);
  cv::Mat rgb;
  if (image != nullptr && image->red_mask == 0xFF0000 && image->green_mask == 0xFF00 &&
      image->blue_mask == 0xFF) {
    rgb.create(area.size(), CV_8UC3);
    for (int y = 0; y < area.height; ++y) {
      for (int x = 0; x < area.width; ++x) {
        const unsigned long pixel = XGetPixel(image, x, y);
        rgb.at<cv::Vec3b>(y, x) =
            cv::Vec3b(static_cast<uchar>((pixel >> 16) & 0xFF),
                      static_cast<uchar>((pixel >> 8) & 0xFF), static_cast<uchar>(pixel & 0xFF));
      }
    }
  }
  if (image != nullptr) XDestroyImage(image);
  return rgb;
}

std::optional<cv::Size> XScreenSize() {
  Display* display = Connection();
  if (display == nullptr) return std::nullopt;
  return cv::Size(DisplayWidth(display, 0), DisplayHeight(display, 0));
}

}  // namespace sandtable::node::testing
