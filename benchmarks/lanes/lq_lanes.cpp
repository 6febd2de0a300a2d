// Measured potential of lock-step SIMD lanes for the batched engine (issue 20, target 1):
// one kernel of a run's step — the Householder LQ of the equilibrated constraint matrix D A by
// rows, and L y = D b by substitution — written once over a scalar type T and run with
// T = double (one run at a time, as the engine does) and T = 4 doubles in one AVX2 register
// (four runs in lock step). The matrices are the crossed four-bar's A (8 × 9) at the states of
// runs of sweep_bench.py (file written by lanes.py), equilibrated by rows. Built with
// -ffp-contract=off (no FMA contraction: a lane's result must be bitwise the scalar run's;
// vsqrtpd / vdivpd round like their scalar forms): the program checks the bitwise equality.
// Not the engine's lq_certified (no pivoting by value, no rank certificate, no sparse column
// lists): it measures what lanes give on the arithmetic of this kernel, the best case.
//
//   g++ -O3 -mavx2 -ffp-contract=off -o /tmp/lq_lanes benchmarks/lanes/lq_lanes.cpp
//   /tmp/lq_lanes A.bin K m n
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

typedef double v4 __attribute__((vector_size(32)));

inline double vsqrt(double x) { return std::sqrt(x); }
inline v4 vsqrt(v4 x) { return v4{std::sqrt(x[0]), std::sqrt(x[1]), std::sqrt(x[2]), std::sqrt(x[3])}; }
inline double sel_nonneg(double x, double a, double b) { return x >= 0.0 ? a : b; }
inline v4 sel_nonneg(v4 x, v4 a, v4 b) {
    auto m = x >= 0.0;  // lane mask
    return m ? a : b;
}
inline double vabs(double x) { return std::fabs(x); }
inline v4 vabs(v4 x) { return x < 0.0 ? -x : x; }

// X: m × n row-major of T (overwritten: L in its lower triangle), b: m (overwritten: y = L⁻¹ b),
// v: scratch n. Row equilibration first (D = 1 / ‖row‖₂), then reflectors by rows.
template <class T>
void lq_solve(T* X, T* b, int m, int n, T* v) {
    for (int i = 0; i < m; ++i) {
        T s = X[i * n] * X[i * n];
        for (int k = 1; k < n; ++k) s += X[i * n + k] * X[i * n + k];
        const T d = 1.0 / vsqrt(s);
        for (int k = 0; k < n; ++k) X[i * n + k] = X[i * n + k] * d;
        b[i] = b[i] * d;
    }
    for (int j = 0; j < m; ++j) {
        T* Xj = X + j * n;
        T s = Xj[j] * Xj[j];
        for (int k = j + 1; k < n; ++k) s += Xj[k] * Xj[k];
        const T x0 = Xj[j];
        const T nrm = vsqrt(s);
        const T alpha = sel_nonneg(x0, -nrm, nrm);
        const T v0 = x0 - alpha;
        const T bj = 2.0 / (s - x0 * x0 + v0 * v0);
        v[j] = v0;
        for (int k = j + 1; k < n; ++k) v[k] = Xj[k];
        Xj[j] = alpha;
        for (int k = j + 1; k < n; ++k) Xj[k] = T{} * 0.0;
        for (int i = j + 1; i < m; ++i) {
            T* Xi = X + i * n;
            T dot = Xi[j] * v[j];
            for (int k = j + 1; k < n; ++k) dot += Xi[k] * v[k];
            dot = dot * bj;
            for (int k = j; k < n; ++k) Xi[k] = Xi[k] - dot * v[k];
        }
    }
    for (int i = 0; i < m; ++i) {  // L y = b
        T r = b[i];
        for (int k = 0; k < i; ++k) r = r - X[i * n + k] * b[k];
        b[i] = r / X[i * n + i];
    }
}

int main(int argc, char** argv) {
    if (argc < 5) {
        std::fprintf(stderr, "usage: lq_lanes A.bin K m n\n");
        return 2;
    }
    const int K = std::atoi(argv[2]), m = std::atoi(argv[3]), n = std::atoi(argv[4]);
    std::vector<double> A(static_cast<size_t>(K) * m * n);
    FILE* f = std::fopen(argv[1], "rb");
    if (!f || std::fread(A.data(), sizeof(double), A.size(), f) != A.size()) return 3;
    std::fclose(f);
    const int K4 = K / 4 * 4;
    std::vector<double> Xs(static_cast<size_t>(K4) * m * n), bs(static_cast<size_t>(K4) * m), vs(n);
    std::vector<v4> Xl(static_cast<size_t>(K4 / 4) * m * n), bl(static_cast<size_t>(K4 / 4) * m), vl(n);
    auto load = [&]() {
        std::memcpy(Xs.data(), A.data(), Xs.size() * sizeof(double));
        for (int r = 0; r < K4; ++r)
            for (int i = 0; i < m; ++i) bs[r * m + i] = 0.1 * (i + 1) + 1e-3 * r;
        for (int g = 0; g < K4 / 4; ++g)
            for (int e = 0; e < m * n; ++e)
                for (int l = 0; l < 4; ++l) Xl[g * m * n + e][l] = A[(static_cast<size_t>(4 * g + l)) * m * n + e];
        for (int g = 0; g < K4 / 4; ++g)
            for (int i = 0; i < m; ++i)
                for (int l = 0; l < 4; ++l) bl[g * m + i][l] = bs[(4 * g + l) * m + i];
    };
    using clk = std::chrono::steady_clock;
    double best_s = 1e30, best_l = 1e30;
    for (int rep = 0; rep < 15; ++rep) {  // interleaved: scalar, lanes, scalar, ...
        load();
        auto t0 = clk::now();
        for (int r = 0; r < K4; ++r) lq_solve<double>(&Xs[static_cast<size_t>(r) * m * n], &bs[r * m], m, n, vs.data());
        auto t1 = clk::now();
        for (int g = 0; g < K4 / 4; ++g) lq_solve<v4>(&Xl[static_cast<size_t>(g) * m * n], &bl[g * m], m, n, vl.data());
        auto t2 = clk::now();
        best_s = std::min(best_s, std::chrono::duration<double>(t1 - t0).count());
        best_l = std::min(best_l, std::chrono::duration<double>(t2 - t1).count());
    }
    long diff = 0;
    for (int g = 0; g < K4 / 4; ++g)
        for (int l = 0; l < 4; ++l) {
            for (int e = 0; e < m * n; ++e)
                diff += std::memcmp(&Xl[g * m * n + e][l], &Xs[(static_cast<size_t>(4 * g + l)) * m * n + e], 8) != 0;
            for (int i = 0; i < m; ++i) diff += std::memcmp(&bl[g * m + i][l], &bs[(4 * g + l) * m + i], 8) != 0;
        }
    std::printf("K %d (%d x %d): scalar %.1f ns/matrix, 4 lanes %.1f ns/matrix, lanes/scalar %.2f, "
                "entries differing bitwise %ld\n",
                K4, m, n, 1e9 * best_s / K4, 1e9 * best_l / K4, best_l / best_s, diff);
    return diff != 0;
}
