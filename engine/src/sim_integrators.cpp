// The integrators of the engine's simulation loop (see nonmin/sim/loop.hpp and sim_detail.hpp):
// RK4, the implicit midpoint rule, Dormand–Prince 5(4) and 8(5,3) with their error control on
// projected solutions and continuous extensions, the quintic Hermite interpolant of fixed steps. Each
// function names the Python function it mirrors (nonmin/sim/_integrators.py).
#include "nonmin/sim/loop.hpp"
#include "nonmin/linalg.hpp"
#include "sim_detail.hpp"

#include <algorithm>
#include <cmath>

namespace nonmin::sim {

namespace detail {

namespace {

constexpr double inf = std::numeric_limits<double>::infinity();

// Dormand–Prince 5(4) (Hairer, Nørsett & Wanner, Solving ODEs I, Table II.5.2), as
// _integrators.py: _DP_C, _DP_A, _DP_B, _DP_E = _DP_B − _DP_BHAT, _DP_D (dense output).
constexpr double DP_C[7] = {0.0, 1.0 / 5, 3.0 / 10, 4.0 / 5, 8.0 / 9, 1.0, 1.0};
constexpr double DP_A[7][6] = {
    {0, 0, 0, 0, 0, 0},
    {1.0 / 5, 0, 0, 0, 0, 0},
    {3.0 / 40, 9.0 / 40, 0, 0, 0, 0},
    {44.0 / 45, -56.0 / 15, 32.0 / 9, 0, 0, 0},
    {19372.0 / 6561, -25360.0 / 2187, 64448.0 / 6561, -212.0 / 729, 0, 0},
    {9017.0 / 3168, -355.0 / 33, 46732.0 / 5247, 49.0 / 176, -5103.0 / 18656, 0},
    {35.0 / 384, 0.0, 500.0 / 1113, 125.0 / 192, -2187.0 / 6784, 11.0 / 84},
};
constexpr double DP_B[7] = {35.0 / 384, 0.0, 500.0 / 1113, 125.0 / 192, -2187.0 / 6784, 11.0 / 84, 0.0};
constexpr double DP_BHAT[7] = {5179.0 / 57600, 0.0,          7571.0 / 16695, 393.0 / 640,
                               -92097.0 / 339200, 187.0 / 2100, 1.0 / 40};
constexpr double DP_D[7] = {-12715105075.0 / 11282082432, 0.0, 87487479700.0 / 32700410799,
                            -10690763975.0 / 1880347072, 701980252875.0 / 199316789632,
                            -1453857185.0 / 822651844,  69997945.0 / 29380423};

}  // namespace

// _integrators._clip
double clip(double t, double h, double t_bound) {
    const double rem = t_bound - t;
    if (h >= rem || rem - h <= 1e-9 * h) return rem;
    return h;
}
namespace {

// RK4.advance: y(t + h) from (t, y) with k1 = f when given
Status rk4_advance(Loop& L, double t, const Vec& y, const Vec* f, double h, Vec& out) {
    const int n2 = 2 * L.n;
    Status s;
    if (f) {
        L.k1 = *f;
    } else if ((s = rhs(L, t, y.data(), L.k1.data())) != Status::ok) {
        return s;
    }
    const double P1 = f ? L.wk_f : L.wk_P;  // the stage powers (the work's quadrature)
    const double hh = 0.5 * h;
    // next to a singular passage the stage states are projected (RK4.step, stages=True): F's
    // derivatives across the manifold grow like 1/σ_min, and an unprojected stage costs the step
    // an error that outgrows its own there (passage_stages decides from k1 = (q̇, q̈))
    const bool sp = L.stage_proj && L.opt.stab == Stabilization::projection && passage_stages(L, t, h, L.k1.data());
    for (int i = 0; i < n2; ++i) L.ys[i] = y[i] + hh * L.k1[i];
    if (sp && (s = project(L, t + 0.5 * h, L.ys.data(), L.opt.projection)) != Status::ok) return s;
    if ((s = rhs(L, t + 0.5 * h, L.ys.data(), L.k2.data())) != Status::ok) return s;
    const double P2 = L.wk_P;
    for (int i = 0; i < n2; ++i) L.ys[i] = y[i] + hh * L.k2[i];
    if (sp && (s = project(L, t + 0.5 * h, L.ys.data(), L.opt.projection)) != Status::ok) return s;
    if ((s = rhs(L, t + 0.5 * h, L.ys.data(), L.k3.data())) != Status::ok) return s;
    const double P3 = L.wk_P;
    for (int i = 0; i < n2; ++i) L.ys[i] = y[i] + h * L.k3[i];
    if (sp && (s = project(L, t + h, L.ys.data(), L.opt.projection)) != Status::ok) return s;
    if ((s = rhs(L, t + h, L.ys.data(), L.k4.data())) != Status::ok) return s;
    const double h6 = h / 6.0;
    for (int i = 0; i < n2; ++i) out[i] = y[i] + h6 * (((L.k1[i] + 2.0 * L.k2[i]) + 2.0 * L.k3[i]) + L.k4[i]);
    L.wk_dW = h6 * (((P1 + 2.0 * P2) + 2.0 * P3) + L.wk_P);
    return Status::ok;
}

// ImplicitMidpoint._solve: fixed-point iteration; returns false when it does not converge
// (Python: None). Errors of the right-hand side inside the iteration count as divergence,
// those of the first two evaluations are returned (they are outside the try in Python).
Status midpoint_solve(Loop& L, double t, const Vec& y, const Vec* f, double h, Vec& out, bool& ok) {
    const int n2 = 2 * L.n;
    ok = false;
    Status s;
    if (f) {
        L.f0 = *f;
    } else if ((s = rhs(L, t, y.data(), L.f0.data())) != Status::ok) {
        return s;
    }
    const double tm = t + 0.5 * h;
    const double hh = 0.5 * h;
    for (int i = 0; i < n2; ++i) L.ys[i] = y[i] + hh * L.f0[i];
    if ((s = rhs(L, tm, L.ys.data(), L.k1.data())) != Status::ok) return s;  // explicit predictor
    double scale = 0.0;
    for (int i = 0; i < n2; ++i) scale = std::max(scale, std::abs(y[i]));
    scale += 1.0;
    double prev = inf;
    for (int it = 0; it < L.opt.max_iter; ++it) {
        for (int i = 0; i < n2; ++i) L.ys[i] = y[i] + hh * L.k1[i];
        s = rhs(L, tm, L.ys.data(), L.kn.data());
        if (s == Status::callback_error) return s;
        if (s != Status::ok) return Status::ok;  // left the model's domain: not converged
        double delta = 0.0;
        for (int i = 0; i < n2; ++i) delta = std::max(delta, std::abs(L.kn[i] - L.k1[i]));
        delta *= std::abs(h);
        if (!std::isfinite(delta) || (it >= 3 && delta > prev)) return Status::ok;  // diverging
        L.k1 = L.kn;
        if (delta <= L.opt.xtol * scale) {
            for (int i = 0; i < n2; ++i) out[i] = y[i] + h * L.k1[i];
            L.wk_dW = h * L.wk_P;  // (the power at the midpoint state of this last iterate)
            ok = true;
            return Status::ok;
        }
        prev = delta;
    }
    return Status::ok;
}

// ImplicitMidpoint._advance: halve the step recursively where the iteration fails
Status midpoint_advance(Loop& L, double t, const Vec& y, const Vec* f, double h, int depth, Vec& out) {
    bool ok = false;
    Status s = midpoint_solve(L, t, y, f, h, out, ok);
    if (s != Status::ok) return s;
    if (ok) return Status::ok;
    if (depth <= 0) {
        L.message = "implicit midpoint: fixed-point iteration did not converge";
        return Status::not_finite;
    }
    Vec& ym = L.half[static_cast<std::size_t>(depth)];
    if ((s = midpoint_advance(L, t, y, f, 0.5 * h, depth - 1, ym)) != Status::ok) return s;
    const double dW = L.wk_dW;
    if ((s = midpoint_advance(L, t + 0.5 * h, ym, nullptr, 0.5 * h, depth - 1, out)) != Status::ok) return s;
    L.wk_dW += dW;
    return Status::ok;
}

// DormandPrince5._stages into L.K (K[0] = f0 given)
Status dp_stages(Loop& L, double t, const Vec& y, double h) {
    const int n2 = 2 * L.n;
    for (int s = 1; s < 7; ++s) {
        for (int i = 0; i < n2; ++i) {
            double acc = 0.0;
            for (int j = 0; j < s; ++j) acc += DP_A[s][j] * L.K(j, i);
            L.ys[i] = y[i] + h * acc;
        }
        const Status st = rhs(L, t + DP_C[s] * h, L.ys.data(), L.tmp2n.data());
        if (st != Status::ok) return st;
        L.K.row(s) = L.tmp2n.transpose();
        L.wk_K[s] = L.wk_P;
    }
    return Status::ok;
}

double rms(const Vec& x, const Vec& scale, int n2) {
    double s = 0.0;
    for (int i = 0; i < n2; ++i) {
        const double r = x[i] / scale[i];
        s += r * r;
    }
    return std::sqrt(s / n2);
}

// DormandPrince5.initial_step (Hairer's heuristic)
Status dp_initial_step(Loop& L, double t0, const Vec& y0, const Vec& f0, double t_bound, int order, double& h_out) {
    const int n2 = 2 * L.n;
    for (int i = 0; i < n2; ++i) L.ev[i] = L.opt.atol + L.opt.rtol * std::abs(y0[i]);
    const double d0 = rms(y0, L.ev, n2);
    const double d1 = rms(f0, L.ev, n2);
    double h0 = (d0 < 1e-5 || d1 < 1e-5) ? 1e-6 : 0.01 * d0 / d1;
    h0 = std::min(h0, std::abs(t_bound - t0));
    for (int i = 0; i < n2; ++i) L.ys[i] = y0[i] + h0 * f0[i];
    const Status s = rhs(L, t0 + h0, L.ys.data(), L.tmp2n.data());
    if (s != Status::ok) return s;
    for (int i = 0; i < n2; ++i) L.kn[i] = L.tmp2n[i] - f0[i];
    const double d2 = rms(L.kn, L.ev, n2) / h0;
    const double dm = std::max(d1, d2);
    const double h1 = dm <= 1e-15 ? std::max(1e-6, h0 * 1e-3) : std::pow(0.01 / dm, 1.0 / order);
    h_out = std::min(std::min(100 * h0, h1), L.opt.h_max);
    return Status::ok;
}

// The continuous extension of the accepted DOPRI5 step (_dp_dense): y0 = L.y0, y1 raw = L.y1.
void dp_dense_setup(Loop& L, double h) {
    const int n2 = 2 * L.n;
    for (int i = 0; i < n2; ++i) {
        L.d_ydiff[i] = L.y1[i] - L.y0[i];
        L.d_bspl[i] = h * L.K(0, i) - L.d_ydiff[i];
        L.d_r3[i] = L.d_ydiff[i] - h * L.K(6, i) - L.d_bspl[i];
        double acc = 0.0;
        for (int j = 0; j < 7; ++j) acc += DP_D[j] * L.K(j, i);
        L.d_r4[i] = h * acc;
    }
}

}  // namespace

void dp_dense(const Loop& L, double t0, double h, double tt, double* out) {
    const int n2 = 2 * L.n;
    const double s = (tt - t0) / h;
    const double s1 = 1.0 - s;
    for (int i = 0; i < n2; ++i)
        out[i] = L.y0[i] + s * (L.d_ydiff[i] + s1 * (L.d_bspl[i] + s * (L.d_r3[i] + s1 * L.d_r4[i])));
}

// _integrators.SingularPassages.zone: adaptive steps near a predicted passage end outside the
// zone |t − t*| < d, d = PASSAGE_ZONE_SIGMA / |dσ/dt| (σ falls linearly into the instant): a
// step end inside it gets its velocity from a projection whose tangent turns by (position
// error)/σ, and an error control that shrinks the steps there walks them into it (measured,
// crossed four-bar, DOP853 rtol 1e-10: steps down to 2e-8 s, ends at σ ~ 2e-6, 1.9e-5 J kicks).
// A step that would end inside ends at its near edge, or, from there, crosses the zone to its
// far edge: `forced`, the error control then accepts it (it cannot be shrunk without ending
// inside). Returns the step to attempt. DOPRI5 caps the half-width at PASSAGE_ZONE_STEP times
// the step it entered with (d_cap): its forced step is then no longer than a step its error
// control accepted (uncapped, A02 N = 40 at rtol 1e-8 crossed 2d ≫ h and failed at t = 4.4 s).
constexpr double PASSAGE_ZONE_SIGMA = 1e-3;
constexpr double PASSAGE_ZONE_STEP = 0.5;

double passage_zone(const Loop& L, double t, double h, bool& forced, double d_cap = inf) {
    forced = false;
    const Passages& P = L.pas;
    if (!L.opt.passages || !P.have_star || P.count < 2) return h;
    const int c = P.count;
    const double slope = (P.ss[c - 2] - P.ss[c - 1]) / (P.ts[c - 1] - P.ts[c - 2]);
    if (!(slope > 0.0) || !std::isfinite(slope)) return h;
    const double g = P.t_star - t;
    const double d = std::min(PASSAGE_ZONE_SIGMA / slope, d_cap);
    if (!(g > 0.0)) return h;
    const double end = g - h;  // the step end's distance before t* (negative: after)
    if (end >= d || end <= -d) return h;  // ends outside the zone
    if (g - d >= 0.2 * h) return g - d;   // end at the near edge
    forced = true;
    return g + d;  // from the near edge (or inside): across to the far edge
}

// DormandPrince5.step with the error measured on projected solutions (the driver's project_y
// when the stabilization is the projection): the accepted projected end is kept in L.yq1.
// Returns the accepted step size in h_acc, the new time in t_new.
Status dp_step(Loop& L, double& h_acc, double& t_new) {
    const int n2 = 2 * L.n;
    const double t = L.t;
    const double t_bound = L.opt.t1;
    Status s;
    if (!L.have_f) {
        if ((s = rhs(L, t, L.y.data(), L.f.data())) != Status::ok) return s;
        L.have_f = true;
        L.wk_f = L.wk_P;
    }
    double h = L.h;
    if (!std::isfinite(h) || h <= 0) {
        if ((s = dp_initial_step(L, t, L.y, L.f, t_bound, 5, h)) != Status::ok) return s;
    }
    h = std::min(h, L.opt.h_max);
    long long rejected = 0;
    const double h_min = L.opt.h_min_factor * std::max(1.0, std::abs(t));
    const bool proj = L.opt.stab == Stabilization::projection;
    const double noise = passage_noise(L);
    bool forced = false;
    const double d_cap = PASSAGE_ZONE_STEP * h;
    while (true) {
        h = clip(t, passage_zone(L, t, passage_place(L, t, h), forced, d_cap), t_bound);
        if (h < h_min) {
            L.message = "dopri5: step size underflow";
            return Status::not_finite;
        }
        L.K.row(0) = L.f.transpose();
        L.wk_K[0] = L.wk_f;
        if ((s = dp_stages(L, t, L.y, h)) != Status::ok) return s;
        for (int i = 0; i < n2; ++i) {
            double b = 0.0, e = 0.0;
            for (int j = 0; j < 7; ++j) {
                b += DP_B[j] * L.K(j, i);
                e += (DP_B[j] - DP_BHAT[j]) * L.K(j, i);
            }
            L.y1[i] = L.y[i] + h * b;
            L.ev[i] = h * e;
        }
        L.yq1 = L.y1;
        if (proj) {  // err = project(t + h, y1) − project(t + h, y1 − err); y1 projected last,
                     // so F at the accepted end reuses its velocity factorization (dynamics_solve)
            for (int i = 0; i < n2; ++i) L.yp[i] = L.y1[i] - L.ev[i];
            if ((s = project(L, t + h, L.yp.data(), L.opt.projection)) != Status::ok) return s;
            if ((s = project(L, t + h, L.yq1.data(), L.opt.projection)) != Status::ok) return s;
            for (int i = 0; i < n2; ++i) L.ev[i] = L.yq1[i] - L.yp[i];
        }
        for (int i = 0; i < n2; ++i) {
            const double big = std::max(std::abs(L.y[i]), std::abs(L.y1[i]));
            L.tmp2n[i] = L.opt.atol + L.opt.rtol * big + noise * (1.0 + big);
        }
        const double err = rms(L.ev, L.tmp2n, n2);
        if (!std::isfinite(err)) {
            ++rejected;
            h *= 0.2;
            continue;
        }
        if (err <= 1.0 || forced) {
            double fac = err == 0.0 ? 5.0 : std::min(5.0, std::max(0.2, 0.9 * std::pow(err, -0.2)));
            if (rejected || forced) fac = std::min(fac, 1.0);
            t_new = (h == t_bound - t) ? t_bound : t + h;
            h_acc = h;
            L.y0 = L.y;
            dp_dense_setup(L, h);
            double dW = 0.0;
            for (int j = 0; j < 7; ++j) dW += DP_B[j] * L.wk_K[j];
            L.wk_dW = h * dW;
            L.h = std::min(h * fac, L.opt.h_max);
            L.n_rejected += rejected;
            return Status::ok;
        }
        ++rejected;
        h *= std::max(0.2, 0.9 * std::pow(err, -0.2));
    }
}

Status dp_advance(Loop& L, double t, const Vec& y, const Vec* f, double h, Vec& out) {
    Status st;
    if (f) {
        L.K.row(0) = f->transpose();
        L.wk_K[0] = L.wk_f;
    } else {
        if ((st = rhs(L, t, y.data(), L.tmp2n.data())) != Status::ok) return st;
        L.K.row(0) = L.tmp2n.transpose();
        L.wk_K[0] = L.wk_P;
    }
    if ((st = dp_stages(L, t, y, h)) != Status::ok) return st;
    for (int i = 0; i < 2 * L.n; ++i) {
        double b = 0.0;
        for (int j = 0; j < 7; ++j) b += DP_B[j] * L.K(j, i);
        out[i] = y[i] + h * b;
    }
    double dW = 0.0;
    for (int j = 0; j < 7; ++j) dW += DP_B[j] * L.wk_K[j];
    L.wk_dW = h * dW;
    return Status::ok;
}

// ------------------------------------------------------------------------------ DOP853

namespace {

// Dormand–Prince 8(5,3) with its 7th-order continuous extension (Hairer, Nørsett & Wanner,
// Solving ODEs I, II.10; the coefficients of Hairer's DOP853): 12 stages, y1 = y + h Σ b_j k_j
// (b = row 12 of A), error estimates of orders 5 and 3 (E5, E3; coefficient of F(t + h, y1) 0),
// three more stages (rows 13–15) for the continuous extension. As _dop853.py.
constexpr double D8_C[16] = {0.0, 0.05260015195876773, 0.0789002279381516, 0.1183503419072274, 0.2816496580927726, 0.3333333333333333, 0.25, 0.3076923076923077, 0.6512820512820513, 0.6, 0.8571428571428571, 1.0, 1.0, 0.1, 0.2, 0.7777777777777778};
// A: row s holds a_sj, j < s (rows 12–15: b and the extension's stages)
constexpr double D8_A[16][15] = {
    {0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0},
    {0.05260015195876773, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0},
    {0.0197250569845379, 0.0591751709536137, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0},
    {0.02958758547680685, 0.0, 0.08876275643042054, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0},
    {0.2413651341592667, 0.0, -0.8845494793282861, 0.924834003261792, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0},
    {0.037037037037037035, 0.0, 0.0, 0.17082860872947386, 0.12546768756682242, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0},
    {0.037109375, 0.0, 0.0, 0.17025221101954405, 0.06021653898045596, -0.017578125, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0},
    {0.03709200011850479, 0.0, 0.0, 0.17038392571223998, 0.10726203044637328, -0.015319437748624402, 0.008273789163814023, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0},
    {0.6241109587160757, 0.0, 0.0, -3.3608926294469414, -0.868219346841726, 27.59209969944671, 20.154067550477894, -43.48988418106996, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0},
    {0.47766253643826434, 0.0, 0.0, -2.4881146199716677, -0.590290826836843, 21.230051448181193, 15.279233632882423, -33.28821096898486, -0.020331201708508627, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0},
    {-0.9371424300859873, 0.0, 0.0, 5.186372428844064, 1.0914373489967295, -8.149787010746927, -18.52006565999696, 22.739487099350505, 2.4936055526796523, -3.0467644718982196, 0.0, 0.0, 0.0, 0.0, 0.0},
    {2.273310147516538, 0.0, 0.0, -10.53449546673725, -2.0008720582248625, -17.9589318631188, 27.94888452941996, -2.8589982771350235, -8.87285693353063, 12.360567175794303, 0.6433927460157636, 0.0, 0.0, 0.0, 0.0},
    {0.054293734116568765, 0.0, 0.0, 0.0, 0.0, 4.450312892752409, 1.8915178993145003, -5.801203960010585, 0.3111643669578199, -0.1521609496625161, 0.20136540080403034, 0.04471061572777259, 0.0, 0.0, 0.0},
    {0.056167502283047954, 0.0, 0.0, 0.0, 0.0, 0.0, 0.25350021021662483, -0.2462390374708025, -0.12419142326381637, 0.15329179827876568, 0.00820105229563469, 0.007567897660545699, -0.008298, 0.0, 0.0},
    {0.03183464816350214, 0.0, 0.0, 0.0, 0.0, 0.028300909672366776, 0.053541988307438566, -0.05492374857139099, 0.0, 0.0, -0.00010834732869724932, 0.0003825710908356584, -0.00034046500868740456, 0.1413124436746325, 0.0},
    {-0.42889630158379194, 0.0, 0.0, 0.0, 0.0, -4.697621415361164, 7.683421196062599, 4.06898981839711, 0.3567271874552811, 0.0, 0.0, 0.0, -0.0013990241651590145, 2.9475147891527724, -9.15095847217987},
};
constexpr double D8_B[12] = {0.054293734116568765, 0.0, 0.0, 0.0, 0.0, 4.450312892752409, 1.8915178993145003, -5.801203960010585, 0.3111643669578199, -0.1521609496625161, 0.20136540080403034, 0.04471061572777259};
constexpr double D8_E3[13] = {-0.18980075407240762, 0.0, 0.0, 0.0, 0.0, 4.450312892752409, 1.8915178993145003, -5.801203960010585, -0.4226823213237919, -0.1521609496625161, 0.20136540080403034, 0.02265179219836082, 0.0};
constexpr double D8_E5[13] = {0.01312004499419488, 0.0, 0.0, 0.0, 0.0, -1.2251564463762044, -0.4957589496572502, 1.6643771824549864, -0.35032884874997366, 0.3341791187130175, 0.08192320648511571, -0.022355307863886294, 0.0};
constexpr double D8_D[4][16] = {
    {-8.428938276109013, 0.0, 0.0, 0.0, 0.0, 0.5667149535193777, -3.0689499459498917, 2.38466765651207, 2.117034582445028, -0.871391583777973, 2.2404374302607883, 0.6315787787694688, -0.08899033645133331, 18.148505520854727, -9.194632392478356, -4.436036387594894},
    {10.427508642579134, 0.0, 0.0, 0.0, 0.0, 242.28349177525817, 165.20045171727028, -374.5467547226902, -22.113666853125306, 7.733432668472264, -30.674084731089398, -9.332130526430229, 15.697238121770845, -31.139403219565178, -9.35292435884448, 35.81684148639408},
    {19.985053242002433, 0.0, 0.0, 0.0, 0.0, -387.0373087493518, -189.17813819516758, 527.8081592054236, -11.57390253995963, 6.8812326946963, -1.0006050966910838, 0.7777137798053443, -2.778205752353508, -60.19669523126412, 84.32040550667716, 11.99229113618279},
    {-25.69393346270375, 0.0, 0.0, 0.0, 0.0, -154.18974869023643, -231.5293791760455, 357.6391179106141, 93.40532418362432, -37.45832313645163, 104.0996495089623, 29.8402934266605, -43.53345659001114, 96.32455395918828, -39.17726167561544, -149.72683625798564},
};

constexpr int D8_STAGES = 12;

// DOP853._stages: rows 1 … last−1 of L.K8 from row 0 (= F(t, y)) at (t, y), step h
Status d8_stages(Loop& L, double t, const Vec& y, double h, int first, int last) {
    const int n2 = 2 * L.n;
    for (int s = first; s < last; ++s) {
        for (int i = 0; i < n2; ++i) {
            double acc = 0.0;
            for (int j = 0; j < s; ++j) acc += D8_A[s][j] * L.K8(j, i);
            L.ys[i] = y[i] + h * acc;
        }
        const Status st = rhs(L, t + D8_C[s] * h, L.ys.data(), L.tmp2n.data());
        if (st != Status::ok) return st;
        L.K8.row(s) = L.tmp2n.transpose();
        L.wk_K[s] = L.wk_P;
    }
    return Status::ok;
}

// y + h Σ_{j<12} b_j k_j into out (and the work's increment h Σ b_j P_j)
void d8_combine(Loop& L, const Vec& y, double h, Vec& out) {
    const int n2 = 2 * L.n;
    double dW = 0.0;
    for (int j = 0; j < D8_STAGES; ++j) dW += D8_B[j] * L.wk_K[j];
    L.wk_dW = h * dW;
    for (int i = 0; i < n2; ++i) {
        double b = 0.0;
        for (int j = 0; j < D8_STAGES; ++j) b += D8_B[j] * L.K8(j, i);
        out[i] = y[i] + h * b;
    }
}

}  // namespace

// DOP853.step (error measured on projected solutions as dp_step): L.y1 the raw end, L.yq1 the
// projected one, L.K8 the stages; F(t + h, y1) (row 12) is evaluated only without the
// projection (the FSAL stage) or for the continuous extension (d8_dense_setup).
Status d8_step(Loop& L, double& h_acc, double& t_new) {
    const int n2 = 2 * L.n;
    const double t = L.t;
    const double t_bound = L.opt.t1;
    Status s;
    if (!L.have_f) {
        if ((s = rhs(L, t, L.y.data(), L.f.data())) != Status::ok) return s;
        L.have_f = true;
        L.wk_f = L.wk_P;
    }
    double h = L.h;
    if (!std::isfinite(h) || h <= 0) {
        if ((s = dp_initial_step(L, t, L.y, L.f, t_bound, 8, h)) != Status::ok) return s;
    }
    h = std::min(h, L.opt.h_max);
    long long rejected = 0;
    const double h_min = L.opt.h_min_factor * std::max(1.0, std::abs(t));
    const bool proj = L.opt.stab == Stabilization::projection;
    const double noise = passage_noise(L);
    L.d8_fsal = L.d8_dense = false;
    bool forced = false;
    while (true) {
        h = clip(t, passage_zone(L, t, passage_place(L, t, h), forced), t_bound);
        if (h < h_min) {
            L.message = "dop853: step size underflow";
            return Status::not_finite;
        }
        L.K8.row(0) = L.f.transpose();
        L.wk_K[0] = L.wk_f;
        if ((s = d8_stages(L, t, L.y, h, 1, D8_STAGES)) != Status::ok) return s;
        d8_combine(L, L.y, h, L.y1);
        for (int i = 0; i < n2; ++i) {
            double e5 = 0.0, e3 = 0.0;
            for (int j = 0; j < D8_STAGES; ++j) {
                e5 += D8_E5[j] * L.K8(j, i);
                e3 += D8_E3[j] * L.K8(j, i);
            }
            L.ev[i] = h * e5;
            L.e3[i] = h * e3;
        }
        L.yq1 = L.y1;
        if (proj) {  // each estimate: project(t + h, y1) − project(t + h, y1 − err), the
                     // estimates' points projected in place first and y1 last (its velocity
                     // factorization is then F's at the accepted end: dynamics_solve)
            for (Vec* e : {&L.ev, &L.e3}) {
                for (int i = 0; i < n2; ++i) (*e)[i] = L.y1[i] - (*e)[i];
                if ((s = project(L, t + h, e->data(), L.opt.projection)) != Status::ok) return s;
            }
            if ((s = project(L, t + h, L.yq1.data(), L.opt.projection)) != Status::ok) return s;
            for (Vec* e : {&L.ev, &L.e3})
                for (int i = 0; i < n2; ++i) (*e)[i] = L.yq1[i] - (*e)[i];
        }
        // Hairer's norm: ‖e5‖² / √(N (‖e5‖² + 0.01 ‖e3‖²)), scaled componentwise
        double s5 = 0.0, s3 = 0.0;
        for (int i = 0; i < n2; ++i) {
            const double big = std::max(std::abs(L.y[i]), std::abs(L.y1[i]));
            const double sc = L.opt.atol + L.opt.rtol * big + noise * (1.0 + big);
            const double a = L.ev[i] / sc, b = L.e3[i] / sc;
            s5 += a * a;
            s3 += b * b;
        }
        const double den = s5 + 0.01 * s3;
        const double err = den > 0.0 ? s5 / std::sqrt(den * n2) : 0.0;
        if (!std::isfinite(err)) {
            ++rejected;
            h *= 0.2;
            continue;
        }
        if (err <= 1.0 || forced) {
            double fac = err == 0.0 ? 6.0 : std::min(6.0, std::max(1.0 / 3.0, 0.9 * std::pow(err, -0.125)));
            if (rejected || forced) fac = std::min(fac, 1.0);
            t_new = (h == t_bound - t) ? t_bound : t + h;
            h_acc = h;
            L.y0 = L.y;
            L.d8_t0 = t;
            L.d8_h = h;
            L.h = std::min(h * fac, L.opt.h_max);
            L.n_rejected += rejected;
            if (!proj) {  // the FSAL stage: the next step's F(t, y)
                if ((s = rhs(L, t + h, L.y1.data(), L.tmp2n.data())) != Status::ok) return s;
                L.K8.row(12) = L.tmp2n.transpose();
                L.wk_K[12] = L.wk_P;
                L.d8_fsal = true;
            }
            return Status::ok;
        }
        ++rejected;
        h *= std::max(1.0 / 3.0, 0.9 * std::pow(err, -0.125));
    }
}

// The continuous extension of the accepted DOP853 step: F(t + h, y1) when not yet evaluated,
// the three extra stages, and the coefficients F8 (once per step).
Status d8_dense_setup(Loop& L) {
    if (L.d8_dense) return Status::ok;
    const int n2 = 2 * L.n;
    const double t0 = L.d8_t0, h = L.d8_h;
    Status s;
    if (!L.d8_fsal) {
        if ((s = rhs(L, t0 + h, L.y1.data(), L.tmp2n.data())) != Status::ok) return s;
        L.K8.row(12) = L.tmp2n.transpose();
        L.wk_K[12] = L.wk_P;
        L.d8_fsal = true;
    }
    if ((s = d8_stages(L, t0, L.y0, h, 13, 16)) != Status::ok) return s;
    for (int i = 0; i < n2; ++i) {
        const double dy = L.y1[i] - L.y0[i];
        L.F8(0, i) = dy;
        L.F8(1, i) = h * L.K8(0, i) - dy;
        L.F8(2, i) = 2.0 * dy - h * (L.K8(12, i) + L.K8(0, i));
        for (int r = 0; r < 4; ++r) {
            double acc = 0.0;
            for (int j = 0; j < 16; ++j) acc += D8_D[r][j] * L.K8(j, i);
            L.F8(3 + r, i) = h * acc;
        }
    }
    L.d8_dense = true;
    return Status::ok;
}

// y(t0 + x h) = y0 + x(F0 + (1−x)(F1 + x(F2 + (1−x)(F3 + x(F4 + (1−x)(F5 + x F6))))))
void d8_dense(const Loop& L, double tt, double* out) {
    const int n2 = 2 * L.n;
    const double x = (tt - L.d8_t0) / L.d8_h;
    const double x1 = 1.0 - x;
    for (int i = 0; i < n2; ++i) {
        double p = L.F8(6, i);
        p = L.F8(5, i) + x * p;
        p = L.F8(4, i) + x1 * p;
        p = L.F8(3, i) + x * p;
        p = L.F8(2, i) + x1 * p;
        p = L.F8(1, i) + x * p;
        p = L.F8(0, i) + x1 * p;
        out[i] = L.y0[i] + x * p;
    }
}

Status d8_advance(Loop& L, double t, const Vec& y, const Vec* f, double h, Vec& out) {
    Status st;
    if (f) {
        L.K8.row(0) = f->transpose();
        L.wk_K[0] = L.wk_f;
    } else {
        if ((st = rhs(L, t, y.data(), L.tmp2n.data())) != Status::ok) return st;
        L.K8.row(0) = L.tmp2n.transpose();
        L.wk_K[0] = L.wk_P;
    }
    if ((st = d8_stages(L, t, y, h, 1, D8_STAGES)) != Status::ok) return st;
    d8_combine(L, y, h, out);
    return Status::ok;
}

bool adaptive(const Loop& L) { return L.opt.method == Method::dopri5 || L.opt.method == Method::dop853; }

// A raw step of size h of the fixed-step method from (t, y) (f: F(t, y) when known)
Status fixed_advance(Loop& L, double t, const Vec& y, const Vec* f, double h, Vec& out) {
    if (L.opt.method == Method::rk4) return rk4_advance(L, t, y, f, h, out);
    if (L.opt.method == Method::rk8) return d8_advance(L, t, y, f, h, out);  // RK8.advance
    return midpoint_advance(L, t, y, f, h, L.opt.max_halvings, out);
}

}  // namespace detail

// ------------------------------------------------------------------------------ singular passages

namespace {

constexpr double inf = std::numeric_limits<double>::infinity();

// _integrators.PASSAGE_ROW_RTOL, PASSAGE_ITERATIONS, PASSAGE_FLOOR, PASSAGE_BAND
constexpr double PASSAGE_ROW_RTOL = 1e-10;
constexpr int PASSAGE_DENSE_ROWS = 32;
constexpr int PASSAGE_MAX_ITERATIONS = 30;
constexpr double PASSAGE_ITER_RTOL = 1e-6;
constexpr double PASSAGE_FLOOR = 1e-7;
constexpr double PASSAGE_BAND = 0.05;
constexpr double PASSAGE_NOISE = 100.0;
constexpr double PASSAGE_STAGE_AHEAD = 2.0;
constexpr double PASSAGE_STAGE_K = 30.0;
constexpr double PASSAGE_STAGE_WINDOW = 0.15;
constexpr double PASSAGE_SIGMA = 2e-4;
constexpr double PASSAGE_WIDEN_MAX = 2.0;
constexpr double PASSAGE_TREND = 1e-9;

// _integrators.passage_time over the history ts, ss (count ≥ 2)
bool passage_time(const Passages& P, double& out) {
    const int c = P.count;
    if (c < 2 || !(P.ss[c - 1] < (1.0 - PASSAGE_TREND) * P.ss[c - 2])) return false;
    const double t0 = P.ts[c - 2], t1 = P.ts[c - 1], s0 = P.ss[c - 2], s1 = P.ss[c - 1];
    const double lin = t1 + s1 * (t1 - t0) / (s0 - s1);
    out = lin;
    if (c < 3 || !(P.ss[c - 2] < (1.0 - PASSAGE_TREND) * P.ss[c - 3])) return true;
    const double ta = P.ts[c - 3], sa = P.ss[c - 3];
    const double d1 = (s0 - sa) / (t0 - ta);
    const double d2 = (s1 - s0) / (t1 - t0);
    const double c2 = (d2 - d1) / (t1 - ta);
    const double b = d2 + c2 * (t1 - t0);
    if (c2 == 0.0) return true;
    const double disc = b * b - 4.0 * c2 * s1;
    if (disc < 0.0) return true;
    const double r = std::sqrt(disc);
    const double r1 = (-b - r) / (2.0 * c2), r2 = (-b + r) / (2.0 * c2);
    double best = inf;
    if (r1 > 0.0) best = std::min(best, r1);
    if (r2 > 0.0) best = std::min(best, r2);
    if (best < inf) out = t1 + best;
    return true;
}


}  // namespace

// The smallest eigenvalue of the symmetric k × k matrix X (row-major, its lower triangle read,
// destroyed), k ≤ PASSAGE_DENSE_ROWS: Householder reduction to tridiagonal form (Golub & Van
// Loan, Alg. 8.3.1; diagonal into d, subdiagonal into e, k entries each), then Newton's method
// on det(T − x I) from x = 0 (below), and where it cannot proceed bisection on the Sturm counts
// of T − x I (the LDLᵀ pivots' signs, LAPACK dlaebz's guard pivmin) from T's Gershgorin interval
// until the bracket is at round-off (2 eps of its ends, or eps ‖T‖ near 0). Both stages are backward stable, so the value is within ~k eps ‖X‖ of the exact one, as a
// dense eigensolver's (Eigen's SelfAdjointEigenSolver, NumPy's eigvalsh in the Python driver),
// at a fraction of its cost: no eigenvectors, no QR sweeps over the whole spectrum.
double sym_min_eigenvalue(double* X, int k, double* d, double* e) {
    if (k == 1) return X[0];
    for (int i = 0; i < k; ++i)  // the upper triangle from the lower one
        for (int j = i + 1; j < k; ++j) X[i * k + j] = X[j * k + i];
    double* v = e + k;  // (scratch after e: the caller gives 3k entries from e on)
    double* w = v + k;
    for (int j = 0; j + 2 < k; ++j) {
        // the reflector of x = X(j+1:, j): H x = −sign(x₀) ‖x‖ e₀
        double nx = 0.0;
        for (int i = j + 1; i < k; ++i) nx += X[i * k + j] * X[i * k + j];
        nx = std::sqrt(nx);
        d[j] = X[j * k + j];
        const double x0 = X[(j + 1) * k + j];
        if (nx == 0.0) {
            e[j] = 0.0;
            continue;
        }
        const double alpha = x0 >= 0.0 ? -nx : nx;
        e[j] = alpha;
        // v = x − α e₀, β = 2 / vᵀv
        double vv = 0.0;
        for (int i = j + 1; i < k; ++i) {
            v[i] = X[i * k + j];
            if (i == j + 1) v[i] -= alpha;
            vv += v[i] * v[i];
        }
        if (vv == 0.0) continue;
        const double beta = 2.0 / vv;
        // p = β X₂₂ v, w = p − (β pᵀv / 2) v, X₂₂ −= v wᵀ + w vᵀ
        double pv = 0.0;
        for (int i = j + 1; i < k; ++i) {
            double s = 0.0;
            for (int c = j + 1; c < k; ++c) s += X[i * k + c] * v[c];
            w[i] = beta * s;
            pv += w[i] * v[i];
        }
        const double half = 0.5 * beta * pv;
        for (int i = j + 1; i < k; ++i) w[i] -= half * v[i];
        for (int i = j + 1; i < k; ++i)
            for (int c = j + 1; c < k; ++c) X[i * k + c] -= v[i] * w[c] + w[i] * v[c];
    }
    d[k - 2] = X[(k - 2) * k + (k - 2)];
    e[k - 2] = X[(k - 1) * k + (k - 2)];
    d[k - 1] = X[(k - 1) * k + (k - 1)];
    // Gershgorin interval of T, the squared subdiagonal, the pivot guard
    double lo = inf, hi = -inf, e2max = 0.0;
    for (int i = 0; i < k; ++i) {
        const double r = (i > 0 ? std::fabs(e[i - 1]) : 0.0) + (i + 1 < k ? std::fabs(e[i]) : 0.0);
        lo = std::min(lo, d[i] - r);
        hi = std::max(hi, d[i] + r);
    }
    for (int i = 0; i + 1 < k; ++i) {
        v[i] = e[i] * e[i];
        e2max = std::max(e2max, v[i]);
    }
    const double pivmin = std::numeric_limits<double>::min() * std::max(1.0, e2max);
    const double eps = std::numeric_limits<double>::epsilon();
    const double tnorm = std::max(std::fabs(lo), std::fabs(hi));
    auto below = [&](double x) {  // whether T has an eigenvalue < x (a negative pivot)
        double q = d[0] - x;
        if (std::fabs(q) < pivmin) q = -pivmin;
        if (q <= 0.0) return true;
        for (int i = 1; i < k; ++i) {
            q = d[i] - x - v[i - 1] / q;
            if (std::fabs(q) < pivmin) q = -pivmin;
            if (q <= 0.0) return true;
        }
        return false;
    };
    // (the count stops at the first nonpositive pivot: only "at least one eigenvalue below x"
    // is needed for the smallest)
    const double tol0 = eps * tnorm;
    // Newton's method on det(T − x I) from x = 0 (T positive definite there: every pivot > 0),
    // deterministic (no warm start: a resumed run stays bitwise the uninterrupted one): with
    // only real roots it increases monotonically to the smallest, quadratically at a simple one.
    // The step is 1 / tr((T − x I)⁻¹) = −1 / Σ q_i'/q_i over the pivots q_i and their
    // derivatives q_i' = −1 + e_{i−1}² q_{i−1}' / q_{i−1}²; at most 60 steps, else bisection.
    auto newton = [&](double x, double& dx) {  // false: a pivot ≤ 0 (x ≥ the smallest eigenvalue)
        double q = d[0] - x;
        if (!(q > pivmin)) return false;
        double r = 1.0 / q, qp = -1.0, S = -r;
        for (int i = 1; i < k; ++i) {
            q = d[i] - x - v[i - 1] * r;
            if (!(q > pivmin)) return false;
            qp = -1.0 + v[i - 1] * qp * (r * r);
            r = 1.0 / q;
            S += qp * r;
        }
        dx = -1.0 / S;
        return std::isfinite(dx) && dx >= 0.0;
    };
    {
        double x = 0.0, dx = 0.0;
        if (newton(x, dx)) {
            for (int it = 0; it < 60; ++it) {  // (4.3 steps on average, at most 14, same test)
                const double xn = x + dx;
                if (dx <= std::max(2.0 * eps * std::fabs(xn), tol0)) return xn;
                double dn = 0.0;
                // a pivot ≤ 0 at xn: in exact arithmetic xn ≤ λ_min, so xn is within round-off
                // of it (measured on 2000 random Gram matrices, k ≤ 32: |error| ≤ 0.75 k eps ‖G‖)
                if (!newton(xn, dn)) return xn;
                x = xn;
                dx = dn;
                lo = x;
            }
        }
    }
    lo -= 2.0 * eps * tnorm + pivmin;
    hi += 2.0 * eps * tnorm + pivmin;
    for (int it = 0; it < 200; ++it) {
        const double mid = 0.5 * (lo + hi);
        if (hi - lo <= std::max(2.0 * eps * std::max(std::fabs(lo), std::fabs(hi)), tol0) || mid == lo || mid == hi)
            break;
        if (below(mid))
            hi = mid;
        else
            lo = mid;
    }
    return 0.5 * (lo + hi);
}

void passage_setup(Loop& L) {
    Passages& P = L.pas;
    const int mr = std::max(L.m_all, 1), n = L.n;
    // (B, G, C and col_rows: sized by make_loop, a spare loop's kept as they are)
    for (Vec* v : {&P.x, &P.y, &P.v, &P.w}) *v = Vec::Zero(mr);
    P.live.assign(static_cast<std::size_t>(mr), 0);
    P.order.assign(static_cast<std::size_t>(mr), 0);
    P.first.assign(static_cast<std::size_t>(mr), 0);
    P.col_ptr.assign(static_cast<std::size_t>(n) + 1, 0);
    P.tri = Vec::Zero(4 * mr);
    if (L.opt.method == Method::dopri5) {  // DormandPrince5.passage_fractions: nodes 0.3 | 0.8
        P.frac[0] = 0.45, P.frac[1] = 0.55, P.frac[2] = 0.65;
        P.n_frac = 3;
    } else if (L.opt.method == Method::dop853 || L.opt.method == Method::rk8) {  // DOP853/RK8.passage_fractions: nodes 1/3 | 0.6
        P.frac[0] = 0.41, P.frac[1] = 0.465, P.frac[2] = 0.52;
        P.n_frac = 3;
    } else {  // Integrator.passage_fractions (RK4, implicit midpoint)
        P.frac[0] = 0.25, P.frac[1] = 0.75;
        P.n_frac = 2;
    }
    P.widen = !detail::adaptive(L) && L.opt.method != Method::rk8;  // fixed-step methods but RK8 (RK8.widen_passages)
    passage_reset(L);
}

double singular_indicator(Loop& L, const Mat& A, int m) {
    Passages& P = L.pas;
    const int n = L.n;
    if (m == 0) return inf;
    // A = L.Ac with its known row pattern (sim_loop.cpp's evaluate): only the pattern's entries
    // are read and written (the others are 0; B's are then never read), in the same order, so
    // the indicator is bitwise the dense scan's
    const bool pat = &A == &L.Ac && !L.pc_start.empty() && !L.gathered.empty() && L.gathered == L.rows;
    const int* pst = pat ? L.pc_start.data() : nullptr;
    const int* pco = pat ? L.pc_cols.data() : nullptr;
    double big = 0.0;
    for (int i = 0; i < m; ++i) {
        P.w[i] = pat ? linalg::row_norm_pattern(&A(i, 0), n, pco + pst[i], pst[i + 1] - pst[i])
                     : linalg::row_norm(&A(i, 0), n);
        big = std::max(big, P.w[i]);
    }
    if (!(big > 0.0 && std::isfinite(big))) {
        P.v_len = -1;
        return 0.0;
    }
    int k = 0;
    for (int i = 0; i < m; ++i)
        if (P.w[i] > PASSAGE_ROW_RTOL * big) P.live[static_cast<std::size_t>(k++)] = i;
    // the equilibrated live rows; rows ordered by their first nonzero column (so the Gram
    // matrix of a chain is banded: the Cholesky factor stays in its envelope)
    for (int r = 0; r < k; ++r) {
        const int i = P.live[static_cast<std::size_t>(r)];
        const double d = 1.0 / P.w[i];
        int fc = n;
        if (pat) {
            for (int t = pst[i]; t < pst[i + 1]; ++t) {
                const int j = pco[t];
                const double b = A(i, j) * d;
                P.B(r, j) = b;
                if (b != 0.0 && fc == n) fc = j;
            }
        } else {
            for (int j = 0; j < n; ++j) {
                const double b = A(i, j) * d;
                P.B(r, j) = b;
                if (b != 0.0 && fc == n) fc = j;
            }
        }
        P.first[static_cast<std::size_t>(r)] = fc;
        P.order[static_cast<std::size_t>(r)] = r;
    }
    bool in_order = true;  // (the rows mostly come by first column: the stable sort is then the identity)
    for (int r = 1; r < k && in_order; ++r)
        in_order = !(P.first[static_cast<std::size_t>(r)] < P.first[static_cast<std::size_t>(r) - 1]);
    if (!in_order)
        std::stable_sort(P.order.begin(), P.order.begin() + k,
                         [&P](int a, int b) { return P.first[static_cast<std::size_t>(a)] < P.first[static_cast<std::size_t>(b)]; });
    // column lists (permuted row positions, increasing)
    std::fill(P.col_ptr.begin(), P.col_ptr.end(), 0);
    auto each_nonzero = [&](int r, auto&& f) {  // f(j) for the nonzero entries of B's row r, j increasing
        if (pat) {
            const int i = P.live[static_cast<std::size_t>(r)];
            for (int t = pst[i]; t < pst[i + 1]; ++t)
                if (P.B(r, pco[t]) != 0.0) f(pco[t]);
        } else {
            for (int j = 0; j < n; ++j)
                if (P.B(r, j) != 0.0) f(j);
        }
    };
    for (int p = 0; p < k; ++p)
        each_nonzero(P.order[static_cast<std::size_t>(p)], [&](int j) { ++P.col_ptr[static_cast<std::size_t>(j) + 1]; });
    for (int j = 0; j < n; ++j) P.col_ptr[static_cast<std::size_t>(j) + 1] += P.col_ptr[static_cast<std::size_t>(j)];
    {
        // fill (col_ptr as running cursor, restored after)
        for (int p = 0; p < k; ++p)
            each_nonzero(P.order[static_cast<std::size_t>(p)], [&](int j) {
                P.col_rows[static_cast<std::size_t>(P.col_ptr[static_cast<std::size_t>(j)]++)] = p;
            });
        for (int j = n; j > 0; --j) P.col_ptr[static_cast<std::size_t>(j)] = P.col_ptr[static_cast<std::size_t>(j) - 1];
        P.col_ptr[0] = 0;
    }
    // the envelope first[p] of G's lower triangle (the first row sharing a column with row p),
    // zeroed there; G = (DA)(DA)ᵀ in the permuted order accumulated over it
    for (int p = 0; p < k; ++p) P.first[static_cast<std::size_t>(p)] = p;
    for (int j = 0; j < n; ++j) {
        const int a0 = P.col_ptr[static_cast<std::size_t>(j)], a1 = P.col_ptr[static_cast<std::size_t>(j) + 1];
        if (a1 > a0) {
            const int p0 = P.col_rows[static_cast<std::size_t>(a0)];  // (the lists increase)
            for (int a = a0 + 1; a < a1; ++a) {
                const int pa = P.col_rows[static_cast<std::size_t>(a)];
                if (p0 < P.first[static_cast<std::size_t>(pa)]) P.first[static_cast<std::size_t>(pa)] = p0;
            }
        }
    }
    for (int p = 0; p < k; ++p)  // (the dense eigensolver reads the whole lower triangle)
        for (int q = k <= PASSAGE_DENSE_ROWS ? 0 : P.first[static_cast<std::size_t>(p)]; q <= p; ++q) P.G(p, q) = 0.0;
    for (int j = 0; j < n; ++j) {
        const int a0 = P.col_ptr[static_cast<std::size_t>(j)], a1 = P.col_ptr[static_cast<std::size_t>(j) + 1];
        for (int a = a0; a < a1; ++a) {
            const int pa = P.col_rows[static_cast<std::size_t>(a)];
            const double ba = P.B(P.order[static_cast<std::size_t>(pa)], j);
            for (int b = a0; b <= a; ++b) {
                const int pb = P.col_rows[static_cast<std::size_t>(b)];
                P.G(pa, pb) += ba * P.B(P.order[static_cast<std::size_t>(pb)], j);
            }
        }
    }
    if (k <= PASSAGE_DENSE_ROWS) {  // the smallest eigenvalue of G (lower triangle), dense
        P.v_len = -1;
        double* X = P.C.data();  // (k × k packed: C holds mr × mr ≥ k²; tri holds 4 mr ≥ 4 k)
        for (int p = 0; p < k; ++p)
            for (int q = 0; q <= p; ++q) X[p * k + q] = P.G(p, q);
        const double lam = sym_min_eigenvalue(X, k, P.tri.data(), P.tri.data() + k);
        if (!std::isfinite(lam)) return 0.0;
        return std::sqrt(std::max(lam, 0.0));
    }
    // Cholesky G = C Cᵀ over the envelope (no fill outside it)
    for (int p = 0; p < k; ++p) {
        const int fp = P.first[static_cast<std::size_t>(p)];
        for (int q = fp; q <= p; ++q) {
            double acc = P.G(p, q);
            const int lo = std::max(fp, P.first[static_cast<std::size_t>(q)]);
            for (int r = lo; r < q; ++r) acc -= P.C(p, r) * P.C(q, r);
            if (q < p) {
                P.C(p, q) = acc / P.C(q, q);
            } else {
                if (!(acc > 0.0) || !std::isfinite(acc)) {
                    P.v_len = -1;
                    return 0.0;
                }
                P.C(p, p) = std::sqrt(acc);
            }
        }
    }
    // inverse iteration from the kept vector (natural order of the live rows) or a fixed start
    if (P.v_len == k) {
        for (int r = 0; r < k; ++r) P.x[r] = P.v[r];
    } else {
        for (int r = 0; r < k; ++r) P.x[r] = 1.0 + 0.5 * std::sin(1.0 + r);
    }
    double nx = 0.0;
    for (int r = 0; r < k; ++r) nx += P.x[r] * P.x[r];
    nx = std::sqrt(nx);
    for (int r = 0; r < k; ++r) P.x[r] /= nx;
    double lam = inf;
    for (int it = 0; it < PASSAGE_MAX_ITERATIONS; ++it) {
        for (int p = 0; p < k; ++p) {  // C u = P x
            const int fp = P.first[static_cast<std::size_t>(p)];
            double acc = P.x[P.order[static_cast<std::size_t>(p)]];
            for (int r = fp; r < p; ++r) acc -= P.C(p, r) * P.w[r];
            P.w[p] = acc / P.C(p, p);
        }
        for (int p = k - 1; p >= 0; --p) {  // Cᵀ z = u (column sweep over the envelope rows)
            const double zp = P.w[p] / P.C(p, p);
            P.w[p] = zp;
            const int fp = P.first[static_cast<std::size_t>(p)];
            for (int r = fp; r < p; ++r) P.w[r] -= P.C(p, r) * zp;
        }
        double ny = 0.0, xy = 0.0;
        for (int p = 0; p < k; ++p) {
            const int r = P.order[static_cast<std::size_t>(p)];
            P.y[r] = P.w[p];
        }
        for (int r = 0; r < k; ++r) {
            ny += P.y[r] * P.y[r];
            xy += P.x[r] * P.y[r];
        }
        ny = std::sqrt(ny);
        if (!(ny > 0.0 && std::isfinite(ny))) {
            P.v_len = -1;
            return 0.0;
        }
        const double prev = lam;
        lam = xy / (ny * ny);
        for (int r = 0; r < k; ++r) P.x[r] = P.y[r] / ny;
        if (std::abs(lam - prev) <= PASSAGE_ITER_RTOL * lam) break;
    }
    for (int r = 0; r < k; ++r) P.v[r] = P.x[r];
    P.v_len = k;
    return std::sqrt(std::max(lam, 0.0));
}

double passage_noise(const Loop& L) {
    if (!L.opt.passages || !std::isfinite(L.pas.sigma)) return 0.0;
    // below the floor: a permanently redundant row (Bricard's mechanism), not a passage
    if (!(L.pas.sigma >= PASSAGE_FLOOR && std::isfinite(L.pas.sigma))) return 0.0;
    return PASSAGE_NOISE * std::numeric_limits<double>::epsilon() / L.pas.sigma;
}

void passage_reset(Loop& L) {
    L.pas.have_last = false;
    L.pas.rate = 0.0;
    L.pas.sigma = inf;
    L.pas.count = 0;
    L.pas.have_star = false;
    L.pas.v_len = -1;
}

void passage_observe(Loop& L, double t, const Mat& A, int m) {
    Passages& P = L.pas;
    const double s = singular_indicator(L, A, m);
    P.sigma = s;
    if (!(s >= PASSAGE_FLOOR && std::isfinite(s))) {
        P.count = 0;
        P.have_star = false;
        P.have_last = false;
        P.rate = 0.0;
        return;
    }
    P.rate = (P.have_last && t > P.last_t) ? std::abs(s - P.ss_last) / (t - P.last_t) : 0.0;
    P.have_last = true;
    P.last_t = t;
    P.ss_last = s;
    if ((P.count && !(t > P.ts[P.count - 1])) || (P.have_star && t >= P.t_star)) P.count = 0;
    if (P.count == 3) {
        for (int i = 0; i < 2; ++i) {
            P.ts[i] = P.ts[i + 1];
            P.ss[i] = P.ss[i + 1];
        }
        P.count = 2;
    }
    P.ts[P.count] = t;
    P.ss[P.count] = s;
    ++P.count;
    P.have_star = passage_time(P, P.t_star);
}

// _integrators.place_step
double passage_place(const Loop& L, double t, double h) {
    const Passages& P = L.pas;
    if (!L.opt.passages || !P.have_star) return h;
    const double g = P.t_star - t;
    double H = h;
    if (P.widen && P.rate > 0.0)
        H = std::min(std::max(h, PASSAGE_SIGMA / (P.frac[0] * P.rate)), PASSAGE_WIDEN_MAX * h);
    if (H > h) {  // the passage step H (place_step with H > h)
        if (!(g > 0.0)) return h;
        const double x = g / H;
        for (int i = 0; i < P.n_frac; ++i)
            if (std::abs(x - P.frac[i]) <= PASSAGE_BAND) return H;
        double fit = -inf, dmin = inf;
        for (int i = 0; i < P.n_frac; ++i) {
            const double d = g - P.frac[i] * H;
            if (!(d > 0.0)) continue;
            if (d <= h) fit = std::max(fit, d);
            dmin = std::min(dmin, d);
        }
        if (fit > -inf) return fit;
        if (dmin < inf) return dmin - h >= 0.2 * h ? h : 0.5 * dmin;
        double best = -inf;
        for (int i = 0; i < P.n_frac; ++i) {
            const double s = g / P.frac[i];
            if (s <= H) best = std::max(best, s);
        }
        return best > -inf ? best : h;
    }
    const double fmax = P.frac[P.n_frac - 1];
    if (!(g > 0.0) || g > (1.0 + fmax + PASSAGE_BAND) * h) return h;
    const double x = g / h;
    for (int i = 0; i < P.n_frac; ++i) {
        const double c = P.frac[i];
        if (std::abs(x - c) <= PASSAGE_BAND || std::abs(x - 1.0 - c) <= PASSAGE_BAND) return h;
    }
    double best = 0.0;
    for (int i = 0; i < P.n_frac; ++i) {
        const double c = P.frac[i];
        double s = g / c;
        if (s <= h) best = std::max(best, s);
        s = g - c * h;
        if (0.2 * h <= s && s <= h) best = std::max(best, s);
    }
    return best > 0.0 ? best : h;
}

// _integrators.SingularPassages.stages: the predicted instant lies within PASSAGE_STAGE_AHEAD
// steps ahead (this step or the next holds it), or nearer (τ = σ/|σ̇|, either side) than both
// PASSAGE_STAGE_K steps and PASSAGE_STAGE_WINDOW times the motion's own time scale ‖q̇‖/‖q̈‖
// (f = F(t, y) = (q̇, q̈)); docs/theory.md, "Projected RK4 stages near a singular passage"
bool passage_stages(const Loop& L, double t, double h, const double* f) {
    const Passages& P = L.pas;
    if (!L.opt.passages || !std::isfinite(P.sigma) || !(P.sigma >= PASSAGE_FLOOR)) return false;
    if (P.have_star && P.t_star > t && P.t_star - t <= PASSAGE_STAGE_AHEAD * h) return true;
    if (!(PASSAGE_STAGE_K * P.rate * h > P.sigma)) return false;
    const int n = L.n;
    double v2 = 0.0, a2 = 0.0;
    for (int i = 0; i < n; ++i) {
        v2 += f[i] * f[i];
        a2 += f[n + i] * f[n + i];
    }
    return P.sigma * std::sqrt(a2) < PASSAGE_STAGE_WINDOW * P.rate * std::sqrt(v2);
}

// _integrators.SingularPassages.holds
bool passage_holds(const Loop& L, double t, double h) {
    const Passages& P = L.pas;
    if (!L.opt.passages || !P.have_star) return false;
    return P.t_star > t && P.t_star - t <= (1.0 + PASSAGE_BAND) * h;
}

void hermite_quintic(int n, const double* y0, const double* f0, const double* y1, const double* f1,
                     double h, double s, double* out) {
    const double t = s / h;
    const double t2 = t * t, t3 = t2 * t, t4 = t3 * t, t5 = t4 * t;
    const double b1 = 10.0 * t3 - 15.0 * t4 + 6.0 * t5;
    const double b2 = t - 6.0 * t3 + 8.0 * t4 - 3.0 * t5;
    const double b3 = -4.0 * t3 + 7.0 * t4 - 3.0 * t5;
    const double b4 = 0.5 * (t2 - 3.0 * t3 + 3.0 * t4 - t5);
    const double b5 = 0.5 * (t3 - 2.0 * t4 + t5);
    const double d1 = 30.0 * t2 - 60.0 * t3 + 30.0 * t4;
    const double d2 = 1.0 - 18.0 * t2 + 32.0 * t3 - 15.0 * t4;
    const double d3 = -12.0 * t2 + 28.0 * t3 - 15.0 * t4;
    const double d4 = t - 4.5 * t2 + 6.0 * t3 - 2.5 * t4;
    const double d5 = 1.5 * t2 - 4.0 * t3 + 2.5 * t4;
    const double hh = h * h;
    for (int i = 0; i < n; ++i) {
        const double dq = y1[i] - y0[i];
        const double v0 = f0[i], v1 = f1[i], a0 = f0[n + i], a1 = f1[n + i];
        out[i] = y0[i] + dq * b1 + h * (v0 * b2 + v1 * b3) + hh * (a0 * b4 + a1 * b5);
        out[n + i] = (dq / h) * d1 + (v0 * d2 + v1 * d3) + h * (a0 * d4 + a1 * d5);
    }
}
}  // namespace nonmin::sim
