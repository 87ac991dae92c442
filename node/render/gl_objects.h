// Owning handles of OpenGL objects (textures, buffers, vertex arrays, framebuffers,
// renderbuffers, programs): move-only, the object deleted when its handle goes, is reset or is
// replaced. Like Magnum's GL wrappers, without the rest of Magnum.
//
// A handle is deleted on the calling thread, which must have the context that made it current
// (OpenGL names belong to a context). An owner whose context cannot be made current at its end
// gives its handles up with Release() rather than call OpenGL without a context (Renderer).
#pragma once

#include <utility>

namespace sandtable::node {

enum class GlObjectKind { kTexture, kBuffer, kVertexArray, kFramebuffer, kRenderbuffer, kProgram };

// glGen* of one object of `kind` (0 for kProgram: programs come from LinkProgram).
unsigned int GenerateGlObject(GlObjectKind kind);
// glDelete* of one object of `kind`; 0 is ignored.
void DeleteGlObject(GlObjectKind kind, unsigned int id);

template <GlObjectKind kKind>
class GlObject {
 public:
  GlObject() = default;
  // Takes ownership of `id` (0: none).
  explicit GlObject(unsigned int id) : id_(id) {}
  // A new object (glGen*); not for programs.
  static GlObject Generate() { return GlObject(GenerateGlObject(kKind)); }
  ~GlObject() { DeleteGlObject(kKind, id_); }
  GlObject(GlObject&& other) noexcept : id_(std::exchange(other.id_, 0)) {}
  GlObject& operator=(GlObject&& other) noexcept {
    if (this != &other) Reset(std::exchange(other.id_, 0));
    return *this;
  }
  GlObject(const GlObject&) = delete;
  GlObject& operator=(const GlObject&) = delete;

  unsigned int get() const { return id_; }
  explicit operator bool() const { return id_ != 0; }
  // Deletes the object held and takes `id` in its place.
  void Reset(unsigned int id = 0) {
    if (id == id_) return;
    DeleteGlObject(kKind, id_);
    id_ = id;
  }
  // Gives the object up without deleting it.
  [[nodiscard]] unsigned int Release() { return std::exchange(id_, 0); }

 private:
  unsigned int id_ = 0;
};

using GlTexture = GlObject<GlObjectKind::kTexture>;
using GlBuffer = GlObject<GlObjectKind::kBuffer>;
using GlVertexArray = GlObject<GlObjectKind::kVertexArray>;
using GlFramebuffer = GlObject<GlObjectKind::kFramebuffer>;
using GlRenderbuffer = GlObject<GlObjectKind::kRenderbuffer>;
using GlProgram = GlObject<GlObjectKind::kProgram>;

}  // namespace sandtable::node
