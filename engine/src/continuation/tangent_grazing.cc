#include "continuation/tangent_grazing.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>
#include <vector>

#include "continuation/bordered_sigma.h"
#include "continuation/signature_switch.h"
#include "orbit/monodromy.h"
#include "orbit/orbit_bvp.h"

namespace drillbif::internal {

StatusOr<PeriodicOrbit> TangentForm(const PeriodicOrbit& orbit, int i) {
  const auto& segs = orbit.signature.segments;
  if (i <= 0 || i + 1 >= static_cast<int>(segs.size()) || segs[i - 1].mode != segs[i + 1].mode) {
    return InvalidArgument("no tangent form: segment " + std::to_string(i) +
                           " does not lie between two segments of one mode");
  }
  PeriodicOrbit t = orbit;
  auto& ts = t.signature.segments;
  ts[i - 1].tangent = true;
  t.durations[i + 1] += t.durations[i];
  t.starts[i + 1] = t.starts[i];
  ts.erase(ts.begin() + i);
  t.durations.erase(t.durations.begin() + i);
  t.starts.erase(t.starts.begin() + i);
  return t;
}

StatusOr<PeriodicOrbit> TouchForm(const HybridModel& model, Propagator& propagator,
                                  const PeriodicOrbit& orbit, double tolerance, int segment,
                                  int guard) {
  // Interior local minima of each guard along each segment: bracketed on a grid of samples, then
  // polished by Newton on h'(t) = 0 with h'' (both along the flow, from the model).
  constexpr int kSamples = 200;
  const auto& segs = orbit.signature.segments;
  if (orbit.starts.size() != segs.size() || orbit.durations.size() != segs.size() ||
      orbit.params.size() != model.num_params()) {
    return InvalidArgument("the orbit's segments, starts, durations or parameters do not match");
  }
  double best_h = std::numeric_limits<double>::infinity();
  int best_segment = -1, best_guard = -1;
  double best_t = 0.0;
  for (int k = 0; k < static_cast<int>(segs.size()); ++k) {
    const double tau = orbit.durations[k];
    if (!(tau > 0.0) || (segment >= 0 && k != segment)) continue;
    const int guards = static_cast<int>(model.guards(segs[k].mode).size());
    for (int e = 0; e < guards; ++e) {
      if (guard >= 0 && e != guard) continue;
      auto at = [&](double t) {
        const StateVector x =
            propagator.FlowMap(segs[k].mode, orbit.starts[k], t, orbit.params, {}).x;
        return model.Guard(segs[k].mode, e, x, orbit.params);
      };
      std::vector<double> h(kSamples + 1);
      for (int j = 0; j <= kSamples; ++j) h[j] = at(tau * j / kSamples).h;
      for (int j = 1; j < kSamples; ++j) {
        if (!(h[j] <= h[j - 1] && h[j] <= h[j + 1])) continue;
        double t = tau * j / kSamples;
        const double lo = tau * (j - 1) / kSamples, hi = tau * (j + 1) / kSamples;
        for (int it = 0; it < 20; ++it) {
          const GuardValue g = at(t);
          if (!(g.ddh > 0.0)) break;
          const double next = std::clamp(t - g.dh / g.ddh, lo, hi);
          const bool done = std::abs(next - t) <= 1e-14 * (1.0 + tau);
          t = next;
          if (done) break;
        }
        const double ht = at(t).h;
        if (std::abs(ht) < best_h) {
          best_h = std::abs(ht);
          best_segment = k, best_guard = e, best_t = t;
        }
      }
    }
  }
  if (best_segment < 0 || best_h > tolerance) {
    return Status(StatusCode::kFailedPrecondition,
                  "no guard touches zero inside a segment of the orbit");
  }
  PeriodicOrbit t = orbit;
  auto& ts = t.signature.segments;
  const int k = best_segment;
  const StateVector touch =
      propagator.FlowMap(ts[k].mode, orbit.starts[k], best_t, orbit.params, {}).x;
  SegmentSpec first = ts[k];
  first.guard = best_guard;
  first.tangent = true;
  ts.insert(ts.begin() + k, first);
  t.starts.insert(t.starts.begin() + k + 1, touch);
  t.durations[k] = best_t;
  t.durations.insert(t.durations.begin() + k + 1, orbit.durations[k] - best_t);
  return t;
}

StatusOr<PeriodicOrbit> GrazingTangentForm(const HybridModel& model, Propagator& propagator,
                                           const PeriodicOrbit& orbit) {
  const auto& d = orbit.durations;
  if (d.empty()) return InvalidArgument("the orbit has no segments");
  const int i = static_cast<int>(
      std::min_element(d.begin(), d.end(),
                       [](double x, double y) { return std::abs(x) < std::abs(y); }) -
      d.begin());
  StatusOr<PeriodicOrbit> tangent = TangentForm(orbit, i);
  if (std::abs(d[i]) > 1e-6 || !tangent.ok()) tangent = TouchForm(model, propagator, orbit);
  if (!tangent.ok()) {
    return Status(StatusCode::kUnimplemented,
                  "no tangent form of the grazing: neither a segment vanishing between two "
                  "segments of one mode nor a guard touching zero inside a segment");
  }
  return tangent;
}

bool EventsOfTwoSurfaces(const HybridModel& model, const Signature& signature, int j) {
  const auto& segs = signature.segments;
  if (j <= 0 || j + 1 >= static_cast<int>(segs.size()) || segs[j - 1].guard < 0 ||
      segs[j].guard < 0) {
    return false;
  }
  return model.guards(segs[j - 1].mode)[segs[j - 1].guard].surface !=
         model.guards(segs[j].mode)[segs[j].guard].surface;
}

int CornerSegment(const HybridModel& model, const PeriodicOrbit& orbit) {
  const auto& segs = orbit.signature.segments;
  if (std::any_of(segs.begin(), segs.end(), [](const SegmentSpec& s) { return s.tangent; })) {
    return -1;
  }
  for (int j = 1; j + 1 < static_cast<int>(segs.size()); ++j) {
    if (std::abs(orbit.durations[j]) <= 1e-9 && EventsOfTwoSurfaces(model, orbit.signature, j)) {
      return j;
    }
  }
  return -1;
}

StatusOr<PeriodicOrbit> MergedForm(const PeriodicOrbit& tangent_orbit, int segment) {
  PeriodicOrbit o = tangent_orbit;
  auto& segs = o.signature.segments;
  for (size_t k = 0; k + 1 < segs.size(); ++k) {
    if (!segs[k].tangent || (segment >= 0 && static_cast<int>(k) != segment)) continue;
    if (segs[k + 1].mode != segs[k].mode) break;
    segs[k].guard = segs[k + 1].guard;
    segs[k].tangent = segs[k + 1].tangent;
    o.durations[k] += o.durations[k + 1];
    segs.erase(segs.begin() + k + 1);
    o.durations.erase(o.durations.begin() + k + 1);
    o.starts.erase(o.starts.begin() + k + 1);
    return o;
  }
  return InvalidArgument("the orbit has no tangent segment followed by one of the same mode");
}

StatusOr<PeriodicOrbit> CrossingForm(const HybridModel& model, Propagator& propagator,
                                     const PeriodicOrbit& tangent_orbit, int* new_segment,
                                     int segment) {
  const auto& segs = tangent_orbit.signature.segments;
  const int j =
      segment >= 0 ? segment
                   : static_cast<int>(std::find_if(segs.begin(), segs.end(),
                                                   [](const SegmentSpec& s) { return s.tangent; }) -
                                      segs.begin());
  if (j >= static_cast<int>(segs.size()) || !segs[j].tangent) {
    return InvalidArgument("no tangent segment " + std::to_string(j));
  }
  StatusOr<PeriodicOrbit> merged = MergedForm(tangent_orbit, j);
  if (!merged.ok()) return merged.status();
  Admissibility touch;
  touch.admissible = false;
  touch.segment = j;
  touch.guard = segs[j].guard;
  SwitchedOrbit crossed = SwitchSignature(model, propagator, *merged, touch);
  if (crossed.new_segment < 0) return Internal("the touch did not split: " + crossed.detail);
  *new_segment = crossed.new_segment;
  return std::move(crossed.orbit);
}

double RateAtTangentEnd(const HybridModel& model, Propagator& propagator,
                        const PeriodicOrbit& orbit, int k) {
  const SegmentSpec& seg = orbit.signature.segments[k];
  const StateVector end =
      propagator.FlowMap(seg.mode, orbit.starts[k], orbit.durations[k], orbit.params, {}).x;
  return model.Guard(seg.mode, seg.guard, end, orbit.params).dh;
}

double TangentEndRate(const HybridModel& model, Propagator& propagator,
                      const PeriodicOrbit& orbit) {
  // TangentEndRates' first, without its vector: this is a grazing curve's condition, evaluated
  // once per difference of its row.
  const auto& segs = orbit.signature.segments;
  for (size_t k = 0; k < segs.size(); ++k) {
    if (segs[k].tangent) return RateAtTangentEnd(model, propagator, orbit, static_cast<int>(k));
  }
  return std::numeric_limits<double>::quiet_NaN();
}

std::vector<int> TangentSegments(const Signature& signature) {
  std::vector<int> tangents;
  for (size_t k = 0; k < signature.segments.size(); ++k) {
    if (signature.segments[k].tangent) tangents.push_back(static_cast<int>(k));
  }
  return tangents;
}

std::vector<double> TangentEndRates(const HybridModel& model, Propagator& propagator,
                                    const PeriodicOrbit& orbit) {
  std::vector<double> rates;
  const auto& segs = orbit.signature.segments;
  for (size_t k = 0; k < segs.size(); ++k) {
    if (segs[k].tangent) {
      rates.push_back(RateAtTangentEnd(model, propagator, orbit, static_cast<int>(k)));
    }
  }
  return rates;
}

StatusOr<PeriodicOrbit> SolveTangentGrazing(const HybridModel& model, Propagator& propagator,
                                            const PeriodicOrbit& guess, int param,
                                            double tolerance) {
  if (std::isnan(TangentEndRate(model, propagator, guess))) {
    return InvalidArgument("the guess has no tangent end");
  }
  return SolveWithConditions(
      model, propagator, guess, {param},
      {ExtraCondition::OfSegmentFlow(
          TangentSegments(guess.signature).front(),
          [&](const PeriodicOrbit& o) { return TangentEndRate(model, propagator, o); })},
      tolerance, "tangency system");
}

ExtraCondition ExtraCondition::Duration(int segment, double length) {
  ExtraCondition c;
  c.kind = Kind::kDuration;
  c.segment = segment;
  c.length = length;
  return c;
}

ExtraCondition ExtraCondition::OfMonodromy(std::function<double(const Eigen::MatrixXd&)> f) {
  ExtraCondition c;
  c.kind = Kind::kMonodromy;
  c.of_monodromy = std::move(f);
  return c;
}

ExtraCondition ExtraCondition::Sigma(const HybridModel& model, Propagator& propagator,
                                     const PeriodicOrbit& at, CurveKind kind) {
  const BorderedSigma sigma(
      ShiftedMonodromy(kind, ReducedMonodromy(model, MonodromyFactors(model, propagator, at))));
  return OfMonodromy(
      [kind, sigma](const Eigen::MatrixXd& m) { return sigma(ShiftedMonodromy(kind, m)); });
}

ExtraCondition ExtraCondition::OfOrbit(std::function<double(const PeriodicOrbit&)> f) {
  ExtraCondition c;
  c.kind = Kind::kOrbit;
  c.of_orbit = std::move(f);
  return c;
}

ExtraCondition ExtraCondition::OfSegmentFlow(int segment,
                                             std::function<double(const PeriodicOrbit&)> f) {
  ExtraCondition c = OfOrbit(std::move(f));
  c.segment = segment;
  return c;
}

double ConditionValue(const HybridModel& model, Propagator& propagator, const PeriodicOrbit& orbit,
                      const ExtraCondition& condition) {
  switch (condition.kind) {
    case ExtraCondition::Kind::kDuration:
      return orbit.durations[condition.segment] - condition.length;
    case ExtraCondition::Kind::kMonodromy:
      return condition.of_monodromy(
          ReducedMonodromy(model, MonodromyFactors(model, propagator, orbit)));
    case ExtraCondition::Kind::kOrbit:
      break;
  }
  return condition.of_orbit(orbit);
}

namespace {

// The difference step of an unknown of value v (ConditionRow).
double Step(double v) { return 1e-6 * (1.0 + std::abs(v)); }

// SolveWithConditions' iterations.
constexpr int kMaxConditionIterations = 30;

// Whether Newton, whose scaled steps so far are `steps`, converges only linearly, too slowly to
// reach `tolerance` in the iterations left: its last five steps each shrank by one ratio between
// 0.7 and 1.01 (all five within 0.01), at the smallest of which the tolerance lies beyond the last
// iteration. Newton next to a singular root shrinks its steps by a fixed factor, 1 - 1/p at a root
// of order p, and repeats one step (ratio 1) where its residual does not move. In the reference
// box the fold / PD step-offs' whole systems that failed so ran at 0.73, 0.84, 0.89 or 1.00 for
// all their 16 to 30 iterations. Successful solves pass through such phases at 0.5 .. 0.67 (roots
// of order 2 and 3, e.g. a fixed-length orbit halving its step towards a double root) and land at
// rounding's floor, hence the lower bound; of the 28.5k solves that succeeded in the reference box
// and with --period2, none had five steps within 0.044 of one ratio in [0.7, 1.01] where this
// test would have stopped them.
bool ConvergesTooSlowly(const std::vector<double>& steps, double tolerance) {
  constexpr int kWindow = 5;
  const int k = static_cast<int>(steps.size());
  if (k <= kWindow) return false;
  double low = std::numeric_limits<double>::infinity(), high = 0.0;
  for (int j = k - kWindow; j < k; ++j) {
    const double ratio = steps[j] / steps[j - 1];
    low = std::min(low, ratio);
    high = std::max(high, ratio);
  }
  if (low < 0.7 || high > 1.01 || high - low > 0.01) return false;
  if (low >= 1.0) return true;
  const double needed = std::log(tolerance / steps.back()) / std::log(low);
  return k + needed > kMaxConditionIterations;
}

// The orbit at y = (X of `bvp`, the free parameters' values), the other parameters from `params`.
// Into *o (its storage reused).
void UnpackWithParams(const OrbitBvp& bvp, const std::vector<int>& free, const Params& params,
                      const Eigen::VectorXd& y, PeriodicOrbit* o) {
  const int m = bvp.size();
  Params p = params;
  for (size_t l = 0; l < free.size(); ++l) p[free[l]] = y[m + static_cast<int>(l)];
  bvp.Unpack(y.head(m), p, o);
}

// The same, returned.
PeriodicOrbit UnpackWithParams(const OrbitBvp& bvp, const std::vector<int>& free,
                               const Params& params, const Eigen::VectorXd& y) {
  PeriodicOrbit o;
  UnpackWithParams(bvp, free, params, y, &o);
  return o;
}

// The monodromy factors of an orbit with one unknown moved (MonodromyRow, MonodromyGradientRow).
class MovedFactors {
 public:
  // `flows` are the segments' flows the orbit's factors were made from; *moved receives a copy
  // of the orbit (its storage reused) to perturb.
  MovedFactors(const HybridModel& model, Propagator& propagator, const PeriodicOrbit& orbit,
               const std::vector<FlowResult>& flows, PeriodicOrbit* moved)
      : model_(model),
        propagator_(propagator),
        orbit_(orbit),
        flows_(flows),
        op_(*moved),
        affine_(dynamic_cast<const LinearForm*>(&model) != nullptr) {
    op_ = orbit;
  }

  // F_i with X's unknown r of segment i moved by `by`: its start's component at X's position r
  // (r < d: X has no phase) or its duration (r = d). With a LinearForm the flow is affine in the
  // start's non-phase part: moving it moves the end by Phi dx and leaves Phi, so only the
  // saltation is recomputed, from the segment's flow.
  StateMatrix Unknown(int i, int r, double by) {
    const int d = model_.state_dim() - 1;
    if (r == d) return Moved(i, op_.durations[i], by);
    const int state = r < model_.phase_index() ? r : r + 1;
    if (!affine_) return Moved(i, op_.starts[i][state], by);
    const FlowResult& flow = flows_[i];
    const StateVector x_end = flow.x + by * flow.state_jacobian.col(state);
    return FactorFromFlow(model_, orbit_, i, x_end, flow.state_jacobian);
  }

  // F_l with its start's phase moved by `by`.
  StateMatrix Phase(int l, double by) { return Moved(l, op_.starts[l][model_.phase_index()], by); }

 private:
  // F_l with `value` (an input of op_'s segment l) moved by `by`; op_ is restored after.
  StateMatrix Moved(int l, double& value, double by) {
    const double v0 = value;
    value += by;
    StateMatrix out = SegmentFactor(model_, propagator_, op_, l);
    value = v0;
    return out;
  }

  const HybridModel& model_;
  Propagator& propagator_;
  const PeriodicOrbit& orbit_;
  const std::vector<FlowResult>& flows_;
  PeriodicOrbit& op_;  // a copy of the orbit, perturbed in place and restored after each use
  bool affine_;        // the model has a LinearForm
};

// X's value of unknown r of segment i (a start's component without the phase, or the duration).
double UnknownValue(const HybridModel& model, const PeriodicOrbit& orbit, int i, int r) {
  const int d = model.state_dim() - 1, ps = model.phase_index();
  return r < d ? orbit.starts[i][r < ps ? r : r + 1] : orbit.durations[i];
}

// prefix[i] = F_{i-1} ... F_0 and suffix[i] = F_{k-1} ... F_i of the factors `base`, i = 0..k.
void PartialProducts(const std::vector<StateMatrix>& base, std::vector<StateMatrix>* prefix,
                     std::vector<StateMatrix>* suffix) {
  const int k = static_cast<int>(base.size()), n = static_cast<int>(base[0].rows());
  prefix->resize(k + 1);
  suffix->resize(k + 1);
  (*prefix)[0] = (*suffix)[k] = StateMatrix::Identity(n, n);
  for (int i = 0; i < k; ++i) MultiplyFactors(base[i], (*prefix)[i], &(*prefix)[i + 1]);
  for (int i = k - 1; i >= 0; --i) MultiplyFactors((*suffix)[i + 1], base[i], &(*suffix)[i]);
}

}  // namespace

void MonodromyRow(const HybridModel& model, Propagator& propagator, const PeriodicOrbit& orbit,
                  const std::vector<StateMatrix>& base, const std::vector<FlowResult>& flows,
                  const std::function<double(const Eigen::Ref<const Eigen::MatrixXd>&)>& f,
                  RowDifferences differences, double f0,
                  Eigen::Ref<Eigen::RowVectorXd, 0, Eigen::InnerStride<>> row,
                  MonodromyRowScratch* scratch) {
  const int k = static_cast<int>(base.size()), d = model.state_dim() - 1;
  const int ps = model.phase_index();
  const double omega = model.ForcingFrequency(orbit.params);
  const bool central = differences == RowDifferences::kCentral;
  auto step = [&](double v) { return central ? Step(v) : ForwardStep(v); };
  MonodromyRowScratch own;
  MonodromyRowScratch& w = scratch != nullptr ? *scratch : own;
  std::vector<StateMatrix>& prefix = w.prefix;
  std::vector<StateMatrix>& suffix = w.suffix;
  PartialProducts(base, &prefix, &suffix);
  MovedFactors moved(model, propagator, orbit, flows, &w.moved);
  // later[i] = sum over l > i of suffix[l + 1] (dF_l / ds_l) prefix[l]: d M per unit phase shift
  // of every segment after i (a duration moves the later phases by omega per unit).
  std::vector<StateMatrix>& later = w.later;
  later.resize(k);
  later[k - 1] = StateMatrix::Zero(d + 1, d + 1);
  for (int l = k - 1; l >= 1; --l) {
    const double h = step(orbit.starts[l][ps]);
    const StateMatrix dfl = central
                                ? StateMatrix((moved.Phase(l, h) - moved.Phase(l, -h)) / (2.0 * h))
                                : StateMatrix((moved.Phase(l, h) - base[l]) / h);
    later[l - 1] = later[l] + suffix[l + 1] * dfl * prefix[l];
  }
  for (int i = 0; i < k; ++i) {
    for (int r = 0; r <= d; ++r) {
      const double h = step(UnknownValue(model, orbit, i, r));
      // f with this unknown moved by sign * h.
      auto moved_f = [&](double sign) {
        StateMatrix full;
        if (r < d) {
          full = suffix[i + 1] * moved.Unknown(i, r, sign * h) * prefix[i];
        } else {
          full = prefix[k] + suffix[i + 1] * (moved.Unknown(i, r, sign * h) - base[i]) * prefix[i] +
                 (sign * omega * h) * later[i];
        }
        return f(WithoutPhase(model, full));
      };
      row[i * (d + 1) + r] =
          central ? (moved_f(1.0) - moved_f(-1.0)) / (2.0 * h) : (moved_f(1.0) - f0) / h;
    }
  }
}

void MonodromyGradientRow(const HybridModel& model, Propagator& propagator,
                          const PeriodicOrbit& orbit, const std::vector<StateMatrix>& base,
                          const std::vector<FlowResult>& flows,
                          const Eigen::Ref<const Eigen::MatrixXd>& gradient,
                          Eigen::Ref<Eigen::RowVectorXd, 0, Eigen::InnerStride<>> row,
                          MonodromyRowScratch* scratch) {
  const int k = static_cast<int>(base.size()), d = model.state_dim() - 1;
  const int ps = model.phase_index();
  const double omega = model.ForcingFrequency(orbit.params);
  MonodromyRowScratch own;
  MonodromyRowScratch& w = scratch != nullptr ? *scratch : own;
  std::vector<StateMatrix>& prefix = w.prefix;
  std::vector<StateMatrix>& suffix = w.suffix;
  PartialProducts(base, &prefix, &suffix);
  // The gradient in the full M: f does not see the phase row and column.
  StateMatrix full = StateMatrix::Zero(d + 1, d + 1);
  for (int a = 0; a <= d; ++a) {
    for (int b = 0; b <= d; ++b) {
      if (a != ps && b != ps) full(a, b) = gradient(a < ps ? a : a - 1, b < ps ? b : b - 1);
    }
  }
  // A change dF_i of factor i alone changes M by suffix[i + 1] dF_i prefix[i], and f by
  // <full, suffix[i + 1] dF_i prefix[i]> = <weight[i], dF_i> (Frobenius products) with
  // weight[i] = suffix[i + 1]^T full prefix[i]^T.
  std::vector<StateMatrix>& weight = w.weight;
  weight.resize(k);
  for (int i = 0; i < k; ++i) {
    weight[i] = suffix[i + 1].transpose() * full * prefix[i].transpose();
  }
  MovedFactors moved(model, propagator, orbit, flows, &w.moved);
  // later[i] = sum over l > i of <weight[l], dF_l / ds_l>: d f per unit phase shift of every
  // segment after i (MonodromyRow's later, contracted).
  std::vector<double>& later = w.later_rates;
  later.assign(k, 0.0);
  for (int l = k - 1; l >= 1; --l) {
    const double h = ForwardStep(orbit.starts[l][ps]);
    const StateMatrix dfl = (moved.Phase(l, h) - base[l]) / h;
    later[l - 1] = later[l] + weight[l].cwiseProduct(dfl).sum();
  }
  for (int i = 0; i < k; ++i) {
    for (int r = 0; r <= d; ++r) {
      const double h = ForwardStep(UnknownValue(model, orbit, i, r));
      const StateMatrix dfi = (moved.Unknown(i, r, h) - base[i]) / h;
      row[i * (d + 1) + r] = weight[i].cwiseProduct(dfi).sum() + (r == d ? omega * later[i] : 0.0);
    }
  }
}

double ConditionRow(const HybridModel& model, Propagator& propagator, const OrbitBvp& bvp,
                    const std::vector<int>& free, const Params& params, const Eigen::VectorXd& y,
                    const ExtraCondition& condition, Eigen::RowVectorXd* row) {
  const int m = bvp.size(), n = static_cast<int>(y.size());
  const PeriodicOrbit o = UnpackWithParams(bvp, free, params, y);
  row->setZero(n);
  if (condition.kind == ExtraCondition::Kind::kDuration) {
    (*row)[bvp.DurationIndex(condition.segment)] = 1.0;
    return ConditionValue(model, propagator, o, condition);
  }
  double c0;
  int first = 0;  // the first column by whole evaluations
  if (condition.kind == ExtraCondition::Kind::kMonodromy) {
    std::vector<FlowResult> flows;
    const std::vector<StateMatrix> factors = MonodromyFactors(model, propagator, o, &flows);
    c0 = condition.of_monodromy(ReducedMonodromy(model, factors));
    MonodromyRow(
        model, propagator, o, factors, flows,
        [&condition](const Eigen::Ref<const Eigen::MatrixXd>& mono) {
          return condition.of_monodromy(mono);
        },
        RowDifferences::kCentral, c0, row->head(m));
    first = m;
  } else {
    c0 = condition.of_orbit(o);
  }
  // y moved in one entry at a time, restored after (the same bits as a fresh copy), and the
  // moved orbits unpacked into one: no allocation per column.
  Eigen::VectorXd yq = y;
  PeriodicOrbit moved;
  const int block = bvp.DurationIndex(0) + 1, only = condition.segment;
  for (int j = first; j < n; ++j) {
    const double h = Step(y[j]);
    // (OfSegmentFlow: the unknowns that move its segment's flow, the rest exactly (c0 - c0).)
    if (!MovesSegmentFlow(j, only, block, m)) {
      (*row)[j] = (c0 - c0) / (2.0 * h);
      continue;
    }
    yq[j] = y[j] + h;
    UnpackWithParams(bvp, free, params, yq, &moved);
    const double cp = ConditionValue(model, propagator, moved, condition);
    yq[j] = y[j] - h;
    UnpackWithParams(bvp, free, params, yq, &moved);
    const double cm = ConditionValue(model, propagator, moved, condition);
    yq[j] = y[j];
    (*row)[j] = (cp - cm) / (2.0 * h);
  }
  return c0;
}

StatusOr<PeriodicOrbit> SolveWithConditions(const HybridModel& model, Propagator& propagator,
                                            const PeriodicOrbit& guess,
                                            const std::vector<int>& free,
                                            const std::vector<ExtraCondition>& conditions,
                                            double tolerance, const std::string& what) {
  const int q = static_cast<int>(free.size());
  if (q < 1 || q > 2) return InvalidArgument("one or two free parameters");
  if (static_cast<int>(conditions.size()) != q) {
    return InvalidArgument("the conditions must have one row per free parameter");
  }
  OrbitBvp bvp(model, propagator, guess.signature, free[0], q > 1 ? free[1] : -1);
  const int m = bvp.size(), n = m + q;
  Params params = guess.params;
  Eigen::VectorXd y(n);
  y.head(m) = bvp.Pack(guess);
  for (int l = 0; l < q; ++l) y[m + l] = params[free[l]];
  Eigen::VectorXd g, gp[2], f(n);
  Eigen::MatrixXd jac(n, n);
  Eigen::RowVectorXd row;
  std::vector<double> steps;  // scaled step norms, for the stagnation test below
  for (int it = 0; it < kMaxConditionIterations; ++it) {
    for (int l = 0; l < q; ++l) params[free[l]] = y[m + l];
    if (!model.ValidateParams(params).ok()) return Internal("left the parameter domain");
    // Every entry of jac is written below: G_X (zeroed by EvaluateInto), G_p, the condition rows.
    if (Status s = bvp.EvaluateInto(y.head(m), params, &g, jac.topLeftCorner(m, m), &gp[0],
                                    q > 1 ? &gp[1] : nullptr);
        !s.ok()) {
      return s;
    }
    f.head(m) = g;
    for (int l = 0; l < q; ++l) jac.col(m + l).head(m) = gp[l];
    for (int l = 0; l < q; ++l) {
      f[m + l] = ConditionRow(model, propagator, bvp, free, params, y, conditions[l], &row);
      jac.row(m + l) = row;
    }
    if (!f.allFinite() || !jac.allFinite()) return Internal("non-finite " + what);
    const Eigen::VectorXd step = jac.partialPivLu().solve(-f);
    if (!step.allFinite()) return Internal("singular " + what);
    y += step;
    const double scaled = step.lpNorm<Eigen::Infinity>() / (1.0 + y.lpNorm<Eigen::Infinity>());
    if (scaled <= tolerance) return UnpackWithParams(bvp, free, params, y);
    // Stagnation: Newton that has not shrunk its smallest step tenfold over the last 8
    // iterations (after 16) is not converging, even linearly (a contraction of 0.75 per step
    // would): stop rather than spend the remaining iterations. Without this test the failing
    // step-offs take about a quarter of the reference box's trace time; with it the step-offs
    // that succeed are the same, and so are the codimension-2 points found (plus a double
    // grazing that COARSE steps find either way). (A window of 6 after 12 loses a slowly
    // converging step-off.)
    steps.push_back(scaled);
    const int k = static_cast<int>(steps.size());
    // And sooner where it converges only linearly, too slowly to end in time.
    if ((k >= 16 && *std::min_element(steps.end() - 8, steps.end()) >
                        0.1 * *std::min_element(steps.end() - 16, steps.end() - 8)) ||
        ConvergesTooSlowly(steps, tolerance)) {
      return Internal("the " + what + " stagnated");
    }
  }
  return Internal("the " + what + " did not converge");
}

}  // namespace drillbif::internal
