// Formatting of results for drillctl: JSON (protobuf's canonical JSON mapping, lowerCamelCase
// field names, every field printed) and CSV (one table per output, comment lines for scalars).
#ifndef DRILLBIF_CLIENT_OUTPUT_H_
#define DRILLBIF_CLIENT_OUTPUT_H_

#include <google/protobuf/descriptor.h>
#include <google/protobuf/message.h>

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "drillbif/common/status.h"
#include "drillbif/v1/continue.pb.h"
#include "drillbif/v1/optimum.pb.h"
#include "drillbif/v1/simulate.pb.h"
#include "drillbif/v1/sweep.pb.h"
#include "drillbif/v1/trace.pb.h"

namespace drillbif::client {

// A message as JSON with the default (lowerCamelCase) names, enums by name and fields at their
// default values printed too (so that "rop": 0 shows). Indented when `pretty`, else one line.
// '<' and '>' are written as themselves, not as protobuf's \u003c and \u003e. Ends with a
// newline.
StatusOr<std::string> ToJson(const google::protobuf::Message& message, bool pretty);

// The table a simulate CSV holds: a CSV file has one table, so at most one of these outputs may be
// requested with it. Measures (rop, power) come as "# name=value" comment lines before the table.
enum class SimulateTable { kNone, kPoincare, kEvents, kModes, kTrajectory };

// The table for the outputs a request asks for; INVALID_ARGUMENT if they need more than one.
StatusOr<SimulateTable> CsvTableFor(const v1::SimulateRequest::Outputs& outputs);

// Simulate result as CSV: "# rop=..." and "# power=..." when measured ("# status=..." and
// "# message=..." first when the run did not complete), then the table with a header row:
//   kPoincare    period,mode,p,y,q
//   kEvents      period,s,t,surface,guard,from_mode,to_mode,tangential,p,y,q
//   kModes       period,modes            (modes separated by spaces)
//   kTrajectory  t,mode,p,y,q,s
// Numbers are printed in the shortest form that reads back to the same double.
std::string SimulateResultToCsv(const v1::SimulateResult& result, SimulateTable table);

// Sweep result as CSV: "# status=..." lines when the sweep or single values did not complete, then
//   direction,value,period,p,y,q,start
// one row per Poincare sample, the up sweep first; start: how the value was started
// (FROM_INITIAL_STATE, FROM_PREVIOUS_VALUE, FROM_EARLIER_VALUE; SweepPoint.Start).
std::string SweepResultToCsv(const v1::SweepResult& result);

// Continuation result as CSV: "# status=..." lines when it did not complete, then
//   value,rop,power,period,stable,signature_text,mu_abs_max
// one row per branch point in branch order (mu_abs_max: the largest |multiplier|, 0 when all are
// structural zeros), then one comment line per special point in the order found:
//   # FOLD value=0.16715050... rop=... power=... stable=false signature=... [detail=...]
// and at a grazing each side's stability at the end (the point's own stable needs both):
//   ... [stable_before=... mu_abs_max_before=...] [stable_after=... mu_abs_max_after=...]
//   [stability_changes=true]
// (a fold / PD / NS next to a grazing: [near_grazing=... near_grazing_value=...
// near_grazing_distance=...]) and last the width of the interval known to hold the point:
//   ... bracket=...
std::string ContinueResultToCsv(const v1::ContinueResult& result);

// Trace result as CSV: "# status=..." lines when it did not complete, then
//   curve,kind,a,b,omega,xi,g,phi0,rop,stable
// one row per curve point (curve: its index), curves in order, then one comment line per
// codimension-2 point and one per note:
//   # FLIP_GRAZING curve=2 a=... b=... omega=... xi=... g=... phi0=... [detail=...]
// With a stability region, one comment line summarises it (its grid and polygons are in the JSON
// output only).
std::string TraceResultToCsv(const v1::TraceResult& result);

// The optimum as one row (empty margin columns when there is none):
//   a,b,omega,xi,g,phi0,rop,margin1,margin2,distance_scaled,nearest_curve_kind,signature,attractors
// (attractors: how many distinct periodic motions the coexistence check found; 1 when all starts
// settle on the optimum's orbit) after the status comment when it did not complete.
std::string OptimumResultToCsv(const v1::OptimumResult& result);

// How ResultPrinter prints a result.
struct PrintOptions {
  // CSV (the kind's table, as *ResultToCsv prints it) instead of JSON (as ToJson prints it).
  bool csv = false;
  // JSON indented (false: one line, --compact). Ignored for CSV.
  bool pretty = true;
  // The table of a simulate result's CSV (the one its request asked for). Unset: the one table
  // the result holds (`jobs result`, which does not know the request); a result holding more
  // than one is INVALID_ARGUMENT, detected at the page where the second table's items begin.
  std::optional<SimulateTable> simulate_table;
};

// Receives the printed text in order, piece by piece; an error stops the printing.
using TextSink = std::function<Status(std::string_view text)>;

namespace internal {
class PageFormat;
}  // namespace internal

// Prints a result that arrives in pages, writing each page's part of the text as it arrives and
// never holding the whole result: the text is byte for byte what ToJson(result, pretty) or the
// kind's *ResultToCsv prints for the whole result message (for a sweep's CSV, whose failure
// comments precede the table, the rows wait until the last page: in memory up to 1 MiB, the rest
// in an unlinked temporary file in $TMPDIR, else /tmp).
//
// A page is a result message of the kind holding the result's summary fields (status, message,
// counters, special points, ...; the kind's first-page-only fields in the first page only) and
// the next items of the kind's paged fields (jobs/registry.h: JobKindSpec::paged_fields), the
// paged fields' items forming one sequence, fields in their order, that the pages split into
// consecutive runs (GetResult's pages; a whole result is one page).
//
//   ResultPrinter::Create(v1::SweepResult::descriptor(), {.csv = true}, write) -> printer
//   for each page: printer->AddPage(page);
//   printer->Finish();
//
// The summary must come first (JSON prints status and message before the items): a run that
// streams its items before its summary is known would have to keep them until it is.
class ResultPrinter {
 public:
  // A printer of results of `result_type` (one of the five kinds' result messages; else
  // INVALID_ARGUMENT) that writes to `sink`.
  static StatusOr<std::unique_ptr<ResultPrinter>> Create(
      const google::protobuf::Descriptor* result_type, const PrintOptions& options, TextSink sink);
  ~ResultPrinter();
  ResultPrinter(const ResultPrinter&) = delete;
  ResultPrinter& operator=(const ResultPrinter&) = delete;

  // Prints the next page. Takes its items: the page's paged fields are left empty. INTERNAL when
  // the page is of another type, when its summary differs from the first page's, or when it
  // holds items of a paged field after items of a later one were printed; the sink's errors.
  Status AddPage(google::protobuf::Message& page);
  // Prints the rest, after the last page. INTERNAL when no page was added.
  Status Finish();

  // The result's status ("COMPLETED", ...) and message, from the first page (empty before it).
  const std::string& status() const { return status_; }
  const std::string& message() const { return message_; }
  // Pages added, and items of the paged fields printed.
  int64_t pages() const { return pages_; }
  int64_t items() const { return items_; }

 private:
  ResultPrinter(const google::protobuf::Descriptor* result_type,
                std::unique_ptr<internal::PageFormat> format, TextSink sink);
  // Checks a page (its summary, and its items before they are printed); for the first page
  // prints what comes before the items.
  Status StartPage(const google::protobuf::Message& summary,
                   const google::protobuf::Message& items);
  // Prints the items of a page (a result message holding only them), chunk by chunk; takes
  // them.
  Status PrintItems(google::protobuf::Message& items);
  // The page's summary fields (first-page-only fields cleared), serialized deterministically.
  std::string SummaryBytes(const google::protobuf::Message& summary) const;
  // Writes `out` to the sink and clears it.
  Status Flush(std::string* out);

  const google::protobuf::Descriptor* result_type_;
  std::vector<const google::protobuf::FieldDescriptor*> paged_fields_;
  std::vector<const google::protobuf::FieldDescriptor*> first_page_fields_;
  std::unique_ptr<internal::PageFormat> format_;
  TextSink sink_;
  std::string first_summary_;  // SummaryBytes of the first page
  std::string status_;
  std::string message_;
  int current_field_ = 0;  // index in paged_fields_ of the field printed last
  int64_t pages_ = 0;
  int64_t items_ = 0;
  bool finished_ = false;
};

}  // namespace drillbif::client

#endif  // DRILLBIF_CLIENT_OUTPUT_H_
