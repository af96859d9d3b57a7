// A fresh SQLite job store for a test: the file jobs.db in the test's temporary directory.
#ifndef DRILLBIF_TESTS_SUPPORT_SQLITE_STORE_H_
#define DRILLBIF_TESTS_SUPPORT_SQLITE_STORE_H_

#include <gtest/gtest.h>

#include <memory>

#include "server/store/sqlite_job_store.h"
#include "support/temp_dir.h"

namespace drillbif::testing {

// The store in `dir`; null, with a test failure saying why, when the directory was not made or
// the store does not open.
inline std::unique_ptr<server::JobStore> OpenSqliteStore(const TempDir& dir) {
  EXPECT_FALSE(dir.path().empty()) << "mkdtemp failed";
  if (dir.path().empty()) return nullptr;
  StatusOr<std::unique_ptr<server::JobStore>> store =
      server::SqliteJobStore::Open(dir.path() + "/jobs.db");
  EXPECT_TRUE(store.ok()) << store.status().ToString();
  return store.ok() ? std::move(store).value() : nullptr;
}

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_SQLITE_STORE_H_
