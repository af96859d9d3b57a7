// Formatting of results for drillctl: JSON (protobuf's canonical JSON mapping, lowerCamelCase
// field names, every field printed) and CSV (one table per output, comment lines for scalars).
#ifndef DRILLBIF_CLIENT_OUTPUT_H_
#define DRILLBIF_CLIENT_OUTPUT_H_

#include <google/protobuf/message.h>

#include <string>

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
//   direction,value,period,p,y,q
// one row per Poincare sample, the up sweep first.
std::string SweepResultToCsv(const v1::SweepResult& result);

// Continuation result as CSV: "# status=..." lines when it did not complete, then
//   value,rop,power,period,stable,signature_text,mu_abs_max
// one row per branch point in branch order (mu_abs_max: the largest |multiplier|, 0 when all are
// structural zeros), then one comment line per special point in the order found:
//   # FOLD value=0.16715050... rop=... power=... stable=false signature=... [detail=...]
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

}  // namespace drillbif::client

#endif  // DRILLBIF_CLIENT_OUTPUT_H_
