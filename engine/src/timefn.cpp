// TimeFunction: evaluation of prescribed motions (see nonmin/timefn.hpp).
#include "nonmin/timefn.hpp"

#include <algorithm>
#include <cmath>

#include "nonmin/tape.hpp"
#include "nonmin/types.hpp"

namespace nonmin {

TimeFunction TimeFunction::constant_speed(double start, double speed) {
    TimeFunction f;
    f.kind = pieces;
    f.breaks = {0.0, 0.0};
    f.coefs = {start, speed};
    f.degree = 1;
    return f;
}

void TimeFunction::validate(const std::string& what) const {
    if (kind == pieces) {
        if (degree < 0 || degree > 15) throw EngineError(what + ": polynomial degree must be in [0, 15]");
        if (breaks.size() < 2) throw EngineError(what + ": a piecewise polynomial needs at least 2 breaks");
        const std::size_t s = breaks.size() - 1;
        if (coefs.size() != s * static_cast<std::size_t>(degree + 1))
            throw EngineError(what + ": expected " + std::to_string(s * (degree + 1)) + " coefficients, got " +
                              std::to_string(coefs.size()));
        for (double x : breaks)
            if (!std::isfinite(x)) throw EngineError(what + ": breaks must be finite");
        for (std::size_t i = 0; i + 1 < breaks.size(); ++i)
            if (!(breaks[i + 1] > breaks[i]) && !(s == 1 && breaks[i + 1] == breaks[i]))
                throw EngineError(what + ": breaks must be strictly increasing");
        for (double x : coefs)
            if (!std::isfinite(x)) throw EngineError(what + ": coefficients must be finite");
    } else if (kind == tape) {
        const int n = static_cast<int>(op.size());
        if (a.size() != op.size() || b.size() != op.size() || c.size() != op.size())
            throw EngineError(what + ": tape arrays differ in length");
        for (int i = 0; i < n; ++i) {
            if (op[i] < 0 || op[i] >= static_cast<int>(TapeOp::num_ops))
                throw EngineError(what + ": unknown tape op " + std::to_string(op[i]));
            if (a[i] < 0 || a[i] > i || b[i] < 0 || b[i] > i)
                throw EngineError(what + ": tape operand out of range at instruction " + std::to_string(i));
        }
        for (int r : out)
            if (r < -1 || r > n) throw EngineError(what + ": tape output register out of range");
    } else if (kind == callback) {
        if (!fn) throw EngineError(what + ": empty callback");
    } else {
        throw EngineError(what + ": unknown time function kind");
    }
}

namespace {

double run_op(int op, double x, double y, double c) {
    switch (static_cast<TapeOp>(op)) {
        case TapeOp::constant: return c;
        case TapeOp::add: return x + y;
        case TapeOp::sub: return x - y;
        case TapeOp::mul: return x * y;
        case TapeOp::div: return x / y;
        case TapeOp::neg: return -x;
        case TapeOp::powi: {
            const int k = static_cast<int>(c);
            double r = 1.0, base = k < 0 ? 1.0 / x : x;
            for (int e = k < 0 ? -k : k; e; e >>= 1, base *= base)
                if (e & 1) r *= base;
            return r;
        }
        case TapeOp::pow: return std::pow(x, y);
        case TapeOp::sqrt: return std::sqrt(x);
        case TapeOp::sin: return std::sin(x);
        case TapeOp::cos: return std::cos(x);
        case TapeOp::tan: return std::tan(x);
        case TapeOp::exp: return std::exp(x);
        case TapeOp::log: return std::log(x);
        case TapeOp::asin: return std::asin(x);
        case TapeOp::acos: return std::acos(x);
        case TapeOp::atan: return std::atan(x);
        case TapeOp::atan2: return std::atan2(x, y);
        case TapeOp::sinh: return std::sinh(x);
        case TapeOp::cosh: return std::cosh(x);
        case TapeOp::tanh: return std::tanh(x);
        case TapeOp::abs: return std::fabs(x);
        case TapeOp::sign: return x > 0.0 ? 1.0 : (x < 0.0 ? -1.0 : 0.0);
        case TapeOp::min: return std::min(x, y);
        case TapeOp::max: return std::max(x, y);
        case TapeOp::square: return x * x;
        default: return std::nan("");
    }
}

}  // namespace

int TimeFunction::eval(double t, double* f, double* scratch) const {
    if (kind == pieces) {
        const std::size_t s = breaks.size() - 1;
        std::size_t i = 0;
        double tau;
        if (hold && t <= breaks.front()) {
            t = breaks.front();
        } else if (hold && t >= breaks.back() && s > 0 && breaks.back() > breaks.front()) {
            t = breaks.back();
        }
        if (s > 1) {
            // the piece with breaks[i] ≤ t (first / last piece outside)
            const auto it = std::upper_bound(breaks.begin() + 1, breaks.end() - 1, t);
            i = static_cast<std::size_t>(it - (breaks.begin() + 1));
        }
        tau = t - breaks[i];
        const double* c0 = coefs.data() + i * static_cast<std::size_t>(degree + 1);
        double v = 0.0, d1 = 0.0, d2 = 0.0;
        for (int k = degree; k >= 0; --k) {  // Horner for f, f', f''
            d2 = d2 * tau + 2.0 * d1;
            d1 = d1 * tau + v;
            v = v * tau + c0[k];
        }
        f[0] = v;
        f[1] = d1;
        f[2] = d2;
        const bool outside = hold && s > 0 && breaks.back() > breaks.front() &&
                             (t <= breaks.front() || t >= breaks.back());
        if (outside) {
            f[1] = 0.0;
            f[2] = 0.0;
        }
    } else if (kind == tape) {
        scratch[0] = t;
        const int n = static_cast<int>(op.size());
        for (int i = 0; i < n; ++i) scratch[1 + i] = run_op(op[i], scratch[a[i]], scratch[b[i]], c[i]);
        for (int j = 0; j < 3; ++j) f[j] = out[j] < 0 ? 0.0 : scratch[out[j]];
    } else {
        if (!fn(t, f)) return EVAL_FAILED;
    }
    return (std::isfinite(f[0]) && std::isfinite(f[1]) && std::isfinite(f[2])) ? EVAL_OK : EVAL_NOT_FINITE;
}

}  // namespace nonmin
