// Model + kernel over a batch of states: for each state i, evaluate the Program at
// (t_i, q_i, qd_i) under one active set, then solve the projection dynamics (forward_dynamics of
// forward.hpp) for q̈_i and f_c,i. Threads (the calling one included) take chunks of consecutive
// states from a shared counter, each with its own ForwardScratch (preallocated once per call);
// a single state and the same state inside a batch give bitwise identical results (same code,
// same order of operations), whatever the thread and the chunk.
#pragma once
#include <cstdint>
#include <memory>
#include <vector>

#include "forward.hpp"
#include "program.hpp"
#include "solver.hpp"

namespace nonmin {

// Every entry is written (the arrays may be uninitialized memory: the threads touch their pages
// first); a failed state's q̈ and f_c read 0.
struct BatchOutputs {
    double* qdd = nullptr;  // N × n (required)
    double* f_c = nullptr;  // N × n or null
    int* rank = nullptr;    // N or null
    int* status = nullptr;  // N (required): Status of each state (0 ok)
};

// The per-thread scratch of earlier calls, kept by the caller for the next call of the same
// Program and active mask (entry j: worker j's; null entries are made by their worker, which
// touches its pages first). A ForwardScratch of A02 N = 40 (n = 243, m = 242) is ~10 MB of
// zeroed buffers: making it took ~7.7 ms per thread and call (CPU, 07:20 UTC), 0.77 µs per
// state of a 10⁴-state batch and 19 µs per state of a 400-state one. Results do not depend on
// it (a scratch holds no state between two states but the validated constant M, which is the
// same for every state).
using ScratchPool = std::vector<std::unique_ptr<ForwardScratch>>;

// f: applied generalized forces, N × n (row stride f_stride: 0 broadcasts one row; null = 0).
// Returns the number of states whose status is not ok. threads ≤ 0: hardware concurrency;
// a Program that is not thread safe runs on the calling thread only. pool: reused scratch
// (null: made for this call); it must belong to this program and active mask.
int forward_batch(const Program& program, int N, const double* t, const double* q, const double* qd,
                  const std::uint8_t* active, const double* f, int f_stride, const SolveOptions& opt,
                  int threads, BatchOutputs out, ScratchPool* pool = nullptr);

}  // namespace nonmin
