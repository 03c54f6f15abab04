// bench/peers/harness.cpp -- the paper's 6-UPS (../../../shared/paper-example.md) built in
// Pinocchio (kinematic tree + RigidConstraintModel loop closures + constraintDynamics) and in
// MuJoCo (same bodies + `connect` equality constraints between sites), checked against rbss's
// numbers at given states, then timed. Driven by run.sh; see README.md.
//
// usage: harness STATES_IN MJCF_OUT RESULTS_OUT TIMING_STATE_INDEX
//   STATES_IN: whitespace-separated numbers, first the count N, then per state
//     t, X(24), Xdot(24), Xddot(24), U(6), lambda(18), M(24*24, row-major), f(18)
//   all in rbss's coordinates X = [d1..d6, phi1..phi6, psi1..psi6, x, y, z, rotx, roty, rotz].
//   RESULTS_OUT: "key value" lines (per-state checks and timings), parsed by report.py.

#include <pinocchio/multibody.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/energy.hpp>
#include <pinocchio/algorithm/constrained-dynamics.hpp>
#include <pinocchio/algorithm/loop-constrained-aba.hpp>

#include <mujoco/mujoco.h>

#include <Eigen/Dense>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

// The robot, the map from rbss's coordinates to Pinocchio's, the Pinocchio model, State, rel,
// median_ns: shared with the generated-code peer (codegen_gen.cpp, codegen_harness.cpp).
#include "stewart_pin.hpp"
// to_mj and the MJCF: shared with deriv_harness.cpp
#include "stewart_mj.hpp"

// The velocity map v = T(X) Xdot (linear in Xdot at fixed X), column by column.
static MatrixXd velocity_map(const double* X, bool mj) {
  MatrixXd T(24, 24);
  VectorXd q(25), v(24);
  double qpos[25], qvel[24];
  for (int j = 0; j < 24; ++j) {
    double e[24] = {0};
    e[j] = 1;
    if (mj) {
      to_mj(X, e, nullptr, qpos, qvel, nullptr);
      for (int r = 0; r < 24; ++r) T(r, j) = qvel[r];
    } else {
      to_pin(X, e, nullptr, q, v, nullptr);
      T.col(j) = v;
    }
  }
  return T;
}

// G_pin (18 x 24): world-frame velocity of Pi on the leg minus that of Pi on the platform, i.e.
// exactly the Jacobian of rbss's f (leg by leg, world x, y, z) in Pinocchio's velocity coords.
static MatrixXd pin_constraint_jacobian(const PinRobot& r, pin::Data& d, const VectorXd& q) {
  pin::computeJointJacobians(r.model, d, q);
  MatrixXd G(18, 24);
  pin::Data::Matrix6x J1(6, 24), J2(6, 24);
  for (int i = 0; i < 6; ++i) {
    J1.setZero();
    J2.setZero();
    pin::getFrameJacobian(r.model, d, r.pz[i], pin::SE3::Identity(), pin::LOCAL_WORLD_ALIGNED, J1);
    pin::getFrameJacobian(r.model, d, r.ff, pin::SE3(Matrix3d::Identity(), plat_point(i)),
                          pin::LOCAL_WORLD_ALIGNED, J2);
    G.middleRows<3>(3 * i) = J1.topRows<3>() - J2.topRows<3>();
  }
  return G;
}

static int site_leg[6], site_plat[6];

static MatrixXd mj_constraint_jacobian(const mjModel* m, const mjData* d) {
  MatrixXd G(18, 24);
  std::vector<mjtNum> j1(3 * m->nv), j2(3 * m->nv);
  for (int i = 0; i < 6; ++i) {
    mj_jacSite(m, d, j1.data(), nullptr, site_leg[i]);
    mj_jacSite(m, d, j2.data(), nullptr, site_plat[i]);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 24; ++c) G(3 * i + r, c) = j1[r * m->nv + c] - j2[r * m->nv + c];
  }
  return G;
}

// ---------------------------------------------------------------------------------------------
// Solve tau = S U - G^T lambda (rbss's sign, design.md) for [U; lambda]; S picks the d dofs.
static VectorXd solve_id(const VectorXd& tau, const MatrixXd& G, double* resid) {
  MatrixXd A(24, 24);
  A.setZero();
  for (int i = 0; i < 6; ++i) A(vLeg(i) + 2, i) = 1.0;
  A.rightCols(18) = -G.transpose();
  VectorXd sol = A.fullPivLu().solve(tau);
  *resid = (A * sol - tau).norm() / tau.norm();
  return sol;
}

int main(int argc, char** argv) {
  if (argc != 5) {
    std::fprintf(stderr, "usage: %s STATES_IN MJCF_OUT RESULTS_OUT TIMING_STATE_INDEX\n", argv[0]);
    return 2;
  }
  std::vector<State> st;
  if (!read_states(argv[1], st)) return 1;
  int n = (int)st.size();
  int ti = std::atoi(argv[4]);
  if (ti < 0 || ti >= n) {
    std::fprintf(stderr, "harness: timing state index %d out of range\n", ti);
    return 1;
  }
  FILE* out = std::fopen(argv[3], "w");
  if (!out) {
    std::fprintf(stderr, "harness: cannot write %s\n", argv[3]);
    return 1;
  }
  std::fprintf(out, "pinocchio_version %s\n", PINOCCHIO_VERSION);
  std::fprintf(out, "mujoco_version %s\n", mj_versionString());
  std::fprintf(out, "eigen_version %d.%d.%d\n", EIGEN_WORLD_VERSION, EIGEN_MAJOR_VERSION,
               EIGEN_MINOR_VERSION);
  std::fprintf(out, "masses %.12f %.12f %.12f\n", LOW.m, UP.m, PLAT.m);

  // --- models
  PinRobot pr = build_pin();
  pin::Data pd(pr.model);
  std::vector<pin::RigidConstraintData> cdatas;
  for (auto& c : pr.cmodels) cdatas.emplace_back(c);
  pin::initConstraintDynamics(pr.model, pd, pr.cmodels, cdatas);
  // Pinocchio's closed-loop constrained ABA (proximal iterations), for information
  pin::Data pd_l(pr.model);
  std::vector<pin::RigidConstraintData> cdatas_l;
  for (auto& c : pr.cmodels) cdatas_l.emplace_back(c);
  pin::computeJointMinimalOrdering(pr.model, pd_l, pr.cmodels);
  // mu = 1e-6 (the header's "typical value"): 3 iterations, ~1e-10 relative accuracy here; 1e-4
  // reaches ~1e-12 in 6 iterations (1.5x the time), 1e-10 and below lose accuracy (1/mu penalty)
  const double LCABA_MU = 1e-6, LCABA_ACC = 1e-12;
  const int LCABA_MAXIT = 100;
  pin::ProximalSettings lset(LCABA_ACC, LCABA_MU, LCABA_MAXIT);
  std::fprintf(out, "lcaba_settings mu %g accuracy %g max_iter %d\n", LCABA_MU, LCABA_ACC, LCABA_MAXIT);

  {
    std::ofstream x(argv[2]);
    x << mjcf();
  }
  char err[1000] = "";
  mjModel* mm = mj_loadXML(argv[2], nullptr, err, sizeof err);
  if (!mm) {
    std::fprintf(stderr, "harness: MuJoCo could not load %s: %s\n", argv[2], err);
    return 1;
  }
  mjData* md = mj_makeData(mm);
  if (mm->nv != 24 || mm->nq != 25 || pr.model.nv != 24 || pr.model.nq != 25) {
    std::fprintf(stderr, "harness: unexpected sizes mj nq %d nv %d, pin nq %d nv %d\n", (int)mm->nq,
                 (int)mm->nv, (int)pr.model.nq, (int)pr.model.nv);
    return 1;
  }
  for (int i = 0; i < 6; ++i) {
    site_leg[i] = mj_name2id(mm, mjOBJ_SITE, ("P" + std::to_string(i + 1) + "_leg").c_str());
    site_plat[i] = mj_name2id(mm, mjOBJ_SITE, ("P" + std::to_string(i + 1) + "_platform").c_str());
  }

  // --- agreement checks, state by state
  std::fprintf(out, "states %d\n", n);
  for (int k = 0; k < n; ++k) {
    const State& s = st[k];
    Eigen::Map<const Eigen::Matrix<double, 24, 24, Eigen::RowMajor>> Mr(s.M);
    Eigen::Map<const VectorXd> Xd(s.Xd, 24), U(s.U, 6), lam(s.lam, 18);
    double ke_r = 0.5 * Xd.dot(Mr * Xd);
    double f_rbss = Eigen::Map<const VectorXd>(s.f, 18).cwiseAbs().maxCoeff();

    // Pinocchio
    VectorXd q(25), v(24), a(24);
    to_pin(s.X, s.Xd, s.Xdd, q, v, &a);
    double ke_p = pin::computeKineticEnergy(pr.model, pd, q, v);
    pin::crba(pr.model, pd, q);
    MatrixXd Mp = pd.M;
    Mp.triangularView<Eigen::StrictlyLower>() = Mp.transpose().triangularView<Eigen::StrictlyLower>();
    MatrixXd Tp = velocity_map(s.X, false);
    MatrixXd Mp_in_rbss = Tp.transpose() * Mp * Tp;
    pin::forwardKinematics(pr.model, pd, q);
    double f_pin = 0;
    for (int i = 0; i < 6; ++i) {
      Vector3d pl = pd.oMi[pr.pz[i]].translation();
      Vector3d pp = pd.oMi[pr.ff].act(plat_point(i));
      f_pin = std::max(f_pin, (pl - pp).cwiseAbs().maxCoeff());
    }
    MatrixXd Gp = pin_constraint_jacobian(pr, pd, q);
    double vel_pin = (Gp * v).cwiseAbs().maxCoeff();
    VectorXd tau = pin::rnea(pr.model, pd, q, v, a);
    double res_p;
    VectorXd sol_p = solve_id(tau, Gp, &res_p);
    // forward dynamics with rbss's U
    VectorXd tau_u = VectorXd::Zero(24);
    for (int i = 0; i < 6; ++i) tau_u[vLeg(i) + 2] = s.U[i];
    VectorXd ddq = pin::constraintDynamics(pr.model, pd, q, v, tau_u, pr.cmodels, cdatas);
    VectorXd ddq_l = pin::lcaba(pr.model, pd_l, q, v, tau_u, pr.cmodels, cdatas_l, lset);
    std::fprintf(out, "lcaba %d fd_acc_rel %.3e iter %d residual %.3e\n", k, rel(ddq_l, a), lset.iter,
                 lset.absolute_residual);
    // Pinocchio's multipliers: force on the leg side (joint 1), in the contact frame of joint 1
    VectorXd lam_fd(18);
    for (int i = 0; i < 6; ++i)
      lam_fd.segment<3>(3 * i) = -pd.oMi[pr.pz[i]].rotation() * pd.lambda_c.segment<3>(3 * i);

    // MuJoCo
    std::vector<mjtNum> qpos(25), qvel(24), qacc(24), Mv(24), rne(24);
    to_mj(s.X, s.Xd, s.Xdd, qpos.data(), qvel.data(), qacc.data());
    mju_copy(md->qpos, qpos.data(), 25);
    mju_copy(md->qvel, qvel.data(), 24);
    mju_zero(md->qfrc_applied, 24);
    mju_zero(md->ctrl, mm->nu);
    mj_forward(mm, md);
    mj_mulM(mm, md, Mv.data(), qvel.data());
    double ke_m = 0.5 * mju_dot(qvel.data(), Mv.data(), 24);
    MatrixXd Mm(24, 24);
    {
      std::vector<mjtNum> dense(24 * 24);
      mj_fullM(mm, md, dense.data());
      for (int r = 0; r < 24; ++r)
        for (int c = 0; c < 24; ++c) Mm(r, c) = dense[r * 24 + c];
    }
    MatrixXd Tm = velocity_map(s.X, true);
    MatrixXd Mm_in_rbss = Tm.transpose() * Mm * Tm;
    double f_mj = 0;
    for (int i = 0; i < 6; ++i)
      for (int j = 0; j < 3; ++j)
        f_mj = std::max(f_mj, std::abs(md->site_xpos[3 * site_leg[i] + j] - md->site_xpos[3 * site_plat[i] + j]));
    MatrixXd Gm = mj_constraint_jacobian(mm, md);
    Eigen::Map<VectorXd> qvel_e(qvel.data(), 24);
    double vel_mj = (Gm * qvel_e).cwiseAbs().maxCoeff();
    mju_copy(md->qacc, qacc.data(), 24);
    mj_rne(mm, md, 1, rne.data());  // M qacc + bias (Coriolis, centrifugal, gravity)
    VectorXd tau_m = Eigen::Map<VectorXd>(rne.data(), 24);
    double res_m;
    VectorXd sol_m = solve_id(tau_m, Gm, &res_m);
    // forward dynamics with rbss's U (soft constraints: see RESULT.md)
    for (int i = 0; i < 6; ++i) md->qfrc_applied[vLeg(i) + 2] = s.U[i];
    mj_forward(mm, md);
    VectorXd qacc_fd = Eigen::Map<VectorXd>(md->qacc, 24);
    Eigen::Map<VectorXd> qacc_e(qacc.data(), 24);
    VectorXd lam_mj_fd(18);  // connect force on site1 (leg) in world = efc_force; rbss: -lambda
    for (int r = 0; r < 18 && r < md->nefc; ++r) lam_mj_fd[r] = -md->efc_force[r];
    int nefc = md->nefc;

    std::fprintf(out, "state %d t %.17g\n", k, s.t);
    std::fprintf(out, "rbss_constraint %.3e rbss_ke %.17g\n", f_rbss, ke_r);
    std::fprintf(out,
                 "pin %d ke %.17g ke_rel %.3e M_rel %.3e f %.3e Gv %.3e U_rel %.3e lambda_rel %.3e "
                 "id_resid %.3e fd_acc_rel %.3e fd_lambda_rel %.3e\n",
                 k, ke_p, std::abs(ke_p - ke_r) / ke_r, rel_m(Mp_in_rbss, Mr), f_pin, vel_pin,
                 rel(sol_p.head(6), U), rel(sol_p.tail(18), lam), res_p, rel(ddq, a), rel(lam_fd, lam));
    std::fprintf(out,
                 "mj %d ke %.17g ke_rel %.3e M_rel %.3e f %.3e Gv %.3e U_rel %.3e lambda_rel %.3e "
                 "id_resid %.3e fd_acc_rel %.3e fd_lambda_rel %.3e nefc %d\n",
                 k, ke_m, std::abs(ke_m - ke_r) / ke_r, rel_m(Mm_in_rbss, Mr), f_mj, vel_mj,
                 rel(sol_m.head(6), U), rel(sol_m.tail(18), lam), res_m, rel(qacc_fd, qacc_e),
                 nefc == 18 ? rel(lam_mj_fd, lam) : -1.0, nefc);
    std::fflush(out);
  }

  // --- MuJoCo's soft constraints: the forward-dynamics error against the impedance d (solimp),
  // at the first TraekP state with t >= 0.3 (or the last one)
  {
    int k = 0;
    while (k + 1 < n && st[k].t < 0.3 - 1e-9) ++k;
    const State& s = st[k];
    std::string path = std::string(argv[2]) + ".solimp.xml";
    for (double dmax : {0.9, 0.99, 0.999, 0.9999}) {
      {
        std::ofstream x(path);
        x << mjcf(dmax);
      }
      mjModel* m2 = mj_loadXML(path.c_str(), nullptr, err, sizeof err);
      if (!m2) {
        std::fprintf(stderr, "harness: MuJoCo could not load %s: %s\n", path.c_str(), err);
        return 1;
      }
      mjData* d2 = mj_makeData(m2);
      std::vector<mjtNum> qpos(25), qvel(24), qacc(24);
      to_mj(s.X, s.Xd, s.Xdd, qpos.data(), qvel.data(), qacc.data());
      mju_copy(d2->qpos, qpos.data(), 25);
      mju_copy(d2->qvel, qvel.data(), 24);
      for (int i = 0; i < 6; ++i) d2->qfrc_applied[vLeg(i) + 2] = s.U[i];
      mj_forward(m2, d2);
      std::fprintf(out, "mj_solimp t %.3f dmax %.4f fd_acc_rel %.3e\n", s.t, dmax,
                   rel(Eigen::Map<VectorXd>(d2->qacc, 24), Eigen::Map<VectorXd>(qacc.data(), 24)));
      mj_deleteData(d2);
      mj_deleteModel(m2);
    }
    std::remove(path.c_str());
  }

  // --- timing, at state ti (rbss's forward_dynamics bench state), back to back
  const State& s = st[ti];
  VectorXd q(25), v(24), a(24), tau_u = VectorXd::Zero(24);
  to_pin(s.X, s.Xd, s.Xdd, q, v, &a);
  for (int i = 0; i < 6; ++i) tau_u[vLeg(i) + 2] = s.U[i];
  const int NB = 201;
  double t_cd = median_ns([&] { pin::constraintDynamics(pr.model, pd, q, v, tau_u, pr.cmodels, cdatas); },
                          2000, NB);
  double t_cd_init = median_ns(
      [&] {
        pin::initConstraintDynamics(pr.model, pd, pr.cmodels, cdatas);
        pin::constraintDynamics(pr.model, pd, q, v, tau_u, pr.cmodels, cdatas);
      },
      1000, NB);
  double t_init = median_ns([&] { pin::initConstraintDynamics(pr.model, pd, pr.cmodels, cdatas); }, 2000, NB);
  // a fresh Data + datas + init + solve: what a caller without preallocation pays
  double t_cd_alloc = median_ns(
      [&] {
        pin::Data d2(pr.model);
        std::vector<pin::RigidConstraintData> c2;
        c2.reserve(6);
        for (auto& c : pr.cmodels) c2.emplace_back(c);
        pin::initConstraintDynamics(pr.model, d2, pr.cmodels, c2);
        pin::constraintDynamics(pr.model, d2, q, v, tau_u, pr.cmodels, c2);
      },
      200, NB);
  double t_lcaba = median_ns([&] { pin::lcaba(pr.model, pd_l, q, v, tau_u, pr.cmodels, cdatas_l, lset); },
                             2000, NB);
  int lcaba_iter = lset.iter;
  double t_crba = median_ns([&] { pin::crba(pr.model, pd, q); }, 5000, NB);
  double t_rnea = median_ns([&] { pin::rnea(pr.model, pd, q, v, a); }, 5000, NB);

  std::vector<mjtNum> qpos(25), qvel(24);
  to_mj(s.X, s.Xd, nullptr, qpos.data(), qvel.data(), nullptr);
  mju_copy(md->qpos, qpos.data(), 25);
  mju_copy(md->qvel, qvel.data(), 24);
  mju_zero(md->qfrc_applied, 24);
  for (int i = 0; i < 6; ++i) md->qfrc_applied[vLeg(i) + 2] = s.U[i];
  double t_mj = median_ns([&] { mj_forward(mm, md); }, 2000, NB);
  mj_forward(mm, md);
  int solver_iter = md->solver_niter[0];
  // the stages of mj_forward, each repeated on valid data from the previous stages
  double t_pos = median_ns([&] { mj_fwdPosition(mm, md); }, 2000, NB);
  double t_vel = median_ns([&] { mj_fwdVelocity(mm, md); }, 2000, NB);
  double t_act = median_ns([&] { mj_fwdActuation(mm, md); }, 2000, NB);
  double t_acc = median_ns([&] { mj_fwdAcceleration(mm, md); }, 2000, NB);
  double t_con = median_ns([&] { mj_fwdConstraint(mm, md); }, 2000, NB);
  double t_crb = median_ns([&] { mj_crb(mm, md); mj_factorM(mm, md); }, 5000, NB);
  std::fprintf(out, "timing_state %d t %.17g\n", ti, s.t);
  std::fprintf(out, "time pin_constraintDynamics %.1f\n", t_cd);
  std::fprintf(out, "time pin_init_plus_constraintDynamics %.1f\n", t_cd_init);
  std::fprintf(out, "time pin_initConstraintDynamics %.1f\n", t_init);
  std::fprintf(out, "time pin_fresh_data_init_constraintDynamics %.1f\n", t_cd_alloc);
  std::fprintf(out, "time pin_lcaba %.1f\n", t_lcaba);
  std::fprintf(out, "lcaba_timing_iter %d\n", lcaba_iter);
  std::fprintf(out, "time pin_crba %.1f\n", t_crba);
  std::fprintf(out, "time pin_rnea %.1f\n", t_rnea);
  std::fprintf(out, "time mj_forward %.1f\n", t_mj);
  std::fprintf(out, "time mj_fwdPosition %.1f\n", t_pos);
  std::fprintf(out, "time mj_fwdVelocity %.1f\n", t_vel);
  std::fprintf(out, "time mj_fwdActuation %.1f\n", t_act);
  std::fprintf(out, "time mj_fwdAcceleration %.1f\n", t_acc);
  std::fprintf(out, "time mj_fwdConstraint %.1f\n", t_con);
  std::fprintf(out, "time mj_crb_factorM %.1f\n", t_crb);
  std::fprintf(out, "mj_solver_iterations %d\n", solver_iter);
  std::fclose(out);
  mj_deleteData(md);
  mj_deleteModel(mm);
  return 0;
}
