// Built-in controllers compiled for the loop (see nonmin/sim/control.hpp).
#include "nonmin/sim/control.hpp"
#include "nonmin/linalg.hpp"
#include "nonmin/rbd/tree_program.hpp"

#include <algorithm>
#include <cmath>
#include <string>

namespace nonmin::sim {

namespace {

constexpr double TINY = std::numeric_limits<double>::min();
constexpr double PROJECT_TOL = 1e-12;   // _targets.project_configuration's tol
constexpr int PROJECT_MAX_ITER = 100;   // and max_iter
constexpr double ON_MANIFOLD_TOL = 1e-9;  // _targets.ON_MANIFOLD_TOL
// Step 3's fast path: σ_min(ZB) (a lower bound of it) must exceed the rank cutoff by this factor
// and ZB must be this well conditioned (so that the LQ solve agrees with the SVD to round-off).
constexpr double CERTIFY_FACTOR = 1e3;
constexpr double CERTIFY_COND = 1e6;

bool finite(const double* x, int len) {
    for (int i = 0; i < len; ++i)
        if (!std::isfinite(x[i])) return false;
    return true;
}

double norm2(const double* x, int len) {
    double s = 0.0;
    for (int i = 0; i < len; ++i) s += x[i] * x[i];
    return std::sqrt(s);
}

// x = (DA)⁺ D b from the certified LQ of D A held in lq (d: D's diagonal, m ≤ n live rows): the
// same operations, in the same order, as Solver::min_norm on that A when it takes the certified
// LQ (its null-space form when n − m ≤ m, else the rows V of the orthogonal factor), so the same
// bits, without factorizing A again. cv: m entries of scratch; V: m × n (used when n − m > m).
void held_min_norm(const linalg::LQWork& lq, const double* d, int m, int n, const double* b, double* cv, double* V,
                   double* x) {
    for (int i = 0; i < m; ++i) cv[i] = d[i] * b[i];  // cv = L⁻¹ D b (the Solver's substitution)
    linalg::lq_lower_subst(lq, m, cv);
    if (n - m <= m) {
        linalg::lq_min_norm(lq, m, n, cv, x);  // (−x)
        for (int j = 0; j < n; ++j) x[j] = -x[j];
        return;
    }
    linalg::lq_rows(lq, m, n, 0, m, V);
    for (int j = 0; j < n; ++j) x[j] = 0.0;
    for (int k = 0; k < m; ++k) {
        const double ck = cv[k];
        const double* Vk = V + static_cast<long>(k) * n;
        for (int j = 0; j < n; ++j) x[j] -= Vk[j] * ck;
    }
    for (int j = 0; j < n; ++j) x[j] = -x[j];
}

}  // namespace

// ------------------------------------------------------------------------------ signals

TimeSignal::TimeSignal(std::vector<TimeFunction> f, bool hold, double lo, double hi)
    : f_(std::move(f)), hold_(hold), lo_(lo), hi_(hi) {
    for (std::size_t j = 0; j < f_.size(); ++j) {
        f_[j].validate("reference component " + std::to_string(j));
        if (!f_[j].thread_safe()) throw EngineError("TimeSignal: a callback time function is not a value");
        scratch_size_ = std::max(scratch_size_, static_cast<std::size_t>(f_[j].scratch_size()));
    }
    if (hold_ && !(lo_ < hi_ && std::isfinite(lo_) && std::isfinite(hi_)))
        throw EngineError("TimeSignal: the hold window must be finite and increasing");
}

TimeSignal TimeSignal::from_ppoly(const std::vector<double>& x, const std::vector<double>& c, int order, int dim,
                                  bool hold) {
    const int pieces = static_cast<int>(x.size()) - 1;
    if (pieces < 1 || order < 1 || dim < 0 || c.size() != static_cast<std::size_t>(order) * pieces * dim)
        throw EngineError("PiecewisePolynomial: need x (p + 1 ≥ 2) and c (order, p, dim)");
    for (int i = 0; i < pieces; ++i)
        if (!(x[i] < x[i + 1])) throw EngineError("PiecewisePolynomial: breakpoints must increase");
    if (!finite(c.data(), static_cast<int>(c.size())) || !finite(x.data(), static_cast<int>(x.size())))
        throw EngineError("PiecewisePolynomial: coefficients and breakpoints must be finite");
    // TimeFunction's pieces: ascending powers; PPoly's: descending. Horner runs over the same
    // coefficients in the same order, so the values are the same bit for bit.
    std::vector<TimeFunction> f(static_cast<std::size_t>(dim));
    for (int d = 0; d < dim; ++d) {
        TimeFunction& fd = f[static_cast<std::size_t>(d)];
        fd.kind = TimeFunction::pieces;
        fd.breaks = x;
        fd.degree = order - 1;
        fd.hold = false;  // (the signal holds, outside [x_0, x_p] strictly)
        fd.coefs.resize(static_cast<std::size_t>(order) * pieces);
        for (int i = 0; i < pieces; ++i)
            for (int k = 0; k < order; ++k)
                fd.coefs[static_cast<std::size_t>(i) * order + k] =
                    c[(static_cast<std::size_t>(order - 1 - k) * pieces + i) * dim + d];
    }
    return TimeSignal(std::move(f), hold, x.front(), x.back());
}

Status TimeSignal::eval(double t, double* x, double* v, double* a) {
    if (!std::isfinite(t)) return Status::not_finite;
    const bool outside = hold_ && (t < lo_ || t > hi_);
    const double s = outside ? std::min(std::max(t, lo_), hi_) : t;
    // a tape's registers: per thread (controllers of a batch may share a reference), sized once
    thread_local std::vector<double> scratch;
    if (scratch.size() < scratch_size_) scratch.resize(scratch_size_);
    double f[3];
    for (std::size_t j = 0; j < f_.size(); ++j) {
        // (a non-finite value is the controller's check: desired() answers not_finite)
        if (f_[j].eval(s, f, scratch.data()) == TimeFunction::EVAL_FAILED) return Status::callback_error;
        x[j] = f[0];
        if (v) v[j] = outside ? 0.0 : f[1];
        if (a) a[j] = outside ? 0.0 : f[2];
    }
    return Status::ok;
}

// ------------------------------------------------------------------------------ the controller

bool passivity_supported(const Program& prog) {
    if (prog.constant_mass() && prog.differentiable()) return true;
    return dynamic_cast<const rbd::TreeProgram*>(&prog) != nullptr;
}

Projected::Projected(const Program& prog, ControlSpec spec)
    : prog_(&prog), s_(std::move(spec)), n_(prog.n()), k_(prog.k()),
      rtol_(s_.rtol > 0.0 ? s_.rtol : DEFAULT_RTOL),
      gravity_in_pass_((s_.law == Law::regulator || s_.law == Law::passivity) && prog.gravity_in_pass()),
      solver_(prog.m_all() + prog.n() + static_cast<int>(s_.fixed.size()) + 1, prog.n()) {
    const int n = n_, k = k_;
    if (s_.Kp.rows() != n || s_.Kp.cols() != n || s_.Kd.rows() != n || s_.Kd.cols() != n ||
        s_.u_min.size() != k || s_.u_max.size() != k)
        throw EngineError("controller: sizes do not match the program");
    if (s_.law == Law::regulator && s_.q_star.size() != n)
        throw EngineError("controller: the target must have the program's n entries");
    if (!(std::isfinite(s_.sigma) && s_.sigma >= 0.0) || (s_.sigma > 0.0 && s_.xi0.size() != n))
        throw EngineError("controller: σ must be ≥ 0, with ξ₀ of n entries when > 0");
    if (s_.law != Law::regulator && (!s_.reference || s_.reference->dim() != n))
        throw EngineError("controller: the tracker needs a reference of dimension n");
    if (s_.law == Law::passivity) {
        if (!passivity_supported(prog))
            throw EngineError("controller: the passivity law needs C and Ȧ, which this program does not give");
        if (!(std::isfinite(s_.lambda) && s_.lambda > 0.0)) throw EngineError("controller: λ must be > 0");
        coriolis_ = prog.constant_mass() ? 0 : 1;
        Tv_ = prog.make_terms();
        Tt_ = prog.make_terms();
        Cm_ = Mat::Zero(n, n);
        Adall_ = Mat::Zero(std::max(prog.m_all(), 1), n);
        for (Vec* v : {&pe_, &ped_, &px_, &pqrd_, &pqrdd_, &psv_, &pt1_, &pt2_, &pt3_}) *v = Vec::Zero(n);
    }
    for (const auto& b : s_.qblocks)
        for (int i : b)
            if (i < 0 || i >= n) throw EngineError("controller: a quaternion block index is out of range");
    for (int i : s_.fixed)
        if (i < 0 || i >= n) throw EngineError("controller: a fixed coordinate index is out of range");
    const int c = static_cast<int>(prog.constraints().size());
    for (const auto& [con, sig] : s_.forces)
        if (con < 0 || con >= c || !sig || sig->dim() != prog.constraints()[con].dim)
            throw EngineError("controller: a force target names no constraint or has the wrong size");
    ws_ = prog.make_workspace();
    Tg_ = prog.make_terms();
    Tu_ = prog.make_terms();
    Tr_ = prog.make_terms();
    for (Vec* v : {&zero_, &fpar_, &w_, &a_, &e_, &x_, &qs_, &vs_, &as_, &last_q_, &last_qd_, &hw_, &tgt_,
                   &dr_, &stepr_, &xr_, &qtmp_, &gtmp_, &c0_, &sf_, &pf_, &y_})
        *v = Vec::Zero(n);
    for (Memo& mm : memo_) mm.q = mm.v = mm.a = Vec::Zero(n);
    Z_ = Mat::Zero(n, n);
    ZMs_ = Mat::Zero(n, n);
    Ss_ = Mat::Zero(n, n);
    xs_ = Vec::Zero(n);
    ys_ = Vec::Zero(n);
    uraw_ = Vec::Zero(k);
    us_ = Vec::Zero(k);
    zf_ = Vec::Zero(n);
    PB_ = Mat::Zero(n, std::max(k, 1));
    ZB_ = Mat::Zero(n, std::max(k, 1));
    G_ = Mat::Zero(n, n);
    Hq_ = Mat::Zero(n, n);
    saturated_steps.assign(static_cast<std::size_t>(k), 0);
    saturated.assign(static_cast<std::size_t>(k), 0);
    max_abs_u.assign(static_cast<std::size_t>(k), 0.0);
    mask_.assign(static_cast<std::size_t>(c), 0);
    if (k > 0) {
        svd_pb_ = Svd(n, k, Eigen::ComputeThinU | Eigen::ComputeThinV);
        svd_vals_ = Svd(n, k);
    }
}

void Projected::attach(const Terms& T, const Mat& A, int m, const std::vector<int>& rows) {
    const int n = n_, k = k_;
    T_ = &T;
    A_ = &A;
    m_ = m;
    rows_ = rows;
    // the active mask and the kinds of the active rows (constraints whose rows are active)
    const auto& cons = prog_->constraints();
    hol_.clear();
    frows_.clear();
    fdim_.clear();
    std::fill(mask_.begin(), mask_.end(), 0);
    int pos = 0;
    for (std::size_t ci = 0; ci < cons.size(); ++ci) {
        const ConstraintInfo& info = cons[ci];
        if (pos >= m || std::find(rows.begin(), rows.end(), info.row) == rows.end()) continue;
        mask_[ci] = 1;
        const int at = static_cast<int>(std::find(rows.begin(), rows.end(), info.row) - rows.begin());
        for (int r = 0; r < info.dim; ++r)
            if (info.kind != ConstraintKind::nonholonomic) hol_.push_back(at + r);
        pos += info.dim;
    }
    if (compiled_mask_.empty()) compiled_mask_ = mask_;
    stale_ = mask_ != compiled_mask_;
    if (stale_) return;  // (the other active set's evaluations go to s_.other_active_set)
    // force control: the commanded constraints that are active, in the order of `forces`
    for (const auto& [con, sig] : s_.forces) {
        if (!mask_[static_cast<std::size_t>(con)]) continue;
        const int at = static_cast<int>(std::find(rows.begin(), rows.end(), cons[con].row) - rows.begin());
        for (int r = 0; r < cons[con].dim; ++r) frows_.push_back(at + r);
        fdim_.push_back(cons[con].dim);
    }
    const int mr = std::max(m, 1);
    const int mp = static_cast<int>(hol_.size() + s_.fixed.size());
    Au_ = Mat::Zero(mr, n);
    V_ = Mat::Zero(std::max(std::min(m, n), 1), n);
    Bq_.assign(static_cast<std::size_t>(mr) * (n + 1), 0.0);
    dq_.assign(static_cast<std::size_t>(mr), 0.0);
    sq_.assign(static_cast<std::size_t>(mr), 0.0);
    cq_.assign(static_cast<std::size_t>(mr) + 1, 0.0);
    lq_ = linalg::LQWork(mr, n);
    lqr_ = linalg::LQWork(mr, n);
    Br_.assign(static_cast<std::size_t>(mr) * (n + 1), 0.0);
    dqr_.assign(static_cast<std::size_t>(mr), 0.0);
    sqr_.assign(static_cast<std::size_t>(mr), 0.0);
    cqr_.assign(static_cast<std::size_t>(mr) + 1, 0.0);
    Vh_.assign(static_cast<std::size_t>(mr) * n, 0.0);
    hv_ = Vec::Zero(std::max(n, k) + 1);
    Ar_ = Mat::Zero(std::max(std::max(mp, m), 1), n);
    br_ = Vec::Zero(std::max(std::max(mp, m), 1));
    const int mf = static_cast<int>(frows_.size());
    if (mf > 0) {
        Mbar_L_ = Mat::Zero(n, n);
        E_ = Mat::Zero(mf, n);
        Gf_ = Mat::Zero(n + mf, std::max(k, 1));
        rhs_ = Vec::Zero(n + mf);
        lam_ = Vec::Zero(mf);
        svd_g_ = Svd(n + mf, std::max(k, 1), Eigen::ComputeThinU | Eigen::ComputeThinV);
        Wf_ = Mat::Zero(n + mf, std::max(k, 1));
        Lf_ = Mat::Zero(n + mf, n + mf);
        rhsf_ = Vec::Zero(n + mf);
        yf_ = Vec::Zero(n + mf);
    }
    if (m > 0) {
        Atrue_ = Mat::Zero(m, n);
        svd_a_ = Svd(m, n, Eigen::ComputeThinU | Eigen::ComputeThinV);
    }
    if (s_.law == Law::passivity) {
        Apinv_ = Mat::Zero(n, mr);
        Adot_ = Mat::Zero(mr, n);
        pm_ = Vec::Zero(mr);
        pm2_ = Vec::Zero(mr);
    }
}

Status Projected::control(double t, const double* q, const double* qd, const std::uint8_t* active, double* u) {
    if (stale_) return s_.other_active_set ? s_.other_active_set->control(t, q, qd, active, u) : Status::bad_shape;
    if (!T_) return Status::bad_shape;
    if (s_.own_terms) {  // the controller's own model (same layout): its terms at this state
        const unsigned need = NEED_M | NEED_H | NEED_B | NEED_A | NEED_GAMMA | own_need();
        const Status s = prog_->evaluate(t, q, qd, mask_.data(), need, Tu_, *ws_);
        if (s != Status::ok) return s;
        for (int i = 0; i < m_; ++i) Au_.row(i) = Tu_.A.row(rows_[static_cast<std::size_t>(i)]);
        return law(t, q, qd, Tu_, Au_, u);
    }
    return law(t, q, qd, *T_, *A_, u);
}

Status Projected::update(double t, const double* q, const double* qd, const std::uint8_t* active) {
    if (stale_) return Status::ok;  // (Python records the steps of the other active set)
    // the loop's last evaluation of the law is usually at this very state (the sample at the
    // projected step end): record it; else evaluate the law here
    bool same = t == last_t_;
    for (int i = 0; same && i < n_; ++i) same = q[i] == last_q_[i] && qd[i] == last_qd_[i];
    if (!same) {
        const unsigned need = NEED_M | NEED_H | NEED_B | NEED_A | NEED_GAMMA | own_need();
        Status s = prog_->evaluate(t, q, qd, active, need, Tu_, *ws_);
        if (s != Status::ok) return s;
        for (int i = 0; i < m_; ++i) Au_.row(i) = Tu_.A.row(rows_[static_cast<std::size_t>(i)]);
        if ((s = law(t, q, qd, Tu_, Au_, us_.data())) != Status::ok) return s;
    }
    record();
    return Status::ok;
}

// ------------------------------------------------------------------------------ step 1

// Z: rows orthonormal, spanning N(A) under the rank policy of range_basis(A, rtol) (P = ZᵀZ).
// Every row live and m ≤ n: the certified LQ of D A (Solver::range_basis's first choice, the
// same calls), Z = the rows m … n − 1 of its orthogonal factor. Otherwise Solver::range_basis
// (V: r × n, rows spanning R(Aᵀ)) and Z from the Householder QR of Vᵀ (its last n − r columns).
Status Projected::nullspace(const Mat& A) {
    const int n = n_, m = m_;
    lq_valid_ = false;
    if (m == 0) {
        rank_ = 0;
        Z_.setIdentity();
        return Status::ok;
    }
    const int live = linalg::equilibrate(A.data(), m, n, nullptr, rtol_, Bq_.data(), dq_.data(), sq_.data());
    if (live == m && m >= linalg::QR_MIN_ROWS && m <= n && m <= linalg::DENSE_INVERSE_MAX_ROWS &&
        linalg::lq_certified(Bq_.data(), m, n, rtol_, lq_, cq_.data()) != linalg::LQ_NONE) {
        rank_ = m;
        lq_valid_ = true;
        if (n > m) linalg::lq_rows(lq_, m, n, m, n - m, Z_.data());
        return Status::ok;
    }
    lq_valid_ = false;
    rank_ = solver_.range_basis(A.data(), m, rtol_, V_.data());
    const int r = rank_;
    // Householder QR of X = Vᵀ (n × r), reflectors in the columns of G_ (rows j.. of column j)
    Mat& H = Hq_;
    for (int j = 0; j < r; ++j)
        for (int i = 0; i < n; ++i) H(i, j) = V_(j, i);
    for (int j = 0; j < r; ++j) {
        double sq = 0.0;
        for (int i = j; i < n; ++i) sq += H(i, j) * H(i, j);
        const double nx = std::sqrt(sq);
        const double alpha = H(j, j) > 0.0 ? -nx : nx;
        const double v0 = H(j, j) - alpha;
        const double vv = sq - H(j, j) * H(j, j) + v0 * v0;
        H(j, j) = v0;
        hv_[j] = vv > 0.0 ? 2.0 / vv : 0.0;  // β_j
        for (int c = j + 1; c < r; ++c) {
            double s = 0.0;
            for (int i = j; i < n; ++i) s += H(i, j) * H(i, c);
            s *= hv_[j];
            for (int i = j; i < n; ++i) H(i, c) -= s * H(i, j);
        }
    }
    for (int a = 0; a < n - r; ++a) {  // Z row a = H_0 ⋯ H_{r−1} e_{r+a}
        double* z = &Z_(a, 0);
        for (int i = 0; i < n; ++i) z[i] = 0.0;
        z[r + a] = 1.0;
        for (int j = r - 1; j >= 0; --j) {
            double s = 0.0;
            for (int i = j; i < n; ++i) s += H(i, j) * z[i];
            s *= hv_[j];
            for (int i = j; i < n; ++i) z[i] -= s * H(i, j);
        }
    }
    return Status::ok;
}

// out = P x = Zᵀ(Z x) (out may be x)
void Projected::project(const double* x, double* out) {
    const int n = n_, d = n_ - rank_;
    for (int a = 0; a < d; ++a) {
        double s = 0.0;
        for (int j = 0; j < n; ++j) s += Z_(a, j) * x[j];
        hw_[a] = s;
    }
    for (int i = 0; i < n; ++i) {
        double s = 0.0;
        for (int a = 0; a < d; ++a) s += Z_(a, i) * hw_[a];
        out[i] = s;
    }
}

// The first d = n − r rows of W = Z B (d × k) and zf = Z f_∥: the actuation and the force to
// realize in the basis Z of N(A) (regulator and force control); returns ‖Z B‖²_F
double Projected::reduce_actuation(const Terms& T, Mat& W, double* zf) const {
    const int n = n_, k = k_, d = n_ - rank_;
    double fro = 0.0;
    for (int a = 0; a < d; ++a) {
        for (int j = 0; j < k; ++j) {
            double s = 0.0;
            for (int i = 0; i < n; ++i) s += Z_(a, i) * T.B(i, j);
            W(a, j) = s;
            fro += s * s;
        }
        double s = 0.0;
        for (int i = 0; i < n; ++i) s += Z_(a, i) * fpar_[i];
        zf[a] = s;
    }
    return fro;
}

// PB = Zᵀ(Z B), kept for σ(PB) in record(), the SVD path and force control
void Projected::ensure_pb(const Terms& T) {
    if (pb_valid_) return;
    const int n = n_, k = k_, d = n_ - rank_;
    for (int j = 0; j < k; ++j) {
        for (int a = 0; a < d; ++a) {
            double s = 0.0;
            for (int i = 0; i < n; ++i) s += Z_(a, i) * T.B(i, j);
            hw_[a] = s;
        }
        for (int i = 0; i < n; ++i) {
            double s = 0.0;
            for (int a = 0; a < d; ++a) s += Z_(a, i) * hw_[a];
            PB_(i, j) = s;
        }
    }
    pb_valid_ = true;
}

// ------------------------------------------------------------------------------ references

// pinv(A, rtol) @ b (nonmin.core.pseudo_inverse: A's own SVD truncated to the rank of the policy);
// with full row rank it is the minimum-norm solution (DA)⁺ D b of Solver::min_norm.
Status Projected::min_norm_true(const Mat& A, int m, const double* b, double* x) {
    const SolveInfo info = solver_.min_norm(A.data(), m, b, rtol_, x);
    if (info.status != Status::ok) return info.status;
    if (info.rank == m) return Status::ok;
    // rank-deficient: the truncated SVD of A itself
    const int n = n_;
    for (int i = 0; i < m; ++i) Atrue_.row(i) = A.row(i);  // (m is the active set's row count)
    Svd& svd = svd_a_;
    svd.compute(Atrue_);
    const auto& sv = svd.singularValues();
    const auto& U = svd.matrixU();
    const auto& Vm = svd.matrixV();
    for (int j = 0; j < n; ++j) x[j] = 0.0;
    for (int kk = 0; kk < info.rank && kk < sv.size(); ++kk) {
        if (!(sv[kk] > 0.0)) continue;
        double c = 0.0;
        for (int i = 0; i < m; ++i) c += U(i, kk) * b[i];
        c /= sv[kk];
        for (int j = 0; j < n; ++j) x[j] += Vm(j, kk) * c;
    }
    return Status::ok;
}

// _targets.project_configuration (Gauss–Newton onto the active position-level constraints, the
// fixed coordinates kept), in place on x; check_on_manifold with `reject`.
Status Projected::project_configuration(double t, double* x) {
    const int n = n_;
    const int mh = static_cast<int>(hol_.size()), nf = static_cast<int>(s_.fixed.size());
    const int mr = mh + nf;
    for (int i = 0; i < n; ++i) tgt_[i] = x[i];
    const double scale = 1.0 + norm2(tgt_.data(), n);
    const unsigned need = NEED_A | NEED_PHI | (s_.mass_metric ? NEED_M : 0u);
    auto rows_at = [&](const double* xx, unsigned nd) -> Status {  // Ar_, br_ = A, φ (+ fixed)
        const Status s = prog_->evaluate(t, xx, zero_.data(), mask_.data(), nd, Tr_, *ws_);
        if (s != Status::ok) return s;
        for (int i = 0; i < mh; ++i) {
            const int r = rows_[static_cast<std::size_t>(hol_[static_cast<std::size_t>(i)])];
            Ar_.row(i) = Tr_.A.row(r);
            br_[i] = Tr_.phi[r];
        }
        for (int i = 0; i < nf; ++i) {
            const int c = s_.fixed[static_cast<std::size_t>(i)];
            Ar_.row(mh + i).setZero();
            Ar_(mh + i, c) = 1.0;
            br_[mh + i] = xx[c] - tgt_[c];
        }
        return Status::ok;
    };
    Status s;
    if (s_.reject) {
        if (mh == 0) return Status::ok;
        if ((s = rows_at(x, NEED_PHI)) != Status::ok) return s;
        return norm2(br_.data(), mh) > ON_MANIFOLD_TOL * scale ? Status::not_finite : Status::ok;
    }
    if (mr == 0) return Status::ok;
    for (int it = 0; it < PROJECT_MAX_ITER; ++it) {
        if ((s = rows_at(x, need)) != Status::ok) return s;
        const double res = norm2(br_.data(), mr);
        if (it == 0 && res <= PROJECT_TOL * scale) return Status::ok;  // the target itself
        for (int j = 0; j < n; ++j) dr_[j] = tgt_[j] - x[j];
        for (int i = 0; i < mr; ++i) {  // b = φ + A d
            double a = br_[i];
            for (int j = 0; j < n; ++j) a += Ar_(i, j) * dr_[j];
            br_[i] = a;
        }
        if (s_.mass_metric) {  // Sᵀ(−A⁺b): forward dynamics with zero force and bias b
            SolveOptions so;
            so.rtol = rtol_;
            const SolveInfo info = solver_.forward(Tr_.M.data(), zero_.data(), Ar_.data(), mr, br_.data(), so,
                                                   stepr_.data(), nullptr);
            if (info.status != Status::ok) return info.status;
        } else {  // −(DA)⁺ D b
            const SolveInfo info = solver_.min_norm(Ar_.data(), mr, br_.data(), rtol_, stepr_.data());
            if (info.status != Status::ok) return info.status;
            for (int j = 0; j < n; ++j) stepr_[j] = -stepr_[j];
        }
        for (int j = 0; j < n; ++j) {
            stepr_[j] += dr_[j];
            x[j] += stepr_[j];
        }
        if (res <= PROJECT_TOL * scale && norm2(stepr_.data(), n) <= 1e3 * PROJECT_TOL * scale) {
            // converged: the residual after this step is at most res (the Gauss–Newton step
            // minimizes the linearized one) plus O(‖step‖²), far below the check's 1e3·tol·scale
            return finite(x, n) ? Status::ok : Status::not_finite;
        }
    }
    if ((s = rows_at(x, NEED_A | NEED_PHI)) != Status::ok) return s;
    const double res = norm2(br_.data(), mr);
    if (!finite(x, n) || res > 1e3 * PROJECT_TOL * scale) return Status::not_finite;  // AssemblyError
    return Status::ok;
}

// Tracker.desired (and a regulator's target under rheonomic constraints): qs_, vs_, as_ at t.
Status Projected::desired(double t, const double* q) {
    const int n = n_;
    const bool tracker = s_.law != Law::regulator;
    Status s;
    if (tracker && s_.qblocks.empty()) {  // (no sign to decide: the reference's values are not needed)
        for (const Memo& mm : memo_)
            if (mm.t == t && mm.signs == 0) {
                qs_ = mm.q;
                vs_ = mm.v;
                as_ = mm.a;
                return Status::ok;
            }
    }
    if (tracker) {
        if ((s = s_.reference->eval(t, qs_.data(), vs_.data(), as_.data())) != Status::ok) return s;
    } else {
        qs_ = s_.q_star;
    }
    unsigned signs = 0;
    if (tracker)
        for (std::size_t b = 0; b < s_.qblocks.size(); ++b) {
            double dot = 0.0;
            for (int i : s_.qblocks[b]) dot += q[i] * qs_[i];
            if (dot < 0.0) signs |= 1u << b;
        }
    for (const Memo& mm : memo_)
        if (mm.t == t && mm.signs == signs) {
            qs_ = mm.q;
            vs_ = mm.v;
            as_ = mm.a;
            return Status::ok;
        }
    if (!finite(qs_.data(), n) || (tracker && (!finite(vs_.data(), n) || !finite(as_.data(), n))))
        return Status::not_finite;  // InputError of the Python controller
    for (std::size_t b = 0; b < s_.qblocks.size(); ++b)
        if (signs & (1u << b))
            for (int i : s_.qblocks[b]) {
                qs_[i] = -qs_[i];
                vs_[i] = -vs_[i];
                as_[i] = -as_[i];
            }
    if ((s = project_configuration(t, qs_.data())) != Status::ok) return s;
    if (tracker && m_ > 0) {
        // project_velocity: q̇* − A⁺(A q̇* + φ_t) at (q*, q̇*)
        if ((s = prog_->evaluate(t, qs_.data(), vs_.data(), mask_.data(), NEED_A | NEED_VELOCITY, Tr_, *ws_)) !=
            Status::ok)
            return s;
        const int m = m_;
        for (int i = 0; i < m; ++i) {
            const int r = rows_[static_cast<std::size_t>(i)];
            Ar_.row(i) = Tr_.A.row(r);
            br_[i] = Tr_.velocity[r];
        }
        // both projections solve with A(q*): one certified LQ of D A(q*) for the two (the bits of
        // Solver::min_norm, which min_norm_true takes at full rank), else min_norm_true each
        const int live = linalg::equilibrate(Ar_.data(), m, n, nullptr, rtol_, Br_.data(), dqr_.data(), sqr_.data());
        const bool held = live == m && m >= linalg::QR_MIN_ROWS && m <= n && m <= linalg::DENSE_INVERSE_MAX_ROWS &&
                          linalg::lq_certified(Br_.data(), m, n, rtol_, lqr_, cqr_.data(), false, false) != linalg::LQ_NONE;
        auto solve = [&](const double* b) -> Status {
            if (!held) return min_norm_true(Ar_, m, b, xr_.data());
            if (!finite(b, m)) return Status::not_finite;
            held_min_norm(lqr_, dqr_.data(), m, n, b, cqr_.data(), Vh_.data(), xr_.data());
            return Status::ok;
        };
        if ((s = solve(br_.data())) != Status::ok) return s;
        for (int j = 0; j < n; ++j) vs_[j] -= xr_[j];
        // project_acceleration: q̈* − A⁺(A q̈* + γ) at (q*, q̇*) (A(q*) as above)
        if ((s = prog_->evaluate(t, qs_.data(), vs_.data(), mask_.data(), NEED_GAMMA, Tr_, *ws_)) != Status::ok)
            return s;
        for (int i = 0; i < m; ++i) {
            double a = Tr_.gamma[rows_[static_cast<std::size_t>(i)]];
            for (int j = 0; j < n; ++j) a += Ar_(i, j) * as_[j];
            br_[i] = a;
        }
        if ((s = solve(br_.data())) != Status::ok) return s;
        for (int j = 0; j < n; ++j) as_[j] -= xr_[j];
    }
    Memo& mm = memo_[static_cast<std::size_t>(memo_next_)];
    memo_next_ = (memo_next_ + 1) % static_cast<int>(memo_.size());
    mm.t = t;
    mm.signs = signs;
    mm.q = qs_;
    mm.v = vs_;
    mm.a = as_;
    return Status::ok;
}

// ------------------------------------------------------------------------------ the law

Status Projected::law(double t, const double* q, const double* qd, const Terms& T, const Mat& A, double* u) {
    const int n = n_, k = k_, m = m_;
    last_t_ = std::numeric_limits<double>::quiet_NaN();  // (set again when the law succeeds)
    pb_valid_ = false;
    lyapunov_ = std::numeric_limits<double>::quiet_NaN();
    Status s = nullspace(A);
    if (s != Status::ok) return s;
    if (s_.law == Law::regulator) {
        // f_∥ = −P(f_g + Kp e + Kd qd), e = q − q* (q* projected, then aligned per quaternion block)
        if (s_.project_target) {
            if ((s = desired(t, q)) != Status::ok) return s;
        } else {
            qs_ = s_.q_star;
        }
        for (const auto& b : s_.qblocks) {
            double dot = 0.0;
            for (int i : b) dot += q[i] * qs_[i];
            if (dot < 0.0)
                for (int i : b) qs_[i] = -qs_[i];
        }
        // f_g = h(t, q, 0): from the caller's evaluation when the program gives it in the same
        // pass (need(): bitwise the h of an evaluation at q̇ = 0), else by an evaluation of its own
        const Vec* fg = &T.f_g;
        if (!gravity_in_pass_) {
            if ((s = prog_->evaluate(t, q, zero_.data(), mask_.data(), NEED_H, Tg_, *ws_)) != Status::ok) return s;
            fg = &Tg_.h;
        }
        if (s_.sigma > 0.0) {  // spring = e + σ‖e‖η (Regulator.law), into e_
            for (int i = 0; i < n; ++i) e_[i] = q[i] - qs_[i];
            const double nv = norm2(qd, n);
            if (nv > 0.0) {
                for (int i = 0; i < n; ++i) x_[i] = qd[i] / nv;
            } else {
                project(s_.xi0.data(), x_.data());
                const double npx = norm2(x_.data(), n);
                for (int i = 0; i < n; ++i) x_[i] = npx > 0.0 ? x_[i] / npx : 0.0;
            }
            const double ke = s_.sigma * norm2(e_.data(), n);
            for (int i = 0; i < n; ++i) e_[i] += ke * x_[i];
            for (int i = 0; i < n; ++i) {
                double a = (*fg)[i];
                for (int j = 0; j < n; ++j) a += s_.Kp(i, j) * e_[j] + s_.Kd(i, j) * qd[j];
                w_[i] = a;
            }
        } else {
            for (int i = 0; i < n; ++i) {
                double a = (*fg)[i];
                for (int j = 0; j < n; ++j) a += s_.Kp(i, j) * (q[j] - qs_[j]) + s_.Kd(i, j) * qd[j];
                w_[i] = a;
            }
        }
        project(w_.data(), fpar_.data());
        for (int i = 0; i < n; ++i) fpar_[i] = -fpar_[i];
    } else if (s_.law == Law::passivity) {
        if ((s = desired(t, q)) != Status::ok) return s;
        const Vec* fg = &T.f_g;  // f_g as the regulator's
        if (!gravity_in_pass_) {
            if ((s = prog_->evaluate(t, q, zero_.data(), mask_.data(), NEED_H, Tg_, *ws_)) != Status::ok) return s;
            fg = &Tg_.h;
        }
        if ((s = passivity_force(t, q, qd, T, A, *fg)) != Status::ok) return s;
    } else {
        // computed torque: a = q̈* − Kd ė − Kp e, f_∥ = P(M(P a + w) − h − f_p), w = −(DA)⁺Dγ
        if ((s = desired(t, q)) != Status::ok) return s;
        for (int i = 0; i < n; ++i) {
            e_[i] = q[i] - qs_[i];
            x_[i] = qd[i] - vs_[i];
        }
        for (int i = 0; i < n; ++i) {
            double a = as_[i];
            for (int j = 0; j < n; ++j) a -= s_.Kd(i, j) * x_[j] + s_.Kp(i, j) * e_[j];
            a_[i] = a;
        }
        if (m > 0) {
            for (int i = 0; i < m; ++i) br_[i] = T.gamma[rows_[static_cast<std::size_t>(i)]];
            if (lq_valid_) {  // step 1's certified LQ of D A: Solver::min_norm's bits, no new factorization
                if (!finite(br_.data(), m)) return Status::not_finite;
                held_min_norm(lq_, dq_.data(), m, n, br_.data(), cq_.data(), Vh_.data(), w_.data());
            } else {
                const SolveInfo info = solver_.min_norm(A.data(), m, br_.data(), rtol_, w_.data());
                if (info.status != Status::ok) return info.status;
            }
            for (int j = 0; j < n; ++j) w_[j] = -w_[j];
        } else {
            w_.setZero();
        }
        project(a_.data(), x_.data());  // x = P a + w
        for (int i = 0; i < n; ++i) x_[i] += w_[i];
        for (int i = 0; i < n; ++i) {  // y = M x − h − f_p
            double a = -T.h[i] - T.f_passive[i];
            for (int j = 0; j < n; ++j) a += T.M(i, j) * x_[j];
            y_[i] = a;
        }
        project(y_.data(), fpar_.data());
    }
    if (k > 0 && k <= n - rank_) ensure_pb(T);  // (σ(PB) in record(): otherwise 0)
    s = frows_.empty() ? actuate(T) : actuate_force(t, T, A);
    if (s != Status::ok) return s;
    for (int j = 0; j < k; ++j)
        if (!std::isfinite(uraw_[j])) return Status::not_finite;
    for (int j = 0; j < k; ++j) u[j] = std::min(std::max(uraw_[j], s_.u_min[j]), s_.u_max[j]);
    last_t_ = t;
    for (int i = 0; i < n; ++i) {
        last_q_[i] = q[i];
        last_qd_[i] = qd[i];
    }
    return Status::ok;
}

// ------------------------------------------------------------------------------ passivity

// A⁺ (n × m) into Apinv_ (nonmin.core.pseudo_inverse(A, rtol): the rank of step 1's policy).
// With step 1's certified LQ of D A (full row rank), A⁺ = (DA)⁺D, column i = (DA)⁺ D e_i by the
// held factor (held_min_norm: no new factorization); else A's own SVD truncated to the rank.
Status Projected::pseudo_inverse(const Mat& A) {
    const int n = n_, m = m_;
    if (lq_valid_) {
        for (int i = 0; i < m; ++i) {
            for (int r = 0; r < m; ++r) pm_[r] = r == i ? 1.0 : 0.0;
            held_min_norm(lq_, dq_.data(), m, n, pm_.data(), cq_.data(), Vh_.data(), pt1_.data());
            for (int j = 0; j < n; ++j) Apinv_(j, i) = pt1_[j];
        }
        return Status::ok;
    }
    for (int i = 0; i < m; ++i) Atrue_.row(i) = A.row(i);
    svd_a_.compute(Atrue_);
    const auto& sv = svd_a_.singularValues();
    const auto& U = svd_a_.matrixU();
    const auto& V = svd_a_.matrixV();
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < m; ++i) Apinv_(j, i) = 0.0;
    for (int kk = 0; kk < rank_ && kk < sv.size(); ++kk) {
        const double inv = sv[kk] > 0.0 ? 1.0 / sv[kk] : 1.0;  // (as pseudo_inverse)
        for (int j = 0; j < n; ++j) {
            const double vj = V(j, kk) * inv;
            for (int i = 0; i < m; ++i) Apinv_(j, i) += vj * U(i, kk);
        }
    }
    return Status::ok;
}

void Projected::lam_p(const double* v, double* out) {  // out = −A⁺ (Ȧ (P v))
    const int n = n_, m = m_;
    project(v, pt3_.data());
    for (int i = 0; i < m; ++i) {
        double a = 0.0;
        for (int j = 0; j < n; ++j) a += Adot_(i, j) * pt3_[j];
        pm2_[i] = a;
    }
    for (int j = 0; j < n; ++j) {
        double a = 0.0;
        for (int i = 0; i < m; ++i) a += Apinv_(j, i) * pm2_[i];
        out[j] = -a;
    }
}

void Projected::lam_p_t(const double* v, double* out) {  // out = −P (Ȧᵀ (A⁺ᵀ v))
    const int n = n_, m = m_;
    for (int i = 0; i < m; ++i) {
        double a = 0.0;
        for (int j = 0; j < n; ++j) a += Apinv_(j, i) * v[j];
        pm2_[i] = a;
    }
    for (int j = 0; j < n; ++j) {
        double a = 0.0;
        for (int i = 0; i < m; ++i) a += Adot_(i, j) * pm2_[i];
        pt3_[j] = -a;
    }
    project(pt3_.data(), out);
}

void Projected::mbar_times(const Terms& T, double mu, const double* v, double* out) {  // (PMP + μ(I − P)) v
    const int n = n_;
    project(v, pt3_.data());
    for (int i = 0; i < n; ++i) {
        double a = 0.0;
        for (int j = 0; j < n; ++j) a += T.M(i, j) * pt3_[j];
        out[i] = a;
    }
    for (int i = 0; i < n; ++i) pt3_[i] = v[i] - pt3_[i];  // Q v
    project(out, out);
    for (int i = 0; i < n; ++i) out[i] += mu * pt3_[i];
}

// Tracker.law, method="passivity" (Slotine–Li on the projected dynamics; _tracking.py):
//   q̇_r = P x, x = q̇* − λe;  q̈_r = Ṗ x + P(q̈* − λė);  s = q̇ − q̇_r;
//   f_∥ = P(M̄ q̈_r + C̄ q̇_r − f_g − f_p − Kd s − Kp e),  W = ½ sᵀM̄s + ½ eᵀKp e,
// with M̄ = PMP + μQ (μ = tr(PMP)/(n − r), _common.mbar), Λ = −A⁺Ȧ, Ṗ = ΛP + PΛᵀ and
// C̄ = PCP + PMṖ − μΛP (eq. (Cbar2)), all as products with vectors (P = ZᵀZ from step 1; A⁺ from
// step 1's certified LQ or A's truncated SVD; Ȧ from the program's tangent along q̇ (planar:
// A has no explicit t) or TreeProgram::jacobian_dot; C = 0 for a constant M, else
// TreeProgram::coriolis_matrix). Into fpar_ and lyapunov_.
Status Projected::passivity_force(double t, const double* q, const double* qd, const Terms& T, const Mat& A,
                                  const Vec& fg) {
    const int n = n_, m = m_, d = n_ - rank_;
    const double lam = s_.lambda;
    Status s;
    // μ = tr(PMP)/(n − r) = tr(Z M Zᵀ)/d; tr(M)/n when d = 0; 1 when not positive
    double mu;
    if (d > 0) {
        double tr = 0.0;
        for (int a = 0; a < d; ++a)
            for (int i = 0; i < n; ++i) {
                double r = 0.0;
                for (int j = 0; j < n; ++j) r += T.M(i, j) * Z_(a, j);
                tr += Z_(a, i) * r;
            }
        mu = tr / d;
    } else {
        mu = T.M.trace() / n;
    }
    if (!(mu > 0.0)) mu = 1.0;
    const bool cons = m > 0;
    if (cons) {  // Ȧ (active rows) and A⁺
        if (coriolis_ == 0) {
            if ((s = prog_->evaluate_tangent(t, q, qd, qd, zero_.data(), mask_.data(), NEED_A, Tv_, Tt_, *ws_)) !=
                Status::ok)
                return s;
            for (int i = 0; i < m; ++i) Adot_.row(i) = Tt_.A.row(rows_[static_cast<std::size_t>(i)]);
        } else {
            const auto& tp = static_cast<const rbd::TreeProgram&>(*prog_);
            if ((s = tp.jacobian_dot(q, qd, mask_.data(), static_cast<rbd::TreeWorkspace&>(*ws_), Adall_.data())) !=
                Status::ok)
                return s;
            for (int i = 0; i < m; ++i) Adot_.row(i) = Adall_.row(rows_[static_cast<std::size_t>(i)]);
        }
        if (!finite(Adot_.data(), m * n)) return Status::not_finite;
        if ((s = pseudo_inverse(A)) != Status::ok) return s;
    }
    for (int i = 0; i < n; ++i) {
        pe_[i] = q[i] - qs_[i];
        ped_[i] = qd[i] - vs_[i];
        px_[i] = vs_[i] - lam * pe_[i];
    }
    project(px_.data(), pqrd_.data());  // q̇_r = P x
    for (int i = 0; i < n; ++i) pt1_[i] = as_[i] - lam * ped_[i];
    project(pt1_.data(), pqrdd_.data());  // q̈_r = P(q̈* − λė) + Ṗ x
    if (cons) {
        lam_p(px_.data(), pt1_.data());
        lam_p_t(px_.data(), pt2_.data());
        for (int i = 0; i < n; ++i) pqrdd_[i] += pt1_[i] + pt2_[i];
    }
    for (int i = 0; i < n; ++i) psv_[i] = qd[i] - pqrd_[i];  // s
    // y = M̄ q̈_r + C̄ q̇_r − f_g − f_p − Kd s − Kp e  (into w_)
    mbar_times(T, mu, pqrdd_.data(), w_.data());
    if (coriolis_ == 1) {  // + P C P q̇_r
        const auto& tp = static_cast<const rbd::TreeProgram&>(*prog_);
        if ((s = tp.coriolis_matrix(q, qd, static_cast<rbd::TreeWorkspace&>(*ws_), Cm_.data())) != Status::ok)
            return s;
        if (!finite(Cm_.data(), n * n)) return Status::not_finite;
        if (cons) project(pqrd_.data(), pt1_.data()); else pt1_ = pqrd_;
        for (int i = 0; i < n; ++i) {
            double a = 0.0;
            for (int j = 0; j < n; ++j) a += Cm_(i, j) * pt1_[j];
            pt2_[i] = a;
        }
        if (cons) project(pt2_.data(), pt2_.data());
        for (int i = 0; i < n; ++i) w_[i] += pt2_[i];
    }
    if (cons) {  // + P M Ṗ q̇_r − μ Λ P q̇_r
        lam_p(pqrd_.data(), pt1_.data());
        lam_p_t(pqrd_.data(), pt2_.data());
        for (int i = 0; i < n; ++i) pt2_[i] += pt1_[i];  // Ṗ q̇_r
        for (int i = 0; i < n; ++i) {
            double a = 0.0;
            for (int j = 0; j < n; ++j) a += T.M(i, j) * pt2_[j];
            a_[i] = a;
        }
        project(a_.data(), a_.data());
        for (int i = 0; i < n; ++i) w_[i] += a_[i] - mu * pt1_[i];
    }
    for (int i = 0; i < n; ++i) {
        double a = w_[i] - fg[i] - T.f_passive[i];
        for (int j = 0; j < n; ++j) a -= s_.Kd(i, j) * psv_[j] + s_.Kp(i, j) * pe_[j];
        w_[i] = a;
    }
    project(w_.data(), fpar_.data());
    // W = ½ sᵀ M̄ s + ½ eᵀ Kp e
    mbar_times(T, mu, psv_.data(), pt1_.data());
    double ws = 0.0, we = 0.0;
    for (int i = 0; i < n; ++i) {
        ws += psv_[i] * pt1_[i];
        double r = 0.0;
        for (int j = 0; j < n; ++j) r += s_.Kp(i, j) * pe_[j];
        we += pe_[i] * r;
    }
    lyapunov_ = 0.5 * ws + 0.5 * we;
    return Status::ok;
}

Status Projected::probe(double t, const double* q, const double* qd, const std::uint8_t* active, double* u) {
    const int n = n_;
    if (Tp_.M.rows() != n) {
        Tp_ = prog_->make_terms();
        Ap_ = Mat::Zero(std::max(prog_->m_all(), 1), n);
    }
    std::vector<int> rows;
    const auto& cons = prog_->constraints();
    for (std::size_t ci = 0; ci < cons.size(); ++ci)
        if (active[ci])
            for (int r = 0; r < cons[ci].dim; ++r) rows.push_back(cons[ci].row + r);
    const unsigned need = NEED_M | NEED_H | NEED_B | NEED_A | NEED_GAMMA | own_need();
    Status s = prog_->evaluate(t, q, qd, active, need, Tp_, *ws_);
    if (s != Status::ok) return s;
    const int m = static_cast<int>(rows.size());
    for (int i = 0; i < m; ++i) Ap_.row(i) = Tp_.A.row(rows[static_cast<std::size_t>(i)]);
    attach(Tp_, Ap_, m, rows);
    return control(t, q, qd, active, u);
}

// ------------------------------------------------------------------------------ step 3

// The minimum-norm solution u of W u = rhs (W: the first `rows` rows of W, k ≥ rows columns;
// overwritten by the Householder reflectors of its LQ; L's factor into Lw) when W's smallest
// singular value (its lower bound 1/‖L⁻¹‖_F) is certified far above the rank cutoff
// rtol·max(‖W‖_F, bscale) and W is well conditioned: then the truncated SVD pseudo-inverse of
// the Python code keeps every singular value, and W⁺ rhs = Q [L⁻¹ rhs; 0] agrees with it to
// round-off. False (u untouched, W and Lw destroyed) otherwise. y: scratch of `rows` entries.
bool Projected::certified_min_norm(Mat& W, Mat& Lw, int rows, int k, const double* rhs, double fro, double bscale,
                                   double* y, double* u) {
    const int d = rows;
    for (int a = 0; a < d; ++a) {
        double sq = 0.0;
        for (int j = a; j < k; ++j) sq += W(a, j) * W(a, j);
        const double nx = std::sqrt(sq);
        if (!(nx > 0.0)) return false;
        const double alpha = W(a, a) > 0.0 ? -nx : nx;
        const double v0 = W(a, a) - alpha;
        const double vv = sq - W(a, a) * W(a, a) + v0 * v0;
        const double beta = vv > 0.0 ? 2.0 / vv : 0.0;
        // the reflector v = (v0, W(a, a+1..)) kept in row a past the diagonal; L_aa = alpha
        W(a, a) = v0;
        for (int b = a + 1; b < d; ++b) {
            double s = 0.0;
            for (int j = a; j < k; ++j) s += W(a, j) * W(b, j);
            s *= beta;
            for (int j = a; j < k; ++j) W(b, j) -= s * W(a, j);
        }
        hv_[a] = beta;
        Lw(a, a) = alpha;  // L's diagonal
        for (int b = a + 1; b < d; ++b) Lw(b, a) = W(b, a);  // L below the diagonal
    }
    // ‖L⁻¹‖_F (σ_min(W) ≥ 1/‖L⁻¹‖_F) and y = L⁻¹ rhs
    double inv_fro = 0.0;
    for (int c = 0; c < d; ++c) {  // column c of L⁻¹ by forward substitution
        for (int i = 0; i < d; ++i) {
            double s = i == c ? 1.0 : 0.0;
            for (int j = c; j < i; ++j) s -= Lw(i, j) * y[j];
            y[i] = i < c ? 0.0 : s / Lw(i, i);
            if (i >= c) inv_fro += y[i] * y[i];
        }
    }
    const double smin_lo = 1.0 / std::sqrt(inv_fro);
    const double ref_hi = std::max({fro, bscale, TINY});
    if (!(std::isfinite(smin_lo) && smin_lo > CERTIFY_FACTOR * rtol_ * ref_hi && fro <= CERTIFY_COND * smin_lo))
        return false;
    for (int i = 0; i < d; ++i) {
        double s = rhs[i];
        for (int j = 0; j < i; ++j) s -= Lw(i, j) * y[j];
        y[i] = s / Lw(i, i);
    }
    // u = H_0 ⋯ H_{d−1} [y; 0]
    for (int j = 0; j < k; ++j) u[j] = j < d ? y[j] : 0.0;
    for (int a = d - 1; a >= 0; --a) {
        double s = 0.0;
        for (int j = a; j < k; ++j) s += W(a, j) * u[j];
        s *= hv_[a];
        for (int j = a; j < k; ++j) u[j] -= s * W(a, j);
    }
    return true;
}

// _common.actuate: u = (PB)⁺ f_∥ with rank(PB) by σ > rtol·max(σ_max, max column norm of B).
Status Projected::actuate(const Terms& T) {
    const int n = n_, k = k_, d = n_ - rank_;
    if (k == 0) {
        last_feasible_ = d == 0;
        if (!last_feasible_ && s_.raise_infeasible) return Status::not_positive_definite;
        return Status::ok;
    }
    double bscale = 0.0;
    for (int j = 0; j < k; ++j) {
        double sq = 0.0;
        for (int i = 0; i < n; ++i) sq += T.B(i, j) * T.B(i, j);
        bscale = std::max(bscale, sq);
    }
    bscale = std::sqrt(bscale);
    if (d > 0 && k >= d) {
        // ZB = Z B (d × k), zf = Z f_∥; LQ of ZB by Householder reflectors on its rows
        Mat& W = ZB_;
        double fro = reduce_actuation(T, W, zf_.data());
        fro = std::sqrt(fro);
        if (certified_min_norm(W, G_, d, k, zf_.data(), fro, bscale, y_.data(), uraw_.data())) {
            last_feasible_ = true;
            ++fast_actuations;
            return Status::ok;
        }
    }
    // the SVD of PB (the Python code's decision, everywhere the fast path is not certified)
    ++svd_actuations;
    ensure_pb(T);
    svd_pb_.compute(PB_.leftCols(k));
    const auto& sv = svd_pb_.singularValues();
    const auto& U = svd_pb_.matrixU();
    const auto& V = svd_pb_.matrixV();
    const double ref = std::max({sv.size() ? sv[0] : 0.0, bscale, TINY});
    int rank_pb = 0;
    for (int i = 0; i < sv.size(); ++i) rank_pb += sv[i] > rtol_ * ref;
    last_feasible_ = rank_pb >= d;
    if (!last_feasible_ && s_.raise_infeasible) return Status::not_positive_definite;
    for (int i = 0; i < sv.size(); ++i) {
        double c = 0.0;
        if (sv[i] > rtol_ * ref) {
            for (int r = 0; r < n; ++r) c += U(r, i) * fpar_[r];
            c /= sv[i];
        }
        y_[i] = c;
    }
    for (int j = 0; j < k; ++j) {
        double a = 0.0;
        for (int i = 0; i < sv.size(); ++i) a += V(j, i) * y_[i];
        uraw_[j] = a;
    }
    return Status::ok;
}

// c₀ (f_c of solve_dynamics(M, g, A, γ)) and sf_ = f_∥ − M M̄⁻¹ P f_∥ in the null-space form,
// from step 1's certified LQ of D A (lq_valid_): w = −(DA)⁺Dγ by held_min_norm, S = Z M Zᵀ
// (d × d, Z_ the same rows as the solver's basis) and its Cholesky factor; q̈ = w + Zᵀ S⁻¹ Z(g − M w),
// c₀ = M q̈ − g (Solver's null-space form), and M̄⁻¹ P f_∥ = Zᵀ S⁻¹ Z f_∥ (M̄ = μVᵀV + ZᵀSZ). Equal
// to the solver's values to round-off, without its second factorization of A nor M̄'s n × n
// factor. False (nothing decided) when step 1 has no certified LQ, an input is not finite or S
// is not numerically positive definite: then the solver decides (and reports).
bool Projected::force_terms_null(const Terms& T, const double* g, const double* gamma) {
    const int n = n_, m = m_, d = n_ - rank_;
    if (!lq_valid_ || !finite(g, n) || !finite(gamma, m)) return false;
    held_min_norm(lq_, dq_.data(), m, n, gamma, cq_.data(), Vh_.data(), xs_.data());
    for (int j = 0; j < n; ++j) xs_[j] = -xs_[j];  // w
    double smax = 0.0;
    for (int a = 0; a < d; ++a) {  // ZM = Z M, S = ZM Zᵀ (lower triangle)
        for (int j = 0; j < n; ++j) ZMs_(a, j) = 0.0;
        for (int i = 0; i < n; ++i) {
            const double c = Z_(a, i);
            for (int j = 0; j < n; ++j) ZMs_(a, j) += c * T.M(i, j);
        }
        for (int c = 0; c <= a; ++c) {
            double s = 0.0;
            for (int j = 0; j < n; ++j) s += ZMs_(a, j) * Z_(c, j);
            Ss_(a, c) = s;
        }
        smax = std::max(smax, Ss_(a, a));
    }
    for (int j = 0; j < d; ++j) {  // Cholesky S = L Lᵀ in place (lower)
        double p = Ss_(j, j);
        for (int c = 0; c < j; ++c) p -= Ss_(j, c) * Ss_(j, c);
        if (!(p > 1e-14 * smax)) return false;
        const double l = std::sqrt(p);
        Ss_(j, j) = l;
        for (int i = j + 1; i < d; ++i) {
            double s = Ss_(i, j);
            for (int c = 0; c < j; ++c) s -= Ss_(i, c) * Ss_(j, c);
            Ss_(i, j) = s / l;
        }
    }
    // x ← Zᵀ S⁻¹ Z x (x: n entries; uses ys_)
    auto null_solve = [&](double* x) {
        for (int a = 0; a < d; ++a) {
            double s = 0.0;
            for (int i = 0; i < n; ++i) s += Z_(a, i) * x[i];
            ys_[a] = s;
        }
        for (int a = 0; a < d; ++a) {
            double s = ys_[a];
            for (int c = 0; c < a; ++c) s -= Ss_(a, c) * ys_[c];
            ys_[a] = s / Ss_(a, a);
        }
        for (int a = d - 1; a >= 0; --a) {
            double s = ys_[a];
            for (int c = a + 1; c < d; ++c) s -= Ss_(c, a) * ys_[c];
            ys_[a] = s / Ss_(a, a);
        }
        for (int i = 0; i < n; ++i) {
            double s = 0.0;
            for (int a = 0; a < d; ++a) s += Z_(a, i) * ys_[a];
            x[i] = s;
        }
    };
    for (int i = 0; i < n; ++i) {  // q̈ = w + Zᵀ S⁻¹ Z (g − M w)
        double s = g[i];
        for (int j = 0; j < n; ++j) s -= T.M(i, j) * xs_[j];
        qtmp_[i] = s;
    }
    null_solve(qtmp_.data());
    for (int i = 0; i < n; ++i) qtmp_[i] += xs_[i];
    for (int i = 0; i < n; ++i) {  // c₀ = M q̈ − g
        double s = 0.0;
        for (int j = 0; j < n; ++j) s += T.M(i, j) * qtmp_[j];
        c0_[i] = s - g[i];
    }
    for (int i = 0; i < n; ++i) pf_[i] = fpar_[i];  // S f_∥ = f_∥ − M Zᵀ S⁻¹ Z f_∥
    null_solve(pf_.data());
    for (int i = 0; i < n; ++i) {
        double a = fpar_[i];
        for (int j = 0; j < n; ++j) a -= T.M(i, j) * pf_[j];
        sf_[i] = a;
    }
    return true;
}

// ForceControl.actuation: [PB; EB] u = [f_∥; E(c₀ − S f_∥) − λ*] by SVD, minimum norm.
Status Projected::actuate_force(double t, const Terms& T, const Mat& A) {
    const int n = n_, k = k_, m = m_, d = n_ - rank_;
    const int mf = static_cast<int>(frows_.size());
    Status s;
    // λ* of the active commanded constraints, in order
    {
        int at = 0, fi = 0;
        for (const auto& [con, sig] : s_.forces) {
            if (!mask_[static_cast<std::size_t>(con)]) continue;
            if ((s = sig->eval(t, lam_.data() + at, nullptr, nullptr)) != Status::ok) return s;
            at += fdim_[static_cast<std::size_t>(fi++)];
        }
        if (!finite(lam_.data(), mf)) return Status::not_finite;
    }
    // c₀ = f_c of solve_dynamics(M, h + f_p, A, γ, rtol) and S f_∥ = f_∥ − M M̄⁻¹ P f_∥: from
    // step 1's LQ in the null-space form when it holds (force_terms_null), else by the solver
    // with μ and M̄'s Cholesky factor
    for (int i = 0; i < n; ++i) gtmp_[i] = T.h[i] + T.f_passive[i];
    for (int i = 0; i < m; ++i) br_[i] = T.gamma[rows_[static_cast<std::size_t>(i)]];
    if (!force_terms_null(T, gtmp_.data(), br_.data())) {
        SolveOptions so;
        so.rtol = rtol_;
        const SolveInfo info = solver_.solve(T.M.data(), gtmp_.data(), A.data(), m, br_.data(), so, qtmp_.data(),
                                             c0_.data(), nullptr, Mbar_L_.data());
        if (info.status != Status::ok) return info.status;
        project(fpar_.data(), pf_.data());
        for (int i = 0; i < n; ++i) {  // L y = P f_∥
            double a = pf_[i];
            for (int j = 0; j < i; ++j) a -= Mbar_L_(i, j) * pf_[j];
            pf_[i] = a / Mbar_L_(i, i);
        }
        for (int i = n - 1; i >= 0; --i) {  // Lᵀ x = y
            double a = pf_[i];
            for (int j = i + 1; j < n; ++j) a -= Mbar_L_(j, i) * pf_[j];
            pf_[i] = a / Mbar_L_(i, i);
        }
        for (int i = 0; i < n; ++i) {
            double a = fpar_[i];
            for (int j = 0; j < n; ++j) a -= T.M(i, j) * pf_[j];
            sf_[i] = a;
        }
    }
    // E: the commanded rows of (A⁺)ᵀ. With the certified LQ of step 1 (full row rank), A⁺ =
    // (DA)⁺D = Qᵀ L⁻¹ D: row f of E is d_f (L⁻¹ e_f)ᵀ Q; else A's own SVD truncated to the rank.
    if (lq_valid_) {
        const int ld = lq_.m_max;
        for (int f = 0; f < mf; ++f) {
            const int row = frows_[static_cast<std::size_t>(f)];
            const double df = dq_[static_cast<std::size_t>(row)];
            for (int i = 0; i < m; ++i) hw_[i] = i < row ? 0.0 : -df * lq_.Li[static_cast<std::size_t>(i) * ld + row];
            linalg::lq_min_norm(lq_, m, n, hw_.data(), &E_(f, 0));  // (−Qᵀ of −d_f L⁻¹ e_f)
        }
    } else {
        for (int i = 0; i < m; ++i) Atrue_.row(i) = A.row(i);
        svd_a_.compute(Atrue_);
        const auto& sv = svd_a_.singularValues();
        const auto& U = svd_a_.matrixU();
        const auto& V = svd_a_.matrixV();
        for (int f = 0; f < mf; ++f) {
            const int row = frows_[static_cast<std::size_t>(f)];
            for (int j = 0; j < n; ++j) {
                double a = 0.0;
                for (int kk = 0; kk < rank_ && kk < sv.size(); ++kk)
                    if (sv[kk] > 0.0) a += V(j, kk) * U(row, kk) / sv[kk];
                E_(f, j) = a;
            }
        }
    }
    // G = [PB; EB], rhs = [f_∥; E(c₀ − S f_∥) − λ*] (PB, G's first n rows, for the SVD path only)
    for (int i = 0; i < n; ++i) rhs_[i] = fpar_[i];
    for (int f = 0; f < mf; ++f) {
        double r = -lam_[f];
        for (int j = 0; j < n; ++j) r += E_(f, j) * (c0_[j] - sf_[j]);
        rhs_[n + f] = r;
        for (int j = 0; j < k; ++j) {
            double a = 0.0;
            for (int i = 0; i < n; ++i) a += E_(f, i) * T.B(i, j);
            Gf_(n + f, j) = a;
        }
    }
    if (k == 0) {
        last_feasible_ = d + mf == 0;
        if (!last_feasible_ && s_.raise_infeasible) return Status::not_positive_definite;
        return Status::ok;
    }
    double bscale = 0.0;
    for (int j = 0; j < k; ++j) {
        double sq = 0.0;
        for (int i = 0; i < n; ++i) sq += T.B(i, j) * T.B(i, j);
        bscale = std::max(bscale, sq);
    }
    bscale = std::sqrt(bscale);
    if (d + mf > 0 && k >= d + mf) {
        // W = [Z B; E B] ((d + mf) × k), rhs = [Z f_∥; E(c₀ − S f_∥) − λ*]: PB = Zᵀ(Z B) and
        // f_∥ = Zᵀ(Z f_∥) with Zᵀ's columns orthonormal, so [PB; EB] and W have the same singular
        // values and the same minimum-norm solution; W's by its certified LQ
        Mat& W = Wf_;
        double fro = reduce_actuation(T, W, rhsf_.data());
        for (int f = 0; f < mf; ++f) {
            for (int j = 0; j < k; ++j) {
                W(d + f, j) = Gf_(n + f, j);
                fro += Gf_(n + f, j) * Gf_(n + f, j);
            }
            rhsf_[d + f] = rhs_[n + f];
        }
        fro = std::sqrt(fro);
        if (certified_min_norm(W, Lf_, d + mf, k, rhsf_.data(), fro, bscale, yf_.data(), uraw_.data())) {
            last_feasible_ = true;
            ++fast_actuations;
            return Status::ok;
        }
    }
    ++svd_actuations;
    ensure_pb(T);
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < k; ++j) Gf_(i, j) = PB_(i, j);
    svd_g_.compute(Gf_);
    const auto& sv = svd_g_.singularValues();
    const auto& U = svd_g_.matrixU();
    const auto& V = svd_g_.matrixV();
    const double ref = std::max({sv.size() ? sv[0] : 0.0, bscale, TINY});
    int rank = 0;
    for (int i = 0; i < sv.size(); ++i) rank += sv[i] > rtol_ * ref;
    last_feasible_ = rank >= d + mf;
    if (!last_feasible_ && s_.raise_infeasible) return Status::not_positive_definite;
    for (int i = 0; i < sv.size(); ++i) {
        double c = 0.0;
        if (sv[i] > rtol_ * ref) {
            for (int r = 0; r < n + mf; ++r) c += U(r, i) * rhs_[r];
            c /= sv[i];
        }
        y_[i] = c;
    }
    for (int j = 0; j < k; ++j) {
        double a = 0.0;
        for (int i = 0; i < sv.size(); ++i) a += V(j, i) * y_[i];
        uraw_[j] = a;
    }
    return Status::ok;
}

// ------------------------------------------------------------------------------ bookkeeping

// The smallest singular value of PB at the last law evaluation (σ(PB)[-1] of _common.actuate):
// 0 when PB has more singular values than n − r (the others vanish exactly; the SVD of the
// rounded PB gives them at round-off).
double Projected::sigma_min_pb() {
    const int n = n_, k = k_, d = n_ - rank_;
    if (k == 0 || !pb_valid_) return 0.0;
    if (std::min(n, k) > d) return 0.0;
    svd_vals_.compute(PB_.leftCols(k));
    const auto& sv = svd_vals_.singularValues();
    return sv.size() ? sv[sv.size() - 1] : 0.0;
}

void Projected::record() {  // ControlState.record of the last law evaluation
    for (int j = 0; j < k_; ++j) {
        const double lo = s_.u_min[j], hi = s_.u_max[j], v = uraw_[j];
        const bool sat = (v <= lo || v >= hi) && (std::isfinite(lo) || std::isfinite(hi));
        saturated[static_cast<std::size_t>(j)] = sat;
        saturated_steps[static_cast<std::size_t>(j)] += sat;
        max_abs_u[static_cast<std::size_t>(j)] = std::max(max_abs_u[static_cast<std::size_t>(j)], std::abs(v));
    }
    ++steps;
    infeasible_steps += last_feasible_ ? 0 : 1;
    min_sigma_pb = std::min(min_sigma_pb, sigma_min_pb());
}

}  // namespace nonmin::sim
