# Every external dependency of Sandtable, found once, as imported targets.
# All come from Debian 12 packages installed by deploy/install-deps.sh.

find_package(Threads REQUIRED)
find_package(Eigen3 3.3 REQUIRED NO_MODULE)            # Eigen3::Eigen
find_package(Ceres REQUIRED)                          # Ceres::ceres
find_package(OpenCV 4 REQUIRED COMPONENTS core imgproc imgcodecs calib3d structured_light videoio)
find_package(glm REQUIRED)                            # glm::glm
find_package(glfw3 3.3 REQUIRED)                      # glfw
find_package(X11 REQUIRED)                            # X11::X11 (window tests read the screen)
find_package(TinyGLTF REQUIRED)                       # TinyGLTF
find_package(nlohmann_json 3 REQUIRED)                # nlohmann_json::nlohmann_json
find_package(embree 3 REQUIRED)                       # embree
find_package(Protobuf REQUIRED)                       # protobuf::libprotobuf, protobuf::protoc
find_package(cppzmq REQUIRED)                         # cppzmq (brings libzmq)
find_package(SQLite3 REQUIRED)                        # SQLite::SQLite3
find_package(ZLIB REQUIRED)                           # ZLIB::ZLIB
find_package(OpenGL REQUIRED COMPONENTS OpenGL EGL)   # OpenGL::OpenGL, OpenGL::EGL
find_package(CLI11 REQUIRED CONFIG)                  # CLI11::CLI11 (command lines)
find_package(nanoflann REQUIRED)                      # nanoflann::nanoflann (k-d trees)
find_package(PkgConfig REQUIRED)
pkg_check_modules(LIBUSB REQUIRED IMPORTED_TARGET libusb-1.0)   # PkgConfig::LIBUSB
# cpp-httplib ships only a pkg-config file (Debian libcpp-httplib-dev): httplib::httplib.
pkg_check_modules(HTTPLIB REQUIRED IMPORTED_TARGET GLOBAL cpp-httplib)
if(NOT TARGET httplib::httplib)
  add_library(httplib::httplib ALIAS PkgConfig::HTTPLIB)
endif()
# LAN discovery (net/discovery.h): CZMQ's zbeacon UDP beacon (Debian libczmq-dev), through its
# pkg-config file.
pkg_check_modules(CZMQ REQUIRED IMPORTED_TARGET libczmq)         # PkgConfig::CZMQ
# MPCDI export and import (common/io/mpcdi.h): the ZIP container and the XML descriptor, through
# their pkg-config files (Debian libminizip-dev, libtinyxml2-dev).
pkg_check_modules(MINIZIP REQUIRED IMPORTED_TARGET minizip)     # PkgConfig::MINIZIP
pkg_check_modules(TINYXML2 REQUIRED IMPORTED_TARGET tinyxml2)   # PkgConfig::TINYXML2
# The lab's report.html from its report.md (GitHub-flavoured tables): cmark-gfm, through its
# pkg-config file (Debian libcmark-gfm-dev, libcmark-gfm-extensions-dev).
pkg_check_modules(CMARK_GFM REQUIRED IMPORTED_TARGET libcmark-gfm)  # PkgConfig::CMARK_GFM

if(SANDTABLE_BUILD_TESTS)
  find_package(GTest REQUIRED)                        # GTest::gtest, GTest::gmock
  find_package(Python3 REQUIRED COMPONENTS Interpreter)  # tests/check_layering.py
  # The console's browser tests (tests/browser): Node.js runs playwright-core, which drives
  # Debian's Chromium; both from deploy/install-deps.sh.
  find_program(SANDTABLE_NODEJS node REQUIRED)
  include(GoogleTest)
endif()
if(SANDTABLE_BUILD_BENCHMARKS)
  find_package(benchmark REQUIRED)                    # benchmark::benchmark
endif()

# OpenCV's config defines no per-module imported target names we can rely on; wrap them.
if(NOT TARGET sandtable_opencv)
  add_library(sandtable_opencv INTERFACE)
  add_library(sandtable::opencv ALIAS sandtable_opencv)
  target_link_libraries(sandtable_opencv INTERFACE ${OpenCV_LIBS})
  target_include_directories(sandtable_opencv SYSTEM INTERFACE ${OpenCV_INCLUDE_DIRS})
endif()
