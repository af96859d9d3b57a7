// The dashboard's files (web/), embedded in the binary at build time by web/embed_files.cmake:
// the generated source defines kDashboardFiles (library drillbif_dashboard_files). Served by
// server/dashboard.h.
#ifndef DRILLBIF_SERVER_DASHBOARD_FILES_H_
#define DRILLBIF_SERVER_DASHBOARD_FILES_H_

#include <cstddef>

namespace drillbif::server {

// One served file.
struct DashboardFile {
  // The URL path it is served at ("/index.html", "/vendor/chart.umd.min.js").
  const char* path;
  // Its bytes (followed by one 0 byte, not counted).
  const unsigned char* data;
  // Bytes.
  std::size_t size;
};

// Every file of the dashboard, and how many.
extern const DashboardFile kDashboardFiles[];
extern const int kDashboardFileCount;

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_DASHBOARD_FILES_H_
