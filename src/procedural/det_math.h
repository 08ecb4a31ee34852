#pragma once
// Sine and cosine from IEEE additions and multiplications only, so every machine computes the
// same bits (libm's sin and cos differ between versions and platforms); the compositor's
// per-instance setup depends on them and must be deterministic to the bit.

#include <cmath>

namespace tessera::detail {

/// sin and cos of `angle` (radians, |angle| < 1e6) to about 1e-15.
inline void detSinCos(double angle, double* sine, double* cosine) {
  constexpr double kInvHalfPi = 0.63661977236758134308;
  // Quadrant by rounding (IEEE-exact), then a Cody-Waite style two-part reduction.
  double k = std::nearbyint(angle * kInvHalfPi);
  constexpr double kHalfPiHigh = 1.5707963267341256e+00;
  constexpr double kHalfPiLow = 6.0771005065061922e-11;
  double r = (angle - k * kHalfPiHigh) - k * kHalfPiLow;
  double r2 = r * r;
  // Taylor series to r^17 / r^18: |r| <= pi/4 makes the next term < 1e-17.
  double s =
      r * (1 + r2 * (-1.0 / 6 +
                     r2 * (1.0 / 120 +
                           r2 * (-1.0 / 5040 +
                                 r2 * (1.0 / 362880 +
                                       r2 * (-1.0 / 39916800 +
                                             r2 * (1.0 / 6227020800.0 +
                                                   r2 * (-1.0 / 1307674368000.0 +
                                                         r2 * (1.0 / 355687428096000.0)))))))));
  double c =
      1 + r2 * (-1.0 / 2 +
                r2 * (1.0 / 24 +
                      r2 * (-1.0 / 720 +
                            r2 * (1.0 / 40320 +
                                  r2 * (-1.0 / 3628800 +
                                        r2 * (1.0 / 479001600 +
                                              r2 * (-1.0 / 87178291200.0 +
                                                    r2 * (1.0 / 20922789888000.0 +
                                                          r2 * (-1.0 / 6402373705728000.0)))))))));
  long quadrant = long(std::fmod(k, 4.0));
  if (quadrant < 0) quadrant += 4;
  switch (quadrant) {
    case 0:
      *sine = s;
      *cosine = c;
      break;
    case 1:
      *sine = c;
      *cosine = -s;
      break;
    case 2:
      *sine = -s;
      *cosine = -c;
      break;
    default:
      *sine = -c;
      *cosine = s;
      break;
  }
}

}  // namespace tessera::detail
