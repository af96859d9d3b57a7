// drillctl: the command line client. Flags become a request proto, which is run either in this
// process by the job runner (--local) or as a job of a drillbif server (--server HOST:PORT, else
// DRILLBIF_SERVER, else localhost:50051; plaintext, or TLS with --tls / --tls-ca;
// client/remote.h), and the result proto is printed as JSON or CSV, the same in both modes: a
// server's result page by page as it arrives (client/output.h, ResultPrinter). `drillctl jobs
// ...` manages the server's jobs (client/jobs_command.h).
//
// Exit codes: 0 completed; 1 the run failed (the partial result is still printed) or the server
// could not be reached; 2 invalid input (bad flags or parameter values, a token the server
// refuses), nothing run; 130 interrupted (Ctrl-C), partial result printed.
#include <grpc/support/log.h>

#include <CLI/CLI.hpp>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <string_view>
#include <variant>

#include "client/jobs_command.h"
#include "client/output.h"
#include "client/plot.h"
#include "client/progress_bar.h"
#include "client/remote.h"
#include "drillbif/continuation/continuation.h"
#include "drillbif/flow/cvode_propagator.h"
#include "drillbif/model/drifting_oscillator.h"
#include "drillbif/region/robust_optimum.h"
#include "drillbif/simulate/simulator.h"
#include "drillbif/simulate/sweep.h"
#include "drillbif/version.h"
#include "jobs/continue_job.h"
#include "jobs/registry.h"
#include "jobs/result_pages.h"
#include "jobs/simulate_job.h"

namespace drillbif::client {
namespace {

constexpr int kExitFailed = 1;
constexpr int kExitUsage = 2;
constexpr int kExitInterrupted = 130;

// Set by SIGINT; read by the progress callbacks and, in server mode, by the thread that cancels a
// Watch stream. A lock-free atomic is safe to store from a signal handler.
std::atomic<bool> g_interrupted = false;
static_assert(std::atomic<bool>::is_always_lock_free);

extern "C" void OnInterrupt(int) { g_interrupted = true; }

bool Interrupted() { return g_interrupted.load(); }

// gRPC logs some transport errors on stderr itself (e.g. "Handshake failed with fatal error ..."
// for a TLS certificate it cannot verify); drillctl reports every rpc's error in its own words,
// so these lines are dropped unless GRPC_VERBOSITY is set (to see them when diagnosing).
extern "C" void DropGrpcLog(gpr_log_func_args*) {}

// Ctrl-C cancels the run through the progress callback (the partial result is printed; in server
// mode the job is cancelled on the server); a second Ctrl-C kills the process (SA_RESETHAND
// restores the default action).
void InstallInterruptHandler() {
  struct sigaction action {};
  action.sa_handler = OnInterrupt;
  action.sa_flags = SA_RESETHAND;
  sigemptyset(&action.sa_mask);
  sigaction(SIGINT, &action, nullptr);
}

int Error(const std::string& message, int code) {
  std::cerr << "drillctl: " << message << "\n";
  return code;
}

// Invalid input of any kind exits 2, and so does a token the server refuses (nothing ran);
// anything else (internal errors, an unreachable server) exits 1.
int ErrorStatus(const Status& status) {
  switch (status.code()) {
    case StatusCode::kInvalidArgument:
    case StatusCode::kNotFound:
    case StatusCode::kOutOfRange:
    case StatusCode::kFailedPrecondition:
    case StatusCode::kUnimplemented:
      return Error("invalid input: " + status.message(), kExitUsage);
    case StatusCode::kUnauthenticated:
      return Error(status.message(), kExitUsage);
    default:
      return Error(status.ToString(), kExitFailed);
  }
}

struct GlobalFlags {
  bool local = false;
  std::string format = "json";
  std::string output;  // empty: stdout
  bool compact = false;
  // Server mode (without --local).
  std::string server;  // empty: DRILLBIF_SERVER, else localhost:50051
  std::string token;   // empty: DRILLBIF_TOKEN, else none
  bool detach = false;
  double timeout = RemoteOptions().rpc_timeout_seconds;
  bool tls = false;
  std::string tls_ca;  // empty: DRILLBIF_TLS_CA, else the system's roots (with --tls)
  int result_page_size = RemoteOptions().result_page_size;  // hidden --result-page-size
};

struct ModelFlags {
  // Defaults: the engine's reference values (MODEL.md).
  Params reference = DriftingOscillator::MakeParams();
  double a = reference[DriftingOscillator::kA];
  double b = reference[DriftingOscillator::kB];
  double omega = reference[DriftingOscillator::kOmega];
  double xi = reference[DriftingOscillator::kXi];
  double g = reference[DriftingOscillator::kG];
  double phi0 = reference[DriftingOscillator::kPhi0];
  // Initial state.
  double p0 = 0.0, y0 = 0.0, q0 = 0.0, s0 = 0.0;
  int transient = SimulationOptions().transient_periods;
  int samples = SimulationOptions().sample_periods;
};

struct SimulateFlags {
  bool measures = false, poincare = false, events = false, modes = false;
  double trajectory_dt = 0.0;
  std::string propagator = "exact";
  double rtol = CvodeOptions().rtol;
  std::vector<CLI::Option*> output_options;
  CLI::Option* rtol_option = nullptr;
};

struct SweepFlags {
  std::string param;
  double min = 0.0, max = 0.0;
  int steps = SweepOptions().steps;
  std::string direction = "up";
  int threads = 0;
  int chunks = 1;
};

struct ContinueFlags {
  std::string param;
  double min = 0.0, max = 0.0;
  std::string direction = "both";
  ContinuationOptions defaults;
  double initial_step = defaults.steps.initial_step;
  double min_step = defaults.steps.min_step;
  double max_step = defaults.steps.max_step;
  int max_steps = defaults.steps.max_steps;
  int target_iterations = defaults.steps.target_iterations;
  double locate_tolerance = defaults.locate_tolerance;
  bool no_switch = false;
  std::vector<std::string> stop_at;
  bool follow_pd = false;
};

struct TraceFlags {
  std::vector<std::string> params;
  std::vector<double> min, max;
  bool region = false;
  std::vector<int> grid;  // empty: the job's default
  bool period2 = false;
  int max_period = 0;         // 0: not given
  std::string curve_steps;    // "": not given
  std::vector<double> seeds;  // values of the first parameter
  bool no_edge_branches = false;
  int threads = 0;  // 0: every core
};

struct OptimumFlags {
  std::vector<double> margin = OptimumOptions().margin;
  bool scaled = false;
  bool no_maps = false;         // server mode: never answer from an optimum map
  bool compute_on_map = false;  // a map's answer that fails verification: compute instead
};

// optimum-map: the conditions and their cells.
struct MapFlags {
  std::vector<std::string> over;
  std::vector<double> from, to;
  std::vector<int> steps;
};

// Accepts finite numbers > 0.
CLI::Validator PositiveDouble() {
  return CLI::Validator(
      [](std::string& text) -> std::string {
        double v = 0.0;
        if (!CLI::detail::lexical_cast(text, v) || !(v > 0.0) || !std::isfinite(v)) {
          return "must be a number > 0, got " + text;
        }
        return {};
      },
      "POSITIVE");
}

void AddModelFlags(CLI::App* cmd, ModelFlags* m) {
  const std::string g = "Model (dimensionless)";
  cmd->add_option("--a", m->a, "Forcing amplitude, >= 0")->group(g)->capture_default_str();
  cmd->add_option("--b", m->b, "Static force (weight on bit), >= 0")
      ->group(g)
      ->capture_default_str();
  cmd->add_option("--omega", m->omega, "Forcing frequency, > 0")->group(g)->capture_default_str();
  cmd->add_option("--xi", m->xi, "Damping ratio of the slider, > 0")
      ->group(g)
      ->capture_default_str();
  cmd->add_option("--g", m->g, "Gap between bit and slider, > 0")->group(g)->capture_default_str();
  cmd->add_option("--phi0", m->phi0, "Forcing phase (radians)")->group(g)->capture_default_str();
  const std::string s = "Initial state";
  cmd->add_option("--p0", m->p0, "Bit position")->group(s)->capture_default_str();
  cmd->add_option("--y0", m->y0, "Bit velocity")->group(s)->capture_default_str();
  cmd->add_option("--q0", m->q0, "Slider-top position, in [0, 1]")->group(s)->capture_default_str();
  cmd->add_option("--s0", m->s0, "Forcing phase (radians)")->group(s)->capture_default_str();
}

// --transient and --samples of a simulation (simulate, sweep).
void AddRunFlags(CLI::App* cmd, ModelFlags* m) {
  const std::string r = "Run";
  cmd->add_option("--transient", m->transient, "Forcing periods discarded first")
      ->group(r)
      ->check(CLI::Range(0, std::numeric_limits<int>::max()))
      ->capture_default_str();
  cmd->add_option("--samples", m->samples, "Forcing periods sampled (Poincare section s = 0)")
      ->group(r)
      ->check(CLI::Range(1, std::numeric_limits<int>::max()))
      ->capture_default_str();
}

// For the commands that look for a start orbit (continue, trace).
void AddStartOrbitFlags(CLI::App* cmd, ModelFlags* m) {
  cmd->add_option("--transient", m->transient,
                  "Forcing periods simulated before the start orbit is looked for")
      ->group("Start orbit")
      ->check(CLI::Range(0, std::numeric_limits<int>::max()))
      ->capture_default_str();
}

v1::ModelParams ToProtoParams(const ModelFlags& m) {
  v1::ModelParams p;
  p.set_a(m.a);
  p.set_b(m.b);
  p.set_omega(m.omega);
  p.set_xi(m.xi);
  p.set_g(m.g);
  p.set_phi0(m.phi0);
  return p;
}

v1::State ToProtoState(const ModelFlags& m) {
  v1::State s;
  s.set_p(m.p0);
  s.set_y(m.y0);
  s.set_q(m.q0);
  s.set_s(m.s0);
  return s;
}

// Writes the text to --output (or stdout). False, with a message on stderr, if writing failed.
bool Write(const GlobalFlags& flags, const std::string& text) {
  if (flags.output.empty()) {
    std::cout << text << std::flush;
    if (std::cout) return true;
    Error("cannot write the result to stdout", kExitFailed);
    return false;
  }
  std::ofstream file(flags.output, std::ios::binary | std::ios::trunc);
  file << text;
  file.close();
  if (file) return true;
  Error("cannot write the result to " + flags.output + ": " + std::strerror(errno), kExitFailed);
  return false;
}

// Where a result goes as it is printed: --output (created or truncated at the first write, so
// that a run that fails before printing leaves it alone) or stdout.
class OutputStream {
 public:
  explicit OutputStream(const std::string& path) : path_(path) {}

  // Writes `text` (flushed, so that each page shows as it arrives).
  Status Write(std::string_view text) {
    if (!error_.empty()) return Internal(error_);
    std::ostream* out = &std::cout;
    if (!path_.empty()) {
      if (!file_.is_open()) file_.open(path_, std::ios::binary | std::ios::trunc);
      out = &file_;
    }
    out->write(text.data(), static_cast<std::streamsize>(text.size()));
    out->flush();
    if (!*out) {
      error_ = "cannot write the result to " + (path_.empty() ? std::string("stdout") : path_) +
               (path_.empty() ? std::string() : std::string(": ") + std::strerror(errno));
      return Internal(error_);
    }
    return Status::Ok();
  }
  TextSink Sink() {
    return [this](std::string_view text) { return Write(text); };
  }
  // Closes the file; the message of the first write that failed, or empty.
  const std::string& Close() {
    if (file_.is_open()) {
      file_.close();
      if (!file_ && error_.empty()) {
        error_ = "cannot write the result to " + path_ + ": " + std::strerror(errno);
      }
    }
    return error_;
  }
  const std::string& error() const { return error_; }

 private:
  std::string path_;
  std::ofstream file_;
  std::string error_;
};

// Exit code and stderr note for a run's final status.
int Finish(const std::string& status, const std::string& message) {
  if (status == "COMPLETED") return 0;
  if (status == "CANCELLED") return Error("interrupted: " + message, kExitInterrupted);
  return Error("run " + status + ": " + message, kExitFailed);
}

// Runs `run` with a progress bar on stderr (Ctrl-C cancels the run through its callback); the
// bar is erased before this returns.
template <typename Run>
auto WithProgressBar(const Run& run) {
  ProgressBar bar(stderr, IsTerminal(stderr));
  return run([&bar](double fraction) {
    bar.Update(fraction);
    return !g_interrupted;
  });
}

// Runs a request in this process through its kind's entry in the job registry (as the server's
// workers run it) and prints the whole result as one page.
template <typename Request>
Status RunLocal(const Request& request, ResultPrinter& printer) {
  StatusOr<std::unique_ptr<google::protobuf::Message>> result =
      WithProgressBar([&](const ProgressCallback& progress)
                          -> StatusOr<std::unique_ptr<google::protobuf::Message>> {
        const jobs::JobKindSpec* spec = jobs::FindKind(Request::descriptor());
        DRILLBIF_RETURN_IF_ERROR(jobs::CheckRequest(*spec, request));
        jobs::RunContext context;
        context.progress = progress;
        return spec->run(request, context);
      });
  if (!result.ok()) return result.status();
  DRILLBIF_RETURN_IF_ERROR(printer.AddPage(**result));
  return printer.Finish();
}

// Runs a request as a job of the server (submitted, followed with the progress bar) and prints
// its result page by page as the pages arrive; a cancelled job (no result on the server) as an
// empty result with status CANCELLED. Ctrl-C while the pages arrive stops fetching them
// (CANCELLED; the result stays on the server).
template <typename Result, typename Request>
Status RunOnServer(RemoteClient& remote, const Request& request, ResultPrinter& printer) {
  DRILLBIF_ASSIGN_OR_RETURN(const RemoteRun run,
                            WithProgressBar([&](const ProgressCallback& progress) {
                              return RunRemote(remote, request, progress, Interrupted);
                            }));
  if (run.cancelled) {
    Result result;
    result.set_status(std::string("CANCELLED"));
    result.set_message(run.message);
    DRILLBIF_RETURN_IF_ERROR(printer.AddPage(result));
  } else {
    DRILLBIF_RETURN_IF_ERROR(
        remote.GetResultPages(run.name, [&](google::protobuf::Message& page) -> Status {
          if (Interrupted()) {
            return Status(StatusCode::kCancelled,
                          "interrupted while printing the result of " + run.name +
                              "; the server keeps it: drillctl jobs result " + run.name);
          }
          return printer.AddPage(page);
        }));
  }
  return printer.Finish();
}

// The exit code for an error while running or printing: the output's own failure first, then
// Ctrl-C, then the error's.
int PrintError(const OutputStream& output, const Status& status) {
  if (!output.error().empty()) return Error(output.error(), kExitFailed);
  if (status.code() == StatusCode::kCancelled && Interrupted()) {
    return Error(status.message(), kExitInterrupted);
  }
  return ErrorStatus(status);
}

// Runs a job in this process (`remote` null) or on the server, and prints its result to
// --output or stdout as JSON or, with --format csv, as its kind's CSV (`table`: a simulate's
// table); with --detach only submits it and prints its operation name. Returns the exit code.
template <typename Result, typename Request>
int RunJob(const GlobalFlags& global, RemoteClient* remote, const Request& request,
           std::optional<SimulateTable> table = std::nullopt) {
  if (remote != nullptr && global.detach) {
    StatusOr<google::longrunning::Operation> op = remote->Submit(request);
    if (!op.ok()) return ErrorStatus(op.status());
    return Write(global, op->name() + "\n") ? 0 : kExitFailed;
  }
  OutputStream output(global.output);
  PrintOptions options;
  options.csv = global.format == "csv";
  options.pretty = !global.compact;
  options.simulate_table = table;
  StatusOr<std::unique_ptr<ResultPrinter>> printer =
      ResultPrinter::Create(Result::descriptor(), options, output.Sink());
  if (!printer.ok()) return ErrorStatus(printer.status());
  const Status printed = remote == nullptr ? RunLocal(request, **printer)
                                           : RunOnServer<Result>(*remote, request, **printer);
  if (!printed.ok()) return PrintError(output, printed);
  if (const std::string& error = output.Close(); !error.empty()) {
    return Error(error, kExitFailed);
  }
  return Finish((*printer)->status(), (*printer)->message());
}

int RunSimulateCommand(const GlobalFlags& global, RemoteClient* remote, const ModelFlags& m,
                       const SimulateFlags& f) {
  v1::SimulateRequest request;
  *request.mutable_params() = ToProtoParams(m);
  *request.mutable_initial_state() = ToProtoState(m);
  request.set_transient_periods(m.transient);
  request.set_sample_periods(m.samples);
  bool any_output = false;
  for (const CLI::Option* opt : f.output_options) any_output = any_output || opt->count() > 0;
  if (any_output) {
    v1::SimulateRequest::Outputs* o = request.mutable_outputs();
    o->set_measures(f.measures);
    o->set_poincare(f.poincare);
    o->set_events(f.events);
    o->set_modes(f.modes);
    o->set_trajectory_dt(f.trajectory_dt);
  }
  request.set_propagator(f.propagator == "cvode" ? v1::CVODE : v1::EXACT);
  if (f.rtol_option->count() > 0) request.set_cvode_rtol(f.rtol);

  std::optional<SimulateTable> table;
  if (global.format == "csv") {
    StatusOr<SimulateTable> t = CsvTableFor(jobs::EffectiveOutputs(request));
    if (!t.ok()) return Error(t.status().message(), kExitUsage);
    table = *t;
  }

  return RunJob<v1::SimulateResult>(global, remote, request, table);
}

int RunSweepCommand(const GlobalFlags& global, RemoteClient* remote, const ModelFlags& m,
                    const SweepFlags& f) {
  v1::SweepRequest request;
  *request.mutable_params() = ToProtoParams(m);
  *request.mutable_initial_state() = ToProtoState(m);
  request.set_transient_periods(m.transient);
  request.set_sample_periods(m.samples);
  request.set_param(f.param);
  request.set_min(f.min);
  request.set_max(f.max);
  request.set_steps(f.steps);
  request.set_direction(f.direction == "down"   ? v1::SweepRequest::DOWN
                        : f.direction == "both" ? v1::SweepRequest::BOTH
                                                : v1::SweepRequest::UP);
  request.set_threads(f.threads);
  if (f.chunks != 1) request.set_chunks(f.chunks);

  return RunJob<v1::SweepResult>(global, remote, request);
}

int RunContinueCommand(const GlobalFlags& global, RemoteClient* remote, const ModelFlags& m,
                       const ContinueFlags& f) {
  v1::ContinueRequest request;
  *request.mutable_params() = ToProtoParams(m);
  *request.mutable_initial_state() = ToProtoState(m);
  request.set_param(f.param);
  request.set_min(f.min);
  request.set_max(f.max);
  request.set_direction(f.direction == "increasing"   ? v1::ContinueRequest::INCREASING
                        : f.direction == "decreasing" ? v1::ContinueRequest::DECREASING
                                                      : v1::ContinueRequest::BOTH);
  request.set_initial_step(f.initial_step);
  request.set_min_step(f.min_step);
  request.set_max_step(f.max_step);
  request.set_max_steps(f.max_steps);
  request.set_target_iterations(f.target_iterations);
  request.set_locate_tolerance(f.locate_tolerance);
  request.set_switch_signatures(!f.no_switch);
  if (f.follow_pd) request.set_follow_period_doubling(true);
  for (const std::string& name : f.stop_at) {
    v1::SpecialPoint::Kind kind;
    if (!v1::SpecialPoint::Kind_Parse(name, &kind) || kind == v1::SpecialPoint::KIND_UNSPECIFIED) {
      return Error("--stop-at: unknown special point kind '" + name +
                       "' (FOLD, PERIOD_DOUBLING, NEIMARK_SACKER, BRANCH_POINT, GRAZING_L1, "
                       "GRAZING_L2, GRAZING_PI, SIGNATURE_CHANGE, ROP_MAX, POWER_MAX)",
                   kExitUsage);
    }
    request.add_stop_at(kind);
  }
  request.set_transient_periods(m.transient);

  return RunJob<v1::ContinueResult>(global, remote, request);
}

// The start orbit, plane and box of trace and optimum.
v1::TraceRequest ToTraceRequest(const ModelFlags& m, const TraceFlags& f) {
  v1::TraceRequest request;
  *request.mutable_params() = ToProtoParams(m);
  *request.mutable_initial_state() = ToProtoState(m);
  request.set_transient_periods(m.transient);
  for (const std::string& name : f.params) request.add_trace_params(name);
  for (double v : f.min) request.add_min(v);
  for (double v : f.max) request.add_max(v);
  for (double v : f.seeds) request.add_seeds(v);
  request.set_no_edge_branches(f.no_edge_branches);
  request.set_threads(f.threads);
  return request;
}

int RunTraceCommand(const GlobalFlags& global, RemoteClient* remote, const ModelFlags& m,
                    const TraceFlags& f) {
  v1::TraceRequest request = ToTraceRequest(m, f);
  request.set_period2(f.period2);
  if (f.max_period != 0) request.set_max_period(f.max_period);
  if (f.curve_steps == "coarse") request.set_curve_steps(v1::CURVE_STEPS_COARSE);
  if (f.curve_steps == "fine") request.set_curve_steps(v1::CURVE_STEPS_FINE);
  if (f.region || !f.grid.empty()) {
    v1::RegionRequest* region = request.mutable_region();
    for (int n : f.grid) region->add_grid(n);
  }
  return RunJob<v1::TraceResult>(global, remote, request);
}

// An optimum the server answered without a job: the result as a job's, and on stderr where it
// came from (a stored result, or an optimum map and how it was verified).
int PrintOptimumAnswer(const GlobalFlags& global, v1::QueryOptimumResponse& answer) {
  if (answer.has_from_map()) {
    std::cerr << "drillctl: answered from the optimum map " << answer.from_map().map() << ": "
              << answer.from_map().verification() << "\n";
  } else {
    std::cerr << "drillctl: answered from the stored result of " << answer.operation() << "\n";
  }
  OutputStream output(global.output);
  PrintOptions options;
  options.csv = global.format == "csv";
  options.pretty = !global.compact;
  StatusOr<std::unique_ptr<ResultPrinter>> printer =
      ResultPrinter::Create(v1::OptimumResult::descriptor(), options, output.Sink());
  if (!printer.ok()) return ErrorStatus(printer.status());
  Status printed = (*printer)->AddPage(*answer.mutable_optimum());
  if (printed.ok()) printed = (*printer)->Finish();
  if (!printed.ok()) return PrintError(output, printed);
  if (const std::string& error = output.Close(); !error.empty()) return Error(error, kExitFailed);
  return Finish((*printer)->status(), (*printer)->message());
}

int RunOptimumCommand(const GlobalFlags& global, RemoteClient* remote, const ModelFlags& m,
                      const TraceFlags& t, const OptimumFlags& f) {
  v1::OptimumRequest request;
  *request.mutable_trace() = ToTraceRequest(m, t);
  for (double v : f.margin) request.add_margin(v);
  request.set_scaled(f.scaled);
  for (int n : t.grid) request.add_grid(n);
  if (remote != nullptr && !global.detach) {
    // A stored answer, or one from an optimum map covering these conditions, before a job.
    v1::QueryOptimumRequest query;
    *query.mutable_request() = request;
    query.set_no_maps(f.no_maps);
    query.set_on_map_failure(f.compute_on_map ? v1::QueryOptimumRequest::COMPUTE
                                              : v1::QueryOptimumRequest::NEAREST_CELL);
    StatusOr<v1::QueryOptimumResponse> answer = remote->QueryOptimum(query);
    if (answer.ok() && answer->has_optimum()) return PrintOptimumAnswer(global, *answer);
    if (!answer.ok() && answer.status().code() == StatusCode::kFailedPrecondition) {
      std::cerr << "drillctl: " << answer.status().message() << "; computing it\n";
    } else if (!answer.ok() && answer.status().code() != StatusCode::kNotFound) {
      return ErrorStatus(answer.status());
    }
  }
  return RunJob<v1::OptimumResult>(global, remote, request);
}

int RunOptimumMapCommand(const GlobalFlags& global, RemoteClient* remote, const ModelFlags& m,
                         const TraceFlags& t, const OptimumFlags& f, const MapFlags& map) {
  v1::OptimumMapRequest request;
  v1::OptimumRequest* optimum = request.mutable_optimum();
  *optimum->mutable_trace() = ToTraceRequest(m, t);
  optimum->mutable_trace()->set_threads(0);  // the map's threads run the cells
  for (double v : f.margin) optimum->add_margin(v);
  optimum->set_scaled(f.scaled);
  for (int n : t.grid) optimum->add_grid(n);
  for (const std::string& name : map.over) request.add_over(name);
  for (double v : map.from) request.add_from(v);
  for (double v : map.to) request.add_to(v);
  for (int n : map.steps) request.add_steps(n);
  request.set_threads(t.threads);
  return RunJob<v1::OptimumMapResult>(global, remote, request);
}

// --grid n1,n2 of trace --region and optimum.
void AddGridFlag(CLI::App* cmd, std::vector<int>* grid, const std::string& help,
                 const std::string& group) {
  cmd->add_option("--grid", *grid, help)
      ->delimiter(',')
      ->expected(2)
      ->check(CLI::Range(3, 1 << 20))
      ->group(group);
}

// The plane and box of trace and optimum.
void AddBoxFlags(CLI::App* cmd, TraceFlags* f) {
  const std::string g = "Plane";
  cmd->add_option("--params", f->params, "The two parameters of the plane, e.g. omega,a")
      ->required()
      ->delimiter(',')
      ->expected(2)
      ->group(g);
  cmd->add_option("--min", f->min, "Lower bounds, one per parameter, e.g. 0.05,0.01")
      ->required()
      ->delimiter(',')
      ->expected(2)
      ->group(g);
  cmd->add_option("--max", f->max, "Upper bounds, one per parameter, e.g. 2,8")
      ->required()
      ->delimiter(',')
      ->expected(2)
      ->group(g);
  cmd->add_option("--seeds", f->seeds,
                  "Values of the first parameter whose attractors (at the other flags' values) "
                  "and their branches start curves too, e.g. 0.07: curves the start's branches "
                  "and switching do not reach")
      ->delimiter(',')
      ->group(g);
  cmd->add_flag("--no-edge-branches", f->no_edge_branches,
                "Do not continue the branches along the box's edges through the curve ends on "
                "them (by default they start more curves: those crossing the edge on a branch "
                "a traced curve ends on)")
      ->group(g);
  cmd->add_option("--threads", f->threads,
                  "Threads the curves are traced on (0: every core; a server uses at most its "
                  "cores); the result is the same for any number")
      ->check(CLI::Range(0, 256))
      ->group(g);
}

struct PlotFlags {
  std::string result;   // the JSON file drillctl printed
  std::string optimum;  // optional: an optimum result to mark on a trace's figure
  std::string script;   // optional: write the gnuplot script here
  PlotOptions options;
};

StatusOr<std::string> ReadFile(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  if (!file) return InvalidArgument("cannot read " + path + ": " + std::strerror(errno));
  std::stringstream text;
  text << file.rdbuf();
  return text.str();
}

// `drillctl plot RESULT.json -o FIGURE.png|svg [--script FILE]`. Invalid input of any kind (an
// unreadable or unknown result, a bad extension or flag, no gnuplot) exits 2; gnuplot failing
// exits 1.
int RunPlotCommand(const GlobalFlags& global, PlotFlags f) {
  if (global.output.empty() && f.script.empty()) {
    return Error("plot: give the figure with -o FIGURE.png (or .svg), or --script FILE",
                 kExitUsage);
  }
  StatusOr<std::string> json = ReadFile(f.result);
  if (!json.ok()) return Error("plot: " + json.status().message(), kExitUsage);
  StatusOr<AnyResult> result = ParseResultJson(*json);
  if (!result.ok()) {
    return Error("plot: " + f.result + ": " + result.status().message(), kExitUsage);
  }
  if (!f.optimum.empty()) {
    StatusOr<std::string> opt_json = ReadFile(f.optimum);
    if (!opt_json.ok()) return Error("plot: --optimum: " + opt_json.status().message(), kExitUsage);
    StatusOr<AnyResult> opt = ParseResultJson(*opt_json);
    if (!opt.ok() || !std::holds_alternative<v1::OptimumResult>(*opt)) {
      return Error("plot: --optimum " + f.optimum + " is not an optimum result" +
                       (opt.ok() ? " (it is a " + ResultKindName(*opt) + " result)"
                                 : ": " + opt.status().message()),
                   kExitUsage);
    }
    if (!std::holds_alternative<v1::TraceResult>(*result)) {
      return Error("plot: --optimum marks an optimum on a trace's figure; " + f.result + " is a " +
                       ResultKindName(*result) + " result",
                   kExitUsage);
    }
    f.options.optimum = std::get<v1::OptimumResult>(*opt);
  }
  f.options.output = global.output.empty()
                         ? std::filesystem::path(f.result).replace_extension(".png").string()
                         : global.output;
  StatusOr<std::string> script = BuildPlotScript(*result, f.options);
  if (!script.ok()) return Error("plot: " + script.status().message(), kExitUsage);
  if (!f.script.empty()) {
    std::ofstream file(f.script, std::ios::binary | std::ios::trunc);
    file << *script;
    file.close();
    if (!file) {
      return Error("plot: cannot write --script " + f.script + ": " + std::strerror(errno),
                   kExitUsage);
    }
  }
  if (global.output.empty()) return 0;
  const Status rendered = RenderWithGnuplot(*script, global.output);
  if (rendered.code() == StatusCode::kFailedPrecondition) {
    return Error("plot: " + rendered.message(), kExitUsage);
  }
  if (!rendered.ok()) return Error("plot: " + rendered.message(), kExitFailed);
  return 0;
}

struct JobsFlags {
  JobsListOptions list;
  std::string id;  // get, watch, cancel, result
};

enum class JobsCommand { kList, kGet, kWatch, kCancel, kResult };

// `drillctl jobs ...`. Exit codes: list, get, cancel 0 (or an error's); watch 0 when the job
// SUCCEEDED, 1 when it FAILED or was CANCELLED, 130 on Ctrl-C (the job goes on); result as the
// command that ran the job.
int RunJobsCommand(const GlobalFlags& global, RemoteClient& remote, JobsCommand command,
                   const JobsFlags& flags) {
  OutputStyle style;
  style.csv = global.format == "csv";
  style.pretty = !global.compact;
  StatusOr<std::string> text = std::string();
  switch (command) {
    case JobsCommand::kList:
      text = JobsList(remote, flags.list, style);
      break;
    case JobsCommand::kGet:
      text = JobsGet(remote, flags.id, style);
      break;
    case JobsCommand::kCancel:
      text = JobsCancel(remote, flags.id, style);
      break;
    case JobsCommand::kResult: {
      OutputStream output(global.output);
      StatusOr<PrintedResult> result = JobsResult(remote, flags.id, style, output.Sink());
      if (!result.ok()) return PrintError(output, result.status());
      if (const std::string& error = output.Close(); !error.empty()) {
        return Error(error, kExitFailed);
      }
      return Finish(result->status, result->message);
    }
    case JobsCommand::kWatch: {
      // Lines are written as they come (to --output too: appended as they come).
      std::ofstream file;
      if (!global.output.empty()) file.open(global.output, std::ios::binary | std::ios::trunc);
      std::ostream& out = global.output.empty() ? std::cout : file;
      StatusOr<v1::JobMetadata> last = JobsWatch(
          remote, flags.id, style, [&out](const std::string& line) { out << line << std::flush; },
          Interrupted);
      if (!last.ok()) {
        if (last.status().code() == StatusCode::kCancelled && Interrupted()) {
          return Error("interrupted (the job goes on)", kExitInterrupted);
        }
        return ErrorStatus(last.status());
      }
      if (!out) return Error("cannot write the progress", kExitFailed);
      if (last->state() == v1::SUCCEEDED) return 0;
      return Error(last->name() + " ended " + v1::JobState_Name(last->state()) +
                       " (drillctl jobs get " + last->name() + " has its error)",
                   kExitFailed);
    }
  }
  if (!text.ok()) return ErrorStatus(text.status());
  return Write(global, *text) ? 0 : kExitFailed;
}

// The box, margin and grid flags of optimum and optimum-map.
void AddOptimumFlags(CLI::App* cmd, TraceFlags* t, OptimumFlags* f) {
  AddBoxFlags(cmd, t);
  cmd->add_option("--margin", f->margin,
                  "Margin in each parameter's units: one value for both or one per parameter "
                  "(e.g. 0.02 or 0.01,0.05); with --scaled, one fraction of the box")
      ->delimiter(',')
      ->expected(1, 2)
      ->check(PositiveDouble())
      ->capture_default_str()
      ->group("Optimum");
  cmd->add_flag("--scaled", f->scaled,
                "The margin is a Euclidean distance in the box scaled to the unit square")
      ->group("Optimum");
  AddGridFlag(cmd, &t->grid,
              "Region grid nodes per parameter, e.g. 401,801 (default: a spacing of half the "
              "margin, at most 1001 per parameter)",
              "Optimum");
}

int Main(int argc, char** argv) {
  if (std::getenv("GRPC_VERBOSITY") == nullptr) gpr_set_log_function(DropGrpcLog);
  CLI::App app{"drillctl: bifurcation analysis of the drifting impact oscillator", "drillctl"};
  app.set_version_flag("--version", EngineVersion());
  app.require_subcommand(1);
  app.fallthrough();  // global flags may also follow the subcommand
  app.footer(
      "Exit codes: 0 completed, 1 run failed (partial result printed) or server unreachable, "
      "2 invalid input or token refused, 130 interrupted.");

  GlobalFlags global;
  const std::string remote_group = "Server mode (without --local)";
  CLI::Option* local_flag =
      app.add_flag("--local", global.local,
                   "Run the engine in this process (default: submit the job to the server)");
  app.add_option("--server", global.server,
                 "drillbif server HOST:PORT (default: $DRILLBIF_SERVER, else localhost:50051)")
      ->excludes(local_flag)
      ->group(remote_group);
  app.add_option("--token", global.token,
                 "Bearer token for the server (default: $DRILLBIF_TOKEN, else none)")
      ->excludes(local_flag)
      ->group(remote_group);
  app.add_flag("--detach", global.detach,
               "Submit the job, print its operation name (operations/ID) and return")
      ->excludes(local_flag)
      ->group(remote_group);
  app.add_option("--timeout", global.timeout, "Deadline of each rpc, in seconds")
      ->check(PositiveDouble())
      ->capture_default_str()
      ->excludes(local_flag)
      ->group(remote_group);
  app.add_flag("--tls", global.tls,
               "Use TLS, verifying the server's certificate against the system's CA roots")
      ->excludes(local_flag)
      ->group(remote_group);
  app.add_option("--tls-ca", global.tls_ca,
                 "Verify the server's certificate against this PEM CA certificate (or the "
                 "server's self-signed one); implies --tls (default: $DRILLBIF_TLS_CA)")
      ->option_text("FILE")
      ->excludes(local_flag)
      ->group(remote_group);
  // Hidden (tests, diagnosis): items per GetResult page.
  app.add_option("--result-page-size", global.result_page_size,
                 "Items per GetResult page of a result")
      ->check(CLI::Range(1, jobs::kMaxResultPageSize))
      ->excludes(local_flag)
      ->group("");
  app.add_option("--format", global.format, "Output format: json or csv")
      ->check(CLI::IsMember({"json", "csv"}))
      ->capture_default_str();
  app.add_option("--output,-o", global.output, "Write the result to FILE (default: stdout)")
      ->option_text("FILE");
  app.add_flag("--compact", global.compact, "JSON on one line (default: indented)");

  ModelFlags model;
  SimulateFlags sim;
  CLI::App* simulate = app.add_subcommand(
      "simulate",
      "Simulate N transient periods, then report the sampled window (default: rop, power and "
      "the Poincare samples of 100 periods after a 500-period transient)");
  AddModelFlags(simulate, &model);
  AddRunFlags(simulate, &model);
  const std::string out = "Outputs (none given: --measures --poincare; any given: exactly those)";
  sim.output_options = {
      simulate->add_flag("--measures", sim.measures, "Mean ROP and dissipated power")->group(out),
      simulate->add_flag("--poincare", sim.poincare, "State at each section s = 0")->group(out),
      simulate->add_flag("--events", sim.events, "Event log (impacts, switches, grazings)")
          ->group(out),
      simulate->add_flag("--modes", sim.modes, "Modes visited in each period")->group(out),
      simulate
          ->add_option("--trajectory-dt", sim.trajectory_dt,
                       "Sample the trajectory every DT (dimensionless time)")
          ->check(PositiveDouble())
          ->option_text("DT")
          ->group(out)};
  simulate->add_option("--propagator", sim.propagator, "Numerical method: exact or cvode")
      ->check(CLI::IsMember({"exact", "cvode"}))
      ->capture_default_str()
      ->group("Method");
  sim.rtol_option =
      simulate->add_option("--rtol", sim.rtol, "Relative tolerance of --propagator cvode")
          ->capture_default_str()
          ->group("Method");

  SweepFlags sw;
  CLI::App* sweep = app.add_subcommand(
      "sweep",
      "Brute-force bifurcation diagram: Poincare samples over a grid of one parameter, each "
      "value starting from the last state of the previous one");
  sweep->add_option("--param", sw.param, "Swept parameter: a, b, omega, xi, g or phi0")
      ->required()
      ->group("Sweep");
  sweep->add_option("--min", sw.min, "First value of the grid")->required()->group("Sweep");
  sweep->add_option("--max", sw.max, "Last value of the grid")->required()->group("Sweep");
  sweep->add_option("--steps", sw.steps, "Number of values, endpoints included")
      ->capture_default_str()
      ->group("Sweep");
  sweep->add_option("--direction", sw.direction, "up, down or both (hysteresis)")
      ->check(CLI::IsMember({"up", "down", "both"}))
      ->capture_default_str()
      ->group("Sweep");
  sweep
      ->add_option("--threads", sw.threads,
                   "Worker threads (0: one per core); a direction uses one unless --chunks > 1")
      ->capture_default_str()
      ->group("Sweep");
  sweep
      ->add_option("--chunks", sw.chunks,
                   "Pieces each direction is split into, run in parallel; each piece after the "
                   "first starts from the initial state (4 x transient), breaking continuity")
      ->capture_default_str()
      ->group("Sweep");
  AddModelFlags(sweep, &model);
  AddRunFlags(sweep, &model);

  ContinueFlags co;
  CLI::App* cont = app.add_subcommand(
      "continue",
      "Numerical continuation of a periodic orbit in one parameter, with its folds, period "
      "doublings, grazings and ROP maxima located; the start orbit is found by simulation from "
      "the initial state at the model parameters");
  const std::string c = "Continuation";
  cont->add_option("--param", co.param, "Continuation parameter: a, b, omega, xi, g or phi0")
      ->required()
      ->group(c);
  cont->add_option("--min", co.min, "Lower bound of the parameter")->required()->group(c);
  cont->add_option("--max", co.max, "Upper bound of the parameter")->required()->group(c);
  cont->add_option("--direction", co.direction,
                   "Way the parameter moves on the first step: increasing, decreasing or both")
      ->check(CLI::IsMember({"increasing", "decreasing", "both"}))
      ->capture_default_str()
      ->group(c);
  cont->add_option("--initial-step", co.initial_step, "Arclength of the first step")
      ->check(PositiveDouble())
      ->capture_default_str()
      ->group(c);
  cont->add_option("--min-step", co.min_step, "Shortest step (shorter: the branch fails)")
      ->check(PositiveDouble())
      ->capture_default_str()
      ->group(c);
  cont->add_option("--max-step", co.max_step, "Longest step")
      ->check(PositiveDouble())
      ->capture_default_str()
      ->group(c);
  cont->add_option("--max-steps", co.max_steps, "Accepted steps per direction")
      ->check(CLI::Range(1, jobs::kMaxContinuationSteps))
      ->capture_default_str()
      ->group(c);
  cont->add_option("--target-iterations", co.target_iterations,
                   "Corrector iterations the step length adapts to")
      ->check(CLI::Range(1, co.defaults.steps.max_iterations))
      ->capture_default_str()
      ->group(c);
  cont->add_option("--locate-tolerance", co.locate_tolerance,
                   "Special points located to this width in the parameter")
      ->check(PositiveDouble())
      ->capture_default_str()
      ->group(c);
  cont->add_flag("--no-switch", co.no_switch,
                 "Stop a direction at its first grazing instead of switching signature")
      ->group(c);
  cont->add_flag("--follow-pd", co.follow_pd,
                 "Also continue the period-2n branch born at the first period doubling")
      ->group(c);
  cont->add_option("--stop-at", co.stop_at,
                   "Stop a direction at its first special point of these kinds, e.g. FOLD")
      ->delimiter(',')
      ->group(c);
  AddModelFlags(cont, &model);
  AddStartOrbitFlags(cont, &model);

  TraceFlags tr;
  CLI::App* trace = app.add_subcommand(
      "trace",
      "Every fold, period-doubling and grazing curve through the start orbit's branches in a box "
      "of two parameters, with the codimension-2 points found on them");
  AddBoxFlags(trace, &tr);
  trace
      ->add_flag("--region", tr.region,
                 "Also compute the stability region of period-1 motion around the start orbit "
                 "(grid with ROP, polygons bounded by the curves)")
      ->group("Region");
  trace
      ->add_flag("--period2", tr.period2,
                 "Also trace the curves of the period-2 branches born at the period doublings, "
                 "and the period-2 grazing curves leaving the flip-grazings (= --max-period 2)")
      ->group("Trace");
  trace
      ->add_option("--max-period", tr.max_period,
                   "Longest period traced along the doubling cascade: 1, 2, 4, 8 or 16")
      ->group("Trace");
  trace
      ->add_option("--curve-steps", tr.curve_steps,
                   "coarse (default) or fine: ~4.5x more vertices per curve, ~1.6x the time, the "
                   "same codimension-2 points to the same tolerance")
      ->check(CLI::IsMember({"fine", "coarse"}))
      ->group("Trace");
  AddGridFlag(trace, &tr.grid,
              "Region grid nodes per parameter, e.g. 201,201 (implies --region; default 201,201)",
              "Region");
  AddModelFlags(trace, &model);
  AddStartOrbitFlags(trace, &model);

  TraceFlags ot;
  OptimumFlags of;
  CLI::App* optimum = app.add_subcommand(
      "optimum",
      "The operating point of maximal ROP where the period-1 orbit is stable and at least a "
      "margin from every bifurcation curve bounding its stability region");
  AddOptimumFlags(optimum, &ot, &of);
  optimum
      ->add_flag("--no-maps", of.no_maps,
                 "Server mode: never answer from an optimum map (a stored result of this exact "
                 "request, else a job)")
      ->group("Optimum");
  optimum
      ->add_flag("--compute-on-map-failure", of.compute_on_map,
                 "Server mode: when a map's interpolated answer fails its verification, compute "
                 "the optimum (default: the nearest cell's point, checked the same way)")
      ->group("Optimum");
  AddModelFlags(optimum, &model);
  AddStartOrbitFlags(optimum, &model);

  TraceFlags mt;
  OptimumFlags mo;
  MapFlags mf;
  CLI::App* optimum_map = app.add_subcommand(
      "optimum-map",
      "The robust optimum at every cell of a grid of operating conditions (e.g. --over b "
      "--from 0.14 --to 0.16 --steps 5), each cell an independent task; the server answers "
      "optimum queries at any condition inside a stored map");
  AddOptimumFlags(optimum_map, &mt, &mo);
  optimum_map
      ->add_option("--over", mf.over,
                   "The conditions varied: one or two model parameters, e.g. b or b,xi")
      ->delimiter(',')
      ->expected(1, 2)
      ->required()
      ->group("Map");
  optimum_map->add_option("--from", mf.from, "First value of each condition")
      ->delimiter(',')
      ->expected(1, 2)
      ->required()
      ->group("Map");
  optimum_map->add_option("--to", mf.to, "Last value of each condition")
      ->delimiter(',')
      ->expected(1, 2)
      ->required()
      ->group("Map");
  optimum_map
      ->add_option("--steps", mf.steps,
                   "Cells along each condition, >= 2 (both ends included; at most 10000 cells)")
      ->delimiter(',')
      ->expected(1, 2)
      ->required()
      ->group("Map");
  AddModelFlags(optimum_map, &model);
  AddStartOrbitFlags(optimum_map, &model);

  PlotFlags pf;
  CLI::App* plot = app.add_subcommand(
      "plot",
      "Draw a result drillctl printed as JSON with gnuplot: continue (measure against the "
      "parameter), sweep (brute-force diagram), trace (two-parameter diagram, region, optimum) "
      "or simulate (phase portrait); the figure is -o FILE.png or FILE.svg");
  plot->add_option("RESULT", pf.result, "The result JSON (drillctl ... -o RESULT.json)")
      ->required();
  plot->add_option("--optimum", pf.optimum,
                   "An optimum result (drillctl optimum) to mark on a trace's figure")
      ->option_text("FILE");
  plot->add_option("--measure", pf.options.measure, "continue: rop or power (pc)")
      ->check(CLI::IsMember({"rop", "power", "pc"}))
      ->capture_default_str();
  plot->add_option("--coordinate", pf.options.coordinate, "sweep: Poincare coordinate p, y or q")
      ->check(CLI::IsMember({"p", "y", "q"}))
      ->capture_default_str();
  plot->add_option("--param", pf.options.param,
                   "Name of the swept parameter for the axis (a sweep result does not hold it)");
  plot->add_option("--title", pf.options.title, "Title (default: derived from the result)");
  plot->add_option("--script", pf.script,
                   "Also write the gnuplot script (self-contained, data inline) to FILE")
      ->option_text("FILE");

  CLI::App* health = app.add_subcommand(
      "health",
      "Ask the server's gRPC health service: prints SERVING and exits 0, else prints the status "
      "and exits 1 (no token needed; for container and service health checks)");

  JobsFlags jf;
  CLI::App* jobs = app.add_subcommand("jobs", "Manage the jobs of a drillbif server");
  jobs->require_subcommand(1);
  jobs->fallthrough();
  CLI::App* jobs_list = jobs->add_subcommand("list", "List jobs, oldest first, one page");
  jobs_list
      ->add_option("--state", jf.list.state,
                   "Only jobs in this state: QUEUED, RUNNING, SUCCEEDED, FAILED, CANCELLED")
      ->check(CLI::IsMember({"QUEUED", "RUNNING", "SUCCEEDED", "FAILED", "CANCELLED"}));
  jobs_list->add_option("--kind", jf.list.kind, "Only jobs of this kind, e.g. sweep")
      ->check(CLI::IsMember({"simulate", "sweep", "continue", "trace", "optimum", "optimum-map"}));
  jobs_list->add_option("--page-size", jf.list.page_size, "Jobs per page (0: the server's 50)")
      ->check(CLI::Range(0, 1000));
  jobs_list->add_option("--page-token", jf.list.page_token, "Token of the page to list");
  jobs_list->add_flag("--all", jf.list.all, "Every page");
  CLI::App* jobs_get = jobs->add_subcommand("get", "A job's operation (with its result)");
  CLI::App* jobs_watch = jobs->add_subcommand("watch", "Stream a job's progress until it finishes");
  CLI::App* jobs_cancel = jobs->add_subcommand("cancel", "Cancel a job");
  CLI::App* jobs_result = jobs->add_subcommand(
      "result", "A finished job's result, printed as the command that ran it prints it");
  for (CLI::App* sub : {jobs_get, jobs_watch, jobs_cancel, jobs_result}) {
    sub->add_option("ID", jf.id, "The job: operations/ID or ID")->required();
    sub->fallthrough();
  }
  jobs_list->fallthrough();

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);  // prints help, version or the error
    return code == 0 ? 0 : kExitUsage;
  }
  if (plot->parsed()) return RunPlotCommand(global, pf);  // no server, no job
  if (global.local && jobs->parsed()) {
    return Error("jobs manages a server's jobs: drop --local", kExitUsage);
  }
  if (global.local && health->parsed()) {
    return Error("health asks a server: drop --local", kExitUsage);
  }
  std::unique_ptr<RemoteClient> remote;
  if (!global.local) {
    RemoteOptions options;
    options.target = ResolveServer(global.server);
    options.token = ResolveToken(global.token);
    options.rpc_timeout_seconds = global.timeout;
    options.tls_ca_file = ResolveTlsCa(global.tls_ca);
    options.tls = global.tls || !options.tls_ca_file.empty();
    options.result_page_size = global.result_page_size;
    StatusOr<std::unique_ptr<RemoteClient>> client = RemoteClient::Connect(options);
    if (!client.ok()) return ErrorStatus(client.status());
    remote = std::move(client).value();
  }
  // Fail on an unwritable --output before computing anything.
  if (!global.output.empty()) {
    std::ofstream probe(global.output, std::ios::binary | std::ios::app);
    if (!probe) {
      return Error("cannot open --output " + global.output + ": " + std::strerror(errno),
                   kExitUsage);
    }
  }
  InstallInterruptHandler();
  if (health->parsed()) {
    StatusOr<std::string> serving = remote->Health();
    if (!serving.ok()) return Error(serving.status().ToString(), kExitFailed);
    if (!Write(global, *serving + "\n")) return kExitFailed;
    return *serving == "SERVING" ? 0 : kExitFailed;
  }
  if (jobs->parsed()) {
    const JobsCommand command = jobs_list->parsed()     ? JobsCommand::kList
                                : jobs_get->parsed()    ? JobsCommand::kGet
                                : jobs_watch->parsed()  ? JobsCommand::kWatch
                                : jobs_cancel->parsed() ? JobsCommand::kCancel
                                                        : JobsCommand::kResult;
    return RunJobsCommand(global, *remote, command, jf);
  }
  if (simulate->parsed()) return RunSimulateCommand(global, remote.get(), model, sim);
  if (cont->parsed()) return RunContinueCommand(global, remote.get(), model, co);
  if (trace->parsed()) return RunTraceCommand(global, remote.get(), model, tr);
  if (optimum->parsed()) return RunOptimumCommand(global, remote.get(), model, ot, of);
  if (optimum_map->parsed()) {
    return RunOptimumMapCommand(global, remote.get(), model, mt, mo, mf);
  }
  return RunSweepCommand(global, remote.get(), model, sw);
}

}  // namespace
}  // namespace drillbif::client

int main(int argc, char** argv) {
  try {
    return drillbif::client::Main(argc, argv);
  } catch (const std::exception& e) {
    std::cerr << "drillctl: internal error: " << e.what() << "\n";
    return 1;
  }
}
