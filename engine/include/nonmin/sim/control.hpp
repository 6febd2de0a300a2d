// Built-in controllers compiled for the loop (nonmin.control). The Python classes stay the
// specification and the fallback (called back) for what is not compiled.
#pragma once
#include <array>
#include <limits>
#include <vector>

#include <Eigen/SVD>

#include "../program.hpp"
#include "loop.hpp"

namespace nonmin::sim {

// nonmin.control.Regulator with σ = 0 (its default) for one active set: f_∥ = −P(f_g + Kp e +
// Kd qd), e = q − q* (q* the target for the active set, quaternion blocks aligned to the
// shortest rotation), u = (PB)⁺ f_∥ (rank of PB by σ > rtol·max(σ_max, max column norm of B)),
// clipped to [u_min, u_max]. P from range_basis(A, rtol); f_g = h(q, 0). update() records what
// ControlState.record does (steps, saturations, infeasible steps, min σ(PB), max |u_raw|).
// An infeasible actuation with on_infeasible="raise", or a non-finite u, is a failure status:
// the loop hands over and the Python controller raises the typed error.
class Regulator final : public Controller {
  public:
    Regulator(const Program& prog, Vec q_star, Mat Kp, Mat Kd, std::vector<std::array<int, 4>> qblocks,
              Vec u_min, Vec u_max, double rtol, bool raise_infeasible);

    void attach(const Terms& T, const Mat& A, int m, const std::vector<int>& rows) override;
    Status control(double t, const double* q, const double* qd, const std::uint8_t* active, double* u) override;
    Status update(double t, const double* q, const double* qd, const std::uint8_t* active) override;
    bool stateless() const override { return true; }  // update() only records

    // ControlState.record's counters over the accepted steps seen
    long long steps = 0, infeasible_steps = 0;
    std::vector<long long> saturated_steps;
    std::vector<std::uint8_t> saturated;
    double min_sigma_pb = std::numeric_limits<double>::infinity();
    std::vector<double> max_abs_u;

  private:
    Status law(double t, const double* q, const double* qd, const std::uint8_t* active, const Terms& T,
               const Mat& A, int m, double* u);
    void record();

    const Program* prog_;
    int n_, k_;
    Vec qs_, qsa_, lo_, hi_;
    Mat Kp_, Kd_;
    std::vector<std::array<int, 4>> qblocks_;
    double rtol_;
    bool raise_;
    // the loop's evaluation
    const Terms* T_ = nullptr;
    const Mat* A_ = nullptr;
    int m_ = 0;
    std::vector<int> rows_;
    // own evaluations (f_g = h(q, 0); update's terms)
    std::unique_ptr<Workspace> ws_;
    Terms Tg_, Tu_;
    Mat Au_, DA_, P_, PB_;
    Vec zero_, fpar_, w_, c_, uraw_, us_;
    // the state of the last law evaluation and what record() needs from it
    double last_t_ = std::numeric_limits<double>::quiet_NaN();
    Vec last_q_, last_qd_;
    bool last_feasible_ = true;
    double last_smin_ = 0.0;
    Eigen::JacobiSVD<Mat> svd_a_, svd_pb_;
};

}  // namespace nonmin::sim
