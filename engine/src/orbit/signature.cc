#include "drillbif/orbit/signature.h"

namespace drillbif {

std::string SignatureString(const HybridModel& model, const Signature& signature) {
  std::string out;
  for (const SegmentSpec& s : signature.segments) {
    if (!out.empty()) out += ' ';
    out += model.mode_name(s.mode);
    out += s.guard >= 0 ? (s.tangent ? "~" : ">") + model.guards(s.mode)[s.guard].surface : "|";
  }
  if (signature.periods > 1) out += " x" + std::to_string(signature.periods);
  return out;
}

std::vector<std::string> SignatureModes(const HybridModel& model, const Signature& signature) {
  std::vector<std::string> modes;
  for (const SegmentSpec& s : signature.segments) modes.emplace_back(model.mode_name(s.mode));
  return modes;
}

bool SameUpToSection(const Signature& a, const Signature& b) {
  if (a == b) return true;
  if (a.periods != b.periods || a.segments.size() != b.segments.size()) return false;
  const size_t k = a.segments.size();
  auto cut = [](const Signature& s) { return s.segments.front().mode == s.segments.back().mode; };
  if (!cut(a) || !cut(b)) return false;
  if (k == 1) return a.segments[0].mode == b.segments[0].mode;
  // The cycle: segments 0 .. k-2, each with the event that ends it (the last segment is the
  // first's beginning, cut off by the section).
  const size_t n = k - 1;
  for (size_t shift = 0; shift < n; ++shift) {
    bool same = true;
    for (size_t i = 0; i < n && same; ++i) same = a.segments[i] == b.segments[(i + shift) % n];
    if (same) return true;
  }
  return false;
}

Status ValidateSignature(const HybridModel& model, const Signature& signature) {
  if (signature.periods < 1) return InvalidArgument("signature periods must be >= 1");
  if (signature.segments.empty()) return InvalidArgument("signature has no segment");
  const int k = static_cast<int>(signature.segments.size());
  for (int i = 0; i < k; ++i) {
    const SegmentSpec& s = signature.segments[i];
    if (s.mode < 0 || s.mode >= model.num_modes()) {
      return InvalidArgument("signature segment " + std::to_string(i) + ": no mode " +
                             std::to_string(s.mode));
    }
    const bool last = i == k - 1;
    if (s.tangent && (last || signature.segments[i + 1].mode != s.mode)) {
      return InvalidArgument("signature segment " + std::to_string(i) +
                             ": a tangent end must be followed by a segment in the same mode");
    }
    if (last != (s.guard < 0) || s.guard >= static_cast<int>(model.guards(s.mode).size())) {
      return InvalidArgument("signature segment " + std::to_string(i) +
                             (last ? ": the last segment must end at the section"
                                   : ": must end on a guard of its mode"));
    }
  }
  return Status::Ok();
}

}  // namespace drillbif
