// The JobStore contract tests run on every implementation: a fresh, empty store of each kind
// (an SQLite file in a temporary directory; a database of a throwaway PostgreSQL cluster), any
// number of connections to it (Open), and SQL behind the store's back (ages, row counts).
//
//   class FooTest : public ::testing::TestWithParam<StoreKind> { ... StoreUnderTest store_; };
//   INSTANTIATE_TEST_SUITE_P(Stores, FooTest, ::testing::ValuesIn(kStoreKinds), StoreKindName);
#ifndef DRILLBIF_TESTS_SUPPORT_STORE_UNDER_TEST_H_
#define DRILLBIF_TESTS_SUPPORT_STORE_UNDER_TEST_H_

#include <gtest/gtest.h>

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "server/store/job_store.h"
#include "server/store/postgres_job_store.h"
#include "server/store/sqlite_job_store.h"
#include "support/postgres_cluster.h"
#include "support/sqlite_sql.h"
#include "support/temp_dir.h"

namespace drillbif::testing {

enum class StoreKind { kSqlite, kPostgres };
inline constexpr StoreKind kStoreKinds[] = {StoreKind::kSqlite, StoreKind::kPostgres};

// "sqlite", "postgres": the parameter's part of the test's name.
inline std::string StoreKindName(const ::testing::TestParamInfo<StoreKind>& info) {
  return info.param == StoreKind::kSqlite ? "sqlite" : "postgres";
}

class StoreUnderTest {
 public:
  explicit StoreUnderTest(StoreKind kind) : kind_(kind) {}

  // Prepares the empty store; false (with a test failure saying why) when it cannot.
  bool Create() {
    if (kind_ == StoreKind::kSqlite) {
      dir_.emplace("drillbif_store");
      EXPECT_FALSE(dir_->path().empty()) << "mkdtemp failed";
      return !dir_->path().empty();
    }
    cluster_ = std::make_unique<PostgresCluster>();
    const bool created = cluster_->ok() && cluster_->CreateDatabase(kDatabase);
    EXPECT_TRUE(created) << cluster_->error();
    return created;
  }

  StoreKind kind() const { return kind_; }

  // A new connection to the store (nullptr, with a test failure, when it cannot be opened).
  std::unique_ptr<server::JobStore> Open() {
    StatusOr<std::unique_ptr<server::JobStore>> store =
        kind_ == StoreKind::kSqlite ? server::SqliteJobStore::Open(path())
                                    : server::PostgresJobStore::Open(cluster_->Uri(kDatabase));
    EXPECT_TRUE(store.ok()) << store.status().ToString();
    return store.ok() ? std::move(store).value() : nullptr;
  }

  // The SQLite file (empty for PostgreSQL).
  std::string path() const { return dir_ ? dir_->path() + "/jobs.db" : std::string(); }

  // The first column of the first row of `sql`, run behind the store's back, as an integer (a
  // test failure on an error). The store's tables and columns are the same in both.
  int64_t SqlInt(const std::string& sql) {
    if (kind_ == StoreKind::kPostgres) {
      const std::string value = cluster_->Query(kDatabase, sql);
      EXPECT_FALSE(value.empty()) << sql;
      return value.empty() ? -1 : std::stoll(value);
    }
    return SqliteInt(path(), sql);
  }

 private:
  static constexpr const char* kDatabase = "jobs";
  StoreKind kind_;
  std::optional<TempDir> dir_;
  std::unique_ptr<PostgresCluster> cluster_;
};

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_STORE_UNDER_TEST_H_
