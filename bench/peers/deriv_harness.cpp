// bench/peers/deriv_harness.cpp -- the derivative peers of issue 36 on the paper's 6-UPS, checked
// against rbss's derivatives at the same states, then timed. Driven by run_derivatives.sh; see
// README.md ("Derivatives").
//
// usage: deriv_harness STATES_IN RBSS_DERIVS MJCF_OUT RESULTS_OUT TIMING_STATE_INDEX
//   STATES_IN: as for harness.cpp (build/states.txt). RBSS_DERIVS: the output of rbss's
//   `peers_derivatives` example (runtime/examples/peers_derivatives.rs) on the same states:
//   "mat K NAME ROWS COLS v..." lines. RESULTS_OUT: "key value" lines for peers.py.
//
// The peers:
// - Pinocchio, numeric: constraintDynamics (default ProximalSettings, as harness.cpp) then
//   computeConstraintDynamicsDerivatives: ddq/dq, ddq/dv, ddq/dtau, dlambda_c/d(q, v, tau);
// - Pinocchio, generated (when linked, see have_cg): CodeGenConstraintDynamicsDerivatives
//   (codegen_gen.cpp ... derivatives) compiled twice by run_derivatives.sh, cg_dcd_portable
//   (gcc -O3) and cg_dcd_native (gcc -O3 -march=native);
// - MuJoCo: mjd_transitionFD (eps 1e-6, centred and forward) with the Euler (semi-implicit)
//   integrator, timestep = rbss's DT, U as the controls of six motors on the slides; MuJoCo
//   4.0.0's mjd_transitionFD refuses RK4, so for RK4 the same differences by hand
//   (transition_fd: one mj_step per perturbation), checked against mjd_transitionFD on Euler.
//
// Agreement (in the peers' coordinates, rbss's perturbations as the columns):
// - Pinocchio: column j is the derivative along rbss's X_j (or Xdot_j, U_j) of Pinocchio's
//   acceleration a and multipliers lambda_c. Pinocchio's: ddq_dq Q_X + ddq_dv V_X (Q_X: the
//   tangent of q(X), pin::difference at q(X); V_X, V_Xd: of v(X, Xd); to_pin). rbss's: the
//   chain rule through the same map, a = K(X, Xd, Xdd): K_X + K_Xdd dXdd/dX, and lambda_c =
//   -R_i(X)^T lambda_i (harness.cpp's map of the multipliers). The map's own derivatives in X
//   by central differences with one Richardson step (h = 1e-3, 5e-4; error ~1e-11), those in
//   Xd and Xdd exact (the map is affine in them).
// - MuJoCo: the transition A (48 x 48, MuJoCo's tangent state: mj_differentiatePos, qvel) and
//   B (48 x 6) against rbss's [F_x F_u] mapped the same way: A P(s) D vs P(s') F_x D and
//   B vs P(s') F_u, with P the map's derivative at the state s and at the step's end s' (rbss's)
//   and D the 12 directions of the constraint manifold (y, ydot of the outputs, from rbss's
//   linearisation: dX = T dy, dXd = dXd/dy dy + T dydot). Off the manifold the two differ by
//   design: MuJoCo's equalities are soft (solref 0.002: a spring-damper pulls the state back),
//   rbss's step has no stabilisation; the full A is reported too, for information.

#include <pinocchio/multibody.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/algorithm/constrained-dynamics.hpp>
#include <pinocchio/algorithm/constrained-dynamics-derivatives.hpp>

#include "stewart_pin.hpp"
#include "stewart_mj.hpp"

#include <cstdio>
#include <cstdlib>
#include <map>
#include <sstream>
#include <string>
#include <vector>

// The generated derivatives are weak symbols: linked when run_derivatives.sh built them (null
// otherwise), so that one object of this file serves both cases.
struct CgAtomicFun {  // CppADCodeGen's `struct LangCAtomicFun` (see codegen_harness.cpp)
  void* libModel;
  void* forward;
  void* reverse;
};
extern "C" {
__attribute__((weak)) void cg_dcd_portable(double const* const* in, double* const* out, CgAtomicFun atomic);
__attribute__((weak)) void cg_dcd_native(double const* const* in, double* const* out, CgAtomicFun atomic);
}
typedef void (*CgFn)(double const* const*, double* const*, CgAtomicFun);
static bool have_cg() { return cg_dcd_portable != nullptr && cg_dcd_native != nullptr; }

static const int NQ = 25, NV = 24, NC = 18, NA = 6, NS = 48;
typedef Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> RowMat;

// rbss's matrices, by state and name
typedef std::map<std::string, MatrixXd> Mats;
static bool read_rbss(const char* path, std::vector<Mats>& mats, std::map<std::string, double>& times) {
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream ls(line);
    std::string key;
    ls >> key;
    if (key == "mat") {
      int k, r, c;
      std::string name;
      ls >> k >> name >> r >> c;
      if (!ls || k < 0 || r <= 0 || c <= 0) break;
      if ((int)mats.size() <= k) mats.resize(k + 1);
      MatrixXd m(r, c);
      for (int i = 0; i < r; ++i)
        for (int j = 0; j < c; ++j) ls >> m(i, j);
      if (!ls) {
        std::fprintf(stderr, "%s: malformed matrix %s at state %d\n", path, name.c_str(), k);
        return false;
      }
      mats[k][name] = m;
    } else if (key == "time") {
      std::string name;
      double ns;
      ls >> name >> ns;
      times[name] = ns;
    }
  }
  return !mats.empty();
}

// rbss's X -> Pinocchio's a (Xdd given), q, v; and lambda_c from rbss's lambda
static VectorXd K_acc(const VectorXd& X, const VectorXd& Xd, const VectorXd& Xdd) {
  VectorXd q(NQ), v(NV), a(NV);
  to_pin(X.data(), Xd.data(), Xdd.data(), q, v, &a);
  return a;
}
static VectorXd V_of(const VectorXd& X, const VectorXd& Xd) {
  VectorXd q(NQ), v(NV);
  to_pin(X.data(), Xd.data(), nullptr, q, v, nullptr);
  return v;
}
static VectorXd Q_of(const VectorXd& X) {
  VectorXd q(NQ), v(NV), z = VectorXd::Zero(24);
  to_pin(X.data(), z.data(), nullptr, q, v, nullptr);
  return q;
}
static VectorXd L_of(const PinRobot& pr, pin::Data& d, const VectorXd& X, const VectorXd& lam) {
  pin::forwardKinematics(pr.model, d, Q_of(X));
  VectorXd lc(NC);
  for (int i = 0; i < 6; ++i) lc.segment<3>(3 * i) = -d.oMi[pr.pz[i]].rotation().transpose() * lam.segment<3>(3 * i);
  return lc;
}

// d/dX_j of F(X) (any vector function), central differences + one Richardson step
template <class F>
static MatrixXd jac_x(F&& f, const VectorXd& X, int rows) {
  MatrixXd J(rows, 24);
  for (int j = 0; j < 24; ++j) {
    auto cd = [&](double h) {
      VectorXd xp = X, xm = X;
      xp[j] += h, xm[j] -= h;
      return VectorXd((f(xp) - f(xm)) / (2 * h));
    };
    J.col(j) = (4 * cd(5e-4) - cd(1e-3)) / 3;
  }
  return J;
}

// MuJoCo: the state map P(s) = d(MuJoCo's tangent state)/d(X, Xd) (48 x 48)
static MatrixXd mj_state_map(const mjModel* m, const VectorXd& X, const VectorXd& Xd) {
  std::vector<mjtNum> q0(NQ), v0(NV);
  to_mj(X.data(), Xd.data(), nullptr, q0.data(), v0.data(), nullptr);
  auto qtan = [&](const VectorXd& x) {
    std::vector<mjtNum> q(NQ), v(NV), dq(NV);
    to_mj(x.data(), Xd.data(), nullptr, q.data(), v.data(), nullptr);
    mj_differentiatePos(m, dq.data(), 1.0, q0.data(), q.data());
    return VectorXd(Eigen::Map<VectorXd>(dq.data(), NV));
  };
  auto vel = [&](const VectorXd& x) {
    std::vector<mjtNum> q(NQ), v(NV);
    to_mj(x.data(), Xd.data(), nullptr, q.data(), v.data(), nullptr);
    return VectorXd(Eigen::Map<VectorXd>(v.data(), NV));
  };
  MatrixXd P = MatrixXd::Zero(NS, NS);
  P.topLeftCorner(NV, 24) = jac_x(qtan, X, NV);
  P.bottomLeftCorner(NV, 24) = jac_x(vel, X, NV);
  for (int j = 0; j < 24; ++j) {  // qvel is linear in Xd
    VectorXd e = VectorXd::Zero(24);
    e[j] = 1;
    std::vector<mjtNum> q(NQ), v(NV);
    to_mj(X.data(), e.data(), nullptr, q.data(), v.data(), nullptr);
    P.block(NV, 24 + j, NV, 1) = Eigen::Map<VectorXd>(v.data(), NV);
  }
  return P;
}

static void mj_set(const mjModel* m, mjData* d, const State& s) {
  mj_resetData(m, d);
  to_mj(s.X, s.Xd, nullptr, d->qpos, d->qvel, nullptr);
  for (int i = 0; i < 6; ++i) d->ctrl[i] = s.U[i];
  mj_forward(m, d);
}

// MuJoCo 4.0.0's mjd_transitionFD refuses the RK4 integrator ("RK4 integrator is not
// supported"); for RK4 the same finite differences by hand, as mjd_transitionFD makes them:
// the state perturbed in MuJoCo's tangent space (mj_integratePos, qvel), the controls,
// each by +-eps (centred) or +eps (forward), one mj_step each from the same warm start,
// the result as the tangent of the next state at the unperturbed one. Also run on Euler,
// against mjd_transitionFD itself (the `fd_by_hand_vs_mjd` line).
static void transition_fd(const mjModel* m, mjData* d, const State& s, double eps, bool centred,
                          RowMat& A, RowMat& B) {
  std::vector<mjtNum> q0(NQ), v0(NV), w0(NV), u0(NA), q1(NQ), v1(NV), dq(NV), q(NQ);
  mj_set(m, d, s);
  mju_copy(q0.data(), d->qpos, NQ);
  mju_copy(v0.data(), d->qvel, NV);
  mju_copy(w0.data(), d->qacc_warmstart, NV);
  mju_copy(u0.data(), d->ctrl, NA);
  // one step from the state perturbed by (dx, du); its tangent against the nominal next state
  auto step = [&](const mjtNum* dx, const mjtNum* du, mjtNum* y) {
    mju_copy(d->qpos, q0.data(), NQ);
    if (dx) mj_integratePos(m, d->qpos, dx, 1.0);
    for (int i = 0; i < NV; ++i) d->qvel[i] = v0[i] + (dx ? dx[NV + i] : 0.0);
    for (int i = 0; i < NA; ++i) d->ctrl[i] = u0[i] + (du ? du[i] : 0.0);
    mju_copy(d->qacc_warmstart, w0.data(), NV);
    d->time = 0;
    mj_step(m, d);
    if (y) {
      mj_differentiatePos(m, y, 1.0, q1.data(), d->qpos);
      for (int i = 0; i < NV; ++i) y[NV + i] = d->qvel[i] - v1[i];
    }
  };
  step(nullptr, nullptr, nullptr);
  mju_copy(q1.data(), d->qpos, NQ);
  mju_copy(v1.data(), d->qvel, NV);
  std::vector<mjtNum> e(NS), yp(NS), ym(NS);
  for (int j = 0; j < NS + NA; ++j) {
    std::fill(e.begin(), e.end(), 0.0);
    e[j < NS ? j : j - NS] = eps;
    const mjtNum* dx = j < NS ? e.data() : nullptr;
    const mjtNum* du = j < NS ? nullptr : e.data();
    step(dx, du, yp.data());
    if (centred) {
      e[j < NS ? j : j - NS] = -eps;
      step(dx, du, ym.data());
    } else {
      std::fill(ym.begin(), ym.end(), 0.0);
    }
    double h = centred ? 2 * eps : eps;
    for (int i = 0; i < NS; ++i) {
      double v = (yp[i] - ym[i]) / h;
      if (j < NS) A(i, j) = v;
      else B(i, j - NS) = v;
    }
  }
  mj_set(m, d, s);
}

int main(int argc, char** argv) {
  if (argc != 6) {
    std::fprintf(stderr, "usage: %s STATES_IN RBSS_DERIVS MJCF_OUT RESULTS_OUT TIMING_STATE_INDEX\n", argv[0]);
    return 2;
  }
  std::vector<State> st;
  if (!read_states(argv[1], st)) return 1;
  std::vector<Mats> rb;
  std::map<std::string, double> rb_times;
  if (!read_rbss(argv[2], rb, rb_times) || rb.size() != st.size()) {
    std::fprintf(stderr, "deriv_harness: %s has no derivatives for the %zu states of %s\n", argv[2],
                 st.size(), argv[1]);
    return 1;
  }
  int n = (int)st.size(), ti = std::atoi(argv[5]);
  if (ti < 0 || ti >= n) {
    std::fprintf(stderr, "deriv_harness: timing state index %d out of range\n", ti);
    return 1;
  }
  FILE* out = std::fopen(argv[4], "w");
  if (!out) {
    std::fprintf(stderr, "deriv_harness: cannot write %s\n", argv[4]);
    return 1;
  }
  std::fprintf(out, "pinocchio_version %s\nmujoco_version %s\n", PINOCCHIO_VERSION, mj_versionString());
  std::fprintf(out, "cg_deriv %d\n", have_cg() ? 1 : 0);

  PinRobot pr = build_pin();
  pin::Data pd(pr.model), pk(pr.model);
  std::vector<pin::RigidConstraintData> cdatas;
  for (auto& c : pr.cmodels) cdatas.emplace_back(c);
  pin::initConstraintDynamics(pr.model, pd, pr.cmodels, cdatas);
  pin::ProximalSettings settings;  // the defaults, as constraintDynamics without settings

  {
    std::ofstream x(argv[3]);
    x << mjcf(0.9999, true);
  }
  char err[1000] = "";
  mjModel* mm = mj_loadXML(argv[3], nullptr, err, sizeof err);
  if (!mm) {
    std::fprintf(stderr, "deriv_harness: MuJoCo could not load %s: %s\n", argv[3], err);
    return 1;
  }
  mjData* md = mj_makeData(mm);
  if (mm->nv != NV || mm->nu != NA || mm->na != 0) {
    std::fprintf(stderr, "deriv_harness: unexpected MuJoCo sizes nv %d nu %d na %d\n", (int)mm->nv,
                 (int)mm->nu, (int)mm->na);
    return 1;
  }
  const double dt = rb[0].count("rk4_F") ? mm->opt.timestep : 0;
  std::fprintf(out, "mj_timestep %g\n", dt);
  MatrixXd S = MatrixXd::Zero(NV, NA);  // tau = S U
  for (int i = 0; i < NA; ++i) S(vLeg(i) + 2, i) = 1;

  // --- agreement, state by state
  std::fprintf(out, "states %d\n", n);
  for (int k = 0; k < n; ++k) {
    const State& s = st[k];
    Mats& r = rb[k];
    Eigen::Map<const VectorXd> X(s.X, 24), Xd(s.Xd, 24);
    VectorXd Xdd = r["xddot"].row(0).transpose(), lam = r["lambda"].row(0).transpose();
    VectorXd q(NQ), v(NV), a_r(NV), tau = S * Eigen::Map<const VectorXd>(s.U, NA);
    to_pin(s.X, s.Xd, Xdd.data(), q, v, &a_r);

    // Pinocchio, numeric
    VectorXd ddq = pin::constraintDynamics(pr.model, pd, q, v, tau, pr.cmodels, cdatas);
    VectorXd lam_c = pd.lambda_c;
    pin::computeConstraintDynamicsDerivatives(pr.model, pd, pr.cmodels, cdatas, settings);
    MatrixXd Aq = pd.ddq_dq, Av = pd.ddq_dv, At = pd.ddq_dtau;
    MatrixXd Lq = pd.dlambda_dq, Lv = pd.dlambda_dv, Lt = pd.dlambda_dtau;

    // the map's derivatives
    VectorXd q0 = Q_of(X);
    MatrixXd Q_X = jac_x(
        [&](const VectorXd& x) {
          VectorXd d(NV);
          pin::difference(pr.model, q0, Q_of(x), d);
          return d;
        },
        X, NV);
    MatrixXd V_X = jac_x([&](const VectorXd& x) { return V_of(x, Xd); }, X, NV);
    MatrixXd V_Xd(NV, 24), K_Xd(NV, 24), K_Xdd(NV, 24);
    VectorXd z = VectorXd::Zero(24), a0 = K_acc(X, Xd, z);
    for (int j = 0; j < 24; ++j) {
      VectorXd e = VectorXd::Zero(24);
      e[j] = 1;
      V_Xd.col(j) = V_of(X, e);
      K_Xdd.col(j) = K_acc(X, Xd, e) - a0;
    }
    // K in Xd: quadratic (w x v, the Euler rates' products) -> central differences are exact
    // up to rounding
    for (int j = 0; j < 24; ++j) {
      VectorXd p = Xd, m = Xd;
      p[j] += 1e-3, m[j] -= 1e-3;
      K_Xd.col(j) = (K_acc(X, p, Xdd) - K_acc(X, m, Xdd)) / 2e-3;
    }
    MatrixXd K_X = jac_x([&](const VectorXd& x) { return K_acc(x, Xd, Xdd); }, X, NV);
    MatrixXd L_X = jac_x([&](const VectorXd& x) { return L_of(pr, pk, x, lam); }, X, NC);
    MatrixXd L_lam(NC, NC);
    L_lam.setZero();
    pin::forwardKinematics(pr.model, pk, q0);
    for (int i = 0; i < 6; ++i) L_lam.block<3, 3>(3 * i, 3 * i) = -pk.oMi[pr.pz[i]].rotation().transpose();

    // rbss's, in Pinocchio's a / lambda_c
    MatrixXd ra_X = K_X + K_Xdd * r["dxddot_dx"], ra_Xd = K_Xd + K_Xdd * r["dxddot_dxdot"];
    MatrixXd ra_U = K_Xdd * r["dxddot_du"];
    MatrixXd rl_X = L_X + L_lam * r["dlambda_dx"], rl_Xd = L_lam * r["dlambda_dxdot"];
    MatrixXd rl_U = L_lam * r["dlambda_du"];
    // Pinocchio's, along rbss's directions
    MatrixXd pa_X = Aq * Q_X + Av * V_X, pa_Xd = Av * V_Xd, pa_U = At * S;
    MatrixXd pl_X = Lq * Q_X + Lv * V_X, pl_Xd = Lv * V_Xd, pl_U = Lt * S;
    std::fprintf(out,
                 "pin %d t %.17g acc_rel %.3e lambda_rel %.3e dacc_dX %.3e dacc_dXd %.3e dacc_dU %.3e "
                 "dlambda_dX %.3e dlambda_dXd %.3e dlambda_dU %.3e\n",
                 k, s.t, rel(ddq, a_r), rel(lam_c, L_lam * lam), rel_m(pa_X, ra_X), rel_m(pa_Xd, ra_Xd),
                 rel_m(pa_U, ra_U), rel_m(pl_X, rl_X), rel_m(pl_Xd, rl_Xd), rel_m(pl_U, rl_U));

    if (have_cg()) {
      const CgFn fns[2] = {cg_dcd_portable, cg_dcd_native};
      const char* names[2] = {"portable", "native"};
      std::vector<double> x(NQ + 2 * NV), y(3 * NV * NV + 3 * NC * NV);
      for (int i = 0; i < NQ; ++i) x[i] = q[i];
      for (int i = 0; i < NV; ++i) x[NQ + i] = v[i], x[NQ + NV + i] = tau[i];
      const double* in[1] = {x.data()};
      double* o[1] = {y.data()};
      for (int b = 0; b < 2; ++b) {
        fns[b](in, o, CgAtomicFun{nullptr, nullptr, nullptr});
        const double* p = y.data();
        MatrixXd cAq = Eigen::Map<RowMat>(const_cast<double*>(p), NV, NV);
        MatrixXd cAv = Eigen::Map<RowMat>(const_cast<double*>(p) + NV * NV, NV, NV);
        MatrixXd cAt = Eigen::Map<RowMat>(const_cast<double*>(p) + 2 * NV * NV, NV, NV);
        const double* pl = p + 3 * NV * NV;
        MatrixXd cLq = Eigen::Map<const MatrixXd>(pl, NC, NV);
        MatrixXd cLv = Eigen::Map<const MatrixXd>(pl + NC * NV, NC, NV);
        MatrixXd cLt = Eigen::Map<const MatrixXd>(pl + 2 * NC * NV, NC, NV);
        double vs_pin = std::max({rel_m(cAq, Aq), rel_m(cAv, Av), rel_m(cAt, At), rel_m(cLq, Lq),
                                  rel_m(cLv, Lv), rel_m(cLt, Lt)});
        std::fprintf(out,
                     "cg %d build %s vs_pin %.3e dacc_dX %.3e dacc_dXd %.3e dacc_dU %.3e dlambda_dX %.3e "
                     "dlambda_dXd %.3e dlambda_dU %.3e\n",
                     k, names[b], vs_pin, rel_m(cAq * Q_X + cAv * V_X, ra_X), rel_m(cAv * V_Xd, ra_Xd),
                     rel_m(cAt * S, ra_U), rel_m(cLq * Q_X + cLv * V_X, rl_X), rel_m(cLv * V_Xd, rl_Xd),
                     rel_m(cLt * S, rl_U));
      }
    }

    // MuJoCo: mjd_transitionFD against rbss's step Jacobians, along the manifold
    MatrixXd T = r["tangent"], Ty = r["dxdot_dy"];
    int dd = (int)T.cols();
    MatrixXd D = MatrixXd::Zero(NS, 2 * dd);
    D.block(0, 0, 24, dd) = T;
    D.block(24, 0, 24, dd) = Ty;
    D.block(24, dd, 24, dd) = T;
    MatrixXd P0 = mj_state_map(mm, X, Xd);
    for (int integ : {(int)mjINT_EULER, (int)mjINT_RK4}) {
      const char* iname = integ == mjINT_RK4 ? "rk4" : "euler";
      MatrixXd F = r[std::string(iname) + "_F"];
      VectorXd nx = r[std::string(iname) + "_next"].row(0).transpose();
      MatrixXd P1 = mj_state_map(mm, nx.head(24), nx.tail(24));
      MatrixXd rF = P1 * F.leftCols(NS), rB = P1 * F.rightCols(NA);
      mm->opt.integrator = integ;
      for (int centred : {1, 0}) {
        RowMat A(NS, NS), B(NS, NA);
        if (integ == mjINT_RK4) {
          transition_fd(mm, md, s, 1e-6, centred, A, B);
        } else {
          mj_set(mm, md, s);
          mjd_transitionFD(mm, md, 1e-6, centred, A.data(), B.data(), nullptr, nullptr);
          RowMat Ah(NS, NS), Bh(NS, NA);
          transition_fd(mm, md, s, 1e-6, centred, Ah, Bh);
          std::fprintf(out, "fd_by_hand_vs_mjd %d centred %d A %.3e B %.3e\n", k, centred,
                       rel_m(MatrixXd(Ah), MatrixXd(A)), rel_m(MatrixXd(Bh), MatrixXd(B)));
        }
        MatrixXd Am = A, Bm = B;
        // where the step lands: MuJoCo's next state against rbss's
        mj_set(mm, md, s);
        mj_step(mm, md);
        std::vector<mjtNum> q1(NQ), v1(NV), dq(NV);
        to_mj(nx.data(), nx.data() + 24, nullptr, q1.data(), v1.data(), nullptr);
        mj_differentiatePos(mm, dq.data(), 1.0, q1.data(), md->qpos);
        double next_pos = Eigen::Map<VectorXd>(dq.data(), NV).cwiseAbs().maxCoeff();
        double next_vel = rel(Eigen::Map<VectorXd>(md->qvel, NV), Eigen::Map<VectorXd>(v1.data(), NV));
        std::fprintf(out,
                     "mj %d integrator %s centred %d F_manifold %.3e F_u %.3e F_full %.3e next_pos %.3e "
                     "next_vel_rel %.3e\n",
                     k, iname, centred, rel_m(Am * P0 * D, rF * D), rel_m(Bm, rB), rel_m(Am * P0, rF),
                     next_pos, next_vel);
      }
    }
    std::fflush(out);
  }

  // --- timing at state ti
  const State& s = st[ti];
  VectorXd q(NQ), v(NV), tau = S * Eigen::Map<const VectorXd>(s.U, NA);
  {
    VectorXd Xdd = rb[ti]["xddot"].row(0).transpose();
    to_pin(s.X, s.Xd, Xdd.data(), q, v, nullptr);
  }
  const int NB = 101;
  double t_cd = median_ns([&] { pin::constraintDynamics(pr.model, pd, q, v, tau, pr.cmodels, cdatas); }, 1000, NB);
  double t_cdd = median_ns(
      [&] { pin::computeConstraintDynamicsDerivatives(pr.model, pd, pr.cmodels, cdatas, settings); }, 300, NB);
  double t_both = median_ns(
      [&] {
        pin::constraintDynamics(pr.model, pd, q, v, tau, pr.cmodels, cdatas);
        pin::computeConstraintDynamicsDerivatives(pr.model, pd, pr.cmodels, cdatas, settings);
      },
      300, NB);
  std::fprintf(out, "timing_state %d t %.17g\n", ti, s.t);
  std::fprintf(out, "time pin_constraintDynamics %.1f\n", t_cd);
  std::fprintf(out, "time pin_computeConstraintDynamicsDerivatives %.1f\n", t_cdd);
  std::fprintf(out, "time pin_constraintDynamics_plus_derivatives %.1f\n", t_both);
  if (have_cg()) {
    std::vector<double> x(NQ + 2 * NV), y(3 * NV * NV + 3 * NC * NV);
    for (int i = 0; i < NQ; ++i) x[i] = q[i];
    for (int i = 0; i < NV; ++i) x[NQ + i] = v[i], x[NQ + NV + i] = tau[i];
    const double* in[1] = {x.data()};
    double* o[1] = {y.data()};
    const CgAtomicFun af{nullptr, nullptr, nullptr};
    std::vector<double> tp, tn;
    for (int r = 0; r < 3; ++r) {
      tp.push_back(median_ns([&] { cg_dcd_portable(in, o, af); }, 300, NB));
      tn.push_back(median_ns([&] { cg_dcd_native(in, o, af); }, 300, NB));
    }
    std::sort(tp.begin(), tp.end());
    std::sort(tn.begin(), tn.end());
    std::fprintf(out, "time cg_constraintDynamicsDerivatives_portable %.1f\n", tp[1]);
    std::fprintf(out, "time cg_constraintDynamicsDerivatives_native %.1f\n", tn[1]);
  }
  {
    RowMat A(NS, NS), B(NS, NA);
    for (int integ : {(int)mjINT_EULER, (int)mjINT_RK4}) {
      const char* iname = integ == mjINT_RK4 ? "rk4" : "euler";
      mm->opt.integrator = integ;
      mj_set(mm, md, s);
      double t_step = median_ns([&] { mj_step(mm, md); mj_set(mm, md, s); }, 200, NB);
      double t_set = median_ns([&] { mj_set(mm, md, s); }, 200, NB);
      std::fprintf(out, "time mj_step_%s %.1f\n", iname, t_step - t_set);
      for (int centred : {1, 0}) {
        mj_set(mm, md, s);
        if (integ != mjINT_RK4) {
          double t = median_ns(
              [&] { mjd_transitionFD(mm, md, 1e-6, centred, A.data(), B.data(), nullptr, nullptr); }, 3, 31);
          std::fprintf(out, "time mjd_transitionFD_%s_%s %.1f\n", iname, centred ? "centred" : "forward", t);
        }
        double th = median_ns([&] { transition_fd(mm, md, s, 1e-6, centred, A, B); }, 3, 31);
        std::fprintf(out, "time mj_fd_by_hand_%s_%s %.1f\n", iname, centred ? "centred" : "forward", th);
      }
    }
  }
  std::fclose(out);
  mj_deleteData(md);
  mj_deleteModel(mm);
  return 0;
}
