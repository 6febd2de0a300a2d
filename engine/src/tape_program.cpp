// TapeProgram: evaluation of an expression tape (see nonmin/tape.hpp).
#include "nonmin/tape.hpp"

#include <algorithm>
#include <cmath>
#include <string>

namespace nonmin {

namespace {

unsigned target_need(TapeTarget t) {
    switch (t) {
        case TapeTarget::M: return NEED_M | NEED_ENERGY;
        case TapeTarget::h:
        case TapeTarget::f_passive: return NEED_H;
        case TapeTarget::B: return NEED_B;
        case TapeTarget::A: return NEED_A;
        case TapeTarget::gamma: return NEED_GAMMA;
        case TapeTarget::phi: return NEED_PHI;
        case TapeTarget::velocity: return NEED_VELOCITY;
        case TapeTarget::V: return NEED_ENERGY;
    }
    return 0;
}

bool binary(TapeOp op) {
    switch (op) {
        case TapeOp::add:
        case TapeOp::sub:
        case TapeOp::mul:
        case TapeOp::div:
        case TapeOp::pow:
        case TapeOp::atan2:
        case TapeOp::min:
        case TapeOp::max: return true;
        default: return false;
    }
}

// A plan's fused op (not a tape op): sin into dst and cos into b of one register
constexpr int TAPE_SINCOS = 100;

inline double powi(double x, long k) {
    if (k < 0) return 1.0 / powi(x, -k);
    double r = 1.0;
    while (k) {
        if (k & 1) r *= x;
        x *= x;
        k >>= 1;
    }
    return r;
}

}  // namespace

TapeProgram::TapeProgram(TapeDescription desc, std::vector<double> params)
    : d_(std::move(desc)), params_(std::move(params)) {
    if (d_.n < 1) throw EngineError("a tape program needs n ≥ 1 coordinates");
    if (static_cast<int>(params_.size()) != d_.n_params)
        throw EngineError("tape: " + std::to_string(params_.size()) + " parameter values for " +
                          std::to_string(d_.n_params) + " parameters");
    for (double p : params_)
        if (!std::isfinite(p)) throw EngineError("tape: parameter values must be finite");
    n_ = d_.n;
    k_ = d_.k;
    constraints_ = d_.constraints;
    m_all_ = 0;
    for (const ConstraintInfo& c : constraints_) {
        if (c.row != m_all_ || c.dim < 1) throw EngineError("tape: constraint '" + c.name + "' rows out of order");
        m_all_ += c.dim;
    }
    const std::size_t N = d_.op.size();
    if (d_.a.size() != N || d_.b.size() != N || d_.c.size() != N)
        throw EngineError("tape: op, a, b, c differ in length");
    const int base = n_inputs();
    for (std::size_t i = 0; i < N; ++i) {
        const int op = d_.op[i];
        if (op < 0 || op >= static_cast<int>(TapeOp::num_ops))
            throw EngineError("tape: unknown op " + std::to_string(op) + " at instruction " + std::to_string(i));
        const int self = base + static_cast<int>(i);
        if (static_cast<TapeOp>(op) != TapeOp::constant) {
            if (d_.a[i] < 0 || d_.a[i] >= self)
                throw EngineError("tape: instruction " + std::to_string(i) + " reads register " +
                                  std::to_string(d_.a[i]) + " before it is written");
            if (binary(static_cast<TapeOp>(op)) && (d_.b[i] < 0 || d_.b[i] >= self))
                throw EngineError("tape: instruction " + std::to_string(i) + " reads register " +
                                  std::to_string(d_.b[i]) + " before it is written");
        }
    }
    const std::size_t E = d_.out_target.size();
    if (d_.out_index.size() != E || d_.out_reg.size() != E) throw EngineError("tape: output table lengths differ");
    need_.assign(N, 0);
    out_row_constraint_.assign(E, -1);
    // constraint of each row
    std::vector<int> row_c(static_cast<std::size_t>(m_all_));
    for (std::size_t ci = 0; ci < constraints_.size(); ++ci)
        for (int r = 0; r < constraints_[ci].dim; ++r)
            row_c[static_cast<std::size_t>(constraints_[ci].row + r)] = static_cast<int>(ci);
    for (std::size_t e = 0; e < E; ++e) {
        const int tg = d_.out_target[e];
        if (tg < 0 || tg > static_cast<int>(TapeTarget::V)) throw EngineError("tape: unknown output target");
        const auto T = static_cast<TapeTarget>(tg);
        long size = 0;
        switch (T) {
            case TapeTarget::M: size = static_cast<long>(n_) * n_; break;
            case TapeTarget::h:
            case TapeTarget::f_passive: size = n_; break;
            case TapeTarget::B: size = static_cast<long>(n_) * k_; break;
            case TapeTarget::A: size = static_cast<long>(m_all_) * n_; break;
            case TapeTarget::gamma:
            case TapeTarget::phi:
            case TapeTarget::velocity: size = m_all_; break;
            case TapeTarget::V: size = 1; break;
        }
        const int idx = d_.out_index[e];
        if (idx < 0 || idx >= size) throw EngineError("tape: output index out of range");
        const int reg = d_.out_reg[e];
        if (reg < 0 || reg >= base + static_cast<int>(N)) throw EngineError("tape: output register out of range");
        if (T == TapeTarget::A) out_row_constraint_[e] = row_c[static_cast<std::size_t>(idx / n_)];
        if (T == TapeTarget::gamma || T == TapeTarget::phi || T == TapeTarget::velocity)
            out_row_constraint_[e] = row_c[static_cast<std::size_t>(idx)];
        if (reg >= base) need_[static_cast<std::size_t>(reg - base)] |= static_cast<std::uint8_t>(target_need(T));
    }
    // an instruction is needed by what needs the instructions that read it
    for (std::size_t i = N; i-- > 0;) {
        const std::uint8_t f = need_[i];
        if (!f || static_cast<TapeOp>(d_.op[i]) == TapeOp::constant) continue;
        if (d_.a[i] >= base) need_[static_cast<std::size_t>(d_.a[i] - base)] |= f;
        if (binary(static_cast<TapeOp>(d_.op[i])) && d_.b[i] >= base)
            need_[static_cast<std::size_t>(d_.b[i] - base)] |= f;
    }
    schedule();
}

void TapeProgram::schedule() {
    // Reorder the instructions (a topological order of their dependencies) so that runs of one
    // op follow each other: the evaluation loop's dispatch then predicts well. Every
    // instruction computes the same op on the same operands, so the results are bitwise
    // unchanged.
    const std::size_t N = d_.op.size();
    if (N < 2) return;
    const int base = n_inputs();
    const int nops = static_cast<int>(TapeOp::num_ops);
    std::vector<int> indeg(N, 0);
    std::vector<std::vector<int>> children(N);
    for (std::size_t i = 0; i < N; ++i) {
        const auto op = static_cast<TapeOp>(d_.op[i]);
        if (op == TapeOp::constant) continue;
        const int a = d_.a[i] - base;
        if (a >= 0) {
            children[static_cast<std::size_t>(a)].push_back(static_cast<int>(i));
            ++indeg[i];
        }
        if (binary(op)) {
            const int b = d_.b[i] - base;
            if (b >= 0 && b != a) {
                children[static_cast<std::size_t>(b)].push_back(static_cast<int>(i));
                ++indeg[i];
            }
        }
    }
    std::vector<std::vector<int>> ready(static_cast<std::size_t>(nops));
    for (std::size_t i = N; i-- > 0;)
        if (indeg[i] == 0) ready[static_cast<std::size_t>(d_.op[i])].push_back(static_cast<int>(i));
    std::vector<int> order;
    order.reserve(N);
    int cur = -1;
    while (order.size() < N) {
        if (cur < 0 || ready[static_cast<std::size_t>(cur)].empty()) {
            cur = -1;
            std::size_t best = 0;
            for (int o = 0; o < nops; ++o)
                if (ready[static_cast<std::size_t>(o)].size() > best) {
                    best = ready[static_cast<std::size_t>(o)].size();
                    cur = o;
                }
            if (cur < 0) throw EngineError("tape: dependency cycle");
        }
        auto& bucket = ready[static_cast<std::size_t>(cur)];
        const int i = bucket.back();
        bucket.pop_back();
        order.push_back(i);
        for (int ch : children[static_cast<std::size_t>(i)])
            if (--indeg[static_cast<std::size_t>(ch)] == 0)
                ready[static_cast<std::size_t>(d_.op[static_cast<std::size_t>(ch)])].push_back(ch);
    }
    std::vector<int> pos(N);
    for (std::size_t k = 0; k < N; ++k) pos[static_cast<std::size_t>(order[k])] = static_cast<int>(k);
    auto remap = [&](int reg) { return reg < base ? reg : base + pos[static_cast<std::size_t>(reg - base)]; };
    std::vector<int> op(N), a(N), b(N);
    std::vector<double> c(N);
    std::vector<std::uint8_t> nd(N);
    for (std::size_t k = 0; k < N; ++k) {
        const auto i = static_cast<std::size_t>(order[k]);
        op[k] = d_.op[i];
        const bool uses = static_cast<TapeOp>(op[k]) != TapeOp::constant;
        a[k] = uses ? remap(d_.a[i]) : d_.a[i];
        b[k] = uses && binary(static_cast<TapeOp>(op[k])) ? remap(d_.b[i]) : d_.b[i];
        c[k] = d_.c[i];
        nd[k] = need_[i];
    }
    d_.op.swap(op);
    d_.a.swap(a);
    d_.b.swap(b);
    d_.c.swap(c);
    need_.swap(nd);
    for (int& r : d_.out_reg) r = remap(r);
}

std::unique_ptr<Workspace> TapeProgram::make_workspace() const {
    auto w = std::make_unique<TapeWorkspace>();
    w->reg.assign(static_cast<std::size_t>(n_inputs()) + d_.op.size(), 0.0);
    std::copy(params_.begin(), params_.end(), w->reg.begin() + 1 + 2 * n_);
    // constants once
    const int base = n_inputs();
    for (std::size_t i = 0; i < d_.op.size(); ++i)
        if (static_cast<TapeOp>(d_.op[i]) == TapeOp::constant) w->reg[static_cast<std::size_t>(base) + i] = d_.c[i];
    return w;
}

const TapePlan& TapeProgram::plan(TapeWorkspace& w, unsigned need) const {
    for (const TapePlan& p : w.plans)
        if (p.need == need) return p;
    TapePlan P;
    P.need = need;
    const int base = n_inputs();
    const std::size_t N = d_.op.size();
    // sin and cos of one register, both needed: one sincos at the first of the two (glibc's
    // sincos is bitwise its sin and cos: checked on 2e7 arguments; the second's register is
    // read only after it in the tape's order, so writing it earlier changes nothing)
    std::vector<int> partner(N, -1);
#if defined(__GLIBC__)
    {
        std::vector<int> sin_of(static_cast<std::size_t>(base) + N, -1), cos_of(sin_of.size(), -1);
        for (std::size_t i = 0; i < N; ++i) {
            if (!(need_[i] & need)) continue;
            const auto op = static_cast<TapeOp>(d_.op[i]);
            if (op == TapeOp::sin && sin_of[static_cast<std::size_t>(d_.a[i])] < 0)
                sin_of[static_cast<std::size_t>(d_.a[i])] = static_cast<int>(i);
            if (op == TapeOp::cos && cos_of[static_cast<std::size_t>(d_.a[i])] < 0)
                cos_of[static_cast<std::size_t>(d_.a[i])] = static_cast<int>(i);
        }
        for (std::size_t x = 0; x < sin_of.size(); ++x)
            if (sin_of[x] >= 0 && cos_of[x] >= 0) {
                partner[static_cast<std::size_t>(sin_of[x])] = cos_of[x];
                partner[static_cast<std::size_t>(cos_of[x])] = sin_of[x];
            }
    }
#endif
    std::vector<char> done(N, 0);
    for (std::size_t i = 0; i < N; ++i) {
        int op = d_.op[i];
        if (!(need_[i] & need) || static_cast<TapeOp>(op) == TapeOp::constant || done[i]) continue;
        int b = binary(static_cast<TapeOp>(op)) ? d_.b[i] : 0;
        int dst = base + static_cast<int>(i);
        if (partner[i] >= 0) {  // sin → (dst, b) = (sin's, cos's register)
            const int j = partner[i];
            done[static_cast<std::size_t>(j)] = 1;
            const bool is_sin = static_cast<TapeOp>(op) == TapeOp::sin;
            dst = base + (is_sin ? static_cast<int>(i) : j);
            b = base + (is_sin ? j : static_cast<int>(i));
            op = TAPE_SINCOS;
        }
        P.dst.push_back(dst);
        P.a.push_back(d_.a[i]);
        P.b.push_back(b);
        P.c.push_back(d_.c[i]);
        if (P.run_op.empty() || P.run_op.back() != op) {
            P.run_op.push_back(op);
            P.run_end.push_back(0);
        }
        P.run_end.back() = static_cast<int>(P.dst.size());
    }
    const int n_targets = static_cast<int>(TapeTarget::V) + 1;
    const std::size_t E = d_.out_target.size();
    for (int T = 0; T < n_targets; ++T) {
        P.out_start.push_back(static_cast<int>(P.out_idx.size()));
        if (!(target_need(static_cast<TapeTarget>(T)) & need)) continue;
        for (std::size_t e = 0; e < E; ++e) {
            if (d_.out_target[e] != T) continue;
            P.out_idx.push_back(d_.out_index[e]);
            P.out_reg.push_back(d_.out_reg[e]);
            P.out_con.push_back(out_row_constraint_[e]);
        }
    }
    P.out_start.push_back(static_cast<int>(P.out_idx.size()));
    w.plans.push_back(std::move(P));
    return w.plans.back();
}

Status TapeProgram::evaluate(double t, const double* q, const double* qd, const std::uint8_t* active,
                             unsigned need, Terms& out, Workspace& wsb) const {
    auto& w = static_cast<TapeWorkspace&>(wsb);
    double* r = w.reg.data();
    const int n = n_;
    r[0] = t;
    std::copy(q, q + n, r + 1);
    std::copy(qd, qd + n, r + 1 + n);
    {
        double acc = t;
        for (int i = 0; i < n; ++i) acc += q[i] * q[i] + qd[i] * qd[i];
        if (!std::isfinite(acc)) {
            if (!std::isfinite(t)) return Status::not_finite;
            for (int i = 0; i < n; ++i)
                if (!std::isfinite(q[i]) || !std::isfinite(qd[i])) return Status::not_finite;
        }
    }
    // the instructions these flags need, run by run (each run one op: one dispatch per run);
    // the same ops on the same operands in the same order as the tape, so bitwise the same
    const TapePlan& P = plan(w, need & NEED_ALL);
    const int* dst = P.dst.data();
    const int* ia = P.a.data();
    const int* ib = P.b.data();
    const double* cc = P.c.data();
    const std::size_t n_runs = P.run_op.size();
    int k = 0;
    for (std::size_t run = 0; run < n_runs; ++run) {
        const int e = P.run_end[run];
#if defined(__GLIBC__)
        if (P.run_op[run] == TAPE_SINCOS) {  // (a plan's op, not a TapeOp: no switch case)
            for (; k < e; ++k) ::sincos(r[ia[k]], &r[dst[k]], &r[ib[k]]);
            continue;
        }
#endif
#define NONMIN_TAPE_RUN(expr)                  \
    for (; k < e; ++k) {                       \
        const double x = r[ia[k]];             \
        r[dst[k]] = (expr);                    \
    }                                          \
    break
        switch (static_cast<TapeOp>(P.run_op[run])) {
            case TapeOp::add: NONMIN_TAPE_RUN(x + r[ib[k]]);
            case TapeOp::sub: NONMIN_TAPE_RUN(x - r[ib[k]]);
            case TapeOp::mul: NONMIN_TAPE_RUN(x * r[ib[k]]);
            case TapeOp::div: NONMIN_TAPE_RUN(x / r[ib[k]]);
            case TapeOp::neg: NONMIN_TAPE_RUN(-x);
            case TapeOp::powi: NONMIN_TAPE_RUN(powi(x, static_cast<long>(cc[k])));
            case TapeOp::pow: NONMIN_TAPE_RUN(std::pow(x, r[ib[k]]));
            case TapeOp::sqrt: NONMIN_TAPE_RUN(std::sqrt(x));
            case TapeOp::sin: NONMIN_TAPE_RUN(std::sin(x));
            case TapeOp::cos: NONMIN_TAPE_RUN(std::cos(x));
            case TapeOp::tan: NONMIN_TAPE_RUN(std::tan(x));
            case TapeOp::exp: NONMIN_TAPE_RUN(std::exp(x));
            case TapeOp::log: NONMIN_TAPE_RUN(std::log(x));
            case TapeOp::asin: NONMIN_TAPE_RUN(std::asin(x));
            case TapeOp::acos: NONMIN_TAPE_RUN(std::acos(x));
            case TapeOp::atan: NONMIN_TAPE_RUN(std::atan(x));
            case TapeOp::atan2: NONMIN_TAPE_RUN(std::atan2(x, r[ib[k]]));
            case TapeOp::sinh: NONMIN_TAPE_RUN(std::sinh(x));
            case TapeOp::cosh: NONMIN_TAPE_RUN(std::cosh(x));
            case TapeOp::tanh: NONMIN_TAPE_RUN(std::tanh(x));
            case TapeOp::abs: NONMIN_TAPE_RUN(std::fabs(x));
            case TapeOp::sign: NONMIN_TAPE_RUN(x > 0.0 ? 1.0 : (x < 0.0 ? -1.0 : 0.0));
            case TapeOp::min: NONMIN_TAPE_RUN(std::fmin(x, r[ib[k]]));
            case TapeOp::max: NONMIN_TAPE_RUN(std::fmax(x, r[ib[k]]));
            case TapeOp::square: NONMIN_TAPE_RUN(x * x);
            default:  // (constant: not in a plan)
                for (; k < e; ++k) r[dst[k]] = 0.0;
                break;
        }
#undef NONMIN_TAPE_RUN
    }
    // outputs: zero what is asked, then scatter the table (target by target, each in table order)
    if (need & NEED_M) out.M.setZero();
    if (need & NEED_H) {
        out.h.setZero();
        out.f_passive.setZero();
    }
    if (need & NEED_B) out.B.setZero();
    const std::size_t nc = constraints_.size();
    for (std::size_t ci = 0; ci < nc; ++ci) {
        if (!active[ci]) continue;
        const ConstraintInfo& c = constraints_[ci];
        if (need & NEED_A) out.A.middleRows(c.row, c.dim).setZero();
        if (need & NEED_GAMMA) out.gamma.segment(c.row, c.dim).setZero();
        if (need & NEED_PHI) out.phi.segment(c.row, c.dim).setZero();
        if (need & NEED_VELOCITY) out.velocity.segment(c.row, c.dim).setZero();
    }
    double T = 0.0, V = 0.0;
    bool finite = true;
    const int* oi = P.out_idx.data();
    const int* orr = P.out_reg.data();
    const int* oc = P.out_con.data();
    const int* os = P.out_start.data();
    auto scatter = [&](TapeTarget tg, double* dest) {
        for (int e = os[static_cast<int>(tg)]; e < os[static_cast<int>(tg) + 1]; ++e) {
            const int ci = oc[e];
            if (ci >= 0 && !active[ci]) continue;
            const double v = r[orr[e]];
            if (!std::isfinite(v)) finite = false;
            dest[oi[e]] = v;
        }
    };
    {  // M (and the kinetic energy from it, in table order)
        const bool wm = (need & NEED_M) != 0, we = (need & NEED_ENERGY) != 0;
        double* Md = out.M.data();
        for (int e = os[0]; e < os[1]; ++e) {
            const double v = r[orr[e]];
            if (!std::isfinite(v)) finite = false;
            const int idx = oi[e];
            if (wm) Md[idx] = v;
            if (we) T += v * qd[idx / n] * qd[idx % n];
        }
    }
    scatter(TapeTarget::h, out.h.data());
    scatter(TapeTarget::f_passive, out.f_passive.data());
    scatter(TapeTarget::B, out.B.data());
    scatter(TapeTarget::A, out.A.data());
    scatter(TapeTarget::gamma, out.gamma.data());
    scatter(TapeTarget::phi, out.phi.data());
    scatter(TapeTarget::velocity, out.velocity.data());
    for (int e = os[static_cast<int>(TapeTarget::V)]; e < os[static_cast<int>(TapeTarget::V) + 1]; ++e) {
        const double v = r[orr[e]];
        if (!std::isfinite(v)) finite = false;
        V = v;
    }
    if (need & NEED_ENERGY) {
        out.kinetic = 0.5 * T;
        out.potential = V;
    }
    return finite ? Status::ok : Status::not_finite;
}

Status TapeProgram::evaluate_tangent(double t, const double* q, const double* qd, const double* dq,
                                     const double* dqd, const std::uint8_t* active, unsigned need, Terms& out,
                                     Terms& tangent, Workspace& wsb) const {
    const Status st = evaluate(t, q, qd, active, need, out, wsb);
    if (st != Status::ok) return st;
    auto& w = static_cast<TapeWorkspace&>(wsb);
    const double* r = w.reg.data();
    w.dreg.assign(w.reg.size(), 0.0);
    double* dr = w.dreg.data();
    const int n = n_;
    std::copy(dq, dq + n, dr + 1);
    std::copy(dqd, dqd + n, dr + 1 + n);
    const int base = n_inputs();
    const std::size_t N = d_.op.size();
    const std::uint8_t* nd = need_.data();
    for (std::size_t i = 0; i < N; ++i) {
        if (!(nd[i] & need)) continue;
        const int ja = d_.a[i], jb = d_.b[i];
        const double x = r[ja], dx = dr[ja];
        const double y = r[base + static_cast<int>(i)];
        double dy = 0.0;
        switch (static_cast<TapeOp>(d_.op[i])) {
            case TapeOp::constant: continue;
            case TapeOp::add: dy = dx + dr[jb]; break;
            case TapeOp::sub: dy = dx - dr[jb]; break;
            case TapeOp::mul: dy = dx * r[jb] + x * dr[jb]; break;
            case TapeOp::div: dy = (dx - y * dr[jb]) / r[jb]; break;
            case TapeOp::neg: dy = -dx; break;
            case TapeOp::powi: {
                const long k = static_cast<long>(d_.c[i]);
                dy = k == 0 ? 0.0 : static_cast<double>(k) * powi(x, k - 1) * dx;
                break;
            }
            case TapeOp::pow: {
                const double b = r[jb], db = dr[jb];
                dy = (dx != 0.0 ? b * std::pow(x, b - 1.0) * dx : 0.0) + (db != 0.0 ? y * std::log(x) * db : 0.0);
                break;
            }
            case TapeOp::sqrt: dy = y > 0.0 ? 0.5 * dx / y : 0.0; break;
            case TapeOp::sin: dy = std::cos(x) * dx; break;
            case TapeOp::cos: dy = -std::sin(x) * dx; break;
            case TapeOp::tan: dy = (1.0 + y * y) * dx; break;
            case TapeOp::exp: dy = y * dx; break;
            case TapeOp::log: dy = dx / x; break;
            case TapeOp::asin: dy = dx / std::sqrt(1.0 - x * x); break;
            case TapeOp::acos: dy = -dx / std::sqrt(1.0 - x * x); break;
            case TapeOp::atan: dy = dx / (1.0 + x * x); break;
            case TapeOp::atan2: {
                const double b = r[jb], r2 = x * x + b * b;
                dy = r2 > 0.0 ? (b * dx - x * dr[jb]) / r2 : 0.0;
                break;
            }
            case TapeOp::sinh: dy = std::cosh(x) * dx; break;
            case TapeOp::cosh: dy = std::sinh(x) * dx; break;
            case TapeOp::tanh: dy = (1.0 - y * y) * dx; break;
            case TapeOp::abs: dy = x > 0.0 ? dx : (x < 0.0 ? -dx : 0.0); break;
            case TapeOp::sign: dy = 0.0; break;
            case TapeOp::min: dy = x <= r[jb] ? dx : dr[jb]; break;
            case TapeOp::max: dy = x >= r[jb] ? dx : dr[jb]; break;
            case TapeOp::square: dy = 2.0 * x * dx; break;
            default: dy = 0.0; break;
        }
        dr[base + static_cast<int>(i)] = dy;
    }
    if (need & NEED_M) tangent.M.setZero();
    if (need & NEED_H) {
        tangent.h.setZero();
        tangent.f_passive.setZero();
    }
    if (need & NEED_B) tangent.B.setZero();
    for (std::size_t ci = 0; ci < constraints_.size(); ++ci) {
        if (!active[ci]) continue;
        const ConstraintInfo& c = constraints_[ci];
        if (need & NEED_A) tangent.A.middleRows(c.row, c.dim).setZero();
        if (need & NEED_GAMMA) tangent.gamma.segment(c.row, c.dim).setZero();
        if (need & NEED_PHI) tangent.phi.segment(c.row, c.dim).setZero();
        if (need & NEED_VELOCITY) tangent.velocity.segment(c.row, c.dim).setZero();
    }
    double dT = 0.0, dV = 0.0;
    for (std::size_t e = 0; e < d_.out_target.size(); ++e) {
        const auto tg = static_cast<TapeTarget>(d_.out_target[e]);
        if (!(target_need(tg) & need)) continue;
        const int ci = out_row_constraint_[e];
        if (ci >= 0 && !active[ci]) continue;
        const double v = r[d_.out_reg[e]], dv = dr[d_.out_reg[e]];
        const int idx = d_.out_index[e];
        switch (tg) {
            case TapeTarget::M:
                if (need & NEED_M) tangent.M.data()[idx] = dv;
                if (need & NEED_ENERGY) {
                    const int a = idx / n, b = idx % n;
                    dT += dv * qd[a] * qd[b] + v * (dqd[a] * qd[b] + qd[a] * dqd[b]);
                }
                break;
            case TapeTarget::h: tangent.h[idx] = dv; break;
            case TapeTarget::f_passive: tangent.f_passive[idx] = dv; break;
            case TapeTarget::B: tangent.B.data()[idx] = dv; break;
            case TapeTarget::A: tangent.A.data()[idx] = dv; break;
            case TapeTarget::gamma: tangent.gamma[idx] = dv; break;
            case TapeTarget::phi: tangent.phi[idx] = dv; break;
            case TapeTarget::velocity: tangent.velocity[idx] = dv; break;
            case TapeTarget::V: dV = dv; break;
        }
    }
    if (need & NEED_ENERGY) {
        tangent.kinetic = 0.5 * dT;
        tangent.potential = dV;
    }
    return Status::ok;
}

}  // namespace nonmin
