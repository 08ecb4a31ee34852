// ptm's predictor 5: the encoder's solve of the fitted normal equations
// (ptm_least_squares_fit.h).
#include "ptm/ptm_least_squares_fit.h"

#include <cmath>
#include <utility>

namespace tessera::detail {

namespace {

// One position's and channel's weights: least squares with a light ridge, so that a position
// or channel the tile barely uses gets small weights rather than wild ones, rounded to signed
// bytes. Gaussian elimination with partial pivoting on the 9x9 system; without the estimate,
// its row and column are the identity's and its moment 0, which solves the other eight terms'
// system and gives the estimate the weight 0.
void solveOne(const double (&gram)[kLsTerms][kLsTerms], const double (&moment)[kLsTerms],
              bool with_estimate, int8_t* weights) {
  double a[kLsTerms][kLsTerms + 1];
  for (uint32_t i = 0; i < kLsTerms; ++i) {
    for (uint32_t j = 0; j < kLsTerms; ++j) a[i][j] = i <= j ? gram[i][j] : gram[j][i];
    a[i][i] += 1e-3 * a[i][i] + 1;
    a[i][kLsTerms] = moment[i];
  }
  if (!with_estimate) {
    constexpr uint32_t kEstimate = kLsTerms - 1;
    for (uint32_t i = 0; i <= kLsTerms; ++i) a[kEstimate][i] = 0;
    for (uint32_t i = 0; i < kLsTerms; ++i) a[i][kEstimate] = 0;
    a[kEstimate][kEstimate] = 1;
  }
  for (uint32_t i = 0; i < kLsTerms; ++i) {
    uint32_t pivot = i;
    for (uint32_t k = i + 1; k < kLsTerms; ++k)
      if (std::abs(a[k][i]) > std::abs(a[pivot][i])) pivot = k;
    std::swap(a[i], a[pivot]);
    for (uint32_t k = 0; k < kLsTerms; ++k) {
      if (k == i) continue;
      const double factor = a[k][i] / a[i][i];
      for (uint32_t j = i; j <= kLsTerms; ++j) a[k][j] -= factor * a[i][j];
    }
  }
  for (uint32_t i = 0; i < kLsTerms; ++i) {
    const double weight = std::round(128 * a[i][kLsTerms] / a[i][i]);
    weights[i] = int8_t(std::clamp(weight, -128.0, 127.0));
  }
}

}  // namespace

void solveLeastSquares(const LsFit& fit, uint32_t channels, bool with_estimate, int8_t* weights) {
  for (uint32_t set = 0; set < kLsSets; ++set)
    for (uint32_t c = 0; c < channels; ++c)
      solveOne(fit.gram[set][c], fit.moment[set][c], with_estimate,
               weights + (set * channels + c) * kLsTerms);
}

}  // namespace tessera::detail
