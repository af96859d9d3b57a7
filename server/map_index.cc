#include "server/map_index.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <utility>

#include "jobs/registry.h"
#include "server/services.h"

namespace drillbif::server {
namespace {

// Refreshes on a query miss at most this often: each is one List of the store.
constexpr auto kRefreshInterval = std::chrono::seconds(1);

}  // namespace

MapIndex::MapIndex(int64_t max_bytes, size_t max_answers)
    : max_bytes_(max_bytes), max_answers_(max_answers) {}

StatusOr<std::shared_ptr<const jobs::LoadedMap>> MapIndex::Load(JobStore& store,
                                                                const JobRecord& job,
                                                                const PageOptions& pages) {
  v1::OptimumMapRequest request;
  if (!request.ParseFromString(job.request)) {
    return InvalidArgument("the stored request of map " + job.id + " does not parse");
  }
  const jobs::JobKindSpec& kind = *jobs::FindKind(v1::OPTIMUM_MAP);
  std::vector<v1::OptimumMapCell> cells;
  std::string token;
  do {
    v1::GetResultResponse page;
    DRILLBIF_RETURN_IF_ERROR(ReadResultPage(store, kind, job.id, 0, token, pages, &page));
    for (v1::OptimumMapCell& cell : *page.mutable_optimum_map()->mutable_cells()) {
      // Queries read the optimum, the orbit and the boundary near it, not the whole region.
      cell.clear_region();
      cell.clear_curves();
      cells.push_back(std::move(cell));
    }
    token = page.next_page_token();
  } while (!token.empty());
  DRILLBIF_ASSIGN_OR_RETURN(jobs::LoadedMap map,
                            jobs::LoadMap(OperationName(job.id), request, std::move(cells)));
  return std::make_shared<const jobs::LoadedMap>(std::move(map));
}

Status MapIndex::Refresh(JobStore& store, const PageOptions& pages, bool force) {
  std::lock_guard<std::mutex> refreshing(refresh_mutex_);
  const auto now = std::chrono::steady_clock::now();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!force && !stale_ && now - last_refresh_ < kRefreshInterval) return Status::Ok();
    stale_ = false;
    last_refresh_ = now;
  }
  ListRequest list;
  list.state = JobState::kSucceeded;
  list.kind = jobs::FindKind(v1::OPTIMUM_MAP)->name;
  list.page_size = 1000;
  list.include_request = true;
  do {
    DRILLBIF_ASSIGN_OR_RETURN(const ListResult page, store.List(list));
    for (const JobRecord& job : page.jobs) {
      {
        std::lock_guard<std::mutex> lock(mutex_);
        if (seen_.count(job.id) || (!job.cache_key.empty() && seen_.count(job.cache_key))) {
          continue;
        }
        seen_.insert(job.id);
        if (!job.cache_key.empty()) seen_.insert(job.cache_key);
      }
      StatusOr<std::shared_ptr<const jobs::LoadedMap>> map = Load(store, job, pages);
      if (!map.ok()) {
        spdlog::warn("optimum map {} not loaded: {}", job.id, map.status().ToString());
        if (map.status().code() != StatusCode::kInvalidArgument) {
          // A store fault: tried again by the next refresh. (A map that no longer plans, or
          // whose bytes do not parse, is not.)
          std::lock_guard<std::mutex> lock(mutex_);
          seen_.erase(job.id);
          seen_.erase(job.cache_key);
        }
        continue;
      }
      std::lock_guard<std::mutex> lock(mutex_);
      if (bytes_ + (*map)->bytes > max_bytes_) {
        spdlog::warn("optimum map {} not loaded: its {} bytes of cells exceed the {} bytes kept",
                     job.id, (*map)->bytes, max_bytes_);
        continue;
      }
      bytes_ += (*map)->bytes;
      overs_.insert((*map)->plan.over);
      maps_.emplace(jobs::MapQueryKey((*map)->request.optimum(), (*map)->plan.over), *map);
      answers_.clear();  // a newer map may answer differently
      answer_of_.clear();
    }
    list.page_token = page.next_page_token;
  } while (!list.page_token.empty());
  return Status::Ok();
}

void MapIndex::MarkStale() {
  std::lock_guard<std::mutex> lock(mutex_);
  stale_ = true;
}

void MapIndex::RemoveJob(const std::string& id) {
  std::lock_guard<std::mutex> lock(mutex_);
  const std::string operation = OperationName(id);
  for (auto it = maps_.begin(); it != maps_.end();) {
    if (it->second->operation == operation) {
      bytes_ -= it->second->bytes;
      it = maps_.erase(it);
    } else {
      ++it;
    }
  }
  answers_.clear();
  answer_of_.clear();
}

void MapIndex::Clear() {
  std::lock_guard<std::mutex> lock(mutex_);
  maps_.clear();
  overs_.clear();
  seen_.clear();
  bytes_ = 0;
  answers_.clear();
  answer_of_.clear();
  stale_ = true;
}

std::shared_ptr<const jobs::LoadedMap> MapIndex::Find(const v1::OptimumRequest& query,
                                                      std::string* nearest) const {
  nearest->clear();
  std::lock_guard<std::mutex> lock(mutex_);
  std::shared_ptr<const jobs::LoadedMap> found;
  double nearest_cells = 0.0;
  for (const std::vector<std::string>& over : overs_) {
    const auto [begin, end] = maps_.equal_range(jobs::MapQueryKey(query, over));
    for (auto it = begin; it != end; ++it) {
      const jobs::LoadedMap& map = *it->second;
      const double outside = jobs::CellsOutside(map, jobs::QueryConditions(map, query));
      if (outside == 0.0) {
        found = it->second;  // the last loaded (most recent) covering map
      } else if (nearest->empty() || outside < nearest_cells) {
        nearest_cells = outside;
        std::string range;
        for (size_t k = 0; k < map.plan.over.size(); ++k) {
          range += fmt::format("{}{} in [{:g}, {:g}]", k ? ", " : "", map.plan.over[k],
                               map.plan.from[k], map.plan.to[k]);
        }
        *nearest = fmt::format("{} covers {} (the query lies {:.3g} cells outside)", map.operation,
                               range, outside);
      }
    }
  }
  return found;
}

std::optional<v1::QueryOptimumResponse> MapIndex::Answer(const std::string& key) {
  std::lock_guard<std::mutex> lock(mutex_);
  const auto it = answer_of_.find(key);
  if (it == answer_of_.end()) return std::nullopt;
  answers_.splice(answers_.begin(), answers_, it->second);
  return it->second->second;
}

void MapIndex::KeepAnswer(const std::string& key, const v1::QueryOptimumResponse& response) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (answer_of_.count(key)) return;
  answers_.emplace_front(key, response);
  answer_of_[key] = answers_.begin();
  while (answers_.size() > max_answers_) {
    answer_of_.erase(answers_.back().first);
    answers_.pop_back();
  }
}

int64_t MapIndex::bytes() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return bytes_;
}

size_t MapIndex::size() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return maps_.size();
}

}  // namespace drillbif::server
