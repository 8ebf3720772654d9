// Model::step (explicit Euler) against a local RK4, for every model's tests
// (test/core/models/): first order, converging to the RK4 reference.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

namespace mppi::testing {

// Classic RK4 with the state accumulated in double (the derivative is the model's float one):
// its error at h = 1e-3 over 1 s is ~h^4 (1e-12), far below everything it is compared with.
template <class Model>
std::vector<double> rk4(const typename Model::Params& p, std::vector<double> x, const std::vector<float>& u,
                        double h, int steps) {
  const int n = Model::kNx;
  auto f = [&](const std::vector<double>& s) {
    std::vector<float> sf(s.begin(), s.end()), df(n);
    for (int i = 0; i < n; ++i) sf[i] = static_cast<float>(s[i]);
    Model::derivative(p, sf.data(), u.data(), df.data());
    return std::vector<double>(df.begin(), df.end());
  };
  std::vector<double> tmp(n);
  for (int k = 0; k < steps; ++k) {
    const auto k1 = f(x);
    for (int i = 0; i < n; ++i) tmp[i] = x[i] + 0.5 * h * k1[i];
    const auto k2 = f(tmp);
    for (int i = 0; i < n; ++i) tmp[i] = x[i] + 0.5 * h * k2[i];
    const auto k3 = f(tmp);
    for (int i = 0; i < n; ++i) tmp[i] = x[i] + h * k3[i];
    const auto k4 = f(tmp);
    for (int i = 0; i < n; ++i) x[i] += h / 6.0 * (k1[i] + 2 * k2[i] + 2 * k3[i] + k4[i]);
  }
  return x;
}

template <class Model>
std::vector<float> euler(const typename Model::Params& p, std::vector<float> x, const std::vector<float>& u,
                         float h, int steps) {
  for (int k = 0; k < steps; ++k) Model::step(p, x.data(), u.data(), h);
  return x;
}

// Explicit Euler with the state accumulated in double, on the model's float derivative.
template <class Model>
std::vector<double> euler_double(const typename Model::Params& p, std::vector<double> x, const std::vector<float>& u,
                                 double h, int steps) {
  std::vector<float> xf(x.size()), df(x.size());
  for (int k = 0; k < steps; ++k) {
    for (std::size_t i = 0; i < x.size(); ++i) xf[i] = static_cast<float>(x[i]);
    Model::derivative(p, xf.data(), u.data(), df.data());
    for (std::size_t i = 0; i < x.size(); ++i) x[i] += h * df[i];
  }
  return x;
}

// Error norm with every component scaled by (1 + |reference|), so rpm and metres weigh alike.
template <class V>
double scaled_error(const V& x, const std::vector<double>& ref) {
  double e = 0.0;
  for (std::size_t i = 0; i < x.size(); ++i) e = std::max(e, std::fabs(x[i] - ref[i]) / (1.0 + std::fabs(ref[i])));
  return e;
}

template <class Model>
void check_integrator(const typename Model::Params& p, const std::vector<float>& x0, const std::vector<float>& u,
                      const char* what) {
  SCOPED_TRACE(what);
  const std::vector<double> x0d(x0.begin(), x0.end());
  const auto ref = rk4<Model>(p, x0d, u, 1e-3, 1000);  // 1 s
  for (double v : ref) ASSERT_TRUE(std::isfinite(v));
  // The trajectory actually moves (otherwise agreement would prove nothing).
  double moved = 0.0;
  for (std::size_t i = 0; i < ref.size(); ++i) moved = std::max(moved, std::fabs(ref[i] - x0d[i]) / (1 + std::fabs(x0d[i])));
  EXPECT_GT(moved, 0.05);

  // Model::step (float Euler) is first order: halving the step halves the error (ratio 2;
  // 1.6..2.5 allows the O(h^2) terms at these steps).
  const double e1 = scaled_error(euler<Model>(p, x0, u, 1e-2f, 100), ref);
  const double e2 = scaled_error(euler<Model>(p, x0, u, 5e-3f, 200), ref);
  const double e3 = scaled_error(euler<Model>(p, x0, u, 2.5e-3f, 400), ref);
  EXPECT_GT(e1, 1e-4) << "the coarse step must show a truncation error well above rounding";
  EXPECT_NEAR(e1 / e2, 2.0, 0.45) << e1 << " " << e2;
  EXPECT_NEAR(e2 / e3, 2.0, 0.45) << e2 << " " << e3;

  // Euler at h = 1e-4 (state accumulated in double: in float, a motor speed of ~3170 rpm
  // stops moving once h k_m |w_des - w| < ulp/2, i.e. within 0.06 rpm of its command, which
  // is rounding, not the integrator). Leading global error (h T / 2) max|x''| / (1 + |x|):
  // the fastest dynamics here are ~40 s^-2 (cart-pole: (m_c + m_p) g / (l m_c) = 39.6), so
  // ~2e-3 at most; 5e-3 leaves margin. And being first order, it is ~1/100 of e1.
  const auto fine = euler_double<Model>(p, x0d, u, 1e-4, 10000);
  const double e_fine = scaled_error(fine, ref);
  EXPECT_LT(e_fine, 5e-3);
  EXPECT_GT(e_fine, 0.5 * e1 / 100.0);
  EXPECT_LT(e_fine, 1.5 * e1 / 100.0);
}

}  // namespace mppi::testing
