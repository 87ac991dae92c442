#include "node/render/gl_objects.h"

#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>

namespace sandtable::node {

unsigned int GenerateGlObject(GlObjectKind kind) {
  GLuint id = 0;
  switch (kind) {
    case GlObjectKind::kTexture:
      glGenTextures(1, &id);
      break;
    case GlObjectKind::kBuffer:
      glGenBuffers(1, &id);
      break;
    case GlObjectKind::kVertexArray:
      glGenVertexArrays(1, &id);
      break;
    case GlObjectKind::kFramebuffer:
      glGenFramebuffers(1, &id);
      break;
    case GlObjectKind::kRenderbuffer:
      glGenRenderbuffers(1, &id);
      break;
    case GlObjectKind::kProgram:
      break;
  }
  return id;
}

void DeleteGlObject(GlObjectKind kind, unsigned int id) {
  if (id == 0) return;
  switch (kind) {
    case GlObjectKind::kTexture:
      glDeleteTextures(1, &id);
      break;
    case GlObjectKind::kBuffer:
      glDeleteBuffers(1, &id);
      break;
    case GlObjectKind::kVertexArray:
      glDeleteVertexArrays(1, &id);
      break;
    case GlObjectKind::kFramebuffer:
      glDeleteFramebuffers(1, &id);
      break;
    case GlObjectKind::kRenderbuffer:
      glDeleteRenderbuffers(1, &id);
      break;
    case GlObjectKind::kProgram:
      glDeleteProgram(id);
      break;
  }
}

}  // namespace sandtable::node
