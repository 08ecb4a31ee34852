// validateBuildOptions: every option judged before an input is opened, each refusal naming the
// value and what is accepted.
#include <gtest/gtest.h>

#include <tessera/build.h>

namespace tessera {
namespace {

BuildOptions valid() {
  BuildOptions options;
  options.inputs = {"synthetic:100x100"};
  options.output = "out.tess";
  return options;
}

std::string refusal(const BuildOptions& options) {
  Result<void> checked = validateBuildOptions(options);
  if (checked) return "";
  EXPECT_EQ(checked.error().code, ErrorCode::kInvalidArgument) << checked.error().message;
  return checked.error().message;
}

TEST(BuildOptions, TheDefaultsAreValid) {
  EXPECT_EQ(refusal(valid()), "");
}

TEST(BuildOptions, EachCodecTakesItsOwnEfforts) {
  struct Case {
    Codec codec;
    int effort;
    bool accepted;
  };
  const Case cases[] = {
      {Codec::kZstd, 22, true},    {Codec::kZstd, -5, true}, {Codec::kZstd, 23, false},
      {Codec::kZstd, -101, false}, {Codec::kPng, 9, true},   {Codec::kPng, 10, false},
      {Codec::kPng, -1, false},    {Codec::kWebp, 9, true},  {Codec::kWebp, 100, false},
      {Codec::kPtm, 4, true},      {Codec::kPtm, 5, false},  {Codec::kPtm, -1, false},
      {Codec::kJpeg, 0, true},     {Codec::kJpeg, 1, false}, {Codec::kRaw, 3, false},
      {Codec::kLz4, 0, true},      {Codec::kLz4, 9, false},
  };
  for (const Case& c : cases) {
    BuildOptions options = valid();
    options.codec = c.codec;
    options.effort = c.effort;
    const std::string message = refusal(options);
    EXPECT_EQ(message.empty(), c.accepted)
        << codecName(c.codec) << " " << c.effort << ": " << message;
    if (!c.accepted) {
      EXPECT_NE(message.find("effort " + std::to_string(c.effort)), std::string::npos) << message;
    }
  }
  BuildOptions png = valid();
  png.codec = Codec::kPng;
  png.effort = 10;
  EXPECT_EQ(refusal(png), "effort 10 out of 0..9 for codec png (the zlib level; 0 = its default)");
  BuildOptions jpeg = valid();
  jpeg.effort = 2;
  EXPECT_EQ(refusal(jpeg), "effort 2: codec jpeg has no effort setting (give 0, or leave it out)");
}

TEST(BuildOptions, NumbersOutOfRangeAreRefusedWithTheirRange) {
  BuildOptions options = valid();
  options.quality = 0;
  EXPECT_EQ(refusal(options), "quality 0 out of 1..100");
  options = valid();
  options.quality = 101;
  EXPECT_EQ(refusal(options), "quality 101 out of 1..100");
  options = valid();
  options.threads = 100000;
  EXPECT_EQ(refusal(options), "100000 threads out of 0..1024 (0 = one per core)");
  options.threads = kMaxBuildThreads;
  EXPECT_EQ(refusal(options), "");
  options = valid();
  options.tile_size_px = 100;
  EXPECT_EQ(refusal(options), "tile size 100 is not a power of two in 64..2048");
  options.tile_size_px = 4096;
  EXPECT_EQ(refusal(options), "tile size 4096 is not a power of two in 64..2048");
  options = valid();
  options.border_px = 17;
  EXPECT_EQ(refusal(options), "border 17 out of 0..16");
  options = valid();
  options.page_tiles_log2 = 9;
  EXPECT_EQ(refusal(options), "directory page side 2^9 out of 2^3..2^8");
}

TEST(BuildOptions, InputsAndOutputAreChecked) {
  BuildOptions options = valid();
  options.inputs.clear();
  EXPECT_EQ(refusal(options), "no input given");
  options = valid();
  options.output.clear();
  EXPECT_EQ(refusal(options), "no output path given");
  options = valid();
  options.inputs = {"./out.tess"};
  EXPECT_EQ(refusal(options), "./out.tess: output would overwrite the input");
  options = valid();
  options.image_names = {"a", "b"};
  EXPECT_EQ(refusal(options), "more image names than inputs");
  options = valid();
  options.codec = Codec::kPtm;
  options.srgb_downsample = true;
  EXPECT_NE(refusal(options).find("--srgb"), std::string::npos);
}

}  // namespace
}  // namespace tessera
