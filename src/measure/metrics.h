// Error metrics for the convergence studies (`tuile converge`, error against time):
// MSE, relative MSE (relMSE = mean((x - r)^2 / (r^2 + eps))) and Veach's efficiency
// 1 / (relMSE * T); plus the log-log helpers the converge report and the plots use.
#pragma once
#include <cstdint>
#include <vector>

namespace tuile {

struct Film;

inline constexpr double relmse_epsilon = 0.01;

// Mean over pixels and channels of (x - ref)^2. Sizes must match (std::invalid_argument).
double mse(const std::vector<float>& x, const std::vector<float>& ref);
// Mean over pixels and channels of (x - ref)^2 / (ref^2 + eps).
double relmse(const std::vector<float>& x, const std::vector<float>& ref, double eps = relmse_epsilon);
// relMSE as the film itself estimates it: the mean over pixels and channels of the
// variance of the pixel mean over (mean^2 + eps). With an unbiased estimator this is the
// expected relMSE against the exact image (what `tuile render --target-error` stops on).
// Infinite below min_samples_for_error_estimate samples per pixel, where the per-pixel
// variances are too few to trust.
inline constexpr uint64_t min_samples_for_error_estimate = 8;
double estimated_relmse(const Film& film, double eps = relmse_epsilon);
// 1 / (relmse * seconds); +inf when the product is 0, NaN when either is negative or NaN.
double efficiency(double relmse, double seconds);

// Least-squares slope of log(y) against log(x) over the points with x > 0 and y > 0.
// NaN with fewer than two usable points or no spread in x.
double loglog_slope(const std::vector<double>& x, const std::vector<double>& y);
// y at x by linear interpolation of log(y) in log(x) between the bracketing points
// (x ascending). NaN when x is outside [x.front(), x.back()].
double loglog_interpolate(const std::vector<double>& x, const std::vector<double>& y, double at);

}  // namespace tuile
