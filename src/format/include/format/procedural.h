#pragma once
// Procedural tiles in the archive (docs/format.md, "Procedural tiles", format 1.1): the
// procedural directory that the section table names as kind 2 (brush images stored once,
// brush records, the underlying height layer), the instance page that a procedural tile entry
// points to, and the entry itself. Pure: bytes in, structs out.

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <tessera/format.h>
#include <tessera/procedural.h>
#include <tessera/result.h>

#include "format/header.h"
#include "format/sections.h"

namespace tessera::detail {

/// The minor version that gives tile kind 3 its meaning and adds the section table whose
/// kProcedural entry is the procedural directory (format/sections.h).
inline constexpr uint16_t kProceduralMinorVersion = 1;

inline constexpr uint8_t kProceduralDirectoryMagic[4] = {'T', 'P', 'R', 'C'};
inline constexpr uint8_t kInstancePageMagic[4] = {'T', 'I', 'P', 'G'};
inline constexpr uint16_t kProceduralDirectoryVersion = 1;
inline constexpr uint32_t kProceduralDirectoryFixedBytes = 64;
inline constexpr uint32_t kProceduralImageRecordBytes = 40;
inline constexpr uint32_t kBrushRecordBytes = 16;
inline constexpr uint32_t kInstancePageHeaderBytes = 8;
inline constexpr uint32_t kInstanceRecordBytes = 48;
/// Bounds that keep a hostile directory from driving allocations.
inline constexpr uint32_t kMaxProceduralBrushes = 65535;
inline constexpr uint32_t kMaxProceduralImages = 65535;
/// Instances in one tile's page: far above what the analysis lets through any time budget.
inline constexpr uint32_t kMaxPageInstances = 1u << 20;
/// The height layer's largest side.
inline constexpr uint32_t kMaxLayerSidePx = 1u << 16;

/// A stored picture: a brush image (4 channels) or the height layer (1 channel), coded with a
/// lossless codec as one rectangle of width x height texels.
struct ProceduralImageRecord {
  BlockRef block;  ///< payload; length 0 only for an absent layer
  uint32_t width_px = 0;
  uint32_t height_px = 0;
  uint32_t channels = 0;  ///< 4 for brush images, 1 for the height layer
  Codec codec = Codec::kZstd;
  friend bool operator==(const ProceduralImageRecord&, const ProceduralImageRecord&) = default;
};

/// A brush: its images are images[image_first, image_first + image_count).
struct ProceduralBrushRecord {
  uint32_t image_first = 0;
  uint32_t image_count = 0;  ///< 1..kMaxBrushImages
  BlendMode blend = BlendMode::kNormal;
  MaskSource mask = MaskSource::kNone;
  uint8_t mask_low = 0;
  uint8_t mask_high = 255;
  friend bool operator==(const ProceduralBrushRecord&, const ProceduralBrushRecord&) = default;
};

/// The procedural directory: what every procedural tile of one image needs besides its page.
struct ProceduralDirectory {
  uint32_t image = 0;                  ///< the archive image whose tiles may be procedural
  ProceduralImageRecord height_layer;  ///< width 0 when the archive has none
  std::vector<ProceduralImageRecord> images;
  std::vector<ProceduralBrushRecord> brushes;
  friend bool operator==(const ProceduralDirectory&, const ProceduralDirectory&) = default;
};

std::vector<uint8_t> encodeProceduralDirectory(const ProceduralDirectory& directory);
/// Checks magic, version, counts against the length (no trailing bytes), reserved bytes, every
/// block inside [header_region_bytes, file_bytes), codecs lossless and known, sizes in bounds,
/// brushes' image ranges inside the image table. `what` prefixes messages.
Result<ProceduralDirectory> decodeProceduralDirectory(std::span<const uint8_t> bytes,
                                                      const FileHeader& header,
                                                      uint32_t image_count,
                                                      const std::string& what);

/// One instance as a page stores it: the page's order is the drawing order, so neither the
/// database id nor the layer is stored.
/// `clips` is empty (nothing clipped) or one per instance.
std::vector<uint8_t> encodeInstancePage(std::span<const BrushInstance> instances,
                                        std::span<const TileClip> clips = {});
/// Checks magic, count against length, every instance's fields (finite, radius and scale > 0,
/// brush below `brush_count`, reserved zero, clip x0 <= x1 and y0 <= y1). Instances come back
/// with id = their position in the page and layer 0; their clips go to `clips` when not null.
Result<std::vector<BrushInstance>> decodeInstancePage(std::span<const uint8_t> bytes,
                                                      uint32_t brush_count, const std::string& what,
                                                      std::vector<TileClip>* clips = nullptr);
inline uint64_t instancePageBytes(size_t instances) {
  return kInstancePageHeaderBytes + uint64_t(instances) * kInstanceRecordBytes;
}

/// The procedural directory's reference among a decoded section table's entries: length 0
/// when the table has none; otherwise at most kMaxMetadataBytes long (kTooLarge), like the
/// metadata, so a hostile table cannot make a reader allocate much.
Result<BlockRef> decodeProceduralRef(std::span<const SectionEntry> sections,
                                     const std::string& name);

/// A procedural tile entry (kind 3): the page's offset, length and checksum in the encoded
/// entry's fields, codec 0. encodeTileEntries writes it as it is.
TileEntry proceduralEntry(uint64_t offset_bytes, uint32_t length_bytes, uint64_t checksum);
/// Decodes a page's entries like decodeTileEntries, and in files of minor >= 1 accepts kind 3
/// entries: page inside the payload area, length of a whole page (8 + 40 n bytes, n >= 0) up to
/// maxPayloadBytes, codec and reserved zero. The reader calls this for 1.1 files.
Result<std::vector<TileEntry>> decodeTileEntriesProcedural(std::span<const uint8_t> bytes,
                                                           const ImageInfo& info,
                                                           const FileHeader& header,
                                                           const std::string& what);

}  // namespace tessera::detail
