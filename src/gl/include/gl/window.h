#pragma once
// The window behind GlContext::window(), for the tools' viewer, whose input handling and
// panel (Dear ImGui) speak GLFW. Kept out of the public headers: no third-party type there.

struct GLFWwindow;

namespace tessera {

/// What GlContext::window() points to. Owned by the context.
struct GlWindow {
  GLFWwindow* glfw = nullptr;  ///< never null for a context that has a window
};

}  // namespace tessera
