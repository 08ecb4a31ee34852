// Writes the seed corpus of codec_fuzzer: a valid payload of every codec for each channel
// count at a few small sizes (decode mode), plus round-trip inputs. Usage:
//   tessera_codec_corpus fuzz/corpus/codec
// The output is deterministic, so regenerating it changes files only when a codec's output
// changes.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "codec_fuzz_input.h"
#include "codecs/encode.h"
#include "ptm/ptm_encode.h"

namespace {

using tessera::Codec;
using tessera::Image;

// Smooth shading with an edge: compresses like a real tile, so payloads stay small and use
// the codecs' prediction and entropy-coding paths rather than their stored/raw fallbacks.
Image makeTile(uint32_t width, uint32_t height, uint32_t channels) {
  Image image(width, height, channels);
  for (uint32_t y = 0; y < height; ++y)
    for (uint32_t x = 0; x < width; ++x)
      for (uint32_t c = 0; c < channels; ++c) {
        const bool edge = x * 2 > width + y;
        const double value =
            128 + 90 * std::sin(0.2 * x + c) * std::cos(0.15 * y) + (edge ? 30 : 0);
        image.row(y)[x * channels + c] = uint8_t(std::fmin(255.0, std::fmax(0.0, value)));
      }
  return image;
}

bool writeFile(const std::filesystem::path& path, const std::vector<uint8_t>& bytes) {
  std::ofstream file(path, std::ios::binary);
  file.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
  if (!file) std::fprintf(stderr, "%s: cannot write\n", path.c_str());
  return bool(file);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s OUTPUT_DIRECTORY\n", argv[0]);
    return 2;
  }
  const std::filesystem::path dir = argv[1];
  std::filesystem::create_directories(dir);
  const Codec codecs[] = {Codec::kRaw,  Codec::kZstd, Codec::kLz4, Codec::kJpeg, Codec::kPng,
                          Codec::kWebp, Codec::kPtm,  Codec::kBc1, Codec::kBc7};
  struct Size {
    uint32_t width, height;
  };
  const Size sizes[] = {{1, 1}, {16, 16}, {23, 9}};
  size_t files = 0, bytes = 0;
  for (Codec codec : codecs) {
    for (uint32_t channels = 1; channels <= 4; ++channels) {
      // BC1 keeps no alpha: its tiles with alpha are only seeded as round trips (refused).
      const bool alpha = channels == 2 || channels == 4;
      for (Size size : sizes) {
        if (codec == Codec::kBc1 && alpha) break;
        Image tile = makeTile(size.width, size.height, channels);
        auto payload = tessera::detail::encodeTile(codec, tile.view(), {});
        if (!payload) {
          std::fprintf(stderr, "%s\n", payload.error().message.c_str());
          return 1;
        }
        std::vector<uint8_t> input =
            tessera::fuzz::codecFuzzHeader(codec, channels, size.width, size.height, false);
        input.insert(input.end(), payload->begin(), payload->end());
        const std::string name = std::string(tessera::codecName(codec)) + "_" +
                                 std::to_string(size.width) + "x" + std::to_string(size.height) +
                                 "x" + std::to_string(channels);
        if (!writeFile(dir / name, input)) return 1;
        ++files;
        bytes += input.size();
      }
      // Round trip: quality 85, default effort, 4:2:0, and a short texel pattern.
      std::vector<uint8_t> input = tessera::fuzz::codecFuzzHeader(codec, channels, 20, 12, true);
      const uint8_t tail[] = {84, 0x10, 0, 17, 200, 255, 3, 90, 91, 92};
      input.insert(input.end(), std::begin(tail), std::end(tail));
      if (!writeFile(dir / ("roundtrip_" + std::string(tessera::codecName(codec)) + "_" +
                            std::to_string(channels)),
                     input))
        return 1;
      ++files;
      bytes += input.size();
    }
  }
  // ptm coded against the fuzzer's parent (fuzzParentTexels), for each quarter, in each mode of
  // the kept variants (docs/codecs.md, "ptm (6)"): the encoder at efforts 1 (nearest parent,
  // zstd), 2 (nearest parent with zstd or coder 7) and 3 (the default); each rANS coder forced
  // ("c1" to "c4", "c6") with the predictor of 1, 3 and 4 whose estimate is smallest, so all are
  // seeded whatever the default picks for these small tiles; the neighbour median and the
  // parent-corrected predictor with coder 7 ("m7", "p7"); predictor 5, whose weights follow the
  // header, with zstd and with coder 6 ("l0", "l6"), and with coder 7 fitted without predictor
  // 4's estimate ("w7"); the default on 64 x 64 texels rounded down to multiples of 16 ("t0"),
  // residuals on a comb, whose payloads carry explicit tables; coder 7 with nearest parent on
  // the same comb with a table wherever one saves any bytes ("t7"); and coder 7 with the median
  // and green-led contexts, with a table wherever one saves any bytes ("g7", 3 and 4 channels).
  const std::string modes[] = {"e1", "e2", "e3", "c1", "c2", "c3", "c4", "c6",
                               "m7", "p7", "l0", "l6", "w7", "t0", "t7", "g7"};
  using tessera::detail::Predictor, tessera::detail::PtmCoder;
  for (const std::string& mode : modes) {
    for (uint32_t channels = 1; channels <= 4; ++channels) {
      if (mode == "g7" && channels < 3) continue;
      for (uint32_t quadrant = 0; quadrant < 2; ++quadrant) {
        const uint32_t side = mode[0] == 't' ? 64 : 16;
        Image tile = makeTile(side, side, channels);
        if (mode[0] == 't')
          for (uint8_t& texel : tile.texels) texel = uint8_t(texel & 0xf0);
        const Image parent_texels = tessera::fuzz::fuzzParentTexels(side, channels);
        const tessera::detail::ParentTexels parent{parent_texels.view(), quadrant, quadrant, side,
                                                   0};
        const PtmCoder coder = PtmCoder(mode[1] - '0');
        auto encode = [&]() -> tessera::Result<std::vector<uint8_t>> {
          tessera::detail::EncodeOptions options;
          if (mode == "t7" || mode == "g7") {
            tessera::detail::PtmRecording recording, led;
            TESSERA_TRY(tessera::detail::recordPtm(
                tile.view(), &parent,
                mode == "t7" ? Predictor::kParentNearest : Predictor::kNeighbourMedian,
                PtmCoder::kRansLanes, nullptr, nullptr, recording));
            if (mode == "g7") tessera::detail::leadRecordingByGreen(recording, led);
            return tessera::detail::encodeRecordedPtm(mode == "g7" ? led : recording,
                                                      PtmCoder::kRansLanes, nullptr, nullptr, 0.0);
          }
          if (mode[0] == 'e' || mode[0] == 't') {
            options.effort = mode[1] - '0';
            return tessera::detail::encodeTile(Codec::kPtm, tile.view(), options, &parent);
          }
          tessera::detail::PtmLeastSquaresFit fit;
          fit.without_estimate = mode[0] == 'w';
          if (mode[0] == 'l' || mode[0] == 'w' || mode[0] == 'm' || mode[0] == 'p') {
            const Predictor predictor = mode[0] == 'm'   ? Predictor::kNeighbourMedian
                                        : mode[0] == 'p' ? Predictor::kParentCorrected
                                                         : Predictor::kLeastSquares;
            return tessera::detail::encodePtm(tile.view(), options, &parent, predictor, coder,
                                              nullptr, &fit);
          }
          Predictor smallest = Predictor::kParentNearest;
          size_t smallest_bytes = SIZE_MAX;
          for (Predictor predictor : {Predictor::kParentNearest, Predictor::kNeighbourMedian,
                                      Predictor::kParentCorrected}) {
            TESSERA_ASSIGN_OR_RETURN(const size_t estimate,
                                     tessera::detail::estimatePtmBytes(
                                         tile.view(), options, &parent, predictor, coder, nullptr));
            if (estimate < smallest_bytes) {
              smallest = predictor;
              smallest_bytes = estimate;
            }
          }
          return tessera::detail::encodePtm(tile.view(), options, &parent, smallest, coder,
                                            nullptr);
        };
        auto payload = encode();
        if (!payload) {
          std::fprintf(stderr, "%s\n", payload.error().message.c_str());
          return 1;
        }
        std::vector<uint8_t> input =
            tessera::fuzz::codecFuzzHeader(Codec::kPtm, channels, side, side, false, quadrant);
        input.insert(input.end(), payload->begin(), payload->end());
        if (!writeFile(dir / ("ptm_parent_" + mode + "_q" + std::to_string(quadrant) + "_" +
                              std::to_string(side) + "x" + std::to_string(side) + "x" +
                              std::to_string(channels)),
                       input))
          return 1;
        ++files;
        bytes += input.size();
      }
    }
  }
  // An input too short to carry a header.
  if (!writeFile(dir / "short", {0x01})) return 1;
  ++files;
  std::printf("wrote %zu files, %zu bytes, to %s\n", files, bytes, dir.c_str());
  return 0;
}
