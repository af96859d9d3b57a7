#include "region/region_boundary.h"

#include <Eigen/Core>
#include <array>
#include <cmath>
#include <cstdint>
#include <unordered_map>
#include <utility>

namespace drillbif::internal {
namespace {

// The cell's corners in counterclockwise order from its lower left, and its edges: edge k joins
// corner k and corner k + 1 (mod 4). Unit-square positions orient the pieces.
constexpr std::array<std::array<int, 2>, 4> kCorner = {{{0, 0}, {1, 0}, {1, 1}, {0, 1}}};
constexpr std::array<std::array<double, 2>, 4> kEdgeMid = {
    {{0.5, 0}, {1, 0.5}, {0.5, 1}, {0, 0.5}}};

struct Crossing {
  RegionVertex vertex;
  double curve_position = 0.0;
};

class Marcher {
 public:
  Marcher(const RegionGrid& grid, int label, const CrossingFunction& crossing,
          const std::vector<RegionCurve>& curves)
      : g_(grid), label_(label), crossing_(crossing), curves_(curves) {}

  std::vector<RegionPolygon> Run() {
    // Oriented pieces, inside on their left, keyed by the edge they start from.
    for (int j = -1; j < g_.n2; ++j) {
      for (int i = -1; i < g_.n1; ++i) AddCell(i, j);
    }
    std::vector<RegionPolygon> rings;
    while (!next_.empty()) {
      const int64_t first = next_.begin()->first;
      std::vector<const Crossing*> ring;
      int64_t key = first;
      do {
        ring.push_back(&CrossingAt(key));
        auto it = next_.find(key);
        const int64_t to = it->second;
        next_.erase(it);
        key = to;
      } while (key != first && next_.count(key) != 0);
      rings.push_back(Follow(ring));
      rings.back().signature = label_;
    }
    return rings;
  }

 private:
  bool In(int i, int j) const {
    return i >= 0 && j >= 0 && i < g_.n1 && j < g_.n2 && g_.label[g_.Index(i, j)] == label_;
  }

  // Edge k of cell (i, j) as a key: its lower-left node and direction (0 along param1).
  int64_t EdgeKey(int i, int j, int k) const {
    const int di = k == 1 ? 1 : 0, dj = k == 2 ? 1 : 0, dir = (k == 1 || k == 3) ? 1 : 0;
    const int64_t node = static_cast<int64_t>(i + di + 1) +
                         static_cast<int64_t>(g_.n1 + 2) * static_cast<int64_t>(j + dj + 1);
    return 2 * node + dir;
  }

  void AddCell(int i, int j) {
    std::array<bool, 4> in;
    for (int c = 0; c < 4; ++c) in[c] = In(i + kCorner[c][0], j + kCorner[c][1]);
    std::array<int, 4> crossed;
    int n = 0;
    for (int k = 0; k < 4; ++k) {
      if (in[k] != in[(k + 1) % 4]) crossed[n++] = k;
    }
    if (n == 2) {
      Eigen::Vector2d centroid(0, 0);
      int count = 0;
      for (int c = 0; c < 4; ++c) {
        if (in[c]) centroid += Eigen::Vector2d(kCorner[c][0], kCorner[c][1]), ++count;
      }
      AddPiece(i, j, crossed[0], crossed[1], centroid / count);
    } else if (n == 4) {
      // Saddle: the two inside corners stay separate; each joins its own two edges.
      for (int c = 0; c < 4; ++c) {
        if (in[c]) AddPiece(i, j, (c + 3) % 4, c, Eigen::Vector2d(kCorner[c][0], kCorner[c][1]));
      }
    }
  }

  // The piece between edges ka and kb of cell (i, j), oriented with `inside` on its left.
  void AddPiece(int i, int j, int ka, int kb, const Eigen::Vector2d& inside) {
    const Eigen::Vector2d a(kEdgeMid[ka][0], kEdgeMid[ka][1]), b(kEdgeMid[kb][0], kEdgeMid[kb][1]);
    const Eigen::Vector2d d = b - a, v = inside - a;
    if (d[0] * v[1] - d[1] * v[0] < 0) std::swap(ka, kb);
    const int64_t from = EdgeKey(i, j, ka), to = EdgeKey(i, j, kb);
    next_[from] = to;
    for (int k : {ka, kb}) {
      const int64_t key = EdgeKey(i, j, k);
      if (crossings_.count(key) != 0) continue;
      const int ci = i + kCorner[k][0], cj = j + kCorner[k][1];
      const int di = i + kCorner[(k + 1) % 4][0], dj = j + kCorner[(k + 1) % 4][1];
      crossings_[key] = In(ci, cj) ? Locate(ci, cj, di, dj) : Locate(di, dj, ci, cj);
    }
  }

  // Edge from inside node (i, j) to outside node (k, l).
  Crossing Locate(int i, int j, int k, int l) const {
    Crossing c;
    if (k < 0 || l < 0 || k >= g_.n1 || l >= g_.n2) {  // beyond the box: the box edge
      c.vertex = {g_.values1[i], g_.values2[j], RegionVertex::kBox};
      return c;
    }
    const EdgeCrossing e = crossing_(g_.Index(i, j), g_.Index(k, l));
    c.vertex = {e.value1, e.value2, e.curve};
    c.curve_position = e.curve_position;
    return c;
  }

  const Crossing& CrossingAt(int64_t key) const { return crossings_.at(key); }

  // The ring's vertices, with the curve's own vertices inserted between two crossings of one curve
  // when they stay within a few grid cells of the pair (so a curve that wanders off between them,
  // e.g. around a loop, is not followed).
  RegionPolygon Follow(const std::vector<const Crossing*>& ring) const {
    RegionPolygon out;
    const double h1 = (g_.values1.back() - g_.values1.front()) / std::max(g_.n1 - 1, 1);
    const double h2 = (g_.values2.back() - g_.values2.front()) / std::max(g_.n2 - 1, 1);
    const size_t n = ring.size();
    for (size_t k = 0; k < n; ++k) {
      const Crossing& a = *ring[k];
      const Crossing& b = *ring[(k + 1) % n];
      out.vertices.push_back(a.vertex);
      if (a.vertex.curve < 0 || a.vertex.curve != b.vertex.curve) continue;
      const RegionCurve& c = curves_[a.vertex.curve];
      const double sa = a.curve_position, sb = b.curve_position;
      if (std::abs(sb - sa) > 64) continue;
      std::vector<RegionVertex> between;
      bool near = true;
      const int step = sb > sa ? 1 : -1;
      for (int m = sb > sa ? static_cast<int>(std::floor(sa)) + 1
                           : static_cast<int>(std::ceil(sa)) - 1;
           step * (m - sb) < 0; m += step) {
        const double x = c.values1[m], y = c.values2[m];
        // Within two cells (in each parameter) of the nearer end of the chord.
        const bool close =
            (std::abs(x - a.vertex.value1) <= 2 * h1 && std::abs(y - a.vertex.value2) <= 2 * h2) ||
            (std::abs(x - b.vertex.value1) <= 2 * h1 && std::abs(y - b.vertex.value2) <= 2 * h2);
        if (!close) {
          near = false;
          break;
        }
        between.push_back({x, y, a.vertex.curve});
      }
      if (near) out.vertices.insert(out.vertices.end(), between.begin(), between.end());
    }
    return out;
  }

  const RegionGrid& g_;
  int label_;
  const CrossingFunction& crossing_;
  const std::vector<RegionCurve>& curves_;
  std::unordered_map<int64_t, int64_t> next_;
  std::unordered_map<int64_t, Crossing> crossings_;
};

}  // namespace

std::vector<RegionPolygon> TraceBoundary(const RegionGrid& grid, int label,
                                         const CrossingFunction& crossing,
                                         const std::vector<RegionCurve>& curves) {
  return Marcher(grid, label, crossing, curves).Run();
}

}  // namespace drillbif::internal
