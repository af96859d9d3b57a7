// The stored optimum maps of a server, for QueryOptimum at conditions between their cells
// (jobs/optimum_map_query.h). Every SUCCEEDED optimum-map job of the store is loaded (its request
// and cells, read page by page) by a refresh, which a query that finds no map asks for: the first
// one (not the start-up, which a large store would slow), then at most once a second, or at once
// after this process completed a map; so maps completed by other processes are found too. Answers
// are kept by the query's cache key until a map is dropped. Bounded: maps beyond `max_bytes` of
// cells are not loaded (logged). Thread-safe.
#ifndef DRILLBIF_SERVER_MAP_INDEX_H_
#define DRILLBIF_SERVER_MAP_INDEX_H_

#include <chrono>
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <unordered_map>
#include <vector>

#include "drillbif/common/status.h"
#include "drillbif/v1/service.pb.h"
#include "jobs/optimum_map_query.h"
#include "server/store/job_store.h"
#include "server/stored_results.h"

namespace drillbif::server {

class MapIndex {
 public:
  explicit MapIndex(int64_t max_bytes = int64_t{256} << 20, size_t max_answers = 4096);

  // Loads the store's maps not loaded yet (when due: see the header, or `force`).
  Status Refresh(JobStore& store, const PageOptions& pages, bool force = false);
  // A map completed in this process: the next Refresh is due at once.
  void MarkStale();
  // Drops the map of job `id` (deleted or evicted) and every kept answer.
  void RemoveJob(const std::string& id);
  // Drops every map and answer (the store was evicted from).
  void Clear();

  // The most recent map covering the query's conditions, or null; then *nearest says which map of
  // the same box lies nearest and how far (empty when none has the same box).
  std::shared_ptr<const jobs::LoadedMap> Find(const v1::OptimumRequest& query,
                                              std::string* nearest) const;

  // A kept answer by the query's cache key.
  std::optional<v1::QueryOptimumResponse> Answer(const std::string& key);
  void KeepAnswer(const std::string& key, const v1::QueryOptimumResponse& response);

  int64_t bytes() const;
  size_t size() const;

 private:
  StatusOr<std::shared_ptr<const jobs::LoadedMap>> Load(JobStore& store, const JobRecord& job,
                                                        const PageOptions& pages);

  const int64_t max_bytes_;
  const size_t max_answers_;
  mutable std::mutex mutex_;
  std::mutex refresh_mutex_;  // one refresh at a time
  std::chrono::steady_clock::time_point last_refresh_{};
  bool stale_ = true;
  // Loaded maps by MapQueryKey (several per key: other condition ranges), with their job ids.
  std::multimap<std::string, std::shared_ptr<const jobs::LoadedMap>> maps_;
  std::set<std::vector<std::string>> overs_;  // the conditions of the loaded maps
  std::set<std::string> seen_;                // job ids and cache keys loaded or refused
  int64_t bytes_ = 0;
  std::list<std::pair<std::string, v1::QueryOptimumResponse>> answers_;  // most recent first
  std::unordered_map<std::string, decltype(answers_)::iterator> answer_of_;
};

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_MAP_INDEX_H_
