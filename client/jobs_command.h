// `drillctl jobs list|get|watch|cancel|result`: managing the jobs of a drillbif server. Each
// function does the rpcs and returns the text to print (JSON or CSV); the command line wiring is
// in main.cc.
//
// JSON is protobuf's JSON mapping of the API's own messages (google.longrunning.Operation,
// ListOperationsResponse, JobMetadata, the result messages). CSV is one row per job:
//   name,kind,state,progress,points,cache_hit,attempts,create_time,start_time,end_time,error
// (times in RFC 3339, UTC; empty when unset; `error` is "CODE: message" of a job that did not
// succeed, quoted when it holds a comma or a quote).
#ifndef DRILLBIF_CLIENT_JOBS_COMMAND_H_
#define DRILLBIF_CLIENT_JOBS_COMMAND_H_

#include <functional>
#include <string>

#include "client/output.h"
#include "client/remote.h"
#include "drillbif/common/status.h"
#include "drillbif/v1/service.pb.h"
#include "google/longrunning/operations.pb.h"

namespace drillbif::client {

// How drillctl prints: JSON (indented unless compact) or CSV.
struct OutputStyle {
  bool csv = false;
  // JSON indented (false: one line, --compact).
  bool pretty = true;
};

// Flags of `jobs list`.
struct JobsListOptions {
  // Only jobs in this state (QUEUED, RUNNING, SUCCEEDED, FAILED, CANCELLED); empty: any.
  std::string state;
  // Only jobs of this kind (simulate, sweep, continue, trace, optimum); empty: any.
  std::string kind;
  // Jobs per page (the server's default 50 when 0; at most 1000).
  int page_size = 0;
  // next_page_token of the previous page; empty: the first page.
  std::string page_token;
  // Follow next_page_token to the end and print every job (one JSON list, or one table).
  bool all = false;
};

// The ListOperations filter for the options ("state=RUNNING AND kind=sweep"); INVALID_ARGUMENT
// for an unknown state or kind.
StatusOr<std::string> ListFilter(const JobsListOptions& options);

// `jobs list`: one page (JSON: the ListOperationsResponse, with nextPageToken; CSV: the rows and
// a last line "# next_page_token=..." when there are more), or every page with `all` (JSON:
// {"operations": [...]}, CSV: every row).
StatusOr<std::string> JobsList(RemoteClient& client, const JobsListOptions& options,
                               const OutputStyle& style);

// `jobs get ID`: the operation (JSON: with its result when done; CSV: its row).
StatusOr<std::string> JobsGet(RemoteClient& client, const std::string& id,
                              const OutputStyle& style);

// `jobs cancel ID`: cancels the job, then prints the operation as `jobs get` does (its state
// may still be RUNNING for the few ms a running job takes to stop).
StatusOr<std::string> JobsCancel(RemoteClient& client, const std::string& id,
                                 const OutputStyle& style);

// `jobs watch ID`: `write` gets the header (CSV) and then one line per JobMetadata of the Watch
// stream (JSON: one compact object per line; CSV: one row), until the job reaches a final state
// or `interrupted` returns true (CANCELLED; the job is not cancelled). Returns the last
// metadata.
StatusOr<v1::JobMetadata> JobsWatch(RemoteClient& client, const std::string& id,
                                    const OutputStyle& style,
                                    const std::function<void(const std::string&)>& write,
                                    const std::function<bool()>& interrupted);

// What `jobs result` printed: the result's own status ("COMPLETED", "FAILED", ...) and message,
// for the exit code.
struct PrintedResult {
  std::string status;
  std::string message;
};

// `jobs result ID`: writes the result of a SUCCEEDED job to `write` page by page as it arrives
// (ResultPrinter), exactly as the command that ran it prints it with --local. A simulate
// result's CSV table is the one output it holds (Poincare samples, events, modes or trajectory;
// none: only the measures); INVALID_ARGUMENT when it holds more than one (use JSON), found at the
// first page holding items of a second one (the pages before are printed). FAILED_PRECONDITION
// when the job did not succeed (its error is in the message), before anything is written.
StatusOr<PrintedResult> JobsResult(RemoteClient& client, const std::string& id,
                                   const OutputStyle& style, const TextSink& write);

}  // namespace drillbif::client

#endif  // DRILLBIF_CLIENT_JOBS_COMMAND_H_
