// Built-in controllers compiled for the loop (see nonmin/sim/control.hpp).
#include "nonmin/sim/control.hpp"

#include <algorithm>
#include <cmath>

namespace nonmin::sim {

Regulator::Regulator(const Program& prog, Vec q_star, Mat Kp, Mat Kd, std::vector<std::array<int, 4>> qblocks,
                     Vec u_min, Vec u_max, double rtol, bool raise_infeasible)
    : prog_(&prog), n_(prog.n()), k_(prog.k()), qs_(std::move(q_star)), lo_(std::move(u_min)),
      hi_(std::move(u_max)), Kp_(std::move(Kp)), Kd_(std::move(Kd)), qblocks_(std::move(qblocks)),
      rtol_(rtol > 0.0 ? rtol : DEFAULT_RTOL), raise_(raise_infeasible) {
    if (qs_.size() != n_ || Kp_.rows() != n_ || Kp_.cols() != n_ || Kd_.rows() != n_ || Kd_.cols() != n_ ||
        lo_.size() != k_ || hi_.size() != k_)
        throw EngineError("Regulator: sizes do not match the program");
    for (const auto& b : qblocks_)
        for (int i : b)
            if (i < 0 || i >= n_) throw EngineError("Regulator: a quaternion block index is out of range");
    qsa_ = qs_;
    ws_ = prog.make_workspace();
    Tg_ = prog.make_terms();
    Tu_ = prog.make_terms();
    zero_ = Vec::Zero(n_);
    fpar_ = Vec::Zero(n_);
    w_ = Vec::Zero(n_);
    c_ = Vec::Zero(std::max(n_, 1));
    uraw_ = Vec::Zero(k_);
    us_ = Vec::Zero(k_);
    P_ = Mat::Zero(n_, n_);
    PB_ = Mat::Zero(n_, std::max(k_, 1));
    last_q_ = Vec::Zero(n_);
    last_qd_ = Vec::Zero(n_);
    saturated_steps.assign(static_cast<std::size_t>(k_), 0);
    saturated.assign(static_cast<std::size_t>(k_), 0);
    max_abs_u.assign(static_cast<std::size_t>(k_), 0.0);
    if (k_ > 0) svd_pb_ = Eigen::JacobiSVD<Mat>(n_, k_, Eigen::ComputeThinU | Eigen::ComputeThinV);
}

void Regulator::attach(const Terms& T, const Mat& A, int m, const std::vector<int>& rows) {
    T_ = &T;
    A_ = &A;
    m_ = m;
    rows_ = rows;
    Au_ = Mat::Zero(std::max(m, 1), n_);
    DA_ = Mat::Zero(std::max(m, 1), n_);
    if (m > 0) svd_a_ = Eigen::JacobiSVD<Mat>(m, n_, Eigen::ComputeThinV);
}

Status Regulator::control(double t, const double* q, const double* qd, const std::uint8_t* active, double* u) {
    if (!T_) return Status::bad_shape;
    return law(t, q, qd, active, *T_, *A_, m_, u);
}

Status Regulator::update(double t, const double* q, const double* qd, const std::uint8_t* active) {
    // the loop's last evaluation of the law is usually at this very state (the sample at the
    // projected step end): record it; else evaluate the law here
    bool same = t == last_t_;
    for (int i = 0; same && i < n_; ++i) same = q[i] == last_q_[i] && qd[i] == last_qd_[i];
    if (!same) {
        Status s = prog_->evaluate(t, q, qd, active, NEED_H | NEED_B | NEED_A, Tu_, *ws_);
        if (s != Status::ok) return s;
        for (int i = 0; i < m_; ++i) Au_.row(i) = Tu_.A.row(rows_[static_cast<std::size_t>(i)]);
        if ((s = law(t, q, qd, active, Tu_, Au_, m_, us_.data())) != Status::ok) return s;
    }
    record();
    return Status::ok;
}

void Regulator::record() {  // ControlState.record of the last law evaluation
    for (int j = 0; j < k_; ++j) {
        const double lo = lo_[j], hi = hi_[j], v = uraw_[j];
        const bool sat = (v <= lo || v >= hi) && (std::isfinite(lo) || std::isfinite(hi));
        saturated[static_cast<std::size_t>(j)] = sat;
        saturated_steps[static_cast<std::size_t>(j)] += sat;
        max_abs_u[static_cast<std::size_t>(j)] = std::max(max_abs_u[static_cast<std::size_t>(j)], std::abs(v));
    }
    ++steps;
    infeasible_steps += last_feasible_ ? 0 : 1;
    min_sigma_pb = std::min(min_sigma_pb, last_smin_);
}

Status Regulator::law(double t, const double* q, const double* qd, const std::uint8_t* active, const Terms& T,
                      const Mat& A, int m, double* u) {
    const int n = n_, k = k_;
    last_t_ = std::numeric_limits<double>::quiet_NaN();  // (set again when the law succeeds)
    // f_g = h(q, 0)
    Status s = prog_->evaluate(t, q, zero_.data(), active, NEED_H, Tg_, *ws_);
    if (s != Status::ok) return s;
    // P = I − Σ_kept v vᵀ of range_basis(A, rtol)
    P_.setIdentity();
    int rank = 0;
    if (m > 0) {
        double big = 0.0;
        for (int i = 0; i < m; ++i) {
            double sq = 0.0;
            for (int j = 0; j < n; ++j) sq += A(i, j) * A(i, j);
            DA_(i, 0) = std::sqrt(sq);  // (norm kept in column 0 until scaled below)
            big = std::max(big, DA_(i, 0));
        }
        for (int i = 0; i < m; ++i) {
            const double nr = DA_(i, 0);
            const double d = nr > rtol_ * big ? 1.0 / nr : 0.0;
            for (int j = 0; j < n; ++j) DA_(i, j) = A(i, j) * d;
        }
        svd_a_.compute(DA_);
        const auto& sv = svd_a_.singularValues();
        const auto& V = svd_a_.matrixV();
        for (int kk = 0; kk < sv.size(); ++kk) {
            if (!(sv[kk] > rtol_ * sv[0])) continue;
            ++rank;
            for (int i = 0; i < n; ++i)
                for (int j = 0; j < n; ++j) P_(i, j) -= V(i, kk) * V(j, kk);
        }
    }
    // e = q − q*, q* aligned per quaternion block
    qsa_ = qs_;
    for (const auto& b : qblocks_) {
        double dot = 0.0;
        for (int i : b) dot += q[i] * qs_[i];
        if (dot < 0.0)
            for (int i : b) qsa_[i] = -qs_[i];
    }
    for (int i = 0; i < n; ++i) {
        double a = Tg_.h[i];
        for (int j = 0; j < n; ++j) a += Kp_(i, j) * (q[j] - qsa_[j]) + Kd_(i, j) * qd[j];
        w_[i] = a;
    }
    for (int i = 0; i < n; ++i) {
        double a = 0.0;
        for (int j = 0; j < n; ++j) a += P_(i, j) * w_[j];
        fpar_[i] = -a;
    }
    const int dof = n - rank;
    bool feasible;
    double s_min = 0.0;
    if (k == 0) {
        feasible = dof == 0;
        if (!feasible && raise_) return Status::not_positive_definite;  // InfeasibleActuationError
    } else {
        PB_.noalias() = P_ * T.B;
        double bscale = 0.0;
        for (int j = 0; j < k; ++j) {
            double sq = 0.0;
            for (int i = 0; i < n; ++i) sq += T.B(i, j) * T.B(i, j);
            bscale = std::max(bscale, sq);
        }
        bscale = std::sqrt(bscale);
        svd_pb_.compute(PB_);
        const auto& sv = svd_pb_.singularValues();
        const auto& U = svd_pb_.matrixU();
        const auto& V = svd_pb_.matrixV();
        const double ref = std::max({sv.size() ? sv[0] : 0.0, bscale, std::numeric_limits<double>::min()});
        int rank_pb = 0;
        for (int i = 0; i < sv.size(); ++i) rank_pb += sv[i] > rtol_ * ref;
        feasible = rank_pb >= dof;
        if (!feasible && raise_) return Status::not_positive_definite;  // InfeasibleActuationError
        for (int i = 0; i < sv.size(); ++i) {
            double c = 0.0;
            if (sv[i] > rtol_ * ref) {
                for (int r = 0; r < n; ++r) c += U(r, i) * fpar_[r];
                c /= sv[i];
            }
            c_[i] = c;
        }
        for (int j = 0; j < k; ++j) {
            double a = 0.0;
            for (int i = 0; i < sv.size(); ++i) a += V(j, i) * c_[i];
            uraw_[j] = a;
        }
        s_min = sv.size() ? sv[sv.size() - 1] : 0.0;
    }
    for (int j = 0; j < k; ++j)
        if (!std::isfinite(uraw_[j])) return Status::not_finite;
    for (int j = 0; j < k; ++j) u[j] = std::min(std::max(uraw_[j], lo_[j]), hi_[j]);
    last_t_ = t;
    for (int i = 0; i < n; ++i) {
        last_q_[i] = q[i];
        last_qd_[i] = qd[i];
    }
    last_feasible_ = feasible;
    last_smin_ = s_min;
    return Status::ok;
}

}  // namespace nonmin::sim
