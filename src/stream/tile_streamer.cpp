// TileStreamer: the per-frame loop of the runtime. Render thread: poll finished loads,
// plan residency, re-prioritise the loader, hand uploads within budget (parent before child).
#include <tessera/stream.h>

#include <algorithm>
#include <optional>
#include <thread>
#include <unordered_map>
#include <unordered_set>

#include <fmt/format.h>

#include "adaptive.h"
#include "loader_pool.h"
#include "residency.h"
#include "upload_budget.h"

namespace tessera {

using Clock = std::chrono::steady_clock;

struct TileStreamer::Impl {
  std::shared_ptr<Archive> archive;
  StreamerOptions options;
  std::unique_ptr<TileCache> cache;
  std::unique_ptr<detail::LoaderPool> loader;
  std::vector<std::unique_ptr<detail::ResidencyManager>> residency;  ///< per image, lazily
  std::unordered_set<TileId, TileIdHash> resident;
  std::unordered_set<TileId, TileIdHash> awaiting_upload;  ///< handed out, pinned, not confirmed
  FrameUpdate update;
  std::vector<detail::LoadEvent> events;
  std::vector<TileRequest> requests;
  /// Tiles the loader delivered and that are not resident; some may have been evicted since.
  std::unordered_set<TileId, TileIdHash> loaded;
  std::vector<TileId> candidates;
  std::vector<TileRequest> candidate_requests;
  std::vector<std::shared_ptr<const DecodedTile>> pinned;
  uint64_t load_failures = 0;
  // Adaptive scheduling (options.adaptive): per image, lazily.
  std::vector<std::unique_ptr<detail::AdaptiveScheduler>> adaptive;
  /// Payload sizes of tiles whose directory page was in memory when first asked.
  static constexpr size_t kMaxKnownSizes = size_t(1) << 20;
  std::unordered_map<TileId, uint32_t, TileIdHash> payload_sizes;
  /// Per image and level: sum and count of known payload sizes, to estimate unknown ones.
  std::vector<std::vector<std::pair<uint64_t, uint64_t>>> size_sums;
  std::unordered_set<TileId, TileIdHash> in_flight;
  /// This frame's uploads; while they are chosen, the candidates so far.
  std::unordered_set<TileId, TileIdHash> uploading;
  /// The byte budget of each frame's uploads, fed the renderer's measured upload times.
  std::optional<detail::UploadBudgetController> upload_budget;
  uint64_t frame_budget_bytes = 0;  ///< this frame's, chosen at the start of chooseUploads

  /// A tile's payload bytes, from its directory entry when its page is in memory (never a
  /// read: the render thread must not wait), else the mean of known ones at its level, else
  /// at any level, else the decoded size (an upper bound for every codec but raw's equal).
  uint64_t payloadBytes(const TileId& id);

  // The steps of update(), in order.
  /// Drains the loader's finished loads into `loaded`, and the failed ones into
  /// update.failures.
  void pollLoads();
  /// The residency manager of `image`, made on first use.
  detail::ResidencyManager& residencyOf(uint32_t image);
  /// Wanted tiles that are neither resident nor loaded go to `requests` (sorted by priority);
  /// loaded ones become this frame's uploads within the budget, parents before children.
  /// Returns the uploads' texel bytes.
  uint64_t chooseUploads(const detail::ResidencyPlan& plan, const ImageInfo& info);
  /// Adaptive scheduling: trims `requests` to what the link delivers in time.
  void scheduleAdaptive(const View& view, uint32_t image, const detail::ResidencyPlan& plan,
                        FrameReport& report);
  /// Resident tiles of `image` that left every (expanded) region go to update.releases.
  void releaseLeft(uint32_t image, const detail::ResidencyManager& residency);
  /// The loader's figures into `report`.
  void reportLoader(FrameReport& report) const;
};

uint64_t TileStreamer::Impl::payloadBytes(const TileId& id) {
  if (auto it = payload_sizes.find(id); it != payload_sizes.end()) return it->second;
  auto& sums = size_sums[id.image];
  if (std::optional<TileEntry> entry = archive->tileEntryIfCached(id)) {
    // Bounded like the archive's own page cache: a long flight over a terapixel image would
    // otherwise remember every tile it passed. The per-level means survive.
    if (payload_sizes.size() >= kMaxKnownSizes) payload_sizes.clear();
    const uint32_t bytes = entry->hasPayload() ? entry->length_bytes : 0;
    payload_sizes.emplace(id, bytes);
    sums[id.level].first += bytes;
    sums[id.level].second += 1;
    return bytes;
  }
  if (sums[id.level].second) return sums[id.level].first / sums[id.level].second;
  uint64_t sum = 0, count = 0;
  for (const auto& [level_sum, level_count] : sums) {
    sum += level_sum;
    count += level_count;
  }
  return count ? sum / count : archive->images()[id.image].storedTileBytes();
}

TileStreamer::TileStreamer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

TileStreamer::~TileStreamer() {
  // Stop loading before the cache it fills goes away.
  impl_->loader.reset();
}

Result<std::unique_ptr<TileStreamer>> TileStreamer::create(std::shared_ptr<Archive> archive,
                                                           const StreamerOptions& options) {
  if (!archive) return fail(ErrorCode::kInvalidArgument, "TileStreamer needs an archive");
  size_t largest_tile = 0;
  for (const ImageInfo& info : archive->images())
    largest_tile = std::max(largest_tile, info.storedTileBytes());
  // The coarsest levels are pinned and a few tiles are always in flight: a budget below
  // that could never make progress.
  size_t minimum = largest_tile * 64;
  if (options.cache_budget_bytes < minimum)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: cache budget of {} bytes is below the {} bytes 64 tiles need",
                            archive->name(), options.cache_budget_bytes, minimum));
  auto impl = std::make_unique<Impl>();
  impl->archive = archive;
  impl->options = options;
  impl->upload_budget.emplace(options.residency);
  impl->cache = std::make_unique<TileCache>(
      options.cache_budget_bytes,
      options.viewer_shift_eviction ? makeViewerShiftPolicy() : makeLruPolicy());
  detail::LoaderOptions loader_options;
  loader_options.threads = options.loader_threads;
  loader_options.priority = options.loader_priority;
  loader_options.recycled_bytes = options.recycled_buffer_bytes;
  loader_options.batch_gap_bytes = options.batch_gap_bytes;
  loader_options.merge_gap_bytes = options.merge_gap_bytes;
  loader_options.max_merged_read_bytes = options.max_merged_read_bytes;
  loader_options.link_sized_reads = options.link_sized_reads;
  loader_options.gap_round_trip_share = options.gap_round_trip_share;
  loader_options.max_link_gap_bytes = options.max_link_gap_bytes;
  loader_options.read_ahead_bytes = options.read_ahead_bytes;
  loader_options.keep_block_compressed = options.keep_block_compressed;
  loader_options.transcode_to_bc1 = options.transcode_to_bc1;
  loader_options.retry_initial = options.retry_initial;
  loader_options.retry_max = options.retry_max;
  impl->loader = std::make_unique<detail::LoaderPool>(archive, *impl->cache, loader_options);
  impl->residency.resize(archive->images().size());
  impl->adaptive.resize(archive->images().size());
  for (const ImageInfo& info : archive->images())
    impl->size_sums.emplace_back(info.level_count, std::pair<uint64_t, uint64_t>{0, 0});
  return std::unique_ptr<TileStreamer>(new TileStreamer(std::move(impl)));
}

void TileStreamer::Impl::pollLoads() {
  events.clear();
  loader->poll(events);
  for (detail::LoadEvent& event : events)
    if (event.ok) {
      loaded.insert(event.id);
    } else if (!event.stale) {
      ++load_failures;
      update.failures.push_back({event.id, event.code, std::move(event.error)});
    }
}

detail::ResidencyManager& TileStreamer::Impl::residencyOf(uint32_t image) {
  if (!residency[image])
    residency[image] = std::make_unique<detail::ResidencyManager>(archive->images()[image], image,
                                                                  options.residency);
  return *residency[image];
}

uint64_t TileStreamer::Impl::chooseUploads(const detail::ResidencyPlan& plan,
                                           const ImageInfo& info) {
  // The render thread tracks "loaded" from the loader's events, so it takes the cache's lock
  // once per frame (findAndPin); a tile evicted meanwhile is simply requested again.
  requests.clear();
  candidates.clear();
  candidate_requests.clear();
  uploading.clear();
  const ResidencyOptions& budget = options.residency;
  frame_budget_bytes = upload_budget->budgetBytes();
  const uint32_t coarsest = info.level_count - 1;
  auto parentReady = [&](const TileId& id) {
    TileId parent{id.image, id.level + 1, id.x / 2, id.y / 2};
    return id.level == coarsest || resident.count(parent) || uploading.count(parent);
  };
  uint64_t candidate_bytes = 0;
  for (const TileRequest& request : plan.wanted) {
    const TileId& id = request.id;
    if (resident.count(id) || awaiting_upload.count(id)) continue;
    if (!loaded.count(id)) {
      requests.push_back(request);
      continue;
    }
    bool budget_left = candidates.size() < budget.upload_budget_tiles &&
                       (frame_budget_bytes == 0 || candidates.empty() ||
                        candidate_bytes + info.storedTileBytes() <= frame_budget_bytes);
    if (budget_left && parentReady(id)) {
      candidates.push_back(id);
      candidate_requests.push_back(request);
      uploading.insert(id);
      candidate_bytes += info.storedTileBytes();
    }
  }
  pinned.clear();
  cache->findAndPin(candidates, pinned);
  uploading.clear();
  uint64_t upload_bytes = 0;
  for (size_t i = 0; i < candidates.size(); ++i) {
    const TileId& id = candidates[i];
    if (!pinned[i]) {
      loaded.erase(id);  // evicted since it loaded
      requests.push_back(candidate_requests[i]);
      continue;
    }
    if (!parentReady(id)) {  // its parent was evicted before it could go up
      cache->unpin(id);
      continue;
    }
    upload_bytes += pinned[i]->uploadBytes().size();
    uploading.insert(id);
    awaiting_upload.insert(id);
    loaded.erase(id);
    update.uploads.push_back(std::move(pinned[i]));
  }
  std::sort(requests.begin(), requests.end(),
            [](const TileRequest& a, const TileRequest& b) { return a.priority < b.priority; });
  return upload_bytes;
}

void TileStreamer::Impl::scheduleAdaptive(const View& view, uint32_t image,
                                          const detail::ResidencyPlan& plan, FrameReport& report) {
  const ImageInfo& info = archive->images()[image];
  if (!adaptive[image])
    adaptive[image] = std::make_unique<detail::AdaptiveScheduler>(
        options.adaptive, info.level_count, info.storedTileBytes(), options.cache_budget_bytes);
  loader->inFlight(in_flight);
  const bool dependent = codecNeedsParent(info.default_codec);
  auto facts = [&](const TileId& id) {
    detail::TileFacts f;
    f.held =
        resident.count(id) || awaiting_upload.count(id) || loaded.count(id) || uploading.count(id);
    f.in_flight = in_flight.count(id) > 0;
    f.payload_bytes = payloadBytes(id);
    f.payload_known = payload_sizes.count(id) > 0;
    if (dependent && id.level + 1 < info.level_count) {
      const TileId parent = Archive::parentTile(id);
      f.parent_ready = cache->contains(parent) || in_flight.count(parent) > 0;
    }
    return f;
  };
  const auto now = options.adaptive.clock ? options.adaptive.clock() : Clock::now();
  adaptive[image]->schedule(view, now, loader->linkEstimate(), plan.wanted, facts, requests,
                            report);
}

void TileStreamer::Impl::releaseLeft(uint32_t image, const detail::ResidencyManager& manager) {
  for (auto it = resident.begin(); it != resident.end();) {
    if (it->image == image && !manager.isKept(*it)) {
      update.releases.push_back(*it);
      loaded.insert(*it);  // probably still cached; found out at the next upload attempt
      it = resident.erase(it);
    } else {
      ++it;
    }
  }
}

void TileStreamer::Impl::reportLoader(FrameReport& report) const {
  const detail::LoaderStats stats = loader->stats();
  report.queue_length = stats.queued;
  report.in_flight = stats.in_flight;
  report.loader_idle_since = stats.idle_since;
  report.bytes_read_total = stats.bytes_read;
  report.payload_bytes_total = stats.payload_bytes;
  report.reads_total = stats.reads;
  report.tiles_loaded_total = stats.tiles_loaded;
  report.load_failures_total = stats.failures;
  report.decode_ms_total = stats.decode_ns / 1e6;
  report.transcode_ms_total = stats.transcode_ns / 1e6;
  report.tiles_transcoded_total = stats.tiles_transcoded;
  report.hinted_bytes_total = stats.hinted_bytes;
  report.link_bytes_per_s = stats.link.bytes_per_s;
  report.link_latency_ms = stats.link.latency_s * 1e3;
  report.queue_wait_ms = stats.link.queue_wait_s * 1e3;
  report.cancelled_total = stats.cancelled;
  report.reads_cancelled_total = stats.reads_cancelled;
  report.parents_queued_total = stats.parents_queued;
  report.parent_fallbacks_total = stats.parent_fallbacks;
  report.children_read_early_total = stats.children_read_early;
  report.loader_rescues_total = stats.rescues;
  report.rescued_batches_total = stats.rescued_batches;
}

const FrameUpdate& TileStreamer::update(const View& view) {
  const auto started = Clock::now();
  Impl& s = *impl_;
  FrameUpdate& out = s.update;
  out.uploads.clear();
  out.releases.clear();
  out.regions.clear();
  out.failures.clear();
  s.pollLoads();

  const uint32_t image = std::min<uint32_t>(view.image, uint32_t(s.archive->images().size() - 1));
  const ImageInfo& info = s.archive->images()[image];
  detail::ResidencyManager& residency = s.residencyOf(image);
  const uint64_t plans_before = residency.plansComputed();
  const detail::ResidencyPlan& plan = residency.plan(view);
  out.replanned = residency.plansComputed() != plans_before;
  ViewerMotion motion = plan.motion;
  motion.tile_size_px = info.tile_size_px;
  s.cache->setViewerMotion(motion);
  out.regions = plan.clip_regions;
  out.clip_region_tiles =
      clipRegionTiles(view.viewportWidth(), view.viewportHeight(), info.tile_size_px);
  out.resident_tiles_bound =
      residentTilesBound(info, view.viewportWidth(), view.viewportHeight(), s.options.residency);

  const uint64_t upload_bytes = s.chooseUploads(plan, info);
  FrameReport& report = out.report;
  report = {};
  report.requested_level = plan.desired_level;
  if (s.options.adaptive.enabled) s.scheduleAdaptive(view, image, plan, report);
  s.loader->setWanted(s.requests);
  s.releaseLeft(image, residency);

  residency.measureCoverage(
      [&](const TileId& id) { return s.resident.count(id) > 0 || s.uploading.count(id) > 0; },
      report);
  s.reportLoader(report);
  report.uploads = out.uploads.size();
  report.upload_bytes = upload_bytes;
  report.upload_budget_bytes = s.frame_budget_bytes;
  report.upload_bytes_per_ms =
      s.options.residency.adaptive_upload.enabled ? s.upload_budget->bytesPerMs() : 0;
  report.update_ms = std::chrono::duration<double, std::milli>(Clock::now() - started).count();
  return out;
}

void TileStreamer::acknowledge(const ApplyResult& result) {
  Impl& s = *impl_;
  uint64_t accepted_bytes = 0;
  for (const TileId& id : result.accepted) {
    if (s.awaiting_upload.erase(id) == 0) continue;
    accepted_bytes += s.archive->images()[id.image].storedTileBytes();
    s.resident.insert(id);
    s.cache->unpin(id);
  }
  for (const TileId& id : result.declined) {
    if (s.awaiting_upload.erase(id) == 0) continue;
    s.cache->unpin(id);
    s.loaded.insert(id);
  }
  // A dropped tile is probably still cached (a renderer that drops a tile to make room, or is
  // replaced, drops one the runtime loaded): offered again from the cache, requested only if
  // it was evicted meanwhile.
  for (const TileId& id : result.dropped)
    if (s.resident.erase(id)) s.loaded.insert(id);
  if (result.upload_ms >= 0) s.upload_budget->observe(accepted_bytes, result.upload_ms);
}

TileState TileStreamer::state(const TileId& id) const {
  if (impl_->resident.count(id)) {
    uint32_t coarsest = impl_->archive->images()[id.image].level_count - 1;
    return id.level == coarsest ? TileState::kLocked : TileState::kResident;
  }
  if (impl_->cache->contains(id)) return TileState::kLoaded;
  if (impl_->loader->isRequested(id)) return TileState::kRequested;
  return TileState::kUnloaded;
}

void TileStreamer::waitIdleForTesting() {
  impl_->loader->waitIdle();
}

const Archive& TileStreamer::archive() const {
  return *impl_->archive;
}
TileCache& TileStreamer::cache() {
  return *impl_->cache;
}
CacheStats TileStreamer::cacheStats() const {
  return impl_->cache->stats();
}

void tuneForRemoteSource(StreamerOptions& options) {
  options.loader_threads = std::max(kRemoteLoaderThreads, std::thread::hardware_concurrency());
  options.merge_gap_bytes = 16 * 1024;
  options.batch_gap_bytes = options.merge_gap_bytes;
  options.read_ahead_bytes = 0;
  options.adaptive.enabled = true;
  options.link_sized_reads = true;
}

}  // namespace tessera
