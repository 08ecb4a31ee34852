// The `tessera._tessera` extension module: the C++ library's public API for Python, wrapped by
// the pure-Python package `tessera` (python/tessera). Errors, then each part.

#include <map>
#include <utility>

#include "bindings.h"

namespace py = pybind11;

namespace tessera::python {
namespace {

/// The Python class per error code; filled once at import, read under the GIL.
std::map<ErrorCode, py::object>& errorClasses() {
  static auto* classes = new std::map<ErrorCode, py::object>();  // never destroyed: outlives
  return *classes;                                               // the interpreter's teardown
}

/// Python class names by code: a subclass of Error (and of the matching built-in exception,
/// so `except FileNotFoundError` and `except ValueError` work as a Python user expects).
struct ErrorClassSpec {
  ErrorCode code;
  const char* name;
  PyObject* builtin;
};

}  // namespace

void registerErrors(py::module_& module) {
  py::object base = py::reinterpret_steal<py::object>(
      PyErr_NewExceptionWithDoc("tessera._tessera.Error",
                                "A Tessera library error: `code` names its kind ('corrupt', "
                                "'not_found', ...), `message` the object and the problem.",
                                PyExc_Exception, nullptr));
  module.attr("Error") = base;
  const ErrorClassSpec specs[] = {
      {ErrorCode::kInvalidArgument, "InvalidArgumentError", PyExc_ValueError},
      {ErrorCode::kNotFound, "NotFoundError", PyExc_FileNotFoundError},
      {ErrorCode::kIo, "IoError", PyExc_OSError},
      {ErrorCode::kCorrupt, "CorruptError", nullptr},
      {ErrorCode::kUnsupported, "UnsupportedError", nullptr},
      {ErrorCode::kTooLarge, "TooLargeError", nullptr},
      {ErrorCode::kCancelled, "CancelledError", nullptr},
      {ErrorCode::kInternal, "InternalError", nullptr},
  };
  for (const ErrorClassSpec& spec : specs) {
    py::tuple bases =
        spec.builtin ? py::make_tuple(base, py::handle(spec.builtin)) : py::make_tuple(base);
    py::object cls = py::reinterpret_steal<py::object>(PyErr_NewException(
        (std::string("tessera._tessera.") + spec.name).c_str(), bases.ptr(), nullptr));
    module.attr(spec.name) = cls;
    errorClasses()[spec.code] = cls;
  }
  py::register_exception_translator([](std::exception_ptr thrown) {
    try {
      if (thrown) std::rethrow_exception(thrown);
    } catch (const LibraryError& e) {
      const py::object& cls = errorClasses().at(e.error.code);
      py::object instance = cls(e.error.message);
      instance.attr("code") = errorCodeName(e.error.code);
      instance.attr("message") = e.error.message;
      PyErr_SetObject(cls.ptr(), instance.ptr());
    }
  });
}

}  // namespace tessera::python

PYBIND11_MODULE(_tessera, module) {
  module.doc() = "Tessera's C++ library (use the `tessera` package, not this module)";
  tessera::python::registerErrors(module);
  tessera::python::registerArchive(module);
  tessera::python::registerBuild(module);
  tessera::python::registerStreamer(module);
}
