// The owning GL handles (node/render/gl_objects.h) on Mesa's llvmpipe through EGL: an object
// lives exactly as long as its handle, through moves, resets and releases.
#include <utility>

#include <gtest/gtest.h>

#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>

#include "node/render/gl_context.h"
#include "node/render/gl_objects.h"

namespace sandtable::node {
namespace {

class GlObjectsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    Expected<std::unique_ptr<GlContext>> context =
        CreateEglContext(cv::Size(16, 16), OutputFormat::kRgba8);
    ASSERT_TRUE(context.ok()) << context.status().ToString();
    context_ = std::move(*context);
    ASSERT_TRUE(context_->MakeCurrent().ok());
  }
  // A texture name is a texture object once it was bound (glIsTexture before that says no).
  static GlTexture BoundTexture() {
    GlTexture texture = GlTexture::Generate();
    glBindTexture(GL_TEXTURE_2D, texture.get());
    glBindTexture(GL_TEXTURE_2D, 0);
    return texture;
  }
  std::unique_ptr<GlContext> context_;
};

TEST_F(GlObjectsTest, DeletesTheObjectWhenTheHandleGoes) {
  unsigned int id = 0;
  {
    GlTexture texture = BoundTexture();
    id = texture.get();
    ASSERT_NE(id, 0u);
    EXPECT_TRUE(glIsTexture(id));
  }
  EXPECT_FALSE(glIsTexture(id));
}

TEST_F(GlObjectsTest, AMoveHandsTheObjectOverAndAnAssignmentDeletesTheOldOne) {
  GlTexture a = BoundTexture();
  const unsigned int first = a.get();
  GlTexture b = std::move(a);
  EXPECT_FALSE(a);  // NOLINT(bugprone-use-after-move): a moved-from handle is empty
  EXPECT_EQ(b.get(), first);
  EXPECT_TRUE(glIsTexture(first));
  b = BoundTexture();
  EXPECT_FALSE(glIsTexture(first));
  EXPECT_TRUE(glIsTexture(b.get()));
}

TEST_F(GlObjectsTest, ResetDeletesAndReleaseKeeps) {
  GlTexture texture = BoundTexture();
  const unsigned int reset = texture.get();
  texture.Reset();
  EXPECT_FALSE(texture);
  EXPECT_FALSE(glIsTexture(reset));

  GlTexture kept = BoundTexture();
  const unsigned int released = kept.Release();
  EXPECT_FALSE(kept);
  EXPECT_TRUE(glIsTexture(released));
  glDeleteTextures(1, &released);
}

TEST_F(GlObjectsTest, EveryKindIsMadeAndDeleted) {
  GlBuffer buffer = GlBuffer::Generate();
  GlVertexArray vao = GlVertexArray::Generate();
  GlFramebuffer fbo = GlFramebuffer::Generate();
  GlRenderbuffer rbo = GlRenderbuffer::Generate();
  glBindBuffer(GL_ARRAY_BUFFER, buffer.get());
  glBindVertexArray(vao.get());
  glBindFramebuffer(GL_FRAMEBUFFER, fbo.get());
  glBindRenderbuffer(GL_RENDERBUFFER, rbo.get());
  glBindBuffer(GL_ARRAY_BUFFER, 0);
  glBindVertexArray(0);
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  glBindRenderbuffer(GL_RENDERBUFFER, 0);
  const unsigned int ids[4] = {buffer.get(), vao.get(), fbo.get(), rbo.get()};
  EXPECT_TRUE(glIsBuffer(ids[0]));
  EXPECT_TRUE(glIsVertexArray(ids[1]));
  EXPECT_TRUE(glIsFramebuffer(ids[2]));
  EXPECT_TRUE(glIsRenderbuffer(ids[3]));
  GlProgram program(glCreateProgram());
  const unsigned int program_id = program.get();
  EXPECT_TRUE(glIsProgram(program_id));
  buffer.Reset();
  vao.Reset();
  fbo.Reset();
  rbo.Reset();
  program.Reset();
  EXPECT_FALSE(glIsBuffer(ids[0]));
  EXPECT_FALSE(glIsVertexArray(ids[1]));
  EXPECT_FALSE(glIsFramebuffer(ids[2]));
  EXPECT_FALSE(glIsRenderbuffer(ids[3]));
  EXPECT_FALSE(glIsProgram(program_id));
  EXPECT_EQ(GlProgram::Generate().get(), 0u);  // programs come from LinkProgram
}

}  // namespace
}  // namespace sandtable::node
