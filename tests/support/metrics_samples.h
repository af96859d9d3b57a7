// The samples of a Prometheus text exposition (GET /metrics), for service tests that read a
// gauge or a counter: "name{labels}" -> value, for every line that is a sample (not a comment).
// It checks nothing of the format: metrics_test.cc parses the exposition strictly.
#ifndef DRILLBIF_TESTS_SUPPORT_METRICS_SAMPLES_H_
#define DRILLBIF_TESTS_SUPPORT_METRICS_SAMPLES_H_

#include <map>
#include <sstream>
#include <string>

namespace drillbif::testing {

inline std::map<std::string, double> MetricsSamples(const std::string& text) {
  std::map<std::string, double> samples;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    const size_t space = line.rfind(' ');
    samples[line.substr(0, space)] = std::stod(line.substr(space + 1));
  }
  return samples;
}

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_METRICS_SAMPLES_H_
