// A prescribed function of time f(t) with its first two derivatives, as plain data (model
// layer): what a driver (rheonomic constraint) of any model source evaluates. Built once from
// nonmin.model.TimeFunction values (src/nonmin/model/_timefn.py):
//
//   polynomial pieces  f(t) = Σ_k c_ik (t − t_i)^k on [t_i, t_{i+1})  (constant speed, polynomials,
//                      cubic splines through knots or samples); outside the knots the end
//                      pieces are extrapolated, or the end values held (rates 0) when `hold`;
//   expression tape    straight-line code over [t] (the TapeOp codes of tape.hpp) whose output
//                      registers hold f, ḟ and f̈ (SymPy differentiates once, in Python);
//   callback           a Python callable t -> (f, ḟ, f̈) (the escape hatch; not thread safe).
//
// eval() writes f[0..2] and needs no allocation: a tape's registers live in caller scratch of
// scratch_size() doubles (the program's workspace).
#pragma once
#include <array>
#include <functional>
#include <string>
#include <vector>

namespace nonmin {

struct TimeFunction {
    enum Kind : int { pieces = 0, tape = 1, callback = 2 };
    int kind = pieces;
    // pieces
    std::vector<double> breaks;  // s + 1 strictly increasing (s = 1 with breaks {t0, t0} allowed: one piece everywhere)
    std::vector<double> coefs;   // s × (degree + 1), ascending powers of (t − breaks[i])
    int degree = 0;
    bool hold = false;
    // tape: register 0 is t, instruction i writes register 1 + i
    std::vector<int> op, a, b;
    std::vector<double> c;
    std::array<int, 3> out{{-1, -1, -1}};  // registers of f, ḟ, f̈ (−1: identically zero)
    // callback: returns false when it failed (the Python error is pending)
    std::function<bool(double, double*)> fn;

    // Throws EngineError naming `what` when the data is inconsistent.
    void validate(const std::string& what) const;
    int scratch_size() const { return kind == tape ? 1 + static_cast<int>(op.size()) : 0; }
    bool thread_safe() const { return kind != callback; }
    // f[0] = f(t), f[1] = ḟ(t), f[2] = f̈(t). Returns EVAL_OK, EVAL_FAILED (the callback failed;
    // its Python error is pending) or EVAL_NOT_FINITE.
    enum : int { EVAL_OK = 0, EVAL_FAILED = 1, EVAL_NOT_FINITE = 2 };
    int eval(double t, double* f, double* scratch) const;

    static TimeFunction constant_speed(double start, double speed);
};

}  // namespace nonmin
