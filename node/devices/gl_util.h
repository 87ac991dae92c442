// Small OpenGL helpers shared by the window projector's blitter and the renderer (node/render):
// GL errors as Status, shader compilation and program linking with the driver's log.
// Every function needs a current OpenGL 3.3 core context on the calling thread.
#pragma once

#include <string>

#include "common/base/status.h"

namespace sandtable::node {

// A full-screen quad (a triangle strip of 4 vertices from gl_VertexID, no vertex buffer) and a
// fragment shader that shows texture `u_image` one texel per pixel (texelFetch, no filtering),
// its row 0 at the top of the output (GL's row 0 is the bottom).
extern const char* const kFullScreenQuadVertexShader;
extern const char* const kTexelBlitFragmentShader;

// "GL_INVALID_OPERATION", ... for a glGetError() value.
std::string GlErrorText(unsigned int error);

// OK when glGetError() reports nothing; INTERNAL "OpenGL: <what>: <error>" otherwise (the
// error queue is drained).
Status CheckGl(const std::string& what);

// Compiles a vertex and a fragment shader and links them. INTERNAL with the driver's log and
// `name` when either does not compile or the program does not link.
Expected<unsigned int> LinkProgram(const std::string& name, const char* vertex_source,
                                   const char* fragment_source);

}  // namespace sandtable::node
