#pragma once
// Small archives for reader tests: build through the public builder from an image written as
// a PNG fixture, and get the archive's bytes for in-memory sources and corruption.

#include <cstdint>
#include <string>
#include <vector>

#include <tessera/build.h>
#include <tessera/format.h>

namespace tessera::test {

/// Writes `image` (1..4 channels) as an 8-bit PNG; "" on success, else what failed.
std::string writeImagePng(const std::string& path, const Image& image);

/// Reads an 8-bit PNG through the builder's PNG band reader; fails the test on error.
Image readImagePng(const std::string& path);

/// Reads a source ("synthetic:..." or a path) whole through the builder's band readers.
Image readSource(const std::string& source);

/// An archive built into a temp dir: its path and its bytes.
struct BuiltArchive {
  std::string path;
  std::vector<uint8_t> bytes;
};

/// Builds `image` (written to `<dir>source.png`; `dir` ends in '/') into `<dir><name>` with
/// `options` (inputs and output are filled in). Fails the test (ADD_FAILURE) and returns empty
/// bytes on error.
BuiltArchive buildFromImage(const Image& image, BuildOptions options, const std::string& dir,
                            const std::string& name = "archive.tess");

/// `bytes` (a whole archive) with its metadata block replaced by `json`, which need not be
/// what a builder writes: the block is appended and the header resealed to point at it, the
/// old block left unreferenced. Fails the test and returns `bytes` unchanged when the header
/// does not decode.
std::vector<uint8_t> withMetadata(std::vector<uint8_t> bytes, const std::string& json);

/// The archive file at `path` rewritten in place by withMetadata.
void rewriteMetadata(const std::string& path, const std::string& json);

/// Flips bit `bit` (0..7) of byte `offset`.
inline void flipBit(std::vector<uint8_t>& bytes, size_t offset, uint32_t bit) {
  bytes[offset] ^= uint8_t(1u << bit);
}

}  // namespace tessera::test
