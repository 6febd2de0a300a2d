// Forward dynamics from a state: one Program evaluation followed by the core solve (the
// pipeline MuJoCo calls mj_forward): q̈(t, q, q̇) under an active mask. Used by the batched
// model + kernel evaluation and its benchmark (benchmarks/model_bench.py).
#pragma once
#include <cstdint>
#include <memory>
#include <vector>

#include "program.hpp"
#include "solver.hpp"

namespace nonmin {

// Scratch of one thread for one Program and active mask (sizes fixed at construction).
struct ForwardScratch {
    ForwardScratch(const Program& p, const std::uint8_t* active);

    Terms terms;
    std::unique_ptr<Workspace> ws;
    Solver solver;
    std::vector<std::uint8_t> active;
    std::vector<int> rows;  // active rows, in order
    bool contiguous = true;  // active rows are 0..m−1 (A, γ used in place)
    int m = 0;
    Mat A;   // gathered active rows (when not contiguous)
    Vec gamma;
    Vec g;   // h + f_passive
    // A's known row pattern restricted to the active rows (program.hpp's RowPattern; empty:
    // unknown): the solve reads only those entries (SolveOptions::a_start, results bitwise equal)
    std::vector<int> pat_start, pat_cols;
    bool mass_known = false;  // constant M evaluated and validated once
    unsigned known = 0;       // SolveOptions::known for a constant M
};

// q̈ at (t, q, q̇) (and f_c if not null); `opt.known` is completed for a constant M.
// f: applied generalized forces added to h + f_passive (n-vector, or null for none).
SolveInfo forward_dynamics(const Program& p, ForwardScratch& s, double t, const double* q,
                           const double* qd, const double* f, const SolveOptions& opt, double* qdd,
                           double* f_c);

}  // namespace nonmin
