// The cache key of a request (CacheKeyOf): the threads a computation runs on do not change its
// result, so they do not change its key; every other field does.
#include <gtest/gtest.h>

#include "drillbif/v1/optimum.pb.h"
#include "drillbif/v1/sweep.pb.h"
#include "drillbif/v1/trace.pb.h"
#include "jobs/optimum_cache.h"
#include "jobs/registry.h"
#include "jobs/request_bytes.h"
#include "support/small_requests.h"

namespace drillbif::jobs {
namespace {

using testing::SmallBoxTrace;

TEST(CacheKey, ATraceOnOtherThreadsHasTheSameKeyAndAnotherBoxAnother) {
  const JobKindSpec& trace = *FindKind(v1::TRACE);
  v1::TraceRequest one = SmallBoxTrace(), four = SmallBoxTrace(), wider = SmallBoxTrace();
  one.set_threads(1);
  four.set_threads(4);
  wider.set_max(0, 0.3);
  EXPECT_EQ(CacheKeyOf(trace, one), CacheKeyOf(trace, four));
  EXPECT_EQ(CacheKeyOf(trace, one), CacheKeyOf(trace, SmallBoxTrace()));  // threads unset
  EXPECT_NE(CacheKeyOf(trace, one), CacheKeyOf(trace, wider));
  EXPECT_EQ(four.threads(), 4);  // the request itself keeps them
  // Without the neutral field the key is the plain one of the request's bytes.
  EXPECT_EQ(CacheKeyOf(trace, SmallBoxTrace()),
            CacheKey("trace", DeterministicBytes(SmallBoxTrace())));
}

TEST(CacheKey, AnOptimumOnOtherThreadsHasTheSameKey) {
  const JobKindSpec& optimum = *FindKind(v1::OPTIMUM);
  v1::OptimumRequest one, two, other_margin;
  *one.mutable_trace() = SmallBoxTrace();
  one.mutable_trace()->set_threads(1);
  *two.mutable_trace() = SmallBoxTrace();
  two.mutable_trace()->set_threads(2);
  other_margin = one;
  other_margin.add_margin(0.05);
  EXPECT_EQ(CacheKeyOf(optimum, one), CacheKeyOf(optimum, two));
  EXPECT_NE(CacheKeyOf(optimum, one), CacheKeyOf(optimum, other_margin));
  // No trace message at all: nothing to clear, a key all the same.
  EXPECT_EQ(CacheKeyOf(optimum, v1::OptimumRequest()).size(), 64u);
}

// The worker's cache of curves for optimum jobs: a trace on any threads serves an optimum.
TEST(CacheKey, TheOptimumCacheKeysCurvesWithoutThreads) {
  v1::TraceRequest one = SmallBoxTrace(), two = SmallBoxTrace(), wider = SmallBoxTrace();
  one.set_threads(1);
  two.set_threads(2);
  wider.set_max(0, 0.3);
  EXPECT_EQ(OptimumCache::KeyOf(one), OptimumCache::KeyOf(two));
  EXPECT_NE(OptimumCache::KeyOf(one), OptimumCache::KeyOf(wider));
}

TEST(CacheKey, ASweepOnOtherThreadsHasTheSameKeyButNotInOtherChunks) {
  const JobKindSpec& sweep = *FindKind(v1::SWEEP);
  v1::SweepRequest one, two, chunked;
  one.set_param("b");
  one.set_threads(1);
  two = one;
  two.set_threads(2);
  chunked = two;
  chunked.set_chunks(2);  // chunks start afresh: another result
  EXPECT_EQ(CacheKeyOf(sweep, one), CacheKeyOf(sweep, two));
  EXPECT_NE(CacheKeyOf(sweep, two), CacheKeyOf(sweep, chunked));
}

}  // namespace
}  // namespace drillbif::jobs
