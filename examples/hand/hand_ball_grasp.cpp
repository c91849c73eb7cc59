// examples/hand/hand_ball_grasp.cpp — finds a grasp of the free ball that the pads hold by pushing
// (issue 26, step 1; grasp.hpp) and writes it for make_hand_scene.py.
//
//   hand_ball_grasp [--scene NAME] [--out FILE] [--diagnose] [--evaluations N] [--no-thumb-base] [--start FILE]
//
// --diagnose: the stored posture's hold by parts (grasp.hpp, diagnoseHold) instead of a search;
// --evaluations: Nelder–Mead's budget for the first target; --no-thumb-base: keep the scene's thumb
// base; --start: the numbers of a "parameters:" line of an earlier run as the start.
//
// NAME: a free-ball scene of examples/scenes (default hand_ball; hand_ball_pinch the thumb-and-index
// reduction), read with examples/hand/NAME_limits.json; its hand is used and its stored grasp is the
// start. Writes FILE (default examples/hand/NAME_grasp.json): the ball's centre, the contact points,
// q and u of the polished equilibrium, and the thumb base (make_hand_scene.py --free-ball reads it
// when it exists; no grasp within the joint ranges has been found yet, examples/hand/README.md). Exit status 0 only when the grasp holds (grasp.hpp: q̈ = 0 polished,
// every contact pressing by the margin and inside the pyramid, tensions and joints in range); 1
// otherwise (nothing written); 2 on bad arguments.
#include "grasp.hpp"

#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdlib>
#include <cstdio>
#include <fstream>
#include <numbers>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

using namespace trellis;

int main(int argc, char** argv) {
  std::string scene = "hand_ball", out;
  bool diagnose = false;
  int evaluations = 0;
  bool thumbBase = true;
  std::string startFile;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if ((a == "--scene" || a == "--out") && i + 1 < argc) (a == "--scene" ? scene : out) = argv[++i];
    else if (a == "--diagnose") diagnose = true;
    else if (a == "--evaluations" && i + 1 < argc) evaluations = std::atoi(argv[++i]);
    else if (a == "--no-thumb-base") thumbBase = false;
    else if (a == "--start" && i + 1 < argc) startFile = argv[++i];
    else if (a == "--help") {
      std::cout << "usage: hand_ball_grasp [--scene NAME] [--out FILE] [--diagnose] [--evaluations N] [--no-thumb-base] [--start FILE]\n";
      return 0;
    } else {
      std::cerr << "hand_ball_grasp: unknown option or missing value '" << a << "' (--help)\n";
      return 2;
    }
  }
  const std::string hand = TRELLIS_HAND_DIR;
  if (out.empty()) out = hand + "/" + scene + "_grasp.json";
  const auto t0 = std::chrono::steady_clock::now();
  std::string text;
  hand::BallLimits limits;
  Eigen::VectorXd q0;
  try {
    const std::string path = std::string(TRELLIS_EXAMPLE_SCENES_DIR) + "/" + scene + ".json";
    std::ifstream in(path);
    if (!in) throw std::runtime_error(path + ": cannot be read");
    std::stringstream buffer;
    buffer << in.rdbuf();
    text = buffer.str();
    const Scene s = parseScene(text, path);
    limits = hand::loadBallLimits(hand + "/" + scene + "_limits.json", s.model);
    q0 = s.q;
  } catch (const std::exception& e) {
    std::cerr << "hand_ball_grasp: " << e.what() << "\n";
    return 2;
  }
  if (diagnose) {
    // The stored posture's hold, whole and by parts (grasp.hpp, diagnoseHold), at the issue's
    // margin and the facets' full friction.
    const Scene s = parseScene(text, scene);
    const double facetMu = limits.friction * std::cos(std::numbers::pi / 8);
    const hand::HoldDiagnosis dg = hand::diagnoseHold(s.model, q0, limits.digits, limits.normalMin, facetMu, 8);
    std::printf("stored posture, f_min %.2f N, mu' %.3f: whole hold residual %.4f\n", limits.normalMin, facetMu,
                dg.whole.relativeResidual);
    std::printf("  ball rows alone: residual %.4f, worst %s\n", dg.ballResidual, dg.ballWorst.c_str());
    for (std::size_t d = 0; d < limits.digits.size(); ++d)
      std::printf("  %-7s rows alone: residual %.4f, worst %s; whole hold: lambda (%.3f, %.3f, %.3f) N\n",
                  limits.digits[d].c_str(), dg.digitResidual[d], dg.digitWorst[d].c_str(), dg.whole.lambda(3 * d),
                  dg.whole.lambda(3 * d + 1), dg.whole.lambda(3 * d + 2));
    Eigen::Index worst = 0;
    dg.whole.residual.cwiseAbs().maxCoeff(&worst);
    std::printf("  whole hold: worst row %s (%.4f); tensions at 0:", s.model.configNames()[worst].c_str(),
                dg.whole.residual(worst));
    for (int k = 0; k < s.model.nu(); ++k)
      if (dg.whole.tension(k) == 0.0) std::printf(" %s", s.model.inputNames()[k].c_str());
    std::printf("\n");
    return 0;
  }
  hand::GraspSearchOptions options;
  if (evaluations > 0) options.maxEvaluations = evaluations;
  if (!thumbBase) options.thumbBaseRotation = 0.0;
  if (!startFile.empty()) {  // the numbers of a "parameters:" line of an earlier run
    std::ifstream in(startFile);
    std::vector<double> v;
    for (double x; in >> x;) v.push_back(x);
    if (v.empty()) {
      std::cerr << "hand_ball_grasp: " << startFile << ": no numbers\n";
      return 2;
    }
    options.start = Eigen::Map<Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(v.size()));
  }
  const hand::FreeBallGrasp g = hand::findFreeBallGrasp(text, limits, options);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("grasp search: %d evaluations, %.2f s; target f_min %.2f N, mu' %.3f\n", g.evaluations, seconds,
              g.targetNormal, g.targetFriction);
  if (g.margins.minNormalContact >= 0) {  // a target was reached: the polished point's figures
    std::printf("ball centre (%.5f, %.5f, %.5f) m; |qdd| %.3g; pad normals within %.3g rad of the centre\n",
                g.centre(0), g.centre(1), g.centre(2), g.accelerationResidual, g.alignment);
    std::printf("residual force %.3g of the rest load\n", g.relativeAcceleration);
    std::printf("thumb base turned by omega = (%.4f, %.4f, %.4f) rad (|omega| %.4f), CMC site moved by (%.4f, %.4f, %.4f) m\n",
                g.thumbTurn(0), g.thumbTurn(1), g.thumbTurn(2), g.thumbTurn.norm(), g.thumbShift(0), g.thumbShift(1),
                g.thumbShift(2));
    std::printf("min normal force %.4f N (%s), worst friction ratio %.4f (%s), max tension %.3f N\n",
                g.margins.minNormal, limits.digits[g.margins.minNormalContact].c_str(), g.margins.worstFrictionRatio,
                limits.digits[g.margins.worstFrictionContact].c_str(), g.u.maxCoeff());
    for (std::size_t d = 0; d < limits.digits.size(); ++d)
      std::printf("  %-7s lambda (n, t1, t2) = (%.4f, %.4f, %.4f) N\n", limits.digits[d].c_str(), g.lambda(3 * d),
                  g.lambda(3 * d + 1), g.lambda(3 * d + 2));
  }
  std::printf("parameters:");
  for (Eigen::Index i = 0; i < g.parameters.size(); ++i) std::printf(" %.17g", g.parameters(i));
  std::printf("\n");
  if (!g.ok) {
    std::printf("FAILED: %s\n", g.message.c_str());
    return 1;
  }
  const Scene s = parseScene(text, scene);
  nlohmann::json j;
  j["description"] = "A grasp of the free ball held by pushing pads (issue 26), found by hand_ball_grasp --scene " +
                     scene + " (examples/hand/grasp.hpp).";
  j["centre"] = {g.centre(0), g.centre(1), g.centre(2)};
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 4; ++k) j["thumb_base"][i][k] = g.thumbBase.matrix()(i, k);
  for (std::size_t d = 0; d < limits.digits.size(); ++d)
    j["contacts"][limits.digits[d]] = {g.contacts[d](0), g.contacts[d](1), g.contacts[d](2)};
  for (int i = 0; i < s.model.nq(); ++i) j["q"][s.model.configNames()[i]] = g.q(i);
  for (int i = 0; i < s.model.nu(); ++i) j["u"][s.model.inputNames()[i]] = g.u(i);
  j["min_normal_force"] = g.margins.minNormal;
  j["worst_friction_ratio"] = g.margins.worstFrictionRatio;
  std::ofstream f(out);
  f.precision(17);
  f << j.dump(1) << "\n";
  if (!f) {
    std::cerr << "hand_ball_grasp: " << out << ": cannot be written\n";
    return 1;
  }
  std::printf("wrote %s\nok\n", out.c_str());
  return 0;
}
