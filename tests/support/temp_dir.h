// A fresh directory under GoogleTest's temp dir, removed with everything in it when destroyed
// (tests that need real files: SQLite stores, server processes).
#ifndef DRILLBIF_TESTS_SUPPORT_TEMP_DIR_H_
#define DRILLBIF_TESTS_SUPPORT_TEMP_DIR_H_

#include <gtest/gtest.h>
#include <stdlib.h>

#include <filesystem>
#include <string>
#include <system_error>

namespace drillbif::testing {

class TempDir {
 public:
  // `prefix` names the directory (prefix_XXXXXX); path() is empty when mkdtemp failed.
  explicit TempDir(const std::string& prefix) {
    std::string pattern = ::testing::TempDir() + prefix + "_XXXXXX";
    path_ = mkdtemp(pattern.data()) != nullptr ? pattern : std::string();
  }
  ~TempDir() {
    std::error_code ignored;
    if (!path_.empty()) std::filesystem::remove_all(path_, ignored);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_TEMP_DIR_H_
