#pragma once
// One headless OpenGL context for a whole GL test program (the EGL display is per process
// anyway), made current on the calling thread.

#include <memory>
#include <stdexcept>

#include <gtest/gtest.h>

#include <tessera/gl.h>

namespace tessera::test {

inline GlContext& sharedGlContext() {
  static std::unique_ptr<GlContext> context = [] {
    auto created = GlContext::createHeadless();
    EXPECT_TRUE(created) << created.error().message;
    return created ? std::move(*created) : nullptr;
  }();
  if (!context) throw std::runtime_error("no headless OpenGL context");
  context->makeCurrent();
  return *context;
}

}  // namespace tessera::test
