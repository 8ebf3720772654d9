// The DDP baseline's pieces: iLQR against the Riccati solution of a linear-quadratic
// problem, the finite-difference derivatives against analytic ones (on the shared
// quadrotor model among others), and settings refused by field name.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <limits>
#include <vector>

#include "mppi/ddp/ddp_controller.hpp"
#include "mppi/ddp/finite_difference.hpp"
#include "mppi/ddp/ilqr.hpp"
#include "mppi/tasks.hpp"

namespace mppi {
namespace {

// x_{i+1} = A x_i + B u_i, s(x) = 1/2 x^T Q x, phi(x) = 1/2 x^T Qf x, R diagonal.
struct LqProblem {
  static constexpr int kNx = 3;
  static constexpr int kNu = 2;
  Eigen::Matrix3d a, q, qf;
  Eigen::Matrix<double, 3, 2> b;
  double r[kNu] = {0.5, 2.0};
  double u_ref[kNu] = {0.0, 0.0};
  double u_lo[kNu], u_hi[kNu];

  LqProblem() {
    a << 1.0, 0.1, 0.0, -0.2, 0.95, 0.1, 0.05, 0.0, 1.02;
    b << 0.0, 0.1, 0.2, 0.0, 0.05, 0.1;
    q = Eigen::Vector3d(1.0, 0.5, 2.0).asDiagonal();
    q(0, 2) = q(2, 0) = 0.3;
    qf = 10.0 * Eigen::Matrix3d::Identity();
    for (int j = 0; j < kNu; ++j) {
      u_lo[j] = -std::numeric_limits<double>::infinity();
      u_hi[j] = std::numeric_limits<double>::infinity();
    }
  }
  void step(const double* x, const double* u, double* xn) const {
    Eigen::Map<Eigen::Vector3d> out(xn);
    out = a * Eigen::Map<const Eigen::Vector3d>(x) + b * Eigen::Map<const Eigen::Vector2d>(u);
  }
  double state_cost(const double* x, int) const {
    const Eigen::Map<const Eigen::Vector3d> v(x);
    return 0.5 * v.dot(q * v);
  }
  double terminal_cost(const double* x) const {
    const Eigen::Map<const Eigen::Vector3d> v(x);
    return 0.5 * v.dot(qf * v);
  }
};

TEST(Ilqr, ConvergesToTheRiccatiSolutionOfAnLqProblem) {
  const LqProblem p;
  const int n = 30;
  // Riccati: the state cost is paid at x_1 .. x_N, so P_N = Q + Qf and stage cost Q.
  const Eigen::Matrix2d r = Eigen::Vector2d(p.r[0], p.r[1]).asDiagonal();
  std::vector<Eigen::Matrix<double, 2, 3>> gain(n);
  Eigen::Matrix3d pm = p.q + p.qf;
  for (int i = n - 1; i >= 0; --i) {
    gain[i] = (r + p.b.transpose() * pm * p.b).ldlt().solve(p.b.transpose() * pm * p.a);
    const Eigen::Matrix3d cl = p.a - p.b * gain[i];
    pm = (i > 0 ? p.q : Eigen::Matrix3d::Zero()) + cl.transpose() * pm * cl + gain[i].transpose() * r * gain[i];
  }
  const Eigen::Vector3d x0(1.0, -0.5, 0.8);
  std::vector<double> u_star(2 * n);
  Eigen::Vector3d x = x0;
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector2d u = -gain[i] * x;
    u_star[2 * i] = u(0);
    u_star[2 * i + 1] = u(1);
    x = p.a * x + p.b * u;
  }

  DdpSettings s;
  s.max_iterations = 5;
  s.mu_init = 0.0;
  s.mu_min = 0.0;
  ddp::Ilqr<LqProblem> solver(s, n);
  std::vector<double> plan(2 * n, 0.0);
  const auto res = solver.solve(p, x0.data(), plan.data());
  ASSERT_TRUE(res.finite);
  EXPECT_GE(res.accepted, 1);
  EXPECT_LT(res.cost, res.cost_initial);
  for (int k = 0; k < 2 * n; ++k) EXPECT_NEAR(plan[k], u_star[k], 1e-6) << "control " << k;
  // The feedback gains of the last backward pass are the Riccati gains.
  for (int i = 0; i < n; ++i) EXPECT_LT((solver.gains()[i] + gain[i]).cwiseAbs().maxCoeff(), 1e-5) << "step " << i;
  // The optimum is a minimum: any other plan costs more.
  std::vector<double> other = plan;
  other[7] += 0.01;
  EXPECT_GT(solver.cost_of(p, x0.data(), other.data()), solver.cost_of(p, x0.data(), plan.data()));
}

TEST(Ilqr, KeepsControlsInsideTheirLimits) {
  LqProblem p;
  for (int j = 0; j < 2; ++j) {
    p.u_lo[j] = -0.3;
    p.u_hi[j] = 0.3;
  }
  DdpSettings s;
  s.max_iterations = 20;
  ddp::Ilqr<LqProblem> solver(s, 30);
  std::vector<double> plan(60, 0.0);
  const double x0[3] = {3.0, -2.0, 2.5};  // far away: the unconstrained optimum saturates
  const auto res = solver.solve(p, x0, plan.data());
  ASSERT_TRUE(res.finite);
  EXPECT_LT(res.cost, res.cost_initial);
  int at_bound = 0;
  for (double u : plan) {
    EXPECT_GE(u, -0.3);
    EXPECT_LE(u, 0.3);
    at_bound += std::fabs(std::fabs(u) - 0.3) < 1e-12;
  }
  EXPECT_GT(at_bound, 0) << "the limits never bound: the test does not test them";
}

TEST(FiniteDifference, StepJacobiansMatchAnAnalyticFunction) {
  // f(x, u) = (sin(x0) u0, x0 x1 + u1^2, exp(x1) - u0 u1)
  auto f = [](const double* x, const double* u, double* y) {
    y[0] = std::sin(x[0]) * u[0];
    y[1] = x[0] * x[1] + u[1] * u[1];
    y[2] = std::exp(x[1]) - u[0] * u[1];
  };
  const double x[2] = {0.7, -0.4}, u[2] = {1.5, -2.0};
  // A function of 2 states into 3 outputs is not a step; embed it: 3 states, x2 unused.
  double a[9], b[6];
  const double x3[3] = {x[0], x[1], 0.0};
  ddp::step_jacobians<3, 2>([&](const double* xs, const double* us, double* y) { f(xs, us, y); }, x3, u, 1e-5, a, b);
  const double da[9] = {std::cos(x[0]) * u[0], x[1], 0.0,  // column 0 (d/dx0)
                        0.0, x[0], std::exp(x[1]),           // column 1
                        0.0, 0.0, 0.0};                      // column 2
  const double db[6] = {std::sin(x[0]), 0.0, -u[1], 0.0, 2.0 * u[1], -u[0]};
  for (int k = 0; k < 9; ++k) EXPECT_NEAR(a[k], da[k], 1e-8) << "A entry " << k;
  for (int k = 0; k < 6; ++k) EXPECT_NEAR(b[k], db[k], 1e-8) << "B entry " << k;
}

TEST(FiniteDifference, QuadrotorStepJacobianMatchesTheModelAnalytically) {
  // Entries of the shared model's Euler step known in closed form, from a tilted state.
  Quadrotor::Params p;
  const float dt = 0.02f;
  double x[16] = {1.0, 2.0, 3.0, 0.5, -0.3, 0.2, 0.1, -0.2, 0.3, 0.4, -0.1, 0.2, 3100, 3200, 3300, 3000};
  const double u[4] = {3500, 2900, 3100, 3300};
  Eigen::Matrix<double, 16, 16> a;
  Eigen::Matrix<double, 16, 4> b;
  ddp::step_jacobians<16, 4>(
      [&](const double* xs, const double* us, double* xn) {
        for (int n = 0; n < 16; ++n) xn[n] = xs[n];
        Quadrotor::step(p, xn, us, dt);
      },
      x, u, 1e-6, a.data(), b.data());
  const double h = static_cast<double>(dt);
  for (int d = 0; d < 3; ++d) EXPECT_NEAR(a(d, 3 + d), h, 1e-9);  // position <- velocity
  for (int m = 0; m < 4; ++m) {
    const double km = static_cast<double>(p.motor_gain);
    EXPECT_NEAR(b(12 + m, m), h * km, 1e-7);         // motor speed <- its command
    EXPECT_NEAR(a(12 + m, 12 + m), 1.0 - h * km, 1e-7);
    // Vertical acceleration <- motor speed: 2 k_F w cos(roll) cos(pitch) / m.
    const double dvz = h * 2.0 * static_cast<double>(p.k_force) * x[12 + m] * std::cos(x[6]) * std::cos(x[7]) /
                       static_cast<double>(p.mass);
    EXPECT_NEAR(a(5, 12 + m), dvz, 1e-6 * std::fabs(dvz)) << "motor " << m;
  }
  EXPECT_NEAR(a(0, 1), 0.0, 1e-12);  // x does not depend on y
  EXPECT_NEAR(b(5, 0), 0.0, 1e-12);  // the command acts through the motor lag only
}

TEST(FiniteDifference, CostGradientAndHessianMatchAndSkipUnusedCoordinates) {
  // s(x) = 2 x0^2 + x0 x2 + exp(-x2) ; x1 and x3 unused.
  auto s = [](const double* x) { return 2.0 * x[0] * x[0] + x[0] * x[2] + std::exp(-x[2]); };
  const double x[4] = {0.3, 5.0, -0.7, 2.0};
  double g[4], h[16];
  const int active = ddp::cost_gradient_hessian<4>(s, x, 1e-4, g, h);
  EXPECT_EQ(active, 2);
  EXPECT_NEAR(g[0], 4.0 * x[0] + x[2], 1e-6);
  EXPECT_EQ(g[1], 0.0);
  EXPECT_NEAR(g[2], x[0] - std::exp(-x[2]), 1e-6);
  EXPECT_EQ(g[3], 0.0);
  EXPECT_NEAR(h[0 * 4 + 0], 4.0, 1e-3);
  EXPECT_NEAR(h[2 * 4 + 0], 1.0, 1e-3);
  EXPECT_NEAR(h[0 * 4 + 2], 1.0, 1e-3);
  EXPECT_NEAR(h[2 * 4 + 2], std::exp(-x[2]), 1e-3);
  for (int k : {1, 3})
    for (int j = 0; j < 4; ++j) {
      EXPECT_EQ(h[k * 4 + j], 0.0);
      EXPECT_EQ(h[j * 4 + k], 0.0);
    }
}

MppiSettings cartpole_mppi() {
  MppiSettings s;
  s.rollouts = 1;
  s.horizon = 50;
  s.dt = 0.02f;
  s.lambda = 0.005f;
  s.nu = 1.0f;
  s.sigma = {0.0707f};
  s.u_min = {-20.0f};
  s.u_max = {20.0f};
  s.u_init = {0.0f};
  return s;
}

TEST(DdpSettings, BadValuesAreRefusedByName) {
  DdpSettings ok;
  EXPECT_EQ(validate(ok, 1), "");
  auto expect_field = [](DdpSettings d, const char* field) {
    const std::string e = validate(d, 1);
    EXPECT_EQ(e.rfind(field, 0), 0u) << "got '" << e << "', expected it to start with " << field;
  };
  DdpSettings d;
  d.max_iterations = 0;
  expect_field(d, "ddp.max_iterations:");
  d = ok;
  d.r = {1.0f, 2.0f};
  expect_field(d, "ddp.r:");
  d = ok;
  d.r = {-1.0f};
  expect_field(d, "ddp.r[0]:");
  d = ok;
  d.obstacle_softness = 0.0;
  expect_field(d, "ddp.obstacle_softness:");
  d = ok;
  d.mu_init = std::nan("");
  expect_field(d, "ddp.mu_init:");
  d = ok;
  d.initial_plan = {1.0f, 1.0f};
  expect_field(d, "ddp.initial_plan:");
  d = ok;
  d.mu_factor = 1.0;
  expect_field(d, "ddp.mu_factor:");
}

TEST(DdpController, RefusesBadSettingsNamingTheField) {
  DdpSettings d;
  d.line_search_steps = 0;
  try {
    DdpController<CartpoleSwingup> c("cartpole_swingup", cartpole_mppi(), d, CartpoleSwingup::Params{});
    FAIL() << "accepted ddp.line_search_steps = 0";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("ddp.line_search_steps"), std::string::npos) << e.what();
  }
  MppiSettings m = cartpole_mppi();
  m.horizon = 0;
  try {
    DdpController<CartpoleSwingup> c("cartpole_swingup", m, DdpSettings{}, CartpoleSwingup::Params{});
    FAIL() << "accepted mppi.horizon = 0";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("mppi.horizon"), std::string::npos) << e.what();
  }
}

TEST(DdpController, WarmStartsByShiftingAndKeepsLimits) {
  DdpSettings d;
  d.initial_plan = {1.0f};
  DdpController<CartpoleSwingup> c("cartpole_swingup", cartpole_mppi(), d, CartpoleSwingup::Params{});
  EXPECT_STREQ(c.backend(), "ddp");
  EXPECT_EQ(c.settings().rollouts, 1);  // what the status reports: one trajectory
  EXPECT_EQ(c.settings().horizon, 50);
  float x[5] = {0, 0, 0, 0, 0}, u = 0.0f;
  int improved = 0;
  for (int cycle = 0; cycle < 10; ++cycle) {
    const auto& st = c.iterate(x, &u);
    ASSERT_TRUE(st.finite);
    EXPECT_GE(st.rollouts, 1);
    improved += c.last_result().cost < c.last_result().cost_initial;
    c.propagate(x, &u, 0.02f);
  }
  EXPECT_GE(improved, 5) << "the solver rarely improved its warm start";
  const std::vector<float> plan = c.plan();
  for (float v : plan) {
    EXPECT_GE(v, -20.0f);
    EXPECT_LE(v, 20.0f);
  }
  EXPECT_EQ(plan.back(), 0.0f) << "the shift appends u_init";
  // fallback(): the held plan's first control, then the plan moves on by one.
  float held = 0.0f;
  c.fallback(&held);
  EXPECT_EQ(held, plan[0]);
  EXPECT_EQ(c.plan()[0], plan[1]);
}

}  // namespace
}  // namespace mppi
