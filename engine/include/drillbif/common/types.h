// Small fixed-capacity Eigen types used throughout the engine. Dynamic size with a compile-time
// maximum keeps every state, Jacobian and parameter vector on the stack: the simulation hot path
// never allocates.
#ifndef DRILLBIF_COMMON_TYPES_H_
#define DRILLBIF_COMMON_TYPES_H_

#include <Eigen/Core>

namespace drillbif {

inline constexpr int kMaxStateDim = 8;  // continuous state, including the forcing phase
inline constexpr int kMaxParams = 12;   // model parameters
inline constexpr double kTwoPi = 6.283185307179586476925286766559;

using StateVector = Eigen::Matrix<double, Eigen::Dynamic, 1, Eigen::ColMajor, kMaxStateDim, 1>;
using StateMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor,
                                  kMaxStateDim, kMaxStateDim>;
using ParamVector = Eigen::Matrix<double, Eigen::Dynamic, 1, Eigen::ColMajor, kMaxParams, 1>;
// d(state)/d(parameters): state_dim rows, num_params columns.
using ParamMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor,
                                  kMaxStateDim, kMaxParams>;
// d(scalar)/d(state) as a row.
using StateRow = Eigen::Matrix<double, 1, Eigen::Dynamic, Eigen::RowMajor, 1, kMaxStateDim>;

}  // namespace drillbif

#endif  // DRILLBIF_COMMON_TYPES_H_
