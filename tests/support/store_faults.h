// Helpers of the store-fault tests (the store alone and through a server): the rule that no SQL
// reaches a client, a file's size, and corruption of a database file's pages behind the back of
// the connections that have it open.
#ifndef DRILLBIF_TESTS_SUPPORT_STORE_FAULTS_H_
#define DRILLBIF_TESTS_SUPPORT_STORE_FAULTS_H_

#include <fcntl.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <random>
#include <string>

namespace drillbif::testing {

// Expects none of the words that would betray SQL (or SQLite's own wording) in a message meant
// for clients.
inline void ExpectNoSql(const std::string& message) {
  for (const char* word : {"SELECT", "INSERT", "UPDATE", "DELETE", "BEGIN", "PRAGMA", "sqlite",
                           "SQLite", "result_chunks", "jobs", "malformed", "locked"}) {
    EXPECT_THAT(message, ::testing::Not(::testing::HasSubstr(word))) << message;
  }
}

// The size of a file in bytes; -1 when it does not exist.
inline int64_t FileSize(const std::string& path) {
  std::error_code error;
  const auto size = std::filesystem::file_size(path, error);
  return error ? -1 : static_cast<int64_t>(size);
}

// Overwrites pages [first, first + count) of the file with pseudo-random bytes (fixed seed),
// behind the back of any connection that has it open.
inline void OverwritePages(const std::string& path, int64_t page_size, int64_t first,
                           int64_t count) {
  std::mt19937 random(12345);
  std::string garbage(static_cast<size_t>(page_size * count), '\0');
  for (char& c : garbage) c = static_cast<char>(random());
  const int fd = open(path.c_str(), O_WRONLY);
  ASSERT_GE(fd, 0) << std::strerror(errno);
  ASSERT_EQ(pwrite(fd, garbage.data(), garbage.size(), first * page_size),
            static_cast<ssize_t>(garbage.size()));
  ASSERT_EQ(fsync(fd), 0);
  close(fd);
}

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_STORE_FAULTS_H_
