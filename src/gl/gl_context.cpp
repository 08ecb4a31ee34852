// OpenGL contexts: EGL surfaceless (headless; Mesa's llvmpipe in CI) or a GLFW window.
#include <epoxy/egl.h>
#include <epoxy/gl.h>

#include <cstdlib>
#include <mutex>

#include <GLFW/glfw3.h>
#include <fmt/format.h>

#include <tessera/gl.h>

#include "gl/window.h"

namespace tessera {

struct GlContext::Impl {
  EGLDisplay display = EGL_NO_DISPLAY;
  EGLContext context = EGL_NO_CONTEXT;
  GlWindow window;  ///< glfw null for a headless context

  ~Impl() {
    if (context != EGL_NO_CONTEXT) {
      eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
      eglDestroyContext(display, context);
    }
    // The display is shared by every context of the process (EGL returns the same one), so
    // it stays initialised; eglTerminate here would pull it from under another context.
    if (window.glfw) glfwDestroyWindow(window.glfw);
  }
};

namespace {

const char* eglErrorName(EGLint error) {
  switch (error) {
    case EGL_NOT_INITIALIZED: return "EGL_NOT_INITIALIZED";
    case EGL_BAD_ALLOC: return "EGL_BAD_ALLOC";
    case EGL_BAD_ATTRIBUTE: return "EGL_BAD_ATTRIBUTE";
    case EGL_BAD_CONFIG: return "EGL_BAD_CONFIG";
    case EGL_BAD_CONTEXT: return "EGL_BAD_CONTEXT";
    case EGL_BAD_DISPLAY: return "EGL_BAD_DISPLAY";
    case EGL_BAD_MATCH: return "EGL_BAD_MATCH";
    case EGL_BAD_PARAMETER: return "EGL_BAD_PARAMETER";
    default: return "EGL error";
  }
}

/// Checks that the current context is 4.5 or newer: every renderer uses 4.5 entry points
/// (direct state access, glCopyImageSubData).
Result<void> requireGl45(const char* what) {
  const int version = epoxy_gl_version();
  if (version < 45)
    return fail(ErrorCode::kUnsupported, fmt::format("{}: OpenGL {}.{} found, 4.5 core needed",
                                                     what, version / 10, version % 10));
  return {};
}

}  // namespace

GlContext::GlContext(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
GlContext::~GlContext() = default;

Result<std::unique_ptr<GlContext>> GlContext::createHeadless() {
  auto impl = std::make_unique<Impl>();
  if (!epoxy_has_egl_extension(EGL_NO_DISPLAY, "EGL_MESA_platform_surfaceless"))
    return fail(ErrorCode::kUnsupported,
                "headless OpenGL: EGL has no surfaceless platform (EGL_MESA_platform_surfaceless;"
                " install Mesa's libegl-mesa0 and libgl1-mesa-dri)");
  impl->display =
      eglGetPlatformDisplayEXT(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
  EGLint major = 0, minor = 0;
  if (impl->display == EGL_NO_DISPLAY || !eglInitialize(impl->display, &major, &minor))
    return fail(ErrorCode::kUnsupported,
                fmt::format("headless OpenGL: cannot initialise the EGL surfaceless display: {}",
                            eglErrorName(eglGetError())));
  if (!eglBindAPI(EGL_OPENGL_API))
    return fail(ErrorCode::kUnsupported, "headless OpenGL: EGL cannot bind the OpenGL API");
  const EGLint attributes[] = {EGL_CONTEXT_MAJOR_VERSION,
                               4,
                               EGL_CONTEXT_MINOR_VERSION,
                               5,
                               EGL_CONTEXT_OPENGL_PROFILE_MASK,
                               EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT,
                               EGL_NONE};
  impl->context = eglCreateContext(impl->display, EGL_NO_CONFIG_KHR, EGL_NO_CONTEXT, attributes);
  if (impl->context == EGL_NO_CONTEXT)
    return fail(ErrorCode::kUnsupported,
                fmt::format("headless OpenGL: no OpenGL 4.5 core context: {}",
                            eglErrorName(eglGetError())));
  if (!eglMakeCurrent(impl->display, EGL_NO_SURFACE, EGL_NO_SURFACE, impl->context))
    return fail(ErrorCode::kUnsupported,
                fmt::format("headless OpenGL: cannot make the context current: {}",
                            eglErrorName(eglGetError())));
  TESSERA_TRY(requireGl45("headless OpenGL"));
  return std::unique_ptr<GlContext>(new GlContext(std::move(impl)));
}

Result<std::unique_ptr<GlContext>> GlContext::createWindow(uint32_t width, uint32_t height,
                                                           const std::string& title) {
  const char* x11 = std::getenv("DISPLAY");
  const char* wayland = std::getenv("WAYLAND_DISPLAY");
  if ((!x11 || !*x11) && (!wayland || !*wayland))
    return fail(ErrorCode::kUnsupported,
                "no display (neither DISPLAY nor WAYLAND_DISPLAY is set): `tessera fly` flies "
                "and renders the same paths headless");
  static std::once_flag once;
  static bool initialised = false;
  std::call_once(once, [] { initialised = glfwInit() == GLFW_TRUE; });
  if (!initialised)
    return fail(ErrorCode::kUnsupported,
                "cannot open the display (glfwInit failed): `tessera fly` works headless");
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 4);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 5);
  glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
  glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
  auto impl = std::make_unique<Impl>();
  impl->window.glfw = glfwCreateWindow(int(width), int(height), title.c_str(), nullptr, nullptr);
  if (!impl->window.glfw)
    return fail(ErrorCode::kUnsupported, "cannot create an OpenGL 4.5 core window");
  glfwMakeContextCurrent(impl->window.glfw);
  TESSERA_TRY(requireGl45("window"));
  return std::unique_ptr<GlContext>(new GlContext(std::move(impl)));
}

void GlContext::makeCurrent() {
  if (impl_->window.glfw)
    glfwMakeContextCurrent(impl_->window.glfw);
  else
    eglMakeCurrent(impl_->display, EGL_NO_SURFACE, EGL_NO_SURFACE, impl_->context);
}

std::string GlContext::description() const {
  auto text = [](GLenum name) {
    const GLubyte* s = glGetString(name);
    return s ? std::string(reinterpret_cast<const char*>(s)) : std::string("?");
  };
  return text(GL_RENDERER) + ", " + text(GL_VERSION);
}

GlWindow* GlContext::window() const {
  return impl_->window.glfw ? &impl_->window : nullptr;
}

}  // namespace tessera
