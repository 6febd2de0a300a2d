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
}  // namespace Eigen
