// Spatial algebra of the rigid-body algorithms (engine/include/nonmin/rbd): rigid placements,
// spatial motions and forces in (linear, angular) order, and spatial inertias, all with Eigen
// fixed-size types. Every spatial quantity of the tree algorithms is expressed in world axes at
// the world origin (Featherstone's "world frame" form), so propagating along the tree is a sum.
//
//   motion  ν = (v_O, ω): v_O the velocity of the body point at the world origin,
//   force   f = (f, n_O): n_O the moment about the world origin,
//   inertia I = (m, h = m c, I_O = I_c + m (|c|² 1 − c cᵀ)):  I ν = (m v_O − h × ω, h × v_O + I_O ω),
//   ν × μ  = (ω × μ_v + v_O × μ_ω, ω × μ_ω),   ν ×* f = (ω × f, ω × n_O + v_O × f).
//
// Every type and function is templated on the scalar S (double, or Dual for forward-mode
// derivatives: dual.hpp); the double names (SE3, Motion, ...) are the aliases used elsewhere.
#pragma once
#include <Eigen/Core>
#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>

#include "../dual.hpp"

namespace nonmin::rbd {

template <class S>
using Vec3T = Eigen::Matrix<S, 3, 1>;
template <class S>
using Mat3T = Eigen::Matrix<S, 3, 3>;
template <class S>
using Vec4T = Eigen::Matrix<S, 4, 1>;
template <class S>
using Mat34T = Eigen::Matrix<S, 3, 4>;
using Vec3 = Vec3T<double>;
using Mat3 = Mat3T<double>;
using Vec4 = Vec4T<double>;
using Mat34 = Mat34T<double>;

// The scalar of a product of an S and an O (double × Dual = Dual).
template <class S, class O>
using Promote = decltype(std::declval<S>() * std::declval<O>());

// x_parent = R x_child + p.
template <class S>
struct SE3T {
    Mat3T<S> R = Mat3T<S>::Identity();
    Vec3T<S> p = Vec3T<S>::Zero();

    template <class O>
    SE3T<Promote<S, O>> operator*(const SE3T<O>& o) const {
        return SE3T<Promote<S, O>>{R * o.R, R * o.p + p};
    }
    template <class O>
    Vec3T<Promote<S, O>> act(const Vec3T<O>& x) const {
        return R * x + p;
    }
};
using SE3 = SE3T<double>;

template <class S>
struct MotionT {
    Vec3T<S> lin = Vec3T<S>::Zero();
    Vec3T<S> ang = Vec3T<S>::Zero();

    MotionT& operator+=(const MotionT& o) {
        lin += o.lin;
        ang += o.ang;
        return *this;
    }
    void set_zero() {
        lin.setZero();
        ang.setZero();
    }
};
using Motion = MotionT<double>;

template <class S>
struct ForceT {
    Vec3T<S> lin = Vec3T<S>::Zero();
    Vec3T<S> ang = Vec3T<S>::Zero();

    ForceT& operator+=(const ForceT& o) {
        lin += o.lin;
        ang += o.ang;
        return *this;
    }
};
using Force = ForceT<double>;

// ν × μ (motion cross product).
template <class S>
inline MotionT<S> cross(const MotionT<S>& v, const MotionT<S>& m) {
    return MotionT<S>{v.ang.cross(m.lin) + v.lin.cross(m.ang), v.ang.cross(m.ang)};
}

// ν ×* f (force cross product).
template <class S>
inline ForceT<S> cross_force(const MotionT<S>& v, const ForceT<S>& f) {
    return ForceT<S>{v.ang.cross(f.lin), v.ang.cross(f.ang) + v.lin.cross(f.lin)};
}

template <class S>
struct InertiaT {
    S m = S(0.0);
    Vec3T<S> h = Vec3T<S>::Zero();
    Mat3T<S> I = Mat3T<S>::Zero();

    ForceT<S> operator*(const MotionT<S>& v) const {
        return ForceT<S>{m * v.lin - h.cross(v.ang), h.cross(v.lin) + I * v.ang};
    }
    InertiaT& operator+=(const InertiaT& o) {
        m += o.m;
        h += o.h;
        I += o.I;
        return *this;
    }
    // The body inertia (mass, centre of mass c, inertia about c; body axes) placed at X.
    static InertiaT from_body(double mass, const Vec3& com, const Mat3& Ic, const SE3T<S>& X) {
        InertiaT out;
        const Vec3T<S> c = X.act(com);
        out.m = S(mass);
        out.h = mass * c;
        out.I = X.R * Ic * X.R.transpose();
        out.I += mass * (c.squaredNorm() * Mat3T<S>::Identity() - c * c.transpose());
        return out;
    }
};
using Inertia = InertiaT<double>;

template <class S>
inline Mat3T<S> skew(const Vec3T<S>& w) {
    Mat3T<S> X;
    X << S(0.0), -w.z(), w.y(), w.z(), S(0.0), -w.x(), -w.y(), w.x(), S(0.0);
    return X;
}

// Rotation of angle θ about the unit axis a (Rodrigues).
template <class S>
inline Mat3T<S> axis_rotation(const Vec3& a, const S& theta) {
    using std::cos;
    using std::sin;
    const S c = cos(theta), s = sin(theta);
    Mat3T<S> R = (1.0 - c) * (a * a.transpose());
    for (int i = 0; i < 3; ++i) R(i, i) += c;
    R(0, 1) -= s * a.z();
    R(1, 0) += s * a.z();
    R(0, 2) += s * a.y();
    R(2, 0) -= s * a.y();
    R(1, 2) -= s * a.x();
    R(2, 1) += s * a.x();
    return R;
}

// Rotation about a coordinate axis (0: x, 1: y, 2: z) with exact zeros and ones.
template <class S>
inline Mat3T<S> coordinate_rotation(int axis, const S& theta) {
    using std::cos;
    using std::sin;
    const S c = cos(theta), s = sin(theta);
    Mat3T<S> R = Mat3T<S>::Identity();
    const int i = (axis + 1) % 3, j = (axis + 2) % 3;
    R(i, i) = c;
    R(j, j) = c;
    R(i, j) = -s;
    R(j, i) = s;
    return R;
}

// Rotation matrix of the quaternion ε = (x, y, z, w) divided by its norm (ε ≠ 0).
template <class S>
inline Mat3T<S> quaternion_rotation(const S* e) {
    using std::sqrt;
    const S n = sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2] + e[3] * e[3]);
    const S x = e[0] / n, y = e[1] / n, z = e[2] / n, w = e[3] / n;
    Mat3T<S> R;
    R << 1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w),  //
        2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w),    //
        2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y);
    return R;
}

// G(ε) = [w 1 − [e]×, −e] (3 × 4): the body angular velocity is ω = 2 G(ε) ε̇ / |ε|².
template <class S>
inline Mat34T<S> quaternion_G(const S* e) {
    Mat34T<S> G;
    G << e[3], e[2], -e[1], -e[0],  //
        -e[2], e[3], e[0], -e[1],   //
        e[1], -e[0], e[3], -e[2];
    return G;
}

// The rotation vector ω = log(R) (|ω| ≤ π): the axis-angle of R.
template <class S>
inline Vec3T<S> log3(const Mat3T<S>& R) {
    using std::atan2;
    using std::sqrt;
    const Vec3T<S> s(R(2, 1) - R(1, 2), R(0, 2) - R(2, 0), R(1, 0) - R(0, 1));  // 2 sin θ a
    const S c = 0.5 * (R.trace() - 1.0);
    const S sn = 0.5 * sqrt(s.squaredNorm());
    const S theta = atan2(sn, c);
    if (theta < 1e-4) {
        const S t2 = theta * theta;
        return (0.5 * (1.0 + t2 / 6.0 + 7.0 * t2 * t2 / 360.0)) * s;
    }
    if (theta < 3.1) return (0.5 * theta / sn) * s;
    // near π: the axis from the symmetric part (R + Rᵀ)/2 − cos θ 1 = (1 − cos θ) a aᵀ
    const Mat3T<S> B = 0.5 * (R + R.transpose()) - c * Mat3T<S>::Identity();
    int i = 0;
    for (int k = 1; k < 3; ++k)
        if (B(k, k) > B(i, i)) i = k;
    const S omc = 1.0 - c;
    Vec3T<S> a;
    a[i] = sqrt((B(i, i) > 0.0 ? B(i, i) : S(0.0)) / omc);
    for (int j = 0; j < 3; ++j)
        if (j != i) a[j] = B(i, j) / (omc * a[i]);
    a /= sqrt(a.squaredNorm());
    if (a.dot(s) < 0.0) a = -a;
    return theta * a;
}

}  // namespace nonmin::rbd
