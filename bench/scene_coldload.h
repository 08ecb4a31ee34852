#pragma once
// tessera-scene-coldload (bench/scene_coldload.sh, docs/scenes.md "Cold load"): the parts of the
// cold-load benchmark shared by its three commands, prepare, tessera and perfile.

#include <cstdint>
#include <set>
#include <string>
#include <vector>

#include <tessera/result.h>
#include <tessera/scene.h>
#include <tessera/view.h>

namespace coldload {

/// One .stg placement and the objects the importer made of it: source indexes
/// [first_object, first_object + object_count), as the builder records in source_index.
struct Placement {
  uint32_t line = 0;  ///< 1-based line of the .stg
  std::string model;  ///< as written in the .stg (relative to its folder)
  uint32_t first_object = 0;
  uint32_t object_count = 0;
};

/// prepare: picks the usable FlightGear models under `models_dir`, writes WORK/sf.stg,
/// WORK/placements.tsv and WORK/files.txt, links WORK/Models and builds WORK/sf.tess.
[[nodiscard]] tessera::Result<void> prepare(const std::string& models_dir,
                                            const std::string& work_dir);

/// The placements WORK/placements.tsv lists (written by prepare).
[[nodiscard]] tessera::Result<std::vector<Placement>> readPlacements(const std::string& path);

/// The named views of the benchmark, framed on the scene's bounds (y up, as .stg scenes are).
std::vector<std::string> viewNames();
[[nodiscard]] tessera::Result<tessera::PerspectiveView> viewByName(
    const std::string& name, const tessera::SceneSummary& summary);

/// Drops `path`'s pages from the page cache (posix_fadvise DONTNEED, no root needed) and
/// returns how many of its pages are still resident afterwards (mincore), 0 when it worked.
[[nodiscard]] tessera::Result<uint64_t> dropFromPageCache(const std::string& path);

/// Per-file loading as a viewer does (scene_coldload_perfile.cpp): reads the .stg at
/// `stg_uri` (a path or http:// URL), then every model of the placements in `lines` (all
/// when empty) and every texture those models use, each file read whole and decoded
/// (Assimp, libpng or libjpeg-turbo) at full resolution, `threads` at a time. Without
/// `parse_models` a model's geometry is read but not parsed (only its texture names are
/// found): the lower bound of a viewer whose models cost nothing to parse.
struct PerFileReport {
  double seconds = 0;
  uint64_t files = 0;  ///< reads (local) or GET requests (HTTP): one per file
  uint64_t bytes = 0;
  uint32_t models = 0;
  uint32_t textures = 0;
  uint64_t texels = 0;  ///< decoded, at full resolution
};
[[nodiscard]] tessera::Result<PerFileReport> loadPerFile(const std::string& stg_uri,
                                                         const std::set<uint32_t>& lines,
                                                         uint32_t threads, bool parse_models);

}  // namespace coldload
