# Finds the Debian packages Tessera links against and defines imported targets for them.
# Used by the build and, installed beside TesseraConfig.cmake, by consumers of the static
# libraries, which must link the same dependencies.
find_package(PkgConfig REQUIRED)
find_package(Threads REQUIRED)
find_package(TIFF REQUIRED)
find_package(PNG REQUIRED)
find_package(JPEG REQUIRED)
find_package(nlohmann_json 3.10 REQUIRED)
find_package(fmt 9 REQUIRED)
pkg_check_modules(TESSERA_ZSTD REQUIRED IMPORTED_TARGET GLOBAL libzstd)
pkg_check_modules(TESSERA_LZ4 REQUIRED IMPORTED_TARGET GLOBAL liblz4)
# Debian's libsquish.pc names a non-existent include directory (/include), which an imported
# pkg-config target refuses; the header and library are found directly instead.
find_path(TESSERA_SQUISH_INCLUDE_DIR squish.h REQUIRED)
find_library(TESSERA_SQUISH_LIBRARY squish REQUIRED)
add_library(tessera_squish INTERFACE IMPORTED GLOBAL)
target_include_directories(tessera_squish INTERFACE ${TESSERA_SQUISH_INCLUDE_DIR})
target_link_libraries(tessera_squish INTERFACE ${TESSERA_SQUISH_LIBRARY})
pkg_check_modules(TESSERA_XXHASH REQUIRED IMPORTED_TARGET GLOBAL libxxhash)
pkg_check_modules(TESSERA_WEBP REQUIRED IMPORTED_TARGET GLOBAL libwebp)
pkg_check_modules(TESSERA_TURBOJPEG REQUIRED IMPORTED_TARGET GLOBAL libturbojpeg)
# Optional: whole-slide import through OpenSlide (libopenslide-dev).
pkg_check_modules(TESSERA_OPENSLIDE IMPORTED_TARGET GLOBAL openslide)
find_package(Boost 1.74 REQUIRED)
# The HTTP byte source (src/stream/http_source.cpp).
pkg_check_modules(TESSERA_CURL REQUIRED IMPORTED_TARGET GLOBAL libcurl)
