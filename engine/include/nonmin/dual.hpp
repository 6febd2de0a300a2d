// Forward-mode differentiation: a dual number x + ε ẋ (ε² = 0) as the scalar of the model
// programs' templated evaluation. Evaluating a Program on duals seeded with (q, dq) and
// (qd, dqd) gives every model term and its exact directional derivative along (dq, dqd) in
// one pass — no step size, no cancellation (docs/theory.md, "Derivatives").
//
// Comparisons and the branches they drive look at the value only: the derivative is that of
// the branch taken at the point (piecewise-smooth terms such as a spring of zero length are
// differentiated on the side the value selects).
#pragma once
#include <Eigen/Core>

#include <cmath>

namespace nonmin {

struct Dual {
    double v = 0.0;  // value
    double d = 0.0;  // directional derivative

    Dual() = default;
    constexpr Dual(double value) : v(value), d(0.0) {}  // NOLINT: constants promote implicitly
    constexpr Dual(double value, double deriv) : v(value), d(deriv) {}

    Dual& operator+=(const Dual& o) {
        v += o.v;
        d += o.d;
        return *this;
    }
    Dual& operator-=(const Dual& o) {
        v -= o.v;
        d -= o.d;
        return *this;
    }
    Dual& operator*=(const Dual& o) {
        d = d * o.v + v * o.d;
        v *= o.v;
        return *this;
    }
    Dual& operator/=(const Dual& o) {
        const double inv = 1.0 / o.v;
        v *= inv;
        d = (d - v * o.d) * inv;
        return *this;
    }
};

inline Dual operator-(const Dual& a) { return {-a.v, -a.d}; }
inline Dual operator+(const Dual& a) { return a; }
inline Dual operator+(Dual a, const Dual& b) { return a += b; }
inline Dual operator-(Dual a, const Dual& b) { return a -= b; }
inline Dual operator*(Dual a, const Dual& b) { return a *= b; }
inline Dual operator/(Dual a, const Dual& b) { return a /= b; }
inline Dual operator+(Dual a, double b) { return {a.v + b, a.d}; }
inline Dual operator+(double b, Dual a) { return {a.v + b, a.d}; }
inline Dual operator-(Dual a, double b) { return {a.v - b, a.d}; }
inline Dual operator-(double b, Dual a) { return {b - a.v, -a.d}; }
inline Dual operator*(Dual a, double b) { return {a.v * b, a.d * b}; }
inline Dual operator*(double b, Dual a) { return {a.v * b, a.d * b}; }
inline Dual operator/(Dual a, double b) { return {a.v / b, a.d / b}; }
inline Dual operator/(double b, const Dual& a) { return Dual(b) / a; }

inline bool operator<(const Dual& a, const Dual& b) { return a.v < b.v; }
inline bool operator>(const Dual& a, const Dual& b) { return a.v > b.v; }
inline bool operator<=(const Dual& a, const Dual& b) { return a.v <= b.v; }
inline bool operator>=(const Dual& a, const Dual& b) { return a.v >= b.v; }
inline bool operator==(const Dual& a, const Dual& b) { return a.v == b.v; }
inline bool operator!=(const Dual& a, const Dual& b) { return a.v != b.v; }

inline Dual sin(const Dual& a) { return {std::sin(a.v), std::cos(a.v) * a.d}; }
inline Dual cos(const Dual& a) { return {std::cos(a.v), -std::sin(a.v) * a.d}; }
inline Dual sqrt(const Dual& a) {
    const double s = std::sqrt(a.v);
    return {s, s > 0.0 ? 0.5 * a.d / s : 0.0};
}
inline Dual hypot(const Dual& a, const Dual& b) {
    const double r = std::hypot(a.v, b.v);
    return {r, r > 0.0 ? (a.v * a.d + b.v * b.d) / r : 0.0};
}
inline Dual atan2(const Dual& y, const Dual& x) {
    const double r2 = x.v * x.v + y.v * y.v;
    return {std::atan2(y.v, x.v), r2 > 0.0 ? (x.v * y.d - y.v * x.d) / r2 : 0.0};
}
inline Dual abs(const Dual& a) { return a.v < 0.0 ? -a : a; }
inline Dual pow(const Dual& a, double p) {
    const double vp = std::pow(a.v, p);
    return {vp, p == 0.0 ? 0.0 : p * std::pow(a.v, p - 1.0) * a.d};
}
inline bool isfinite(const Dual& a) { return std::isfinite(a.v) && std::isfinite(a.d); }
inline double value(const Dual& a) { return a.v; }
inline double value(double a) { return a; }
inline double tangent(const Dual& a) { return a.d; }
inline double tangent(double) { return 0.0; }


// A dual number with W tangent directions at once, x + Σ_k ε_k ẋ_k (ε_i ε_j = 0): one evaluation
// seeded with W directions gives the value once and the W directional derivatives (the value is
// not recomputed per direction, and the tangent loops vectorize). Operators are hidden friends,
// so doubles convert on either side.
#if defined(__GNUC__) || defined(__clang__)
#define NONMIN_DUAL_INLINE __attribute__((always_inline)) inline
#else
#define NONMIN_DUAL_INLINE inline
#endif

// On a function: inline every call it makes (Eigen's per-scalar functors and the dual numbers'
// operators included). On DualN scalars GCC otherwise leaves the functors out of line, which
// costs 1.7× the instructions of an RNEA pass (measured with callgrind on a 6-joint chain).
#if defined(__GNUC__) && !defined(__clang__)
#define NONMIN_FLATTEN __attribute__((flatten))
#else
#define NONMIN_FLATTEN
#endif

template <int W>
struct DualN {
    double v = 0.0;
    double d[W];

    NONMIN_DUAL_INLINE DualN() : v(0.0) {
        for (int i = 0; i < W; ++i) d[i] = 0.0;
    }
    NONMIN_DUAL_INLINE DualN(double value) : v(value) {  // NOLINT: constants promote implicitly
        for (int i = 0; i < W; ++i) d[i] = 0.0;
    }

    NONMIN_DUAL_INLINE DualN& operator+=(const DualN& o) {
        v += o.v;
        for (int i = 0; i < W; ++i) d[i] += o.d[i];
        return *this;
    }
    NONMIN_DUAL_INLINE DualN& operator-=(const DualN& o) {
        v -= o.v;
        for (int i = 0; i < W; ++i) d[i] -= o.d[i];
        return *this;
    }
    NONMIN_DUAL_INLINE DualN& operator*=(const DualN& o) {
        for (int i = 0; i < W; ++i) d[i] = d[i] * o.v + v * o.d[i];
        v *= o.v;
        return *this;
    }
    NONMIN_DUAL_INLINE DualN& operator/=(const DualN& o) {
        const double inv = 1.0 / o.v;
        v *= inv;
        for (int i = 0; i < W; ++i) d[i] = (d[i] - v * o.d[i]) * inv;
        return *this;
    }
    NONMIN_DUAL_INLINE DualN& operator+=(double b) {
        v += b;
        return *this;
    }
    NONMIN_DUAL_INLINE DualN& operator-=(double b) {
        v -= b;
        return *this;
    }
    NONMIN_DUAL_INLINE DualN& operator*=(double b) {
        v *= b;
        for (int i = 0; i < W; ++i) d[i] *= b;
        return *this;
    }
    NONMIN_DUAL_INLINE DualN& operator/=(double b) {
        return *this *= (1.0 / b);
    }
    // f(v) with derivative f'(v): the chain rule on every direction
    NONMIN_DUAL_INLINE DualN chain(double fv, double dfv) const {
        DualN r(fv);
        for (int i = 0; i < W; ++i) r.d[i] = dfv * d[i];
        return r;
    }

    NONMIN_DUAL_INLINE friend DualN operator-(const DualN& a) {
        DualN r;
        r.v = -a.v;
        for (int i = 0; i < W; ++i) r.d[i] = -a.d[i];
        return r;
    }
    NONMIN_DUAL_INLINE friend DualN operator+(const DualN& a) { return a; }
    NONMIN_DUAL_INLINE friend DualN operator+(DualN a, const DualN& b) { return a += b; }
    NONMIN_DUAL_INLINE friend DualN operator-(DualN a, const DualN& b) { return a -= b; }
    NONMIN_DUAL_INLINE friend DualN operator*(DualN a, const DualN& b) { return a *= b; }
    NONMIN_DUAL_INLINE friend DualN operator/(DualN a, const DualN& b) { return a /= b; }
    NONMIN_DUAL_INLINE friend DualN operator+(DualN a, double b) { return a += b; }
    NONMIN_DUAL_INLINE friend DualN operator+(double b, DualN a) { return a += b; }
    NONMIN_DUAL_INLINE friend DualN operator-(DualN a, double b) { return a -= b; }
    NONMIN_DUAL_INLINE friend DualN operator-(double b, const DualN& a) {
        DualN r = -a;
        r.v += b;
        return r;
    }
    NONMIN_DUAL_INLINE friend DualN operator*(DualN a, double b) { return a *= b; }
    NONMIN_DUAL_INLINE friend DualN operator*(double b, DualN a) { return a *= b; }
    NONMIN_DUAL_INLINE friend DualN operator/(DualN a, double b) { return a *= (1.0 / b); }
    NONMIN_DUAL_INLINE friend DualN operator/(double b, const DualN& a) {
        const double inv = 1.0 / a.v;
        return a.chain(b * inv, -b * inv * inv);
    }

    NONMIN_DUAL_INLINE friend bool operator<(const DualN& a, const DualN& b) { return a.v < b.v; }
    NONMIN_DUAL_INLINE friend bool operator>(const DualN& a, const DualN& b) { return a.v > b.v; }
    NONMIN_DUAL_INLINE friend bool operator<=(const DualN& a, const DualN& b) { return a.v <= b.v; }
    NONMIN_DUAL_INLINE friend bool operator>=(const DualN& a, const DualN& b) { return a.v >= b.v; }
    NONMIN_DUAL_INLINE friend bool operator==(const DualN& a, const DualN& b) { return a.v == b.v; }
    NONMIN_DUAL_INLINE friend bool operator!=(const DualN& a, const DualN& b) { return a.v != b.v; }

    NONMIN_DUAL_INLINE friend DualN sin(const DualN& a) { return a.chain(std::sin(a.v), std::cos(a.v)); }
    NONMIN_DUAL_INLINE friend DualN cos(const DualN& a) { return a.chain(std::cos(a.v), -std::sin(a.v)); }
    NONMIN_DUAL_INLINE friend DualN sqrt(const DualN& a) {
        const double s = std::sqrt(a.v);
        return a.chain(s, s > 0.0 ? 0.5 / s : 0.0);
    }
    NONMIN_DUAL_INLINE friend DualN log(const DualN& a) { return a.chain(std::log(a.v), 1.0 / a.v); }
    NONMIN_DUAL_INLINE friend DualN exp(const DualN& a) {
        const double e = std::exp(a.v);
        return a.chain(e, e);
    }
    NONMIN_DUAL_INLINE friend DualN hypot(const DualN& a, const DualN& b) {
        const double r = std::hypot(a.v, b.v);
        DualN out(r);
        if (r > 0.0)
            for (int i = 0; i < W; ++i) out.d[i] = (a.v * a.d[i] + b.v * b.d[i]) / r;
        return out;
    }
    NONMIN_DUAL_INLINE friend DualN atan2(const DualN& y, const DualN& x) {
        const double r2 = x.v * x.v + y.v * y.v;
        DualN out(std::atan2(y.v, x.v));
        if (r2 > 0.0)
            for (int i = 0; i < W; ++i) out.d[i] = (x.v * y.d[i] - y.v * x.d[i]) / r2;
        return out;
    }
    NONMIN_DUAL_INLINE friend DualN abs(const DualN& a) { return a.v < 0.0 ? -a : a; }
    NONMIN_DUAL_INLINE friend DualN pow(const DualN& a, double p) {
        const double vp = std::pow(a.v, p);
        return a.chain(vp, p == 0.0 ? 0.0 : p * std::pow(a.v, p - 1.0));
    }
    NONMIN_DUAL_INLINE friend bool isfinite(const DualN& a) {
        bool ok = std::isfinite(a.v);
        for (int i = 0; i < W; ++i) ok = ok && std::isfinite(a.d[i]);
        return ok;
    }
    NONMIN_DUAL_INLINE friend double value(const DualN& a) { return a.v; }
};

// Direction widths of the multi-direction evaluations (Program::residual_tangents): the
// directions are taken DUAL_WIDTH at a time.
constexpr int DUAL_WIDTH = 4;
using DualW = DualN<DUAL_WIDTH>;

}  // namespace nonmin

namespace Eigen {
template <>
struct NumTraits<nonmin::Dual> : NumTraits<double> {
    using Real = nonmin::Dual;
    using NonInteger = nonmin::Dual;
    using Nested = nonmin::Dual;
    using Literal = nonmin::Dual;
    enum {
        IsComplex = 0,
        IsInteger = 0,
        IsSigned = 1,
        RequireInitialization = 1,
        ReadCost = 2,
        AddCost = 2,
        MulCost = 4,
    };
};
// Mixed expressions of dual and double matrices (model constants times state-dependent terms).
template <typename BinaryOp>
struct ScalarBinaryOpTraits<nonmin::Dual, double, BinaryOp> {
    using ReturnType = nonmin::Dual;
};
template <typename BinaryOp>
struct ScalarBinaryOpTraits<double, nonmin::Dual, BinaryOp> {
    using ReturnType = nonmin::Dual;
};
template <int W>
struct NumTraits<nonmin::DualN<W>> : NumTraits<double> {
    using Real = nonmin::DualN<W>;
    using NonInteger = nonmin::DualN<W>;
    using Nested = nonmin::DualN<W>;
    using Literal = nonmin::DualN<W>;
    enum {
        IsComplex = 0,
        IsInteger = 0,
        IsSigned = 1,
        RequireInitialization = 1,
        ReadCost = 1 + W,
        AddCost = 1 + W,
        MulCost = 1 + 2 * W,
    };
};
template <int W, typename BinaryOp>
struct ScalarBinaryOpTraits<nonmin::DualN<W>, double, BinaryOp> {
    using ReturnType = nonmin::DualN<W>;
};
template <int W, typename BinaryOp>
struct ScalarBinaryOpTraits<double, nonmin::DualN<W>, BinaryOp> {
    using ReturnType = nonmin::DualN<W>;
};
}  // namespace Eigen
