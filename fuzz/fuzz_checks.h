// What the fuzz targets (fuzz/*_fuzz.cc) share: the invariant check that stops the run, and
// message comparisons that survive a re-encoding.
#ifndef DRILLBIF_FUZZ_FUZZ_CHECKS_H_
#define DRILLBIF_FUZZ_FUZZ_CHECKS_H_

#include <google/protobuf/message.h>
#include <google/protobuf/util/field_comparator.h>
#include <google/protobuf/util/message_differencer.h>

#include <cstdio>
#include <memory>
#include <string>

// Stops the run when `condition` is false: prints what was expected and traps, which libFuzzer
// reports as a crash and saves the input (a violated invariant is a finding like a crash).
#define DRILLBIF_FUZZ_CHECK(condition, what)                                              \
  do {                                                                                    \
    if (!(condition)) {                                                                   \
      std::fprintf(stderr, "invariant violated at %s:%d: %s\n  %s\n", __FILE__, __LINE__, \
                   #condition, std::string(what).c_str());                                \
      __builtin_trap();                                                                   \
    }                                                                                     \
  } while (false)

namespace drillbif::fuzz {

// Whether two messages hold the same values. NaN equals NaN: the JSON mapping writes every NaN
// as "NaN", so a re-encoding keeps NaN-ness, not the payload bits. A field set to its default
// equals an unset one (EQUIVALENT), and -0 equals 0: a proto3 double of -0.0 is serialized (its
// bits are not zero) but protobuf's JSON parser reads "-0" back as an unset +0, the same number.
inline bool SameMessage(const google::protobuf::Message& a, const google::protobuf::Message& b) {
  google::protobuf::util::DefaultFieldComparator comparator;
  comparator.set_treat_nan_as_equal(true);
  google::protobuf::util::MessageDifferencer differencer;
  differencer.set_message_field_comparison(google::protobuf::util::MessageDifferencer::EQUIVALENT);
  differencer.set_field_comparator(&comparator);
  return differencer.Compare(a, b);
}

// `message` without its unknown fields (at any depth): what a JSON re-encoding keeps.
inline std::unique_ptr<google::protobuf::Message> KnownFieldsOf(
    const google::protobuf::Message& message) {
  std::unique_ptr<google::protobuf::Message> copy(message.New());
  copy->CopyFrom(message);
  copy->DiscardUnknownFields();
  return copy;
}

}  // namespace drillbif::fuzz

#endif  // DRILLBIF_FUZZ_FUZZ_CHECKS_H_
