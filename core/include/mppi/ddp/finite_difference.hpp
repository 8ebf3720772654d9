// Finite differences in double on the shared model and cost templates (instantiated with
// V = double, hd.hpp): the DDP baseline's derivatives, with no second copy of any model.
// Matrices are written column-major (Eigen's default): element (row, col) at col * rows + row.
#pragma once

#include <algorithm>
#include <cmath>

namespace mppi::ddp {

// Step of coordinate z: relative to its size, at least `rel` in absolute terms.
inline double fd_step_for(double z, double rel) { return rel * std::max(1.0, std::fabs(z)); }

// Jacobians of x_next = f(x, u) by central differences: a (NX x NX) = df/dx, b (NX x NU)
// = df/du. f is called as f(const double* x, const double* u, double* x_next).
template <int NX, int NU, class F>
void step_jacobians(F&& f, const double* x, const double* u, double rel, double* a, double* b) {
  double xp[NX], up[NU], fp[NX], fm[NX];
  std::copy_n(x, NX, xp);
  std::copy_n(u, NU, up);
  for (int c = 0; c < NX; ++c) {
    const double h = fd_step_for(x[c], rel);
    xp[c] = x[c] + h;
    f(xp, u, fp);
    xp[c] = x[c] - h;
    f(xp, u, fm);
    xp[c] = x[c];
    const double inv = 1.0 / (2.0 * h);
    for (int r = 0; r < NX; ++r) a[c * NX + r] = (fp[r] - fm[r]) * inv;
  }
  for (int c = 0; c < NU; ++c) {
    const double h = fd_step_for(u[c], rel);
    up[c] = u[c] + h;
    f(x, up, fp);
    up[c] = u[c] - h;
    f(x, up, fm);
    up[c] = u[c];
    const double inv = 1.0 / (2.0 * h);
    for (int r = 0; r < NX; ++r) b[c * NX + r] = (fp[r] - fm[r]) * inv;
  }
}

// Gradient g (N) and Hessian h (N x N, symmetric) of a scalar s(x) by finite differences;
// returns how many coordinates s depends on here.
// A coordinate whose forward step leaves s unchanged (bit for bit) is taken as one s does
// not depend on here: its row and column are zero. That skips most of the Hessian for costs
// that read a few coordinates of a large state (the quadrotor forest: 7 of 16). The
// gradient and the diagonal are central; the off-diagonal terms use the forward points.
template <int N, class S>
int cost_gradient_hessian(S&& s, const double* x, double rel, double* g, double* h) {
  double xp[N], fp[N], step[N];
  int active[N];
  int na = 0;
  std::copy_n(x, N, xp);
  const double f0 = s(x);
  for (int i = 0; i < N * N; ++i) h[i] = 0.0;
  for (int i = 0; i < N; ++i) {
    g[i] = 0.0;
    step[i] = fd_step_for(x[i], rel);
    xp[i] = x[i] + step[i];
    fp[i] = s(static_cast<const double*>(xp));
    if (fp[i] != f0) {
      xp[i] = x[i] - step[i];
      const double fm = s(static_cast<const double*>(xp));
      g[i] = (fp[i] - fm) / (2.0 * step[i]);
      h[i * N + i] = (fp[i] - 2.0 * f0 + fm) / (step[i] * step[i]);
      active[na++] = i;
    }
    xp[i] = x[i];
  }
  for (int a = 0; a < na; ++a) {
    const int i = active[a];
    for (int b = a + 1; b < na; ++b) {
      const int j = active[b];
      xp[i] = x[i] + step[i];
      xp[j] = x[j] + step[j];
      const double fij = s(static_cast<const double*>(xp));
      xp[i] = x[i];
      xp[j] = x[j];
      const double v = (fij - fp[i] - fp[j] + f0) / (step[i] * step[j]);
      h[j * N + i] = v;
      h[i * N + j] = v;
    }
  }
  return na;
}

}  // namespace mppi::ddp
