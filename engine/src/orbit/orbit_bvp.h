// The multi-segment boundary-value system of a periodic orbit (see orbit/periodic_orbit.h for the
// unknowns and conditions): residual, Jacobian in the unknowns, and derivative in one parameter.
// Shared by the orbit solver and the continuation.
#ifndef DRILLBIF_ORBIT_ORBIT_BVP_H_
#define DRILLBIF_ORBIT_ORBIT_BVP_H_

#include <Eigen/Dense>
#include <span>
#include <vector>

#include "drillbif/flow/propagator.h"
#include "drillbif/orbit/periodic_orbit.h"

namespace drillbif::internal {

// The columns `columns` of a * b, for an n x n `a` and an n x m `b`, into *out (resized to n x m;
// its other columns are left as they were or are a * b's): the same bits as Eigen's
// `out->noalias() = a * b` gives them (its general product kernel for these shapes starts every
// entry from +0, adds the depth's products in order, and adds the sum, times alpha = 1, to the
// zeroed destination). Where Eigen would take its coefficient-based product instead (2 n + m
// below EIGEN_GEMM_TO_COEFFBASED_THRESHOLD), or `a` is not finite, it is Eigen's product itself.
void ProductOnColumns(const StateMatrix& a, const Eigen::MatrixXd& b, std::span<const int> columns,
                      Eigen::MatrixXd* out);

class OrbitBvp {
 public:
  // `param`: index of the parameter whose derivative Evaluate() can give (-1: none); `param2`
  // a second one (a two-parameter curve's), given in the same pass of flows.
  OrbitBvp(const HybridModel& model, Propagator& propagator, Signature signature, int param,
           int param2 = -1);

  const Signature& signature() const { return signature_; }
  // Number of unknowns (= number of conditions): k (d + 1) with k segments, d = state_dim - 1.
  int size() const { return segments() * (d_ + 1); }
  // Index in X of segment i's duration (after its start state).
  int DurationIndex(int i) const { return i * (d_ + 1) + d_; }
  int segments() const { return static_cast<int>(signature_.segments.size()); }

  // X from an orbit of this signature, and back (the phases s_i follow from the durations).
  Eigen::VectorXd Pack(const PeriodicOrbit& orbit) const;
  void Unpack(const Eigen::Ref<const Eigen::VectorXd>& x, const Params& params,
              PeriodicOrbit* orbit) const;

  // G(X; params), and when non-null dG/dX, dG/dparams[param] and dG/dparams[param2]. INTERNAL
  // if a flow fails. `flows`, when non-null, receives each segment's flow with its state
  // Jacobian (for the monodromy's factors: orbit/monodromy.h, FactorsFromFlows).
  Status Evaluate(const Eigen::Ref<const Eigen::VectorXd>& x, const Params& params,
                  Eigen::VectorXd* g, Eigen::MatrixXd* gx, Eigen::VectorXd* gp,
                  Eigen::VectorXd* gp2 = nullptr, std::vector<FlowResult>* flows = nullptr) const;
  // As Evaluate, with dG/dX written into `gx`, a size() x size() block (e.g. the top-left corner
  // of a continuation's Jacobian), instead of a matrix that the caller would then copy there.
  Status EvaluateInto(const Eigen::Ref<const Eigen::VectorXd>& x, const Params& params,
                      Eigen::VectorXd* g, Eigen::Ref<Eigen::MatrixXd> gx, Eigen::VectorXd* gp,
                      Eigen::VectorXd* gp2 = nullptr,
                      std::vector<FlowResult>* flows = nullptr) const;

 private:
  // Evaluate's body; `gx`, when non-null, is size() x size().
  Status EvaluateImpl(const Eigen::Ref<const Eigen::VectorXd>& x, const Params& params,
                      Eigen::VectorXd* g, Eigen::Ref<Eigen::MatrixXd>* gx, Eigen::VectorXd* gp,
                      Eigen::VectorXd* gp2, std::vector<FlowResult>* flows) const;
  // gx's rows first, first + 1, ... = -(`src`'s rows but the phase's) in the columns
  // dend_columns_ (src n x size()).
  void NegatedRowsWithoutPhase(const Eigen::MatrixXd& src, int first,
                               Eigen::Ref<Eigen::MatrixXd>* gx) const;

  const HybridModel& model_;
  Propagator& propagator_;
  Signature signature_;
  int param_, param2_;
  int d_;   // reduced state dimension
  int ps_;  // phase index
  // Evaluate's workspace (d end / dX, and the jump's Jacobian times it), kept so that Newton's
  // iterations do not allocate it anew: an OrbitBvp is used by one thread (its propagator's).
  mutable Eigen::MatrixXd dend_, jdend_;
  mutable std::vector<int> dend_columns_;  // dend_'s columns that are not zero (its segment's)
};

}  // namespace drillbif::internal

#endif  // DRILLBIF_ORBIT_ORBIT_BVP_H_
