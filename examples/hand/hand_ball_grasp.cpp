// examples/hand/hand_ball_grasp.cpp — finds a grasp of the free ball that the pads hold by pushing
// (issue 26, step 1; grasp.hpp) and writes it for make_hand_scene.py.
//
//   hand_ball_grasp [--scene NAME] [--out FILE] [--diagnose] [--evaluations N] [--no-thumb-base] [--start FILE]
//                   [--nlp] [--max-iterations N]
//
// --nlp: the hold as a smooth program (grasp.hpp, solveGraspNlp: Ipopt over q, u and the margin s,
// exact first derivatives) from the posture of --start (or the stored grasp), no search;
// --max-iterations N: Ipopt's limit for each of --nlp's two solves (3000; the stored hold: 8000);
// --diagnose: the stored posture's hold by parts (grasp.hpp, diagnoseHold) instead of a search;
// --evaluations: Nelder–Mead's budget for the first target; --no-thumb-base: keep the scene's thumb
// base; --start: the numbers of a "parameters:" line of an earlier run as the start.
//
// NAME: a free-ball scene of examples/scenes (default hand_ball; hand_ball_pinch the thumb-and-index
// reduction), read with examples/hand/NAME_limits.json; its hand is used and its stored grasp is the
// start. Writes FILE (default examples/hand/NAME_grasp.json): the ball's centre, the contact points,
// q and u of the polished equilibrium, and the thumb base (make_hand_scene.py --free-ball reads it
// when it exists; the stored one is --nlp's, examples/hand/README.md). Exit status 0 only when the grasp holds (grasp.hpp: q̈ = 0 polished,
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
  int nlpIterations = 0;  // --max-iterations: each Ipopt solve of --nlp (0, not given: GraspNlpOptions' default)
  bool thumbBase = true;
  std::string startFile;
  bool nlp = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if ((a == "--scene" || a == "--out") && i + 1 < argc) (a == "--scene" ? scene : out) = argv[++i];
    else if (a == "--diagnose") diagnose = true;
    else if (a == "--evaluations" && i + 1 < argc) evaluations = std::atoi(argv[++i]);
    else if (a == "--max-iterations" && i + 1 < argc) {
      const std::string v = argv[++i];
      char* end = nullptr;
      const long k = std::strtol(v.c_str(), &end, 10);
      if (end == v.c_str() || *end != '\0' || k < 1 || k > 1000000) {
        std::cerr << "hand_ball_grasp: --max-iterations: '" << v << "' is not an integer in [1, 1000000]\n";
        return 2;
      }
      nlpIterations = static_cast<int>(k);
    }
    else if (a == "--no-thumb-base") thumbBase = false;
    else if (a == "--nlp") nlp = true;
    else if (a == "--start" && i + 1 < argc) startFile = argv[++i];
    else if (a == "--help") {
      std::cout << "usage: hand_ball_grasp [--scene NAME] [--out FILE] [--diagnose] [--evaluations N] [--no-thumb-base] [--start FILE] [--nlp] [--max-iterations N]\n";
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
  // The stored grasp file (make_hand_scene.py --free-ball reads it).
  const auto write = [&](const hand::FreeBallGrasp& g, const std::string& how) {
    const Scene s = parseScene(text, scene);
    nlohmann::json j;
    j["description"] = "A grasp of the free ball held by pushing pads (issue 26), found by hand_ball_grasp --scene " +
                       scene + how + " (examples/hand/grasp.hpp).";
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
  };
  if (nlp) {
    // The start's placed scene (thumb base, ball, contact sites) and its NNLS hold, no search.
    options.maxEvaluations = 0;
    hand::FreeBallGrasp g = hand::findFreeBallGrasp(text, limits, options);
    if (g.scene.empty()) {
      std::cerr << "hand_ball_grasp: the start's posture cannot be built: " << g.message << "\n";
      return 1;
    }
    const Scene start = parseScene(g.scene, "<start>");
    hand::GraspNlpOptions nlpOptions;
    if (nlpIterations > 0) nlpOptions.ipopt.maxIterations = nlpIterations;
    const hand::GraspNlpResult r = hand::solveGraspNlp(g.scene, g.q, g.u, limits, nlpOptions);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const hand::GraspCheck& c = r.check;
    std::printf("grasp nlp: %s, %d iterations, %ld evaluations, Ipopt %.2f s, whole %.2f s\n", r.nlp.ipoptStatus.c_str(),
                r.nlp.iterations, r.nlp.evaluations, r.nlp.solveTime, seconds);
    std::printf("margin s %.4f N (needed %.2f N); constraint violation %.3g (first, relaxed solve: %.3g after %d "
                "iterations), bound violation %.3g\n", r.margin, limits.normalMin, r.nlp.constraintViolation,
                r.relaxedViolation, r.firstIterations, r.nlp.boundViolation);
    Eigen::Index maxTendon = 0;
    r.u.maxCoeff(&maxTendon);
    if (c.margins.minNormalContact >= 0 && c.margins.worstFrictionContact >= 0)
      std::printf("min normal force %.4f N (%s), worst friction ratio %.4f (%s), max tension %.3f N (%s)\n",
                  c.margins.minNormal, limits.digits[c.margins.minNormalContact].c_str(), c.margins.worstFrictionRatio,
                  limits.digits[c.margins.worstFrictionContact].c_str(), r.u.maxCoeff(),
                  start.model.inputNames()[maxTendon].c_str());
    std::printf("|qdd| %.3g, residual force %.3g of the rest load, |h| %.3g m, facet ratio %.4f, pad tilt %.4f rad, "
                "range excess %.3g rad\n", c.accelerationResidual, c.relativeAcceleration, c.constraintResidual,
                c.facetRatio, r.alignment, c.rangeExcess);
    for (std::size_t d = 0; d < limits.digits.size() && r.lambda.size() > 0; ++d)
      std::printf("  %-7s lambda (n, t1, t2) = (%.4f, %.4f, %.4f) N\n", limits.digits[d].c_str(), r.lambda(3 * d),
                  r.lambda(3 * d + 1), r.lambda(3 * d + 2));
    std::printf("design: ball centre (%.5f, %.5f, %.5f) m; thumb base turn |omega| %.4f rad, shift (%.4f, %.4f, %.4f) m\n",
                r.centre(0), r.centre(1), r.centre(2), g.thumbTurn.norm(), g.thumbShift(0), g.thumbShift(1), g.thumbShift(2));
    std::printf("q:");
    for (int i = 0; i < start.model.nq(); ++i) std::printf(" %s=%.4f", start.model.configNames()[i].c_str(), r.q(i));
    std::printf("\nreport: %s\n", r.report.c_str());
    if (!r.ok) {
      std::printf("FAILED: no hold: %s (Ipopt: %s)\n", c.message.c_str(),
                  r.nlp.ok() ? "a local maximum of s" : r.nlp.status.message.c_str());
      return 1;
    }
    std::printf("a hold (checkGrasp); the margin s %s\n",
                r.nlp.ok() ? "is a local maximum (Ipopt converged)"
                           : ("is not certified as a local maximum (Ipopt: " + r.nlp.status.message + ")").c_str());
    hand::FreeBallGrasp h = g;
    h.q = r.q;
    h.u = r.u;
    h.centre = r.centre;
    h.contacts = r.contacts;
    h.margins = c.margins;
    return write(h, " --nlp");
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
  return write(g, "");
}
