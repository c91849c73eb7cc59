// optimization/src/ipopt_status.hpp — Ipopt's return status as a name and as the library's
// OptimizationCode: one mapping for every Ipopt solve (optimizer.cpp, nlp.cpp). Internal: Ipopt
// appears in no public header.
#pragma once

#include "trellis/optimization/optimizer.hpp"

#include <IpIpoptApplication.hpp>

#include <string>

namespace trellis::detail {

inline std::string applicationStatusName(Ipopt::ApplicationReturnStatus s) {
  switch (s) {
    case Ipopt::Solve_Succeeded: return "Solve_Succeeded";
    case Ipopt::Solved_To_Acceptable_Level: return "Solved_To_Acceptable_Level";
    case Ipopt::Infeasible_Problem_Detected: return "Infeasible_Problem_Detected";
    case Ipopt::Search_Direction_Becomes_Too_Small: return "Search_Direction_Becomes_Too_Small";
    case Ipopt::Diverging_Iterates: return "Diverging_Iterates";
    case Ipopt::User_Requested_Stop: return "User_Requested_Stop";
    case Ipopt::Feasible_Point_Found: return "Feasible_Point_Found";
    case Ipopt::Maximum_Iterations_Exceeded: return "Maximum_Iterations_Exceeded";
    case Ipopt::Restoration_Failed: return "Restoration_Failed";
    case Ipopt::Error_In_Step_Computation: return "Error_In_Step_Computation";
    case Ipopt::Maximum_CpuTime_Exceeded: return "Maximum_CpuTime_Exceeded";
    case Ipopt::Not_Enough_Degrees_Of_Freedom: return "Not_Enough_Degrees_Of_Freedom";
    case Ipopt::Invalid_Problem_Definition: return "Invalid_Problem_Definition";
    case Ipopt::Invalid_Option: return "Invalid_Option";
    case Ipopt::Invalid_Number_Detected: return "Invalid_Number_Detected";
    case Ipopt::Unrecoverable_Exception: return "Unrecoverable_Exception";
    case Ipopt::NonIpopt_Exception_Thrown: return "NonIpopt_Exception_Thrown";
    case Ipopt::Insufficient_Memory: return "Insufficient_Memory";
    case Ipopt::Internal_Error: return "Internal_Error";
  }
  return "Unknown_Status";
}

inline OptimizationCode classify(Ipopt::ApplicationReturnStatus s) {
  switch (s) {
    case Ipopt::Solve_Succeeded: return OptimizationCode::kSolved;
    case Ipopt::Solved_To_Acceptable_Level: return OptimizationCode::kSolvedAcceptable;
    case Ipopt::Infeasible_Problem_Detected: return OptimizationCode::kInfeasible;
    case Ipopt::Maximum_Iterations_Exceeded:
    case Ipopt::Maximum_CpuTime_Exceeded: return OptimizationCode::kIterationLimit;
    case Ipopt::User_Requested_Stop: return OptimizationCode::kStopped;
    default: return OptimizationCode::kFailed;
  }
}

}  // namespace trellis::detail
