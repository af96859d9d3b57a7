#include "problems/forced_rotation.h"

#include <cmath>

namespace drillbif::testing {

Params ForcedRotation::MakeParams(double mu, double amplitude, double omega) {
  Params p(3);
  p << mu, amplitude, omega;
  return p;
}

Status ForcedRotation::ValidateParams(const Params& p) const {
  if (p.size() != 3 || !p.allFinite()) return InvalidArgument("forced_rotation: 3 finite params");
  if (!(p[kOmega] > 0.0)) return InvalidArgument("omega must be > 0");
  return Status::Ok();
}

Status ForcedRotation::ValidateState(const StateVector& x, const Params&, double) const {
  if (x.size() != 3 || !x.allFinite()) return InvalidArgument("forced_rotation: 3 finite states");
  return Status::Ok();
}

void ForcedRotation::VectorField(int, const StateVector& x, const Params& p,
                                 StateVector* dx) const {
  dx->resize(3);
  (*dx)[kX] = p[kMu] * x[kX] - x[kY] + p[kAmplitude] * std::cos(x[kS]);
  (*dx)[kY] = x[kX] + p[kMu] * x[kY];
  (*dx)[kS] = p[kOmega];
}

void ForcedRotation::StateJacobian(int, const StateVector& x, const Params& p,
                                   StateMatrix* j) const {
  j->setZero(3, 3);
  (*j)(kX, kX) = p[kMu], (*j)(kX, kY) = -1.0, (*j)(kX, kS) = -p[kAmplitude] * std::sin(x[kS]);
  (*j)(kY, kX) = 1.0, (*j)(kY, kY) = p[kMu];
}

void ForcedRotation::ParamJacobian(int, const StateVector& x, const Params&, ParamMatrix* j) const {
  j->setZero(3, 3);
  (*j)(kX, kMu) = x[kX], (*j)(kY, kMu) = x[kY];
  (*j)(kX, kAmplitude) = std::cos(x[kS]);
  (*j)(kS, kOmega) = 1.0;
}

Transition ForcedRotation::Jump(int, int, const StateVector& x, const Params&) const {
  Transition t;
  t.x = x;
  t.jacobian = StateMatrix::Identity(3, 3);
  t.param_jacobian = ParamMatrix::Zero(3, 3);
  return t;
}

MeasureVector ForcedRotation::MeasureRates(int, const StateVector& x, const Params&) const {
  MeasureVector m(2);
  m << x[kX] * x[kX], x[kY] * x[kY];
  return m;
}

double ForcedRotation::TimeScale(int, const Params& p) const {
  return 1.0 / std::max({1.0, std::abs(p[kMu]), p[kOmega]});
}

void ForcedRotation::ToAugmented(const StateVector& x, const Params&, Eigen::VectorXd* z) const {
  z->resize(5);
  *z << x[kX], x[kY], std::cos(x[kS]), std::sin(x[kS]), 1.0;
}

void ForcedRotation::AugmentedMatrix(int, const Params& p, Eigen::MatrixXd* a) const {
  a->setZero(5, 5);
  (*a)(0, 0) = p[kMu], (*a)(0, 1) = -1.0, (*a)(0, 2) = p[kAmplitude];
  (*a)(1, 0) = 1.0, (*a)(1, 1) = p[kMu];
  (*a)(2, 3) = -p[kOmega], (*a)(3, 2) = p[kOmega];
}

void ForcedRotation::AugmentedMatrixDerivative(int, const Params&, int k,
                                               Eigen::MatrixXd* da) const {
  da->setZero(5, 5);
  if (k == kMu) (*da)(0, 0) = (*da)(1, 1) = 1.0;
  if (k == kAmplitude) (*da)(0, 2) = 1.0;
  if (k == kOmega) (*da)(2, 3) = -1.0, (*da)(3, 2) = 1.0;
}

void ForcedRotation::AugmentedInitialDerivative(const StateVector&, const Params&, int,
                                                Eigen::VectorXd* dz) const {
  dz->setZero(5);
}

}  // namespace drillbif::testing
