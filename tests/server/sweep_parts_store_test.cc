// StoreSweepParts on a SQLite store, without a server: a sweep's pieces stored as children and
// run by the parent itself give the local run's result; a run of the sweep again (requeued and
// claimed anew) resumes the pieces the earlier run finished instead of running them again; a
// piece whose run fails fails the sweep with its error.
#include <gtest/gtest.h>

#include <optional>
#include <string>

#include "jobs/registry.h"
#include "jobs/request_bytes.h"
#include "jobs/sweep_job.h"
#include "server/sweep_fan_out.h"
#include "support/claimed_parent.h"
#include "support/small_requests.h"
#include "support/sqlite_store.h"
#include "support/temp_dir.h"

namespace drillbif::server {
namespace {

class SweepPartsStore : public ::testing::Test {
 protected:
  void SetUp() override {
    store_ = drillbif::testing::OpenSqliteStore(dir_);
    ASSERT_NE(store_, nullptr);
    // Two chunks a direction: four pieces.
    request_ = drillbif::testing::SmallSweep(0.08, 6);
    request_.set_direction(v1::SweepRequest::BOTH);
    request_.set_transient_periods(30);
    request_.set_sample_periods(3);
    request_.set_chunks(2);
    std::optional<JobRecord> parent =
        drillbif::testing::SubmitAndClaim(*store_, "sweep", request_, "parent");
    ASSERT_TRUE(parent.has_value());
    parent_ = *parent;
  }

  void Claim() {
    StatusOr<std::optional<JobRecord>> claimed = store_->ClaimNext("parent");
    ASSERT_TRUE(claimed.ok() && claimed->has_value());
    parent_ = **claimed;
  }

  // Runs a claimed child as a worker does and records its outcome.
  bool RunChild(const JobRecord& child) {
    ++ran_;
    const jobs::JobKindSpec* kind = jobs::FindChildKind(child.kind);
    EXPECT_NE(kind, nullptr) << child.kind;
    StatusOr<jobs::JobOutput> out = jobs::RunJob(*kind, child.request, {});
    if (!out.ok()) return false;
    return store_->Complete(child.id, child.run, jobs::DeterministicBytes(*out->result), 0).ok();
  }

  StatusOr<v1::SweepResult> Fanned(StoreSweepParts& parts) {
    return jobs::RunSweep(request_, {.sweep_parts = &parts});
  }

  // Everything but the wall time equals the local run's, bit for bit (serialized bytes).
  void ExpectLocal(v1::SweepResult fanned) {
    StatusOr<v1::SweepResult> local = jobs::RunSweep(request_);
    ASSERT_TRUE(local.ok());
    fanned.clear_wall_seconds();
    local->clear_wall_seconds();
    EXPECT_EQ(fanned.up_size(), 6);
    EXPECT_EQ(jobs::DeterministicBytes(fanned), jobs::DeterministicBytes(*local));
  }

  drillbif::testing::TempDir dir_{"drillbif_sweep_parts"};
  std::unique_ptr<JobStore> store_;
  v1::SweepRequest request_;
  JobRecord parent_;
  int ran_ = 0;
};

TEST_F(SweepPartsStore, ARunAgainResumesThePiecesTheEarlierRunFinished) {
  {
    StoreSweepParts first(*store_, parent_, "parent", 0,
                          [&](const JobRecord& child) { return RunChild(child); }, {});
    StatusOr<v1::SweepResult> fanned = Fanned(first);
    ASSERT_TRUE(fanned.ok()) << fanned.status().ToString();
    ExpectLocal(*fanned);
    EXPECT_EQ(first.stored(), 4);
    EXPECT_EQ(first.run_here(), 4);  // nobody else takes them
    EXPECT_EQ(first.resumed(), 0);
    EXPECT_EQ(ran_, 4);
  }
  // The sweep's worker stopped before recording its result: the sweep runs again.
  ASSERT_TRUE(store_->Requeue(parent_.id, parent_.run).ok());
  Claim();
  StoreSweepParts second(*store_, parent_, "parent", 0,
                         [&](const JobRecord& child) { return RunChild(child); }, {});
  StatusOr<v1::SweepResult> again = Fanned(second);
  ASSERT_TRUE(again.ok()) << again.status().ToString();
  ExpectLocal(*again);
  EXPECT_EQ(second.resumed(), 4);
  EXPECT_EQ(second.stored(), 0);
  EXPECT_EQ(ran_, 4) << "no piece ran twice";
}

TEST_F(SweepPartsStore, APieceThatFailsFailsTheSweepWithItsError) {
  StoreSweepParts parts(
      *store_, parent_, "parent", 0,
      [&](const JobRecord& child) {
        EXPECT_TRUE(
            store_->Fail(child.id, child.run, StatusCode::kInternal, "injected failure").ok());
        return false;
      },
      {});
  StatusOr<v1::SweepResult> fanned = Fanned(parts);
  ASSERT_FALSE(fanned.ok());
  EXPECT_EQ(fanned.status().code(), StatusCode::kInternal);
  EXPECT_NE(fanned.status().message().find("injected failure"), std::string::npos)
      << fanned.status().message();
  EXPECT_NE(fanned.status().message().find("sweep_part"), std::string::npos)
      << fanned.status().message();
}

}  // namespace
}  // namespace drillbif::server
