#include "jobs/job_common.h"

#include <charconv>
#include <chrono>
#include <string>
#include <utility>

#include "drillbif/orbit/signature.h"

namespace drillbif::jobs::internal {

const Osc& Model() {
  static const Osc model;
  return model;
}

std::string Num(double v) {
  char buf[32];
  const auto [end, ec] = std::to_chars(buf, buf + sizeof(buf), v);
  return ec == std::errc() ? std::string(buf, end) : std::string("?");
}

double Seconds(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

Params ToEngineParams(const v1::ModelParams& m) {
  Params p = Osc::MakeParams();
  if (m.has_a()) p[Osc::kA] = m.a();
  if (m.has_b()) p[Osc::kB] = m.b();
  if (m.has_omega()) p[Osc::kOmega] = m.omega();
  if (m.has_xi()) p[Osc::kXi] = m.xi();
  if (m.has_g()) p[Osc::kG] = m.g();
  if (m.has_phi0()) p[Osc::kPhi0] = m.phi0();
  return p;
}

StateVector ToEngineState(bool has_state, const v1::State& s) {
  if (!has_state) return DefaultInitialState(Model());
  StateVector x(4);
  x << s.p(), s.y(), s.q(), s.s();
  return x;
}

v1::ModelParams ToProtoParams(const Params& p) {
  v1::ModelParams out;
  out.set_a(p[Osc::kA]);
  out.set_b(p[Osc::kB]);
  out.set_omega(p[Osc::kOmega]);
  out.set_xi(p[Osc::kXi]);
  out.set_g(p[Osc::kG]);
  out.set_phi0(p[Osc::kPhi0]);
  return out;
}

StatusOr<PeriodicOrbit> StartOrbit(Propagator& propagator, const Params& params,
                                   const StateVector& x0, int transient_periods,
                                   const ProgressCallback& progress) {
  const Osc& model = Model();
  GuessOptions guess;
  guess.transient_periods = transient_periods;
  StatusOr<PeriodicOrbit> orbit =
      OrbitFromSimulation(model, propagator, params, x0, guess, progress);
  if (!orbit.ok()) {
    if (orbit.status().code() == StatusCode::kCancelled) return orbit.status();
    return FailedPrecondition(
        "the start state is not near a periodic orbit: " + orbit.status().message() +
        " (try another initial_state, more transient_periods, or a parameter value where the "
        "motion is periodic)");
  }
  PeriodicOrbit solved = *orbit;
  const OrbitSolveSummary summary =
      SolveOrbit(model, propagator, OrbitSolverOptions(), &solved, progress);
  if (summary.cancelled()) return Cancelled("cancelled while solving the start orbit");
  if (!summary.completed()) {
    return FailedPrecondition(
        "the start state is not near a periodic orbit: Newton on the period-" +
        std::to_string(solved.signature.periods) + " orbit " +
        SignatureString(model, orbit->signature) + " found by simulation did not converge (" +
        TerminationName(summary.termination) + ": " + summary.message +
        "); try more transient_periods");
  }
  return solved;
}

ProgressCallback StageProgress(const ProgressCallback& progress, double lo, double hi) {
  if (!progress) return {};
  return [progress, lo, hi](double f) { return progress(lo + (hi - lo) * f); };
}

Status CheckParamValues(const Params& params, int index,
                        std::initializer_list<std::pair<const char*, double>> bounds) {
  for (const auto& [field, v] : bounds) {
    Params p = params;
    p[index] = v;
    if (Status s = Model().ValidateParams(p); !s.ok()) {
      return InvalidArgument(std::string(field) + ": " + s.message());
    }
  }
  return Status::Ok();
}

const char* ResultStatus(Termination termination) {
  return termination == Termination::kNoConvergence ? TerminationName(Termination::kFailed)
                                                    : TerminationName(termination);
}

const char* ResultStatus(const RunSummary& summary) {
  if (summary.failed() && summary.status.code() == StatusCode::kNotFound) return "NOT_FOUND";
  return ResultStatus(summary.termination);
}

v1::Mode ToProtoMode(int mode) {
  switch (mode) {
    case Osc::kNoContact:
      return v1::NO_CONTACT;
    case Osc::kContact:
      return v1::CONTACT;
    case Osc::kProgression:
      return v1::PROGRESSION;
  }
  return v1::MODE_UNSPECIFIED;
}

void ToProto(const PoincareSample& in, v1::PoincarePoint* out) {
  out->set_period(in.period);
  out->set_mode(ToProtoMode(in.mode));
  out->set_p(in.x[Osc::kP]);
  out->set_y(in.x[Osc::kY]);
  out->set_q(in.x[Osc::kQ]);
}

}  // namespace drillbif::jobs::internal
