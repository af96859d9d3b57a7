// "Every core": the thread count that options asking for 0 threads mean.
#ifndef DRILLBIF_COMMON_THREADS_H_
#define DRILLBIF_COMMON_THREADS_H_

#include <algorithm>
#include <thread>

namespace drillbif {

// The cores of this machine (std::thread::hardware_concurrency), at least 1 where it is unknown.
inline int Cores() { return static_cast<int>(std::max(1u, std::thread::hardware_concurrency())); }

// `threads` when positive, else every core.
inline int ThreadsOrCores(int threads) { return threads > 0 ? threads : Cores(); }

}  // namespace drillbif

#endif  // DRILLBIF_COMMON_THREADS_H_
