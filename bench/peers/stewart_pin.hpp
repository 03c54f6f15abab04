// bench/peers/stewart_pin.hpp -- the paper's 6-UPS (../../../shared/paper-example.md) in Pinocchio:
// the robot's numbers, the map from rbss's coordinates to Pinocchio's, the model (tree + six
// CONTACT_3D loop closures), the states file and the timing loop. Shared by harness.cpp (numeric
// Pinocchio and MuJoCo), codegen_gen.cpp (Pinocchio's CppADCodeGen generator) and
// codegen_harness.cpp (the generated C, checked and timed). Include after any Pinocchio
// codegen header (pinocchio/codegen/cppadcg.hpp must come first).
#pragma once

#include <pinocchio/multibody.hpp>
#include <pinocchio/algorithm/constrained-dynamics.hpp>

#include <Eigen/Dense>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

namespace pin = pinocchio;
using Eigen::Matrix3d;
using Eigen::MatrixXd;
using Eigen::Vector3d;
using Eigen::VectorXd;

// ---------------------------------------------------------------------------------------------
// The robot, every number from shared/paper-example.md (and models/stewart_6ups.toml).
static const double PI = 3.14159265358979323846;
static const double R0 = 0.489, RP = 0.389, H = 0.0, RHO = 7800.0;
static const double R_LOW = 0.05, L_LOW = 0.5, R_UP = 0.04, L_UP = 0.8, T_PLAT = 0.02;
static const double ALPHA_DEG[6] = {-15, 15, 105, 135, 225, 255};
static const double BETA_DEG[6] = {-45, 45, 75, 165, 195, 285};
static const Vector3d GRAVITY(0, 0, -9.81);

struct Cyl {
  double m, ixx, izz;
};
static Cyl cylinder(double r, double l) {
  double m = RHO * PI * r * r * l;
  return {m, m * (3 * r * r + l * l) / 12.0, m * r * r / 2.0};
}
static const Cyl LOW = cylinder(R_LOW, L_LOW);    // 30.630528372500 kg, com (0,0,+0.25)
static const Cyl UP = cylinder(R_UP, L_UP);       // 31.365661053441 kg, com (0,0,-0.40)
static const Cyl PLAT = cylinder(RP, T_PLAT);     // 74.160674941682 kg, com (0,0,0)

static Matrix3d Rx(double a) { return Eigen::AngleAxisd(a, Vector3d::UnitX()).toRotationMatrix(); }
static Matrix3d Ry(double a) { return Eigen::AngleAxisd(a, Vector3d::UnitY()).toRotationMatrix(); }
static Matrix3d Rz(double a) { return Eigen::AngleAxisd(a, Vector3d::UnitZ()).toRotationMatrix(); }
static double deg(double d) { return d * PI / 180.0; }
// base joint 0i: Rz(alpha) Tx(r0); platform joint Pi in the platform frame: Rz(beta) Tz(h) Tx(rp)
static Vector3d base_point(int i) { return Rz(deg(ALPHA_DEG[i])) * Vector3d(R0, 0, 0); }
static Vector3d plat_point(int i) { return Rz(deg(BETA_DEG[i])) * Vector3d(RP, 0, H); }

// rbss coordinate indices
static int iD(int i) { return i; }
static int iPhi(int i) { return 6 + i; }
static int iPsi(int i) { return 12 + i; }
static const int IX = 18, IROT = 21;

// Both libraries: dofs [platform free joint (6), leg1 (phi, psi, d), ..., leg6 (phi, psi, d)],
// configurations [platform (7), leg1 (phi, psi, d), ...].
static int vLeg(int i) { return 6 + 3 * i; }
static int qLeg(int i) { return 7 + 3 * i; }

// ---------------------------------------------------------------------------------------------
// State map from rbss's coordinates to the libraries'.
// Platform A_p = Tx(x) Ty(y) Tz(z) Rx(a) Ry(b) Rz(c): R = Rx(a) Ry(b) Rz(c),
// world angular velocity w = E(a, b) [a', b', c'] with E = [e_x, Rx(a) e_y, Rx(a) Ry(b) e_z].
struct PlatformKin {
  Matrix3d R;
  Vector3d p, pd, pdd, w, wd;  // world: position, velocity, acceleration, omega, omega dot
};
static PlatformKin platform_kin(const double* X, const double* Xd, const double* Xdd) {
  PlatformKin k;
  double a = X[IROT], b = X[IROT + 1], c = X[IROT + 2];
  double ad = Xd[IROT], bd = Xd[IROT + 1], cd = Xd[IROT + 2];
  double add = Xdd ? Xdd[IROT] : 0, bdd = Xdd ? Xdd[IROT + 1] : 0, cdd = Xdd ? Xdd[IROT + 2] : 0;
  k.R = Rx(a) * Ry(b) * Rz(c);
  Vector3d e1 = Vector3d::UnitX(), e2 = Rx(a) * Vector3d::UnitY(), e3 = Rx(a) * Ry(b) * Vector3d::UnitZ();
  k.p = Vector3d(X[IX], X[IX + 1], X[IX + 2]);
  k.pd = Vector3d(Xd[IX], Xd[IX + 1], Xd[IX + 2]);
  k.pdd = Xdd ? Vector3d(Xdd[IX], Xdd[IX + 1], Xdd[IX + 2]) : Vector3d::Zero();
  k.w = e1 * ad + e2 * bd + e3 * cd;
  Vector3d w1 = e1 * ad, w2 = e1 * ad + e2 * bd;  // angular velocities of the frames Rx, Rx Ry
  k.wd = e1 * add + e2 * bdd + e3 * cdd + w1.cross(e2) * bd + w2.cross(e3) * cd;
  return k;
}

// Pinocchio: free flyer q = [p, quat(x, y, z, w)], v = body twist [R^T p', R^T w],
// a = d v / dt = [R^T p'' - w_b x v_b, R^T w'].
static void to_pin(const double* X, const double* Xd, const double* Xdd, VectorXd& q, VectorXd& v,
                   VectorXd* a) {
  PlatformKin k = platform_kin(X, Xd, Xdd);
  Eigen::Quaterniond quat(k.R);
  q.head<3>() = k.p;
  q.segment<4>(3) = quat.coeffs();
  Vector3d vb = k.R.transpose() * k.pd, wb = k.R.transpose() * k.w;
  v.head<3>() = vb;
  v.segment<3>(3) = wb;
  if (a) {
    a->head<3>() = k.R.transpose() * k.pdd - wb.cross(vb);
    a->segment<3>(3) = k.R.transpose() * k.wd;
  }
  for (int i = 0; i < 6; ++i) {
    int qi = qLeg(i), vi = vLeg(i);
    q[qi] = X[iPhi(i)], q[qi + 1] = X[iPsi(i)], q[qi + 2] = X[iD(i)];
    v[vi] = Xd[iPhi(i)], v[vi + 1] = Xd[iPsi(i)], v[vi + 2] = Xd[iD(i)];
    if (a) (*a)[vi] = Xdd[iPhi(i)], (*a)[vi + 1] = Xdd[iPsi(i)], (*a)[vi + 2] = Xdd[iD(i)];
  }
}

// ---------------------------------------------------------------------------------------------
// Pinocchio model.
struct PinRobot {
  pin::Model model;
  std::vector<pin::JointIndex> pz;  // the prismatic joint of each leg (its origin is Pi)
  pin::JointIndex ff;
  std::vector<pin::RigidConstraintModel> cmodels;
};

static PinRobot build_pin() {
  PinRobot r;
  pin::Model& m = r.model;
  m.gravity = pin::Motion(GRAVITY, Vector3d::Zero());
  // platform: free flyer from the world, disc inertia about its centre (the frame origin)
  r.ff = m.addJoint(0, pin::JointModelFreeFlyer(), pin::SE3::Identity(), "platform");
  m.appendBodyToJoint(r.ff,
                      pin::Inertia(PLAT.m, Vector3d::Zero(),
                                   Vector3d(PLAT.ixx, PLAT.ixx, PLAT.izz).asDiagonal().toDenseMatrix()));
  for (int i = 0; i < 6; ++i) {
    std::string n = "leg" + std::to_string(i + 1);
    // base joint 0i = Rz(alpha_i) Tx(r0); universal joint Rx(phi) Ry(psi); prismatic Tz(d)
    pin::SE3 base(Rz(deg(ALPHA_DEG[i])), base_point(i));
    pin::JointIndex jx = m.addJoint(0, pin::JointModelRX(), base, n + "_phi");
    pin::JointIndex jy = m.addJoint(jx, pin::JointModelRY(), pin::SE3::Identity(), n + "_psi");
    m.appendBodyToJoint(jy, pin::Inertia(LOW.m, Vector3d(0, 0, L_LOW / 2),
                                         Vector3d(LOW.ixx, LOW.ixx, LOW.izz).asDiagonal().toDenseMatrix()));
    pin::JointIndex jz = m.addJoint(jy, pin::JointModelPZ(), pin::SE3::Identity(), n + "_d");
    m.appendBodyToJoint(jz, pin::Inertia(UP.m, Vector3d(0, 0, -L_UP / 2),
                                         Vector3d(UP.ixx, UP.ixx, UP.izz).asDiagonal().toDenseMatrix()));
    r.pz.push_back(jz);
    (void)jx;
  }
  // loop closures: origin of the prismatic joint frame (Pi on the leg) = Pi on the platform
  for (int i = 0; i < 6; ++i) {
    pin::RigidConstraintModel c(pin::CONTACT_3D, m, r.pz[i], pin::SE3::Identity(), r.ff,
                                pin::SE3(Rz(deg(BETA_DEG[i])), plat_point(i)), pin::LOCAL);
    // Baumgarte corrector: default Kp = Kd = 0 (no correction), as in rbss's plain solve
    r.cmodels.push_back(c);
  }
  return r;
}

// ---------------------------------------------------------------------------------------------
// Helpers.
static double rel(const VectorXd& a, const VectorXd& ref) {
  return (a - ref).cwiseAbs().maxCoeff() / std::max(ref.cwiseAbs().maxCoeff(), 1e-300);
}
static double rel_m(const MatrixXd& a, const MatrixXd& ref) {
  return (a - ref).cwiseAbs().maxCoeff() / std::max(ref.cwiseAbs().maxCoeff(), 1e-300);
}

template <class F>
static double median_ns(F&& f, int batch, int nbatch) {
  for (int i = 0; i < batch; ++i) f();  // warm-up
  std::vector<double> t(nbatch);
  for (int b = 0; b < nbatch; ++b) {
    auto t0 = std::chrono::steady_clock::now();
    for (int i = 0; i < batch; ++i) f();
    auto t1 = std::chrono::steady_clock::now();
    t[b] = std::chrono::duration<double, std::nano>(t1 - t0).count() / batch;
  }
  std::nth_element(t.begin(), t.begin() + nbatch / 2, t.end());
  return t[nbatch / 2];
}

struct State {
  double t, X[24], Xd[24], Xdd[24], U[6], lam[18], M[576], f[18];
};

// STATES_IN (see harness.cpp): the count N, then per state t, X(24), Xdot(24), Xddot(24), U(6),
// lambda(18), M(24*24, row-major), f(18). Returns false (with a message) when malformed.
static bool read_states(const char* path, std::vector<State>& st) {
  std::ifstream in(path);
  int n = 0;
  if (!(in >> n) || n <= 0) {
    std::fprintf(stderr, "cannot read state count from %s\n", path);
    return false;
  }
  st.resize(n);
  for (auto& s : st) {
    in >> s.t;
    for (double& v : s.X) in >> v;
    for (double& v : s.Xd) in >> v;
    for (double& v : s.Xdd) in >> v;
    for (double& v : s.U) in >> v;
    for (double& v : s.lam) in >> v;
    for (double& v : s.M) in >> v;
    for (double& v : s.f) in >> v;
  }
  if (!in) {
    std::fprintf(stderr, "%s is truncated or malformed\n", path);
    return false;
  }
  return true;
}
