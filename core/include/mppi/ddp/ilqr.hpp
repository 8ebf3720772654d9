// iLQR (the Gauss-Newton form of DDP: second-order cost terms, first-order dynamics;
// Li & Todorov 2004, Tassa, Mansard & Todorov 2014) for the MPC-DDP baseline. The solver
// is generic over a problem P: it differentiates P's step and state cost by finite
// differences (mppi/ddp/finite_difference.hpp), so any model of core/ can be used unchanged.
//
//   minimise  J = sum_{i<N} [ 1/2 (u_i - u_ref)^T diag(r) (u_i - u_ref) + s(x_{i+1}, i+1) ] + phi(x_N)
//   subject to x_{i+1} = f(x_i, u_i),  u_lo <= u_i <= u_hi
//
// P provides: kNx, kNu; step(x, u, x_next) (double arrays); state_cost(x, i) (the cost of
// being at x at step i = 1..N); terminal_cost(x); and the arrays r, u_ref, u_lo, u_hi.
//
// Control limits: the line search clamps every control into the box, and the backward pass
// takes a control whose Newton step would leave the box as clamped at the bound for that
// step (its feedforward moves it onto the bound, its feedback row is zero, the free
// controls are re-solved with it fixed: one active-set pass of box-DDP).
// Regularisation: Levenberg-Marquardt on Q_uu, in controls scaled by their half range.
//
// All buffers are sized at construction: solve() allocates nothing.
#pragma once

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "mppi/ddp/finite_difference.hpp"
#include "mppi/ddp/settings.hpp"

namespace mppi::ddp {

struct IlqrResult {
  int iterations = 0;          // iterations run (backward + forward pass)
  int accepted = 0;            // iterations whose line search found a lower cost
  int backward_failures = 0;   // Q_uu not positive definite: mu raised and retried
  double cost_initial = 0.0;   // J of the plan given
  double cost = 0.0;           // J of the plan returned
  double mu = 0.0;             // regularisation at the end
  bool converged = false;      // the last step changed J by less than the tolerance
  bool finite = true;          // the plan returned and its cost are finite
};

template <class P>
class Ilqr {
 public:
  static constexpr int NX = P::kNx;
  static constexpr int NU = P::kNu;
  using VecX = Eigen::Matrix<double, NX, 1>;
  using VecU = Eigen::Matrix<double, NU, 1>;
  using MatXX = Eigen::Matrix<double, NX, NX>;
  using MatUU = Eigen::Matrix<double, NU, NU>;
  using MatUX = Eigen::Matrix<double, NU, NX>;
  using MatXU = Eigen::Matrix<double, NX, NU>;

  Ilqr(const DdpSettings& s, int horizon)
      : s_(s),
        n_(horizon),
        x_(static_cast<std::size_t>(horizon + 1)),
        u_(static_cast<std::size_t>(horizon)),
        xt_(static_cast<std::size_t>(horizon + 1)),
        ut_(static_cast<std::size_t>(horizon)),
        a_(static_cast<std::size_t>(horizon)),
        b_(static_cast<std::size_t>(horizon)),
        lx_(static_cast<std::size_t>(horizon + 1)),
        lxx_(static_cast<std::size_t>(horizon + 1)),
        k_(static_cast<std::size_t>(horizon)),
        kk_(static_cast<std::size_t>(horizon)),
        mu_(s.mu_init) {}

  int horizon() const { return n_; }
  double mu() const { return mu_; }
  void set_mu(double mu) { mu_ = std::clamp(mu, s_.mu_min, s_.mu_max); }

  // Improves the plan `plan` (horizon x NU, row per step) from x0 with at most
  // s.max_iterations iterations (fewer once converged); the plan is clamped into the box.
  IlqrResult solve(const P& p, const double* x0, double* plan, double tolerance = 1e-7) {
    IlqrResult r;
    for (int i = 0; i < n_; ++i)
      for (int j = 0; j < NU; ++j) u_[i](j) = std::clamp(plan[i * NU + j], p.u_lo[j], p.u_hi[j]);
    for (int n = 0; n < NX; ++n) x_[0](n) = x0[n];
    double cost = rollout(p);
    r.cost_initial = cost;
    for (int j = 0; j < NU; ++j) {
      const double half = 0.5 * (p.u_hi[j] - p.u_lo[j]);
      scale2_(j) = std::isfinite(half) && half > 0.0 ? 1.0 / (half * half) : 1.0;
    }
    for (int it = 0; it < s_.max_iterations && std::isfinite(cost); ++it) {
      ++r.iterations;
      derivatives(p);
      bool ok = false;
      for (int attempt = 0; attempt < 8 && !ok; ++attempt) {
        ok = backward(p);
        if (!ok) {
          ++r.backward_failures;
          mu_ = std::min(s_.mu_max, std::max(mu_ * s_.mu_factor, s_.mu_min > 0.0 ? s_.mu_min : 1e-9));
        }
      }
      if (!ok) break;
      bool accepted = false;
      double alpha = 1.0, new_cost = cost;
      for (int ls = 0; ls < s_.line_search_steps; ++ls, alpha *= 0.5) {
        new_cost = forward(p, alpha);
        const double expected = -(alpha * dv1_ + alpha * alpha * dv2_);
        const double actual = cost - new_cost;
        if (std::isfinite(new_cost) && actual > 0.0 && (expected <= 0.0 || actual > 1e-4 * expected)) {
          accepted = true;
          break;
        }
      }
      if (!accepted) {
        mu_ = std::min(s_.mu_max, std::max(mu_ * s_.mu_factor, s_.mu_min > 0.0 ? s_.mu_min : 1e-9));
        if (mu_ >= s_.mu_max) break;
        continue;
      }
      ++r.accepted;
      std::swap(x_, xt_);
      std::swap(u_, ut_);
      const double change = cost - new_cost;
      cost = new_cost;
      mu_ = std::max(s_.mu_min, mu_ / s_.mu_factor);
      if (change < tolerance * (1.0 + std::fabs(cost))) {
        r.converged = true;
        break;
      }
    }
    r.cost = cost;
    r.mu = mu_;
    r.finite = std::isfinite(cost);
    for (int i = 0; i < n_; ++i) {
      for (int j = 0; j < NU; ++j) {
        if (!std::isfinite(u_[i](j))) r.finite = false;
        plan[i * NU + j] = u_[i](j);
      }
    }
    return r;
  }

  // The nominal trajectory of the last solve (horizon + 1 states) and the feedback gains.
  const std::vector<VecX>& states() const { return x_; }
  const std::vector<MatUX>& gains() const { return kk_; }
  const std::vector<VecU>& feedforward() const { return k_; }

  // Total cost of the plan (horizon x NU) from x0, without changing the solver's state
  // beyond its scratch trajectory.
  double cost_of(const P& p, const double* x0, const double* plan) {
    for (int n = 0; n < NX; ++n) xt_[0](n) = x0[n];
    double j = 0.0;
    for (int i = 0; i < n_; ++i) {
      for (int c = 0; c < NU; ++c) ut_[i](c) = plan[i * NU + c];
      j += control_cost(p, ut_[i]);
      p.step(xt_[i].data(), ut_[i].data(), xt_[i + 1].data());
      j += p.state_cost(xt_[i + 1].data(), i + 1);
    }
    return j + p.terminal_cost(xt_[n_].data());
  }

 private:
  static double control_cost(const P& p, const VecU& u) {
    double c = 0.0;
    for (int j = 0; j < NU; ++j) c += 0.5 * p.r[j] * (u(j) - p.u_ref[j]) * (u(j) - p.u_ref[j]);
    return c;
  }

  // x_ from u_: the nominal trajectory and its cost.
  double rollout(const P& p) {
    double j = 0.0;
    for (int i = 0; i < n_; ++i) {
      j += control_cost(p, u_[i]);
      p.step(x_[i].data(), u_[i].data(), x_[i + 1].data());
      j += p.state_cost(x_[i + 1].data(), i + 1);
    }
    return j + p.terminal_cost(x_[n_].data());
  }

  void derivatives(const P& p) {
    for (int i = 0; i < n_; ++i)
      step_jacobians<NX, NU>([&](const double* x, const double* u, double* xn) { p.step(x, u, xn); }, x_[i].data(),
                             u_[i].data(), s_.fd_step, a_[i].data(), b_[i].data());
    lx_[0].setZero();
    lxx_[0].setZero();
    for (int i = 1; i < n_; ++i) {
      cost_gradient_hessian<NX>([&](const double* x) { return p.state_cost(x, i); }, x_[i].data(), s_.fd_hessian_step,
                                lx_[i].data(), lxx_[i].data());
      if (s_.convexify) convexify(lxx_[i]);
    }
    cost_gradient_hessian<NX>([&](const double* x) { return p.state_cost(x, n_) + p.terminal_cost(x); },
                              x_[n_].data(), s_.fd_hessian_step, lx_[n_].data(), lxx_[n_].data());
    if (s_.convexify) convexify(lxx_[n_]);
  }

  // The nearest positive semi-definite matrix (negative eigenvalues set to zero), computed on
  // the coordinates the cost depends on (non-zero rows), in fixed-capacity storage.
  void convexify(MatXX& h) {
    int idx[NX];
    int na = 0;
    for (int i = 0; i < NX; ++i)
      if (!h.row(i).isZero(0.0)) idx[na++] = i;
    if (na == 0) return;
    using Small = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, NX, NX>;
    Small m(na, na);
    for (int a = 0; a < na; ++a)
      for (int b = 0; b < na; ++b) m(a, b) = h(idx[a], idx[b]);
    Eigen::SelfAdjointEigenSolver<Small> eig(m);
    if (eig.info() != Eigen::Success) return;
    if (eig.eigenvalues().minCoeff() >= 0.0) return;
    const auto lam = eig.eigenvalues().cwiseMax(0.0);
    m = eig.eigenvectors() * lam.asDiagonal() * eig.eigenvectors().transpose();
    for (int a = 0; a < na; ++a)
      for (int b = 0; b < na; ++b) h(idx[a], idx[b]) = m(a, b);
  }

  // The Riccati sweep; false if a Q_uu was not positive definite (raise mu, try again).
  bool backward(const P& p) {
    VecX vx = lx_[n_];
    MatXX vxx = lxx_[n_];
    dv1_ = 0.0;
    dv2_ = 0.0;
    for (int i = n_ - 1; i >= 0; --i) {
      const MatXX& a = a_[i];
      const MatXU& b = b_[i];
      VecU lu;
      MatUU luu = MatUU::Zero();
      for (int j = 0; j < NU; ++j) {
        lu(j) = p.r[j] * (u_[i](j) - p.u_ref[j]);
        luu(j, j) = p.r[j];
      }
      const VecX qx = lx_[i] + a.transpose() * vx;
      const VecU qu = lu + b.transpose() * vx;
      const MatXU vxx_b = vxx * b;
      const MatXX qxx = lxx_[i] + a.transpose() * vxx * a;
      MatUU quu = luu + b.transpose() * vxx_b;
      quu = 0.5 * (quu + quu.transpose()).eval();
      const MatUX qux = vxx_b.transpose() * a;
      MatUU quu_reg = quu;
      for (int j = 0; j < NU; ++j) quu_reg(j, j) += mu_ * scale2_(j);

      // Unconstrained Newton step, then one active-set pass on the box.
      Eigen::LLT<MatUU> llt(quu_reg);
      if (llt.info() != Eigen::Success) return false;
      VecU k = -llt.solve(qu);
      MatUX kk = -llt.solve(qux);
      bool any_clamped = false;
      VecU kc = VecU::Zero();
      Eigen::Matrix<bool, NU, 1> clamped;
      for (int j = 0; j < NU; ++j) {
        const double target = u_[i](j) + k(j);
        clamped(j) = target > p.u_hi[j] || target < p.u_lo[j];
        if (clamped(j)) {
          kc(j) = std::clamp(target, p.u_lo[j], p.u_hi[j]) - u_[i](j);
          any_clamped = true;
        }
      }
      if (any_clamped) {
        MatUU m = quu_reg;
        VecU rhs = qu + quu_reg * kc;
        MatUX rhs_k = qux;
        for (int j = 0; j < NU; ++j) {
          if (!clamped(j)) continue;
          m.row(j).setZero();
          m.col(j).setZero();
          m(j, j) = 1.0;
          rhs(j) = -kc(j);
          rhs_k.row(j).setZero();
        }
        // Free rows: rhs = Qu_f + Quu_fc kc, clamped rows: k_c = kc.
        for (int j = 0; j < NU; ++j)
          if (!clamped(j)) rhs(j) = qu(j) + (quu_reg.row(j) * kc)(0, 0);
        Eigen::LLT<MatUU> llt_free(m);
        if (llt_free.info() != Eigen::Success) return false;
        k = -llt_free.solve(rhs);
        kk = -llt_free.solve(rhs_k);
        for (int j = 0; j < NU; ++j)
          if (clamped(j)) k(j) = kc(j);
      }
      if (!k.allFinite() || !kk.allFinite()) return false;
      k_[i] = k;
      kk_[i] = kk;
      dv1_ += k.dot(qu);
      dv2_ += 0.5 * k.dot(quu * k);
      vx = qx + kk.transpose() * quu * k + kk.transpose() * qu + qux.transpose() * k;
      vxx = qxx + kk.transpose() * quu * kk + kk.transpose() * qux + qux.transpose() * kk;
      vxx = 0.5 * (vxx + vxx.transpose()).eval();
    }
    return true;
  }

  // The new trajectory xt_, ut_ for step size alpha; returns its cost.
  double forward(const P& p, double alpha) {
    xt_[0] = x_[0];
    double j = 0.0;
    for (int i = 0; i < n_; ++i) {
      VecU u = u_[i] + alpha * k_[i] + kk_[i] * (xt_[i] - x_[i]);
      for (int c = 0; c < NU; ++c) u(c) = std::clamp(u(c), p.u_lo[c], p.u_hi[c]);
      ut_[i] = u;
      j += control_cost(p, u);
      p.step(xt_[i].data(), u.data(), xt_[i + 1].data());
      j += p.state_cost(xt_[i + 1].data(), i + 1);
      if (!std::isfinite(j)) return std::numeric_limits<double>::infinity();
    }
    return j + p.terminal_cost(xt_[n_].data());
  }

  DdpSettings s_;
  int n_;
  std::vector<VecX> x_;
  std::vector<VecU> u_;
  std::vector<VecX> xt_;
  std::vector<VecU> ut_;
  std::vector<MatXX> a_;
  std::vector<MatXU> b_;
  std::vector<VecX> lx_;
  std::vector<MatXX> lxx_;
  std::vector<VecU> k_;
  std::vector<MatUX> kk_;
  VecU scale2_ = VecU::Ones();
  double mu_;
  double dv1_ = 0.0, dv2_ = 0.0;
};

}  // namespace mppi::ddp
