// A throwaway PostgreSQL cluster for tests: a fresh temporary directory holding a copy of an
// initdb'd data directory, a server listening only on a Unix socket in that directory (no TCP
// port to collide with), stopped and removed when the object goes. initdb runs once per machine
// and PostgreSQL version (into a template directory under the system's temp dir, created under
// a file lock so that tests running in parallel wait for one another): copying its ~40 MB costs
// far less than initdb's 0.5 to 1.5 s, and every test starts its own cluster. Run as root (CI
// containers), the cluster's commands run as the postgres user (initdb refuses root). The binaries
// come from DRILLBIF_PG_BINDIR, set by tests/CMakeLists.txt to Debian's
// /usr/lib/postgresql/<version>/bin (scripts/setup.sh installs the postgresql package).
#ifndef DRILLBIF_TESTS_SUPPORT_POSTGRES_CLUSTER_H_
#define DRILLBIF_TESTS_SUPPORT_POSTGRES_CLUSTER_H_

#include <fcntl.h>
#include <pwd.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/file.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <string>
#include <system_error>

namespace drillbif::testing {

#ifndef DRILLBIF_PG_BINDIR
#define DRILLBIF_PG_BINDIR ""
#endif

class PostgresCluster {
 public:
  // The database user the cluster is created for (trust authentication on the socket).
  static constexpr const char* kUser = "drillbif";

  // Starts the cluster; error() says why when it could not (ok() false).
  PostgresCluster() { Start(); }
  ~PostgresCluster() {
    if (started_) Run(Bin("pg_ctl") + " -D " + dir_ + "/data -m fast -w stop");
    std::error_code ignored;
    if (!dir_.empty()) std::filesystem::remove_all(dir_, ignored);
  }
  PostgresCluster(const PostgresCluster&) = delete;
  PostgresCluster& operator=(const PostgresCluster&) = delete;

  bool ok() const { return started_; }
  const std::string& error() const { return error_; }

  // Creates an empty database `name` (a plain identifier); false on failure, with error().
  bool CreateDatabase(const std::string& name) {
    if (!Run(Bin("createdb") + " -h " + dir_ + " -U " + kUser + " " + name)) {
      error_ = "createdb " + name + " failed (" + dir_ + "/log)";
      return false;
    }
    return true;
  }

  // Stops the server as a crash would (immediate shutdown) and starts it again; the data stays.
  bool Stop() { return Run(Bin("pg_ctl") + " -D " + dir_ + "/data -m immediate -w stop"); }
  bool Restart() { return StartServer(); }

  // The URI of database `name`: the socket directory as the host parameter.
  std::string Uri(const std::string& name) const {
    return std::string("postgresql://") + kUser + "@/" + name + "?host=" + dir_;
  }

  // The first column of the first row of `sql` in database `name`, through psql (behind the
  // store's back); "" on failure.
  std::string Query(const std::string& name, const std::string& sql) const {
    const std::string command = Bin("psql") + " -h " + dir_ + " -U " + kUser + " -d " + name +
                                " -tA -v ON_ERROR_STOP=1 -c \"" + sql + "\" 2>>" + dir_ + "/log";
    FILE* pipe = popen(command.c_str(), "r");
    if (pipe == nullptr) return "";
    std::string out;
    char buffer[256];
    while (fgets(buffer, sizeof(buffer), pipe) != nullptr) out += buffer;
    if (pclose(pipe) != 0) return "";
    const size_t end = out.find('\n');
    return end == std::string::npos ? out : out.substr(0, end);
  }

 private:
  static std::string Bin(const char* program) {
    return std::string(DRILLBIF_PG_BINDIR) + "/" + program;
  }

  // Runs a server-side command (as the postgres user when root), its output to the log.
  bool Run(const std::string& command) const {
    const std::string as = geteuid() == 0 ? "runuser -u postgres -- " : "";
    return std::system((as + command + " >>" + dir_ + "/log 2>&1").c_str()) == 0;
  }

  void Start() {
    if (std::string(DRILLBIF_PG_BINDIR).empty() || !std::filesystem::exists(Bin("initdb"))) {
      error_ = "PostgreSQL's initdb not found (DRILLBIF_PG_BINDIR '" +
               std::string(DRILLBIF_PG_BINDIR) + "'): run scripts/setup.sh";
      return;
    }
    std::string pattern = BaseDir() + "/drillbif_pg_XXXXXX";
    if (mkdtemp(pattern.data()) == nullptr) {
      error_ = "mkdtemp failed";
      return;
    }
    dir_ = pattern;
    if (geteuid() == 0) {
      const passwd* postgres = getpwnam("postgres");
      if (postgres == nullptr || chown(dir_.c_str(), postgres->pw_uid, postgres->pw_gid) != 0) {
        error_ = "running as root and cannot hand " + dir_ + " to the postgres user";
        return;
      }
    }
    const std::string data_template = Template();
    if (data_template.empty()) return;
    if (std::system(("cp -a " + data_template + " " + dir_ + "/data").c_str()) != 0) {
      error_ = "cannot copy " + data_template + " to " + dir_;
      return;
    }
    started_ = StartServer();
  }

  bool StartServer() {
    if (Run(Bin("pg_ctl") + " -D " + dir_ + "/data -l " + dir_ +
            "/server.log -w -t 60 -o \"-c listen_addresses='' -c unix_socket_directories=" + dir_ +
            " -c fsync=off -c full_page_writes=off -c dynamic_shared_memory_type=mmap\" start")) {
      return true;
    }
    error_ = "pg_ctl start failed (" + dir_ + "/server.log)";
    return false;
  }

  // Where clusters live: /dev/shm when it has room (copying the template's ~1000 files to the
  // disk costs ~0.9 s of system time measured, to memory 0.06 s), else the system's temp dir.
  static std::string BaseDir() {
    struct statvfs fs;
    if (statvfs("/dev/shm", &fs) == 0 &&
        static_cast<double>(fs.f_bavail) * static_cast<double>(fs.f_frsize) > 1e9) {
      return "/dev/shm";
    }
    return std::filesystem::temp_directory_path().string();
  }

  // The initdb'd data directory every cluster copies, made by the first test that needs it;
  // "" (with error_) when it cannot be made.
  std::string Template() {
    std::string name = DRILLBIF_PG_BINDIR;
    for (char& c : name) c = c == '/' ? '_' : c;
    const std::string path = BaseDir() + "/drillbif_pg_template" + name;
    const int lock = open((path + ".lock").c_str(), O_CREAT | O_RDWR | O_CLOEXEC, 0600);
    if (lock < 0 || flock(lock, LOCK_EX) != 0) {
      error_ = "cannot lock " + path + ".lock";
      if (lock >= 0) close(lock);
      return "";
    }
    if (!std::filesystem::exists(path + "/PG_VERSION")) {
      std::error_code ignored;
      std::filesystem::remove_all(path, ignored);
      std::filesystem::remove_all(path + ".new", ignored);
      // No fsync: the clusters live as long as a test; a crash loses nothing worth keeping.
      if (!Run(Bin("initdb") + " -D " + path + ".new -A trust -U " + kUser +
               " -E UTF8 --no-sync --wal-segsize=1") ||
          std::rename((path + ".new").c_str(), path.c_str()) != 0) {
        error_ = "initdb failed (" + dir_ + "/log)";
      }
    }
    close(lock);
    return error_.empty() ? path : "";
  }

  std::string dir_;
  std::string error_;
  bool started_ = false;
};

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_POSTGRES_CLUSTER_H_
