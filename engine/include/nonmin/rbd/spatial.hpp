// Spatial algebra of the rigid-body algorithms (engine/include/nonmin/rbd): rigid placements,
// spatial motions and forces in (linear, angular) order, and spatial inertias, all with Eigen
// fixed-size types. Every spatial quantity of the tree algorithms is expressed in world axes at
// the world origin (Featherstone's "world frame" form), so propagating along the tree is a sum.
//
//   motion  ν = (v_O, ω): v_O the velocity of the body point at the world origin,
//   force   f = (f, n_O): n_O the moment about the world origin,
//   inertia I = (m, h = m c, I_O = I_c + m (|c|² 1 − c cᵀ)):  I ν = (m v_O − h × ω, h × v_O + I_O ω),
//   ν × μ  = (ω × μ_v + v_O × μ_ω, ω × μ_ω),   ν ×* f = (ω × f, ω × n_O + v_O × f).
#pragma once
#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cmath>

namespace nonmin::rbd {

using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;
using Vec4 = Eigen::Vector4d;
using Mat34 = Eigen::Matrix<double, 3, 4>;

// x_parent = R x_child + p.
struct SE3 {
    Mat3 R = Mat3::Identity();
    Vec3 p = Vec3::Zero();

    SE3 operator*(const SE3& o) const { return SE3{R * o.R, R * o.p + p}; }
    Vec3 act(const Vec3& x) const { return R * x + p; }
};

struct Motion {
    Vec3 lin = Vec3::Zero();
    Vec3 ang = Vec3::Zero();

    Motion& operator+=(const Motion& o) {
        lin += o.lin;
        ang += o.ang;
        return *this;
    }
    void set_zero() {
        lin.setZero();
        ang.setZero();
    }
};

struct Force {
    Vec3 lin = Vec3::Zero();
    Vec3 ang = Vec3::Zero();

    Force& operator+=(const Force& o) {
        lin += o.lin;
        ang += o.ang;
        return *this;
    }
};

// ν × μ (motion cross product).
inline Motion cross(const Motion& v, const Motion& m) {
    return Motion{v.ang.cross(m.lin) + v.lin.cross(m.ang), v.ang.cross(m.ang)};
}

// ν ×* f (force cross product).
inline Force cross_force(const Motion& v, const Force& f) {
    return Force{v.ang.cross(f.lin), v.ang.cross(f.ang) + v.lin.cross(f.lin)};
}

struct Inertia {
    double m = 0.0;
    Vec3 h = Vec3::Zero();
    Mat3 I = Mat3::Zero();

    Force operator*(const Motion& v) const {
        return Force{m * v.lin - h.cross(v.ang), h.cross(v.lin) + I * v.ang};
    }
    Inertia& operator+=(const Inertia& o) {
        m += o.m;
        h += o.h;
        I += o.I;
        return *this;
    }
    // The body inertia (mass, centre of mass c, inertia about c; body axes) placed at X.
    static Inertia from_body(double mass, const Vec3& com, const Mat3& Ic, const SE3& X) {
        Inertia out;
        const Vec3 c = X.act(com);
        out.m = mass;
        out.h = mass * c;
        out.I = X.R * Ic * X.R.transpose();
        out.I += mass * (c.squaredNorm() * Mat3::Identity() - c * c.transpose());
        return out;
    }
};

inline Mat3 skew(const Vec3& w) {
    Mat3 S;
    S << 0.0, -w.z(), w.y(), w.z(), 0.0, -w.x(), -w.y(), w.x(), 0.0;
    return S;
}

// Rotation of angle θ about the unit axis a (Rodrigues).
inline Mat3 axis_rotation(const Vec3& a, double theta) {
    const double c = std::cos(theta), s = std::sin(theta);
    Mat3 R = (1.0 - c) * (a * a.transpose());
    R.diagonal().array() += c;
    R(0, 1) -= s * a.z();
    R(1, 0) += s * a.z();
    R(0, 2) += s * a.y();
    R(2, 0) -= s * a.y();
    R(1, 2) -= s * a.x();
    R(2, 1) += s * a.x();
    return R;
}

// Rotation about a coordinate axis (0: x, 1: y, 2: z) with exact zeros and ones.
inline Mat3 coordinate_rotation(int axis, double theta) {
    const double c = std::cos(theta), s = std::sin(theta);
    Mat3 R = Mat3::Identity();
    const int i = (axis + 1) % 3, j = (axis + 2) % 3;
    R(i, i) = c;
    R(j, j) = c;
    R(i, j) = -s;
    R(j, i) = s;
    return R;
}

// Rotation matrix of the quaternion ε = (x, y, z, w) divided by its norm (ε ≠ 0).
inline Mat3 quaternion_rotation(const double* e) {
    const double n = std::sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2] + e[3] * e[3]);
    const double x = e[0] / n, y = e[1] / n, z = e[2] / n, w = e[3] / n;
    Mat3 R;
    R << 1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),  //
        2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),    //
        2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y);
    return R;
}

// G(ε) = [w 1 − [e]×, −e] (3 × 4): the body angular velocity is ω = 2 G(ε) ε̇ / |ε|².
inline Mat34 quaternion_G(const double* e) {
    Mat34 G;
    G << e[3], e[2], -e[1], -e[0],  //
        -e[2], e[3], e[0], -e[1],   //
        e[1], -e[0], e[3], -e[2];
    return G;
}

// The rotation vector ω = log(R) (|ω| ≤ π): the axis-angle of R.
inline Vec3 log3(const Mat3& R) {
    const Vec3 s(R(2, 1) - R(1, 2), R(0, 2) - R(2, 0), R(1, 0) - R(0, 1));  // 2 sin θ a
    const double c = 0.5 * (R.trace() - 1.0);
    const double sn = 0.5 * s.norm();
    const double theta = std::atan2(sn, c);
    if (theta < 1e-4) {
        const double t2 = theta * theta;
        return 0.5 * (1.0 + t2 / 6.0 + 7.0 * t2 * t2 / 360.0) * s;
    }
    if (theta < 3.1) return (0.5 * theta / sn) * s;
    // near π: the axis from the symmetric part (R + Rᵀ)/2 − cos θ 1 = (1 − cos θ) a aᵀ
    const Mat3 B = 0.5 * (R + R.transpose()) - c * Mat3::Identity();
    int i = 0;
    B.diagonal().maxCoeff(&i);
    const double omc = 1.0 - c;
    Vec3 a;
    a[i] = std::sqrt(std::max(B(i, i), 0.0) / omc);
    for (int j = 0; j < 3; ++j)
        if (j != i) a[j] = B(i, j) / (omc * a[i]);
    a.normalize();
    if (a.dot(s) < 0.0) a = -a;
    return theta * a;
}

}  // namespace nonmin::rbd
