// Pinocchio's C++ timing of the same terms `softcontact bench dynamics` times, on the same URDF and with
// the same method: 1000 pre-drawn random states, N calls cycling through them, best of R repetitions.
// Prints one JSON object {"name": ns_per_call, ...}. Built and run by run.sh beside this file.
#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/compute-all-terms.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/multibody.hpp>
#include <pinocchio/parsers/urdf.hpp>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

using Vec = Eigen::VectorXd;

template <typename F> double best_ns(F &&f, long calls, int reps) {
  double best = 1e300;
  for (int r = 0; r < reps; ++r) {
    auto t0 = std::chrono::steady_clock::now();
    for (long i = 0; i < calls; ++i) f(i);
    auto t1 = std::chrono::steady_clock::now();
    double ns = std::chrono::duration<double, std::nano>(t1 - t0).count() / double(calls);
    if (ns < best) best = ns;
  }
  return best;
}

int main(int argc, char **argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s URDF [CALLS] [REPS]\n", argv[0]);
    return 2;
  }
  const long calls = argc > 2 ? std::atol(argv[2]) : 1000000;
  const int reps = argc > 3 ? std::atoi(argv[3]) : 5;
  pinocchio::Model model;
  pinocchio::urdf::buildModel(std::string(argv[1]), model);
  pinocchio::Data data(model);
  const auto tool = model.getFrameId("lwr_tool");
  const int n_states = 1000;
  std::vector<Vec> q(n_states), v(n_states), a(n_states), tau(n_states);
  std::srand(7);
  for (int i = 0; i < n_states; ++i) {
    q[i] = pinocchio::randomConfiguration(model);
    v[i] = Vec::Random(model.nv);
    a[i] = Vec::Random(model.nv);
    tau[i] = Vec::Random(model.nv) * 10.0;
  }
  Eigen::Matrix<double, 6, Eigen::Dynamic> J(6, model.nv);
  double sink = 0.0;
  auto k = [&](long i) { return int(i % n_states); };

  double fk_jac = best_ns([&](long i) {
    J.setZero();
    pinocchio::computeFrameJacobian(model, data, q[k(i)], tool, pinocchio::LOCAL_WORLD_ALIGNED, J);
    sink += J(0, 0);
  }, calls, reps);
  double rnea = best_ns([&](long i) { sink += pinocchio::rnea(model, data, q[k(i)], v[k(i)], a[k(i)])[0]; }, calls, reps);
  double crba = best_ns([&](long i) { sink += pinocchio::crba(model, data, q[k(i)])(0, 0); }, calls, reps);
  double grav = best_ns([&](long i) { sink += pinocchio::computeGeneralizedGravity(model, data, q[k(i)])[0]; }, calls, reps);
  double nle = best_ns([&](long i) { sink += pinocchio::nonLinearEffects(model, data, q[k(i)], v[k(i)])[0]; }, calls, reps);
  double aba = best_ns([&](long i) { sink += pinocchio::aba(model, data, q[k(i)], v[k(i)], tau[k(i)])[0]; }, calls, reps);
  double minv = best_ns([&](long i) { sink += pinocchio::computeMinverse(model, data, q[k(i)])(0, 0); }, calls, reps);
  double all = best_ns([&](long i) {
    pinocchio::computeAllTerms(model, data, q[k(i)], v[k(i)]);
    sink += data.M(0, 0);
  }, calls, reps);
  std::printf("{\"fk_jacobian\": %.2f, \"rnea\": %.2f, \"crba\": %.2f, \"gravity\": %.2f, "
              "\"nonlinear_effects\": %.2f, \"aba\": %.2f, \"minverse\": %.2f, \"control_tick\": %.2f, "
              "\"sink\": %g}\n",
              fk_jac, rnea, crba, grav, nle, aba, minv, all, sink);
  return 0;
}
