#include "scene_residency.h"

#include <algorithm>
#include <functional>
#include <tuple>

#include <tessera/check.h>

namespace tessera::detail {

SceneResidency::SceneResidency(std::vector<std::vector<uint64_t>> level_bytes)
    : level_bytes_(std::move(level_bytes)), textures_(level_bytes_.size()) {
  for (size_t t = 0; t < textures_.size(); ++t) {
    TESSERA_CHECK(!level_bytes_[t].empty()) << "texture " << t << " has no level";
    TextureState& state = textures_[t];
    state.coarsest = uint32_t(level_bytes_[t].size() - 1);
    state.resident = state.wanted = state.coarsest;
    pinned_bytes_ += level_bytes_[t].back();
  }
}

void SceneResidency::setDemand(const std::vector<TextureDemand>& demands) {
  ++frame_;
  for (uint32_t t : demanded_) {
    textures_[t].wanted = textures_[t].coarsest;
    textures_[t].pixels = 0;
  }
  demanded_.clear();
  for (const TextureDemand& demand : demands) {
    TextureState& state = textures_[demand.texture];
    if (state.last_seen_frame != frame_) {
      state.wanted = state.coarsest;
      state.pixels = 0;
      state.last_seen_frame = frame_;
      demanded_.push_back(demand.texture);
    }
    state.wanted = std::min({state.wanted, demand.wanted_level, state.coarsest});
    state.pixels += demand.pixels;
  }
}

std::vector<LevelRef> SceneResidency::nextLoads(uint64_t budget_bytes,
                                                const std::vector<bool>& busy) const {
  // What eviction could free without dropping anything the screen wants now.
  uint64_t excess = 0;
  for (uint32_t t : refined_) {
    const TextureState& state = textures_[t];
    for (uint32_t level = state.resident; level < std::min(state.wanted, state.coarsest); ++level) {
      excess += level_bytes_[t][level];
    }
  }
  const uint64_t floor_bytes = budgeted_bytes_ - excess;
  struct Candidate {
    uint64_t miss;
    uint32_t texture;
  };
  std::vector<Candidate> candidates;
  for (uint32_t t : demanded_) {
    const TextureState& state = textures_[t];
    if (state.resident <= state.wanted || (t < busy.size() && busy[t])) continue;
    if (floor_bytes + level_bytes_[t][state.resident - 1] > budget_bytes) continue;
    candidates.push_back({state.pixels * (state.resident - state.wanted), t});
  }
  std::sort(candidates.begin(), candidates.end(), [](const Candidate& a, const Candidate& b) {
    return std::tie(b.miss, a.texture) < std::tie(a.miss, b.texture);
  });
  std::vector<LevelRef> loads;
  loads.reserve(candidates.size());
  for (const Candidate& c : candidates)
    loads.push_back({c.texture, textures_[c.texture].resident - 1});
  return loads;
}

bool SceneResidency::loaded(const LevelRef& level) {
  TextureState& state = textures_[level.texture];
  if (level.level + 1 != state.resident) return false;
  if (state.resident == state.coarsest) refined_.push_back(level.texture);
  state.resident = level.level;
  budgeted_bytes_ += level_bytes_[level.texture][level.level];
  return true;
}

std::vector<LevelRef> SceneResidency::evictTo(uint64_t budget_bytes) {
  std::vector<LevelRef> dropped;
  if (budgeted_bytes_ <= budget_bytes) return dropped;
  // Eviction rank, smallest first: levels the texture does not want now (out of view: oldest
  // seen first; then larger levels first), then wanted levels of the fewest pixels. A heap of
  // the refined textures' finest levels, a texture pushed again while it has one to drop.
  using Rank = std::tuple<bool, uint64_t, uint64_t, uint32_t>;
  auto rank = [&](uint32_t t) {
    const TextureState& state = textures_[t];
    const bool needed = state.resident >= state.wanted;
    const uint64_t bytes = level_bytes_[t][state.resident];
    return Rank(needed, needed ? state.pixels : state.last_seen_frame, needed ? 0 : ~bytes, t);
  };
  std::vector<Rank> heap;
  heap.reserve(refined_.size());
  for (uint32_t t : refined_) heap.push_back(rank(t));
  std::make_heap(heap.begin(), heap.end(), std::greater<>());
  while (budgeted_bytes_ > budget_bytes && !heap.empty()) {
    std::pop_heap(heap.begin(), heap.end(), std::greater<>());
    const uint32_t t = std::get<3>(heap.back());
    heap.pop_back();
    TextureState& state = textures_[t];
    dropped.push_back({t, state.resident});
    budgeted_bytes_ -= level_bytes_[t][state.resident];
    ++state.resident;
    if (state.resident < state.coarsest) {
      heap.push_back(rank(t));
      std::push_heap(heap.begin(), heap.end(), std::greater<>());
    }
  }
  // Textures back at their coarsest leave the candidates.
  std::erase_if(refined_,
                [&](uint32_t t) { return textures_[t].resident == textures_[t].coarsest; });
  return dropped;
}

}  // namespace tessera::detail
