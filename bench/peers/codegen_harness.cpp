// bench/peers/codegen_harness.cpp -- Pinocchio's generated constraintDynamics (CppADCodeGen, see
// codegen_gen.cpp) for the paper's 6-UPS, checked against numeric pinocchio::constraintDynamics
// and rbss's numbers at the states of harness.cpp, then timed. Driven by run.sh
// (PEERS_CODEGEN=1); see README.md.
//
// usage: codegen_harness STATES_IN RESULTS_OUT TIMING_STATE_INDEX
//   STATES_IN, TIMING_STATE_INDEX: as for harness.cpp. RESULTS_OUT: "key value" lines.
//
// The generated C (build/codegen/src/constraintDynamics_forward_zero.c) is compiled twice by
// run.sh, into two objects whose function is renamed with -D: cg_cd_portable (gcc -O3, no -march)
// and cg_cd_native (gcc -O3 -march=native). This file itself is compiled like harness.cpp (no
// -march: an earlier attempt found that a -march=native build of code using the prebuilt
// libpinocchio_default aborts with boost::bad_get, presumably a layout mismatch of the
// Eigen/Boost types across the library boundary).

#include "stewart_pin.hpp"

#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

// CppADCodeGen's `struct LangCAtomicFun` (three pointers, unused: this model has no atomic
// functions), passed by value; the layout matches the C definition in the generated file.
struct CgAtomicFun {
  void* libModel;
  void* forward;
  void* reverse;
};
extern "C" {
void cg_cd_portable(double const* const* in, double* const* out, CgAtomicFun atomic);
void cg_cd_native(double const* const* in, double* const* out, CgAtomicFun atomic);
}
typedef void (*CgFn)(double const* const*, double* const*, CgAtomicFun);

static const int NQ = 25, NV = 24, NC = 18, NX = NQ + 2 * NV, NY = NV + NC;

// in = [q, v, tau], out = [ddq, lambda_c]
static void eval(CgFn f, const VectorXd& q, const VectorXd& v, const VectorXd& tau, VectorXd& ddq,
                 VectorXd& lam) {
  double x[NX], y[NY];
  for (int i = 0; i < NQ; ++i) x[i] = q[i];
  for (int i = 0; i < NV; ++i) x[NQ + i] = v[i], x[NQ + NV + i] = tau[i];
  const double* in[1] = {x};
  double* out[1] = {y};
  f(in, out, CgAtomicFun{nullptr, nullptr, nullptr});
  ddq = Eigen::Map<VectorXd>(y, NV);
  lam = Eigen::Map<VectorXd>(y + NV, NC);
}

int main(int argc, char** argv) {
  if (argc != 4) {
    std::fprintf(stderr, "usage: %s STATES_IN RESULTS_OUT TIMING_STATE_INDEX\n", argv[0]);
    return 2;
  }
  std::vector<State> st;
  if (!read_states(argv[1], st)) return 1;
  int n = (int)st.size();
  int ti = std::atoi(argv[3]);
  if (ti < 0 || ti >= n) {
    std::fprintf(stderr, "codegen_harness: timing state index %d out of range\n", ti);
    return 1;
  }
  FILE* out = std::fopen(argv[2], "w");
  if (!out) {
    std::fprintf(stderr, "codegen_harness: cannot write %s\n", argv[2]);
    return 1;
  }
  PinRobot pr = build_pin();
  pin::Data pd(pr.model);
  std::vector<pin::RigidConstraintData> cdatas;
  for (auto& c : pr.cmodels) cdatas.emplace_back(c);
  pin::initConstraintDynamics(pr.model, pd, pr.cmodels, cdatas);

  // --- agreement, state by state: generated (both builds) vs numeric Pinocchio vs rbss
  const CgFn fns[2] = {cg_cd_portable, cg_cd_native};
  const char* names[2] = {"portable", "native"};
  for (int k = 0; k < n; ++k) {
    const State& s = st[k];
    VectorXd q(NQ), v(NV), a(NV), tau = VectorXd::Zero(NV);
    to_pin(s.X, s.Xd, s.Xdd, q, v, &a);
    for (int i = 0; i < 6; ++i) tau[vLeg(i) + 2] = s.U[i];
    VectorXd ddq_num = pin::constraintDynamics(pr.model, pd, q, v, tau, pr.cmodels, cdatas);
    VectorXd lam_num = pd.lambda_c;
    Eigen::Map<const VectorXd> lam_rbss(s.lam, NC);
    for (int b = 0; b < 2; ++b) {
      VectorXd ddq, lam_c;
      eval(fns[b], q, v, tau, ddq, lam_c);
      // rbss's multipliers: lambda = -R lambda_c, R the leg's contact frame (pd.oMi after the
      // numeric call at the same q)
      VectorXd lam(NC);
      for (int i = 0; i < 6; ++i)
        lam.segment<3>(3 * i) = -pd.oMi[pr.pz[i]].rotation() * lam_c.segment<3>(3 * i);
      std::fprintf(out,
                   "cg %d build %s t %.17g acc_vs_rbss %.3e lambda_vs_rbss %.3e acc_vs_pin %.3e "
                   "lambda_vs_pin %.3e pin_acc_vs_rbss %.3e\n",
                   k, names[b], s.t, rel(ddq, a), rel(lam, lam_rbss), rel(ddq, ddq_num),
                   rel(lam_c, lam_num), rel(ddq_num, a));
    }
  }

  // --- timing at state ti, the two builds alternately (3 rounds each, median of the rounds'
  // medians), the numeric call once in between for reference
  const State& s = st[ti];
  VectorXd q(NQ), v(NV), a(NV), tau = VectorXd::Zero(NV);
  to_pin(s.X, s.Xd, s.Xdd, q, v, &a);
  for (int i = 0; i < 6; ++i) tau[vLeg(i) + 2] = s.U[i];
  double x[NX], y[NY];
  for (int i = 0; i < NQ; ++i) x[i] = q[i];
  for (int i = 0; i < NV; ++i) x[NQ + i] = v[i], x[NQ + NV + i] = tau[i];
  const double* in[1] = {x};
  double* outp[1] = {y};
  const CgAtomicFun af{nullptr, nullptr, nullptr};
  const int NB = 201, BATCH = 2000, ROUNDS = 3;
  std::vector<double> tp, tn;
  for (int r = 0; r < ROUNDS; ++r) {
    tp.push_back(median_ns([&] { cg_cd_portable(in, outp, af); }, BATCH, NB));
    tn.push_back(median_ns([&] { cg_cd_native(in, outp, af); }, BATCH, NB));
  }
  double t_num = median_ns([&] { pin::constraintDynamics(pr.model, pd, q, v, tau, pr.cmodels, cdatas); },
                           BATCH, NB);
  std::sort(tp.begin(), tp.end());
  std::sort(tn.begin(), tn.end());
  std::fprintf(out, "cg_timing_state %d t %.17g\n", ti, s.t);
  std::fprintf(out, "time cg_constraintDynamics_portable %.1f\n", tp[ROUNDS / 2]);
  std::fprintf(out, "time cg_constraintDynamics_native %.1f\n", tn[ROUNDS / 2]);
  std::fprintf(out, "time cg_pin_constraintDynamics_numeric %.1f\n", t_num);
  std::fprintf(out, "cg_rounds_portable");
  for (double t : tp) std::fprintf(out, " %.1f", t);
  std::fprintf(out, "\ncg_rounds_native");
  for (double t : tn) std::fprintf(out, " %.1f", t);
  std::fprintf(out, "\n");
  std::fclose(out);
  return 0;
}
