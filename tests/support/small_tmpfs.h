// A small tmpfs for tests of a full disk, mounted in a mount namespace private to the test
// process (nothing outside sees it; it vanishes with the process even if the test crashes), and
// a helper that fills a file system. Enter the namespace before any thread starts (gtest runs
// each test in a process of its own under ctest).
#ifndef DRILLBIF_TESTS_SUPPORT_SMALL_TMPFS_H_
#define DRILLBIF_TESTS_SUPPORT_SMALL_TMPFS_H_

#include <fcntl.h>
#include <sched.h>
#include <sys/mount.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <string>

namespace drillbif::testing {

// A small tmpfs mounted at a directory, in a mount namespace private to this test process (so
// that nothing outside sees it and it vanishes with the process, even if the test crashes).
class SmallTmpfs {
 public:
  // Mounts `bytes` of tmpfs at `dir`; error() says why not when it could not.
  SmallTmpfs(const std::string& dir, int64_t bytes) : dir_(dir) {
    const std::string options = "size=" + std::to_string(bytes);
    if (!EnterMountNamespace()) return;
    if (mount("tmpfs", dir.c_str(), "tmpfs", 0, options.c_str()) != 0) {
      error_ = std::string("mount tmpfs: ") + std::strerror(errno);
      return;
    }
    mounted_ = true;
  }
  ~SmallTmpfs() {
    if (mounted_) umount2(dir_.c_str(), MNT_DETACH);
  }
  SmallTmpfs(const SmallTmpfs&) = delete;
  SmallTmpfs& operator=(const SmallTmpfs&) = delete;

  const std::string& error() const { return error_; }

 private:
  // As root: a new mount namespace. Otherwise: a user namespace mapping this user to root in it,
  // with its own mount namespace (what `unshare -Urm` does).
  bool EnterMountNamespace() {
    if (unshare(CLONE_NEWNS) != 0) {
      const uid_t uid = getuid();
      const gid_t gid = getgid();
      if (unshare(CLONE_NEWUSER | CLONE_NEWNS) != 0) {
        error_ = std::string("unshare: ") + std::strerror(errno);
        return false;
      }
      if (!WriteFile("/proc/self/setgroups", "deny") ||
          !WriteFile("/proc/self/uid_map", "0 " + std::to_string(uid) + " 1") ||
          !WriteFile("/proc/self/gid_map", "0 " + std::to_string(gid) + " 1")) {
        error_ = "cannot map the user into its namespace";
        return false;
      }
    }
    // Mounts made here must not propagate to the parent namespace.
    if (mount(nullptr, "/", nullptr, MS_REC | MS_PRIVATE, nullptr) != 0) {
      error_ = std::string("make / private: ") + std::strerror(errno);
      return false;
    }
    return true;
  }
  static bool WriteFile(const char* path, const std::string& text) {
    std::ofstream out(path);
    out << text;
    out.close();
    return static_cast<bool>(out);
  }

  std::string dir_;
  std::string error_;
  bool mounted_ = false;
};

// Writes a file until the file system is full; returns the bytes written.
inline int64_t FillDisk(const std::string& path) {
  const int fd = open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  if (fd < 0) return -1;
  const std::string block(4096, 'f');
  int64_t written = 0;
  for (;;) {
    const ssize_t n = write(fd, block.data(), block.size());
    if (n <= 0) break;
    written += n;
  }
  close(fd);
  return written;
}

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_SMALL_TMPFS_H_
