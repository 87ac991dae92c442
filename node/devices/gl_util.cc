#include "node/devices/gl_util.h"

#include <algorithm>

#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>

namespace sandtable::node {
namespace {

Expected<GLuint> CompileShader(const std::string& name, GLenum type, const char* source) {
  const GLuint shader = glCreateShader(type);
  glShaderSource(shader, 1, &source, nullptr);
  glCompileShader(shader);
  GLint ok = GL_FALSE;
  glGetShaderiv(shader, GL_COMPILE_STATUS, &ok);
  if (ok != GL_TRUE) {
    GLint length = 0;
    glGetShaderiv(shader, GL_INFO_LOG_LENGTH, &length);
    std::string log(static_cast<size_t>(std::max(length, 1)), '\0');
    glGetShaderInfoLog(shader, length, nullptr, log.data());
    glDeleteShader(shader);
    return InternalError("OpenGL: " + name + ": " +
                         (type == GL_VERTEX_SHADER ? "vertex" : "fragment") +
                         " shader does not compile: " + log);
  }
  return shader;
}

}  // namespace

const char* const kFullScreenQuadVertexShader = R"(#version 330 core
void main() {
  vec2 corner = vec2(float(gl_VertexID & 1), float(gl_VertexID >> 1));
  gl_Position = vec4(corner * 2.0 - 1.0, 0.0, 1.0);
}
)";

const char* const kTexelBlitFragmentShader = R"(#version 330 core
uniform sampler2D u_image;
out vec4 o_colour;
void main() {
  ivec2 size = textureSize(u_image, 0);
  ivec2 texel = ivec2(int(gl_FragCoord.x), size.y - 1 - int(gl_FragCoord.y));
  o_colour = vec4(texelFetch(u_image, texel, 0).rgb, 1.0);
}
)";

std::string GlErrorText(unsigned int error) {
  switch (error) {
    case GL_INVALID_ENUM:
      return "GL_INVALID_ENUM";
    case GL_INVALID_VALUE:
      return "GL_INVALID_VALUE";
    case GL_INVALID_OPERATION:
      return "GL_INVALID_OPERATION";
    case GL_OUT_OF_MEMORY:
      return "GL_OUT_OF_MEMORY";
    case GL_INVALID_FRAMEBUFFER_OPERATION:
      return "GL_INVALID_FRAMEBUFFER_OPERATION";
    default:
      return "GL error " + std::to_string(error);
  }
}

Status CheckGl(const std::string& what) {
  const GLenum error = glGetError();
  if (error == GL_NO_ERROR) return OkStatus();
  while (glGetError() != GL_NO_ERROR) {
  }
  return InternalError("OpenGL: " + what + ": " + GlErrorText(error));
}

Expected<unsigned int> LinkProgram(const std::string& name, const char* vertex_source,
                                   const char* fragment_source) {
  Expected<GLuint> vertex = CompileShader(name, GL_VERTEX_SHADER, vertex_source);
  if (!vertex.ok()) return vertex.status();
  Expected<GLuint> fragment = CompileShader(name, GL_FRAGMENT_SHADER, fragment_source);
  if (!fragment.ok()) {
    glDeleteShader(*vertex);
    return fragment.status();
  }
  const GLuint program = glCreateProgram();
  glAttachShader(program, *vertex);
  glAttachShader(program, *fragment);
  glLinkProgram(program);
  glDeleteShader(*vertex);
  glDeleteShader(*fragment);
  GLint linked = GL_FALSE;
  glGetProgramiv(program, GL_LINK_STATUS, &linked);
  if (linked != GL_TRUE) {
    GLint length = 0;
    glGetProgramiv(program, GL_INFO_LOG_LENGTH, &length);
    std::string log(static_cast<size_t>(std::max(length, 1)), '\0');
    glGetProgramInfoLog(program, length, nullptr, log.data());
    glDeleteProgram(program);
    return InternalError("OpenGL: " + name + ": the program does not link: " + log);
  }
  return program;
}

}  // namespace sandtable::node
