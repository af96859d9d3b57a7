// SQL on an SQLite store's file behind the store's back (a connection of its own): what the
// store tests use to read rows the API does not show or to set what the clock would.
#ifndef DRILLBIF_TESTS_SUPPORT_SQLITE_SQL_H_
#define DRILLBIF_TESTS_SUPPORT_SQLITE_SQL_H_

#include <gtest/gtest.h>
#include <sqlite3.h>

#include <cstdint>
#include <string>

namespace drillbif::testing {

// Runs one SQL statement on the file at `path` and returns the first column of the first row as
// an integer (0 if none); an SQLite error is a test failure.
inline int64_t SqliteInt(const std::string& path, const std::string& sql) {
  sqlite3* db = nullptr;
  int64_t value = 0;
  if (sqlite3_open(path.c_str(), &db) == SQLITE_OK) {
    sqlite3_stmt* statement = nullptr;
    if (sqlite3_prepare_v2(db, sql.c_str(), -1, &statement, nullptr) == SQLITE_OK &&
        sqlite3_step(statement) == SQLITE_ROW) {
      value = sqlite3_column_int64(statement, 0);
    }
    sqlite3_finalize(statement);
  }
  EXPECT_EQ(sqlite3_errcode(db), SQLITE_OK) << sql << ": " << sqlite3_errmsg(db);
  sqlite3_close(db);
  return value;
}

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_SQLITE_SQL_H_
