#include "format/procedural.h"

#include <bit>
#include <cmath>
#include <cstring>

#include <fmt/format.h>

#include "format/byte_io.h"
#include "format/checksum.h"
#include "format/directory.h"

namespace tessera::detail {

namespace {

void storeBlockRef(uint8_t* p, const BlockRef& block) {
  storeU64(p, block.offset_bytes);
  storeU64(p + 8, block.length_bytes);
  storeU64(p + 16, block.checksum);
}

BlockRef loadBlockRef(const uint8_t* p) {
  return {loadU64(p), loadU64(p + 8), loadU64(p + 16)};
}

Result<void> checkPayloadBlock(const BlockRef& block, const FileHeader& header,
                               const std::string& what) {
  if (block.length_bytes == 0) return fail(ErrorCode::kCorrupt, what + ": empty block");
  if (block.offset_bytes < header.header_region_bytes || block.offset_bytes > header.file_bytes ||
      block.length_bytes > header.file_bytes - block.offset_bytes)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: block [{}, +{}) outside the payload area",
                                                 what, block.offset_bytes, block.length_bytes));
  return {};
}

void storeImageRecord(uint8_t* p, const ProceduralImageRecord& record) {
  storeBlockRef(p, record.block);
  storeU32(p + 24, record.width_px);
  storeU32(p + 28, record.height_px);
  p[32] = uint8_t(record.channels);
  p[33] = uint8_t(record.codec);
}

Result<ProceduralImageRecord> loadImageRecord(const uint8_t* p, const FileHeader& header,
                                              uint32_t channels, uint32_t max_side,
                                              const std::string& what) {
  ProceduralImageRecord record;
  record.block = loadBlockRef(p);
  record.width_px = loadU32(p + 24);
  record.height_px = loadU32(p + 28);
  record.channels = p[32];
  if (!allZero(p + 34, 6)) return fail(ErrorCode::kCorrupt, what + ": reserved bytes are not zero");
  if (p[33] > uint8_t(Codec::kPtm) || !codecIsLossless(Codec(p[33])) ||
      p[33] == uint8_t(Codec::kPtm))
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: codec {} is not a lossless picture codec", what, p[33]));
  record.codec = Codec(p[33]);
  if (record.channels != channels)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: {} channels, expected {}", what, record.channels, channels));
  if (record.width_px == 0 || record.height_px == 0 || record.width_px > max_side ||
      record.height_px > max_side)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: size {}x{} out of 1..{}", what,
                                                 record.width_px, record.height_px, max_side));
  TESSERA_TRY(checkPayloadBlock(record.block, header, what));
  // A lossless codec never needs more than this for a picture (the same bound as tiles).
  uint64_t raw = uint64_t(record.width_px) * record.height_px * channels;
  if (record.block.length_bytes > 2 * raw + 65536)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: payload of {} bytes for {} texel bytes", what,
                                                 record.block.length_bytes, raw));
  return record;
}

bool finite(float v) {
  return std::isfinite(v);
}

}  // namespace

std::vector<uint8_t> encodeProceduralDirectory(const ProceduralDirectory& directory) {
  size_t total = kProceduralDirectoryFixedBytes +
                 directory.images.size() * kProceduralImageRecordBytes +
                 directory.brushes.size() * kBrushRecordBytes;
  std::vector<uint8_t> bytes(total, 0);
  uint8_t* p = bytes.data();
  std::memcpy(p, kProceduralDirectoryMagic, 4);
  storeU16(p + 4, kProceduralDirectoryVersion);
  storeU32(p + 8, directory.image);
  storeU32(p + 12, uint32_t(directory.brushes.size()));
  storeU32(p + 16, uint32_t(directory.images.size()));
  if (directory.height_layer.width_px != 0) storeImageRecord(p + 24, directory.height_layer);
  p += kProceduralDirectoryFixedBytes;
  for (const ProceduralImageRecord& image : directory.images) {
    storeImageRecord(p, image);
    p += kProceduralImageRecordBytes;
  }
  for (const ProceduralBrushRecord& brush : directory.brushes) {
    storeU32(p, brush.image_first);
    storeU16(p + 4, uint16_t(brush.image_count));
    p[6] = uint8_t(brush.blend);
    p[7] = uint8_t(brush.mask);
    p[8] = brush.mask_low;
    p[9] = brush.mask_high;
    p += kBrushRecordBytes;
  }
  return bytes;
}

Result<ProceduralDirectory> decodeProceduralDirectory(std::span<const uint8_t> bytes,
                                                      const FileHeader& header,
                                                      uint32_t image_count,
                                                      const std::string& what) {
  if (bytes.size() < kProceduralDirectoryFixedBytes)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: procedural directory of {} bytes is "
                            "shorter than its {}-byte header",
                            what, bytes.size(), kProceduralDirectoryFixedBytes));
  const uint8_t* p = bytes.data();
  if (std::memcmp(p, kProceduralDirectoryMagic, 4) != 0)
    return fail(ErrorCode::kCorrupt, what + ": procedural directory has a bad magic");
  if (loadU16(p + 4) != kProceduralDirectoryVersion)
    return fail(ErrorCode::kUnsupported,
                fmt::format("{}: procedural directory version {} (this build reads {})", what,
                            loadU16(p + 4), kProceduralDirectoryVersion));
  if (loadU16(p + 6) != 0 || loadU32(p + 20) != 0)
    return fail(ErrorCode::kCorrupt, what + ": procedural directory reserved fields not zero");
  ProceduralDirectory directory;
  directory.image = loadU32(p + 8);
  uint32_t brush_count = loadU32(p + 12);
  uint32_t images = loadU32(p + 16);
  if (directory.image >= image_count)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: procedural directory names image {} of {}",
                                                 what, directory.image, image_count));
  if (brush_count == 0 || brush_count > kMaxProceduralBrushes || images == 0 ||
      images > kMaxProceduralImages)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: {} brushes with {} images out of bounds",
                                                 what, brush_count, images));
  uint64_t expected = kProceduralDirectoryFixedBytes +
                      uint64_t(images) * kProceduralImageRecordBytes +
                      uint64_t(brush_count) * kBrushRecordBytes;
  if (bytes.size() != expected)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: procedural directory of {} bytes, its counts need {}", what,
                            bytes.size(), expected));
  if (!allZero(p + 24, kProceduralImageRecordBytes)) {
    TESSERA_ASSIGN_OR_RETURN(
        directory.height_layer,
        loadImageRecord(p + 24, header, 1, kMaxLayerSidePx, what + ": height layer"));
  }
  const uint8_t* q = p + kProceduralDirectoryFixedBytes;
  directory.images.reserve(images);
  for (uint32_t i = 0; i < images; ++i, q += kProceduralImageRecordBytes) {
    TESSERA_ASSIGN_OR_RETURN(
        ProceduralImageRecord record,
        loadImageRecord(q, header, 4, kMaxBrushSidePx, fmt::format("{}: brush image {}", what, i)));
    directory.images.push_back(record);
  }
  directory.brushes.reserve(brush_count);
  for (uint32_t b = 0; b < brush_count; ++b, q += kBrushRecordBytes) {
    std::string brush_what = fmt::format("{}: brush {}", what, b);
    ProceduralBrushRecord brush;
    brush.image_first = loadU32(q);
    brush.image_count = loadU16(q + 4);
    if (q[6] >= kBlendModeCount)
      return fail(ErrorCode::kCorrupt, fmt::format("{}: unknown blend mode {}", brush_what, q[6]));
    if (q[7] > uint8_t(MaskSource::kSlope))
      return fail(ErrorCode::kCorrupt, fmt::format("{}: unknown mask source {}", brush_what, q[7]));
    brush.blend = BlendMode(q[6]);
    brush.mask = MaskSource(q[7]);
    brush.mask_low = q[8];
    brush.mask_high = q[9];
    if (!allZero(q + 10, 6))
      return fail(ErrorCode::kCorrupt, brush_what + ": reserved bytes are not zero");
    if (brush.image_count == 0 || brush.image_count > kMaxBrushImages ||
        brush.image_first > images || brush.image_count > images - brush.image_first)
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: images [{}, +{}) outside the {} stored", brush_what,
                              brush.image_first, brush.image_count, images));
    if (brush.mask != MaskSource::kNone && directory.height_layer.width_px == 0)
      return fail(ErrorCode::kCorrupt, brush_what + ": masked by a layer the archive lacks");
    directory.brushes.push_back(brush);
  }
  return directory;
}

std::vector<uint8_t> encodeInstancePage(std::span<const BrushInstance> instances,
                                        std::span<const TileClip> clips) {
  TESSERA_CHECK(clips.empty() || clips.size() == instances.size()) << "one clip per instance";
  std::vector<uint8_t> bytes(instancePageBytes(instances.size()), 0);
  uint8_t* p = bytes.data();
  std::memcpy(p, kInstancePageMagic, 4);
  storeU32(p + 4, uint32_t(instances.size()));
  p += kInstancePageHeaderBytes;
  for (size_t i = 0; i < instances.size(); ++i) {
    const BrushInstance& instance = instances[i];
    const TileClip clip = clips.empty() ? TileClip{} : clips[i];
    storeU64(p, std::bit_cast<uint64_t>(instance.x_px));
    storeU64(p + 8, std::bit_cast<uint64_t>(instance.y_px));
    storeU32(p + 16, std::bit_cast<uint32_t>(instance.radius_px));
    storeU32(p + 20, std::bit_cast<uint32_t>(instance.rotation_rad));
    storeU32(p + 24, std::bit_cast<uint32_t>(instance.scale));
    storeU32(p + 28, instance.tint_rgba);
    storeU32(p + 32, instance.brush);
    p[36] = instance.opacity;
    p[37] = instance.variant;
    storeU16(p + 40, clip.x0);
    storeU16(p + 42, clip.y0);
    storeU16(p + 44, clip.x1);
    storeU16(p + 46, clip.y1);
    p += kInstanceRecordBytes;
  }
  return bytes;
}

Result<std::vector<BrushInstance>> decodeInstancePage(std::span<const uint8_t> bytes,
                                                      uint32_t brush_count, const std::string& what,
                                                      std::vector<TileClip>* clips) {
  if (bytes.size() < kInstancePageHeaderBytes ||
      std::memcmp(bytes.data(), kInstancePageMagic, 4) != 0)
    return fail(ErrorCode::kCorrupt, what + ": not an instance page (bad magic or too short)");
  uint32_t count = loadU32(bytes.data() + 4);
  if (count > kMaxPageInstances || bytes.size() != instancePageBytes(count))
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: instance page of {} bytes cannot hold {} instances", what,
                            bytes.size(), count));
  std::vector<BrushInstance> instances(count);
  if (clips) clips->assign(count, TileClip{});
  const uint8_t* p = bytes.data() + kInstancePageHeaderBytes;
  for (uint32_t i = 0; i < count; ++i, p += kInstanceRecordBytes) {
    BrushInstance& instance = instances[i];
    instance.id = i;
    instance.x_px = std::bit_cast<double>(loadU64(p));
    instance.y_px = std::bit_cast<double>(loadU64(p + 8));
    instance.radius_px = std::bit_cast<float>(loadU32(p + 16));
    instance.rotation_rad = std::bit_cast<float>(loadU32(p + 20));
    instance.scale = std::bit_cast<float>(loadU32(p + 24));
    instance.tint_rgba = loadU32(p + 28);
    instance.brush = loadU32(p + 32);
    instance.opacity = p[36];
    instance.variant = p[37];
    if (loadU16(p + 38) != 0)
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: instance {} reserved bytes not zero", what, i));
    const TileClip clip{loadU16(p + 40), loadU16(p + 42), loadU16(p + 44), loadU16(p + 46)};
    if (clip.x0 > clip.x1 || clip.y0 > clip.y1)
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: instance {} has an inverted clip", what, i));
    if (clips) (*clips)[i] = clip;
    if (instance.brush >= brush_count)
      return fail(ErrorCode::kCorrupt, fmt::format("{}: instance {} names brush {} of {}", what, i,
                                                   instance.brush, brush_count));
    if (!std::isfinite(instance.x_px) || !std::isfinite(instance.y_px) ||
        !finite(instance.radius_px) || !(instance.radius_px > 0) ||
        !finite(instance.rotation_rad) || !finite(instance.scale) || !(instance.scale > 0))
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: instance {} has a non-finite or non-positive field", what, i));
  }
  return instances;
}

Result<BlockRef> decodeProceduralRef(std::span<const SectionEntry> sections,
                                     const std::string& name) {
  const BlockRef block = findSection(sections, SectionKind::kProcedural);
  if (block.length_bytes > kMaxMetadataBytes)
    return fail(ErrorCode::kTooLarge,
                fmt::format("{}: procedural directory of {} bytes", name, block.length_bytes));
  return block;
}

TileEntry proceduralEntry(uint64_t offset_bytes, uint32_t length_bytes, uint64_t checksum) {
  TileEntry entry;
  entry.kind = TileKind::kProcedural;
  entry.offset_bytes = offset_bytes;
  entry.length_bytes = length_bytes;
  entry.checksum = checksum;
  return entry;
}

Result<std::vector<TileEntry>> decodeTileEntriesProcedural(std::span<const uint8_t> bytes,
                                                           const ImageInfo& info,
                                                           const FileHeader& header,
                                                           const std::string& what) {
  if (header.version_minor < kProceduralMinorVersion)
    return decodeTileEntries(bytes, info, header, what);
  if (bytes.size() % kTileEntryBytes)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: {} bytes is not a whole number of entries", what, bytes.size()));
  // Non-procedural entries keep the 1.0 rules: decode each through decodeTileEntries, whose
  // reserved-field check holds for a header of minor 0 (the fields are the same in 1.1).
  FileHeader as_v10 = header;
  as_v10.version_minor = 0;
  size_t count = bytes.size() / kTileEntryBytes;
  std::vector<TileEntry> entries(count);
  uint64_t max_payload = maxPayloadBytes(info);
  for (size_t i = 0; i < count; ++i) {
    const uint8_t* p = bytes.data() + i * kTileEntryBytes;
    if (p[12] != uint8_t(TileKind::kProcedural)) {
      TESSERA_ASSIGN_OR_RETURN(
          std::vector<TileEntry> one,
          decodeTileEntries(bytes.subspan(i * kTileEntryBytes, kTileEntryBytes), info, as_v10,
                            fmt::format("{} (entry {})", what, i)));
      entries[i] = one[0];
      continue;
    }
    TileEntry entry = proceduralEntry(loadU64(p), loadU32(p + 8), loadU64(p + 16));
    if (p[13] != 0 || loadU16(p + 14) != 0)
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: procedural entry {} has a codec or reserved bits", what, i));
    if (entry.length_bytes < kInstancePageHeaderBytes || entry.length_bytes > max_payload ||
        (entry.length_bytes - kInstancePageHeaderBytes) % kInstanceRecordBytes)
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: procedural entry {} page length {} is not 8 + 40 n <= {}", what,
                              i, entry.length_bytes, max_payload));
    if (entry.offset_bytes < header.header_region_bytes || entry.offset_bytes > header.file_bytes ||
        entry.length_bytes > header.file_bytes - entry.offset_bytes)
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: procedural entry {} page [{}, +{}) outside the payload area",
                              what, i, entry.offset_bytes, entry.length_bytes));
    entries[i] = entry;
  }
  return entries;
}

}  // namespace tessera::detail
