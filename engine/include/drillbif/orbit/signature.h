// Signature of a periodic orbit of a hybrid model: the sequence of modes it visits from the
// Poincare section s = 0 and the guard that ends each segment, over n forcing periods. The last
// segment ends at the section s = 2 pi n (guard -1), not at an event.
//
// Example, the drifting oscillator's reference orbit (MODEL.md), period 1:
//   NC -impact-> CwoP -progression-> CwP -stick-> CwoP -separation-> NC -section
#ifndef DRILLBIF_ORBIT_SIGNATURE_H_
#define DRILLBIF_ORBIT_SIGNATURE_H_

#include <string>
#include <vector>

#include "drillbif/model/hybrid_model.h"

namespace drillbif {

struct SegmentSpec {
  int mode = 0;
  int guard = -1;  // guard of `mode` that ends the segment; -1: the segment ends at the section
  // The segment ends where its guard touches zero tangentially (h = 0, h' = 0) and the flow goes
  // on in the same mode (no jump): the touching point of a grazing orbit, used to follow grazing
  // curves in two parameters (h' = 0 is then the curve's defining condition).
  bool tangent = false;
  bool operator==(const SegmentSpec& o) const {
    return mode == o.mode && guard == o.guard && tangent == o.tangent;
  }
};

struct Signature {
  int periods = 1;                    // n: forcing periods of the orbit
  std::vector<SegmentSpec> segments;  // at least one; only the last has guard -1
  bool operator==(const Signature& o) const {
    return periods == o.periods && segments == o.segments;
  }
};

// "NC>Pi CwoP>l1 CwP>l1 CwoP>l2 NC|" (mode, then the surface that ends it; | the section).
std::string SignatureString(const HybridModel& model, const Signature& signature);
// The modes of the segments, in order ("NC", "CwoP", ...).
std::vector<std::string> SignatureModes(const HybridModel& model, const Signature& signature);
// Whether two signatures describe one cyclic sequence of segments and differ only in where the
// Poincare section s = 0 cuts it (where an event crosses the section the signature rotates:
// "NC>Pi CwoP>l2 NC|" and "CwoP>l2 NC>Pi CwoP|"). The segment the section cuts is the first and
// the last, of one mode; a signature whose last and first modes differ matches itself only.
bool SameUpToSection(const Signature& a, const Signature& b);

// INVALID_ARGUMENT unless the signature is well formed for the model (mode and guard indices,
// only the last segment ending at the section, periods >= 1).
Status ValidateSignature(const HybridModel& model, const Signature& signature);

}  // namespace drillbif

#endif  // DRILLBIF_ORBIT_SIGNATURE_H_
