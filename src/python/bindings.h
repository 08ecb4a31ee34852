#pragma once
// Shared by the binding files of the `tessera._tessera` extension module (docs/python.md):
// how library errors become Python exceptions, and the registration of each part.

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <tessera/format.h>

#include <tessera/result.h>

namespace tessera::python {

/// A library Error on its way to Python: thrown by the bindings, turned into the tessera.Error
/// subclass of its code (with `code` and `message` attributes) by a registered translator.
struct LibraryError {
  Error error;
};

/// Creates tessera.Error and its subclasses in `module` and registers the translator.
void registerErrors(pybind11::module_& module);

/// The value of `result`, or throws its error as LibraryError.
template <typename T>
T valueOrThrow(Result<T> result) {
  if (!result) throw LibraryError{std::move(result).error()};
  return std::move(result).value();
}
inline void throwIfError(const Result<void>& result) {
  if (!result) throw LibraryError{result.error()};
}

/// An (height, width, channels) uint8 array over `image`'s texels without a copy; `owner`
/// keeps them alive as long as the array lives.
inline pybind11::array_t<uint8_t> arrayOver(const Image& image, pybind11::object owner) {
  const pybind11::ssize_t h = image.height_px, w = image.width_px, c = image.channels;
  return pybind11::array_t<uint8_t>({h, w, c}, {w * c, c, pybind11::ssize_t(1)},
                                    image.texels.data(), std::move(owner));
}

void registerArchive(pybind11::module_& module);
void registerBuild(pybind11::module_& module);
void registerStreamer(pybind11::module_& module);

}  // namespace tessera::python
