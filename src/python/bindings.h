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

/// The NumPy dtype of a sample type: uint8, uint16 or float32 (samples are host order).
inline pybind11::dtype dtypeOf(SampleType type) {
  switch (type) {
    case SampleType::kU16: return pybind11::dtype::of<uint16_t>();
    case SampleType::kF32: return pybind11::dtype::of<float>();
    default: return pybind11::dtype::of<uint8_t>();
  }
}

/// An (height, width, channels) array of the image's sample type over its texels without a
/// copy; `owner` keeps them alive as long as the array lives.
inline pybind11::array arrayOver(const Image& image, pybind11::object owner) {
  const pybind11::ssize_t h = image.height_px, w = image.width_px, c = image.channels;
  const pybind11::ssize_t s = sampleBytes(image.sample_type);
  return pybind11::array(dtypeOf(image.sample_type), {h, w, c}, {w * c * s, c * s, s},
                         image.texels.data(), std::move(owner));
}

void registerArchive(pybind11::module_& module);
void registerBuild(pybind11::module_& module);
void registerStreamer(pybind11::module_& module);

}  // namespace tessera::python
