// bench/peers/codegen_gen.cpp -- Pinocchio's generated code for the paper's 6-UPS: records
// pinocchio::constraintDynamics (the model of stewart_pin.hpp: a tree of six RX-RY-PZ legs and a
// free-flyer platform, six CONTACT_3D loop closures, default ProximalSettings) on CppAD<CG<double>>
// with Pinocchio's CodeGenConstraintDynamics, and writes CppADCodeGen's straight-line C sources;
// with the second argument `derivatives`, the same for its derivatives
// (CodeGenConstraintDynamicsDerivatives: constraintDynamics then
// computeConstraintDynamicsDerivatives on the tape). Driven by run.sh (PEERS_CODEGEN=1) and
// run_derivatives.sh; see README.md.
//
// usage: codegen_gen OUT_DIR [derivatives]
//   (prints "key value" lines: tape size, CppAD/CppADCodeGen versions)
//   OUT_DIR/constraintDynamics_forward_zero.c: the function
//     void constraintDynamics_forward_zero(double const *const *in, double *const *out,
//                                          struct LangCAtomicFun atomicFun)
//   in[0] = [q (25), v (24), tau (24)], out[0] = [ddq (24), lambda_c (18)] (Pinocchio's
//   coordinates and multipliers, as pinocchio::constraintDynamics returns them); the other files
//   are CppADCodeGen's library glue (info, sparsity, atomic-function table), not used here.
//   With `derivatives`: OUT_DIR/constraintDynamicsDerivatives_forward_zero.c, same signature,
//   in[0] as above, out[0] = [ddq_dq, ddq_dv, ddq_dtau (24 x 24 each, row-major),
//   dlambda_dq, dlambda_dv, dlambda_dtau (18 x 24 each, column-major)], the layout of
//   CodeGenConstraintDynamicsDerivatives::buildMap.
//
// CppADCodeGen 2.4.3's ModelLibraryCSourceGen::saveSources does not compile (it calls
// ModelCSourceGen::getSources() without the two arguments that takes);
// SaveFilesModelLibraryProcessor does the same job. Pinocchio's CodeGenBase::initLib/compileLib (dlopen of a library built with
// -Ofast) is not used: the harness compiles and links the C itself, with the flags it reports.

#include <pinocchio/codegen/cppadcg.hpp>  // must come before any other Pinocchio header
#include <pinocchio/codegen/cppadcg-algo.hpp>
#include <cppad/cg/configure.hpp>  // CPPAD_CG_VERSION

#include "stewart_pin.hpp"

#include <cstdio>
#include <string>

template <class Base>
struct Gen : Base {
  Gen(const pin::Model& m, const std::vector<pin::RigidConstraintModel>& c, const std::string& name)
      : Base(m, c, name, "cg_" + name), name(name) {}
  std::string name;

  // Record the tape (the CodeGen class's buildMap) and write the C sources.
  void save(const std::string& dir) {
    this->buildMap();
    CppAD::cg::ModelCSourceGen<double> cgen(this->ad_fun, name);
    cgen.setCreateForwardZero(true);
    cgen.setCreateJacobian(false);
    cgen.setCreateSparseJacobian(false);
    cgen.setCreateHessian(false);
    cgen.setCreateSparseHessian(false);
    cgen.setCreateForwardOne(false);
    cgen.setCreateReverseOne(false);
    cgen.setCreateReverseTwo(false);
    // one function, one file: no split into *_forward_zero_indep* pieces
    cgen.setMaxAssignmentsPerFunc(100000000);
    CppAD::cg::ModelLibraryCSourceGen<double> lib(cgen);
    CppAD::cg::SaveFilesModelLibraryProcessor<double> proc(lib);
    proc.saveSourcesTo(dir);
    // "key value" lines on stdout (run.sh keeps them in build/codegen/gen_info.txt)
    std::printf("cg_tape inputs %zu outputs %zu variables %zu\n", (size_t)this->ad_fun.Domain(),
                (size_t)this->ad_fun.Range(), (size_t)this->ad_fun.size_var());
    std::printf("cppad_version %s\n", CPPAD_PACKAGE_STRING);
    std::printf("cppadcg_version %s\n", CPPAD_CG_VERSION);
    std::printf("cg_pinocchio_version %s\n", PINOCCHIO_VERSION);
  }
};

int main(int argc, char** argv) {
  bool derivatives = argc == 3 && std::string(argv[2]) == "derivatives";
  if (argc != 2 && !derivatives) {
    std::fprintf(stderr, "usage: %s OUT_DIR [derivatives]\n", argv[0]);
    return 2;
  }
  PinRobot pr = build_pin();
  if (pr.model.nq != 25 || pr.model.nv != 24 || pr.cmodels.size() != 6) {
    std::fprintf(stderr, "codegen: unexpected model sizes nq %d nv %d constraints %zu\n",
                 (int)pr.model.nq, (int)pr.model.nv, pr.cmodels.size());
    return 1;
  }
  if (derivatives) {
    Gen<pin::CodeGenConstraintDynamicsDerivatives<double>> g(pr.model, pr.cmodels,
                                                             "constraintDynamicsDerivatives");
    g.save(argv[1]);
  } else {
    Gen<pin::CodeGenConstraintDynamics<double>> g(pr.model, pr.cmodels, "constraintDynamics");
    g.save(argv[1]);
  }
  return 0;
}
