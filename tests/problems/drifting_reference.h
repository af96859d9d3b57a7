// Reference values of the drifting impact oscillator published in shared MODEL.md, from an
// independent high-precision computation (closed-form flows, events polished to machine precision,
// checked against an adaptive integrator at rtol 1e-12). Each value carries its stated precision.
#ifndef DRILLBIF_TESTS_PROBLEMS_DRIFTING_REFERENCE_H_
#define DRILLBIF_TESTS_PROBLEMS_DRIFTING_REFERENCE_H_

#include "drillbif/model/drifting_oscillator.h"

namespace drillbif::testing {

// Reference parameters a = 0.3, b = 0.15, omega = 0.1, xi = 0.05, g = 0.02, phi0 = 0.
inline Params ReferenceParams() { return DriftingOscillator::MakeParams(); }

// Fixed point of the Poincare map at s = 0 of the stable period-1 orbit, to 1e-7 (7 decimals).
inline constexpr double kRefFixedP = -60.1843758;
inline constexpr double kRefFixedY = 2.7611142;
inline constexpr double kRefFixedQ = 0.0;
inline constexpr double kRefFixedPrecision = 1e-7;

// Means over the orbit, to 10 decimals.
inline constexpr double kRefRop = 0.4988765850;
inline constexpr double kRefPc = 0.0084749152;
inline constexpr double kRefMeasurePrecision = 1e-10;

// Phases of the events in one period (5 decimals): impact, progression start, progression end,
// separation.
inline constexpr double kRefImpactS = 1.16088;
inline constexpr double kRefProgressionS = 1.16470;
inline constexpr double kRefStickS = 2.01055;
inline constexpr double kRefSeparationS = 2.16351;
inline constexpr double kRefPhasePrecision = 1e-5;

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_PROBLEMS_DRIFTING_REFERENCE_H_
